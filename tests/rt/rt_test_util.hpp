// SPDX-License-Identifier: BSD-3-Clause
// Test helpers shared by the rt suites.
#pragma once
#include <string>

/// The error of a Result, or "" when it holds a value (safe inside *_MESSAGE, which doctest
/// may evaluate on success too).
template <class R>
std::string err_of(const R& r) {
  return r.ok() ? std::string() : r.error();
}
