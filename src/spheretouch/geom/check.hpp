// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// ST_ASSERT(cond, what): an invariant the code relies on (what a comment would call "cannot
/// happen", or a precondition a caller must meet). Checked in debug, sanitizer and fuzzer builds
/// (meson defines ST_CHECKS there): a broken one calls the assert handler, by default printing the
/// file, line, condition and `what` and aborting, so the fuzzers and the sanitizer suites see it.
/// Compiled out of release builds (the expression is still type-checked, never evaluated). Bad
/// INPUT is never an invariant: it gets a Result error or a flag.
#pragma once
#include <spheretouch/abi.hpp>

namespace st {
inline namespace SPHERETOUCH_ABI {

/// What a broken invariant reports.
struct AssertInfo {
  const char* cond;  ///< the condition's text
  const char* what;  ///< what it means, in words
  const char* file;  ///< source file of the ST_ASSERT
  int line;          ///< its line
};

/// Called when an ST_ASSERT fails. It must not return: abort, or throw (a test checking that an
/// assert fires; the throw then leaves through the asserting function, so only where that
/// function is not noexcept). If it returns, the default report and abort follow.
using AssertHandler = void (*)(const AssertInfo&);

/// Installs `handler` for every thread (nullptr: the default, print and abort); returns the
/// previous one.
AssertHandler set_assert_handler(AssertHandler handler) noexcept;

/// True when the library itself was compiled with its ST_ASSERTs checked (ST_CHECKS).
bool library_checks_enabled() noexcept;

namespace detail {
/// The failure path of ST_ASSERT: the handler, then the default report and abort.
[[noreturn]] void assert_failed(const char* cond, const char* what, const char* file, int line);
}  // namespace detail

}  // namespace SPHERETOUCH_ABI
}  // namespace st

#if defined(ST_CHECKS)
/// Checks an invariant: when `cond` is false, calls the assert handler (set_assert_handler()).
#define ST_ASSERT(cond, what) \
  ((cond) ? static_cast<void>(0) : ::st::detail::assert_failed(#cond, what, __FILE__, __LINE__))
#else
/// An invariant, checked where ST_CHECKS is defined (debug, sanitizer, fuzzer builds); here only
/// type-checked, never evaluated.
#define ST_ASSERT(cond, what) static_cast<void>(sizeof((cond) ? 1 : 0))
#endif
