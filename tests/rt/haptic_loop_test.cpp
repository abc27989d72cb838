// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/haptic_loop.*: deadline accounting with synthetic time (exact), a 2 s real run
// with tick and miss accounting (counts only, never wall-clock assertions), injected overruns,
// real-time refusals reported, and no heap allocation on the tick path.
#include <spheretouch/rt/haptic_loop.hpp>

#include <doctest/doctest.h>

#include "rt_test_util.hpp"

#include <chrono>
#include <thread>

#include "alloc_counter.hpp"
#include <spheretouch/rt/clock.hpp>

using namespace st::rt;

TEST_CASE("DeadlineSchedule: late wake-ups skip whole periods, never burst") {
  DeadlineSchedule s(1000, 100);
  CHECK(s.on_wake(1000) == 0);  // on time
  s.advance();
  CHECK(s.on_wake(1199) == 0);  // 99 late: still inside its period, runs late
  CHECK(s.index() == 1);
  s.advance();
  CHECK(s.on_wake(1300) == 1);  // deadline 1200 fully passed: skip to 1300
  CHECK(s.index() == 3);
  CHECK(s.deadline_ns() == 1300);
  s.advance();
  CHECK(s.on_wake(2050) == 6);  // deadlines 1400..1900 missed, run for 2000
  CHECK(s.deadline_ns() == 2000);
  CHECK(s.index() == 10);
}

namespace {
struct CountingHandler : TickHandler {
  std::uint64_t calls = 0;
  std::uint64_t last_index = 0;
  std::uint64_t index_gaps = 0;  // sum of (index - last_index - 1): the misses the handler saw
  // The misses of a run of `periods` deadlines as the handler can count them: the gaps before and
  // between its ticks, and the deadlines after its last tick (missed at the end of the run, seen
  // by no later tick).
  std::uint64_t misses_seen(std::uint64_t periods) const {
    return calls == 0 ? periods : index_gaps + (periods - 1 - last_index);
  }
  std::uint64_t slow_every = 0;  // every n-th tick busy-waits slow_periods
  double slow_periods = 0;
  std::uint64_t slow_ticks = 0;
  void tick(const TickInfo& info) noexcept override {
    if (calls > 0)
      index_gaps += info.deadline_index - last_index - 1;
    else
      index_gaps += info.deadline_index;
    last_index = info.deadline_index;
    ++calls;
    if (slow_every && calls % slow_every == 0) {
      ++slow_ticks;
      const std::int64_t until =
          info.woke_ns + static_cast<std::int64_t>(slow_periods * static_cast<double>(info.period_ns));
      while (now_ns() < until) {}
    }
  }
};
}  // namespace

TEST_CASE("HapticLoop: 2 s at 1 kHz, every deadline is a tick or a miss") {
  HapticLoopConfig c = DefaultHapticLoopConfig();
  c.max_periods = 2000;
  auto loop = std::make_unique<HapticLoop>(c);
  CountingHandler h;
  auto r = loop->run(h);
  REQUIRE_MESSAGE(r.ok(), err_of(r));
  const LoopStats& s = loop->stats();
  CHECK(s.ticks + s.misses == 2000);
  CHECK(s.ticks == h.calls);
  CHECK(s.misses == h.misses_seen(2000));
  CHECK(s.ticks > 0);
  CHECK(s.wake_latency.count() >= s.ticks);
  CHECK(s.tick_compute.count() == s.ticks);
  MESSAGE("ticks " << s.ticks << ", misses " << s.misses << ", wake p99 " << s.wake_latency.percentile_ns(0.99) << " ns");
}

TEST_CASE("HapticLoop: a tick that overruns 2.5 periods costs at least one miss, no burst") {
  HapticLoopConfig c = DefaultHapticLoopConfig();
  c.max_periods = 1000;
  auto loop = std::make_unique<HapticLoop>(c);
  CountingHandler h;
  h.slow_every = 100;
  h.slow_periods = 2.5;
  REQUIRE(loop->run(h).ok());
  const LoopStats& s = loop->stats();
  CHECK(s.ticks + s.misses == 1000);
  CHECK(h.slow_ticks >= 5);
  CHECK(s.misses >= h.slow_ticks);  // each slow tick spans >= 2 whole deadlines
  CHECK(s.overruns >= h.slow_ticks);
  CHECK(s.misses == h.misses_seen(1000));
}

TEST_CASE("HapticLoop: start/stop on its own thread; counters readable while running") {
  auto loop = std::make_unique<HapticLoop>(DefaultHapticLoopConfig());
  CountingHandler h;
  auto r = loop->start(h);
  REQUIRE(r.ok());
  CHECK(r.value().describe() == "no real-time settings requested");
  while (loop->ticks() < 50) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  loop->stop();
  CHECK_FALSE(loop->running());
  CHECK(loop->stats().ticks == h.calls);
  CHECK(loop->stats().ticks >= 50);
  loop->stop();  // idempotent
}

TEST_CASE("HapticLoop: real-time requests are reported, refusals never silent") {
  HapticLoopConfig c = DefaultHapticLoopConfig();
  c.cpu = 100000 % 1024;  // a CPU this machine does not have: refused with EINVAL
  c.prefault_stack_bytes = 64 * 1024;
  c.max_periods = 5;
  auto loop = std::make_unique<HapticLoop>(c);
  CountingHandler h;
  auto r = loop->run(h);
  REQUIRE(r.ok());
  CHECK(r.value().affinity.requested);
  CHECK_FALSE(r.value().affinity.applied);
  CHECK(r.value().prefault.applied);
  CHECK_FALSE(r.value().all_applied());
  CHECK(r.value().describe().find("CPU affinity: refused") != std::string::npos);

  c.strict = true;
  auto strict_loop = std::make_unique<HapticLoop>(c);
  auto rs = strict_loop->start(h);
  REQUIRE_FALSE(rs.ok());
  CHECK(rs.error().find("CPU affinity: refused") != std::string::npos);
  CHECK_FALSE(strict_loop->running());

  // SCHED_FIFO may or may not be granted here (root in a container, RT throttling); either way
  // the report says which.
  HapticLoopConfig f = DefaultHapticLoopConfig();
  f.fifo_priority = 10;
  f.max_periods = 3;
  auto fifo_loop = std::make_unique<HapticLoop>(f);
  auto rf = fifo_loop->start(h);  // own thread: the test thread keeps its policy
  REQUIRE(rf.ok());
  fifo_loop->stop();
  CHECK(rf.value().fifo.requested);
  CHECK(rf.value().fifo.applied == (rf.value().fifo.error == 0));
  MESSAGE("SCHED_FIFO request here: " << rf.value().describe());
}

TEST_CASE("HapticLoop: a pre-fault larger than the loop thread's stack is refused, not a crash") {
  // Sizes leave room for ThreadSanitizer, whose static TLS (~0.8 MB) comes out of every stack.
  constexpr std::size_t kStack = 4 << 20;
  struct RestoreDefault {  // later tests must get the old default even if a REQUIRE fails here
    std::size_t bytes = default_thread_stack();
    ~RestoreDefault() { (void)set_default_thread_stack(bytes); }
  } restore;
  REQUIRE(restore.bytes > 0);
  REQUIRE(set_default_thread_stack(kStack).ok());
  CHECK(default_thread_stack() == kStack);
  CountingHandler h;
  HapticLoopConfig c = DefaultHapticLoopConfig();
  c.max_periods = 3;
  c.prefault_stack_bytes = 4 * kStack;  // touching it would crash
  auto big = std::make_unique<HapticLoop>(c);
  auto r = big->start(h);
  REQUIRE(r.ok());
  big->stop();
  CHECK(r.value().prefault.requested);
  CHECK_FALSE(r.value().prefault.applied);
  CHECK(r.value().prefault.error == ENOMEM);
  CHECK(r.value().stack_left > 0);
  // glibc may hand out a cached stack up to 4x the asked size, so bound by the request, not kStack.
  CHECK(r.value().stack_left < c.prefault_stack_bytes);
  INFO(r.value().describe());
  CHECK(r.value().describe().find("stack pre-fault: refused") != std::string::npos);
  CHECK(r.value().describe().find("KiB of stack left") != std::string::npos);

  c.prefault_stack_bytes = kStack / 4;  // fits, with the margin kept free
  auto fits = std::make_unique<HapticLoop>(c);
  auto rf = fits->start(h);
  REQUIRE(rf.ok());
  fits->stop();
  CHECK(rf.value().prefault.applied);

  c.strict = true;  // strict: the refusal stops the start
  c.prefault_stack_bytes = 4 * kStack;
  auto strict_loop = std::make_unique<HapticLoop>(c);
  CHECK_FALSE(strict_loop->start(h).ok());

  CHECK_FALSE(set_default_thread_stack(1024).ok());  // below PTHREAD_STACK_MIN: an error, nothing changed
  CHECK(default_thread_stack() == kStack);
}

TEST_CASE("HapticLoop: config validation names the field") {
  HapticLoopConfig c = DefaultHapticLoopConfig();
  c.rate_hz = 0;
  CHECK(HapticLoop::check(c).find("rate_hz") != std::string::npos);
  c = DefaultHapticLoopConfig();
  c.fifo_priority = 100;
  CHECK(HapticLoop::check(c).find("fifo_priority") != std::string::npos);
  c = DefaultHapticLoopConfig();
  c.rate_hz = std::numeric_limits<double>::quiet_NaN();
  CHECK(HapticLoop::check(c).find("rate_hz") != std::string::npos);
  CHECK(HapticLoop::check(DefaultHapticLoopConfig()).empty());
}

TEST_CASE("alloc counter: counts what it should (positive control)") {
  st::test::arm_alloc_counter();
  int* volatile p = new int(3);
  const std::uint64_t n = st::test::disarm_alloc_counter();
  delete p;
  CHECK(n >= 1);
}

TEST_CASE("HapticLoop: the tick path allocates nothing") {
  auto loop = std::make_unique<HapticLoop>(DefaultHapticLoopConfig());
  CountingHandler h;
  REQUIRE(loop->start(h).ok());
  while (loop->ticks() < 20) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  // Armed while the loop runs on its own; this thread only polls an atomic and sleeps.
  st::test::arm_alloc_counter();
  const std::uint64_t t0 = loop->ticks();
  while (loop->ticks() < t0 + 300) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  const std::uint64_t allocs = st::test::disarm_alloc_counter();
  loop->stop();
  CHECK(allocs == 0);
  MESSAGE("allocations during " << loop->stats().ticks - t0 << "+ ticks: " << allocs
                                << std::string(st::test::counts_malloc() ? " (malloc and new counted)"
                                                                         : " (operator new counted)"));
}
