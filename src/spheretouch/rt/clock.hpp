// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Monotonic time in integer nanoseconds, the one clock of the real-time core. CLOCK_MONOTONIC
/// is system-wide, so timestamps compare across processes sharing a segment (ShmSegment).
/// On Linux x86-64 clock_gettime is served by the vDSO (no system call) when the clocksource
/// is tsc or kvm-clock; the haptic tick relies on that (HapticLoop: "no syscall but the sleep").
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <ctime>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Now on CLOCK_MONOTONIC, ns.
inline std::int64_t now_ns() noexcept {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

/// A nanosecond count as a timespec (non-negative input).
inline timespec to_timespec(std::int64_t ns) noexcept {
  timespec ts;
  ts.tv_sec = static_cast<time_t>(ns / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(ns % 1'000'000'000);
  return ts;
}

}  // namespace st::rt
