// SPDX-License-Identifier: BSD-3-Clause
// The assert handler of ST_ASSERT (check.hpp).
#include <spheretouch/geom/check.hpp>

#include <atomic>
#include <cstdio>
#include <cstdlib>

namespace st {
inline namespace SPHERETOUCH_ABI {
namespace {
std::atomic<AssertHandler> g_handler{nullptr};
}  // namespace

AssertHandler set_assert_handler(AssertHandler handler) noexcept { return g_handler.exchange(handler); }

bool library_checks_enabled() noexcept {
#if defined(ST_CHECKS)
  return true;
#else
  return false;
#endif
}

void detail::assert_failed(const char* cond, const char* what, const char* file, int line) {
  if (const AssertHandler h = g_handler.load()) h(AssertInfo{cond, what, file, line});
  std::fprintf(stderr, "%s:%d: invariant broken: %s (%s)\n", file, line, what, cond);
  std::fflush(stderr);
  std::abort();
}

}  // namespace SPHERETOUCH_ABI
}  // namespace st
