// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// ST_ASSERT(cond, what): an invariant the code relies on (what a comment would call "cannot
/// happen"). Checked in debug, sanitizer and fuzzer builds (meson defines ST_CHECKS there): a
/// broken one prints the file, line, condition and `what`, then aborts, so the fuzzers and the
/// sanitizer suites see it. Compiled out of release builds (the expression is still type-checked,
/// never evaluated). Bad INPUT is never an invariant: it gets a Result error or a flag.
#pragma once
#include <spheretouch/abi.hpp>

#if defined(ST_CHECKS)
#include <cstdio>
#include <cstdlib>

namespace st::detail {
[[noreturn]] inline void assert_failed(const char* cond, const char* what, const char* file, int line) noexcept {
  std::fprintf(stderr, "%s:%d: invariant broken: %s (%s)\n", file, line, what, cond);
  std::fflush(stderr);
  std::abort();
}
}  // namespace st::detail

/// Checks an invariant: when `cond` is false, prints file, line, `cond` and `what`, then aborts.
#define ST_ASSERT(cond, what) \
  ((cond) ? static_cast<void>(0) : ::st::detail::assert_failed(#cond, what, __FILE__, __LINE__))
#else
/// An invariant, checked where ST_CHECKS is defined (debug, sanitizer, fuzzer builds); here only
/// type-checked, never evaluated.
#define ST_ASSERT(cond, what) static_cast<void>(sizeof((cond) ? 1 : 0))
#endif
