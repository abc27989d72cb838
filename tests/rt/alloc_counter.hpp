// SPDX-License-Identifier: BSD-3-Clause
// Test helper: counts heap allocations made while armed. Replaces the global operator new
// family (and, outside sanitizer builds, malloc/calloc/realloc via glibc's __libc_* entry
// points) for the whole test binary; disarmed it only forwards.
#pragma once
#include <atomic>
#include <cstdint>

namespace st::test {

/// Starts counting allocations (from any thread).
void arm_alloc_counter();
/// Stops counting; returns the allocations counted since arm_alloc_counter().
std::uint64_t disarm_alloc_counter();
/// The calling thread's allocations are never counted (e.g. a stand-in collision thread that
/// shares the process with the tick path under test).
void exclude_this_thread();
/// True when malloc itself is counted (not just operator new).
bool counts_malloc();

}  // namespace st::test
