// SPDX-License-Identifier: BSD-3-Clause
#include <spheretouch/rt/haptic_loop.hpp>

#include <alloca.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <cerrno>
#include <climits>
#include <cstdint>
#include <cmath>
#include <cstring>
#include <future>
#include <sstream>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/constants.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

HapticLoopConfig DefaultHapticLoopConfig() { return HapticLoopConfig{}; }

bool RtReport::all_applied() const {
  for (const RtStep* s : {&fifo, &affinity, &mlock, &prefault})
    if (s->requested && !s->applied) return false;
  return true;
}

std::string RtReport::describe() const {
  std::ostringstream os;
  auto one = [&](const char* what, const RtStep& s) {
    if (!s.requested) return;
    if (os.tellp() > 0) os << "; ";
    os << what << ": " << (s.applied ? "applied" : "refused");
    if (!s.applied) os << " (" << std::strerror(s.error) << ")";
  };
  one("SCHED_FIFO", fifo);
  one("CPU affinity", affinity);
  one("mlockall", mlock);
  one("stack pre-fault", prefault);
  if (prefault.requested && !prefault.applied && stack_left)
    os << " [" << stack_left / 1024 << " KiB of stack left, " << kPrefaultStackMargin / 1024 << " KiB of it kept free]";
  if (os.tellp() == 0) os << "no real-time settings requested";
  return os.str();
}

std::string HapticLoop::check(const HapticLoopConfig& c) {
  std::ostringstream os;
  if (!(std::isfinite(c.rate_hz) && c.rate_hz >= kMinRateHz && c.rate_hz <= kMaxRateHz))
    os << "haptic loop: rate_hz = " << c.rate_hz << ", expected " << kMinRateHz << ".." << kMaxRateHz;
  else if (c.fifo_priority < 0 || c.fifo_priority > 99)
    os << "haptic loop: fifo_priority = " << c.fifo_priority << ", expected 0 (off) or 1..99";
  else if (c.cpu < -1 || c.cpu >= CPU_SETSIZE)
    os << "haptic loop: cpu = " << c.cpu << ", expected -1 (off) or 0.." << CPU_SETSIZE - 1;
  return os.str();
}

namespace {
// Touches n bytes of stack so the tick path does not page-fault on first use of it.
__attribute__((noinline)) void prefault_stack(std::size_t n) {
  auto* p = static_cast<volatile char*>(alloca(n));
  for (std::size_t i = 0; i < n; i += 4096) p[i] = 0;
  if (n) p[n - 1] = 0;
}

// Bytes of the calling thread's stack below this frame (0 if the bounds cannot be read).
__attribute__((noinline)) std::size_t stack_left_here() {
  pthread_attr_t attr;
  if (pthread_getattr_np(pthread_self(), &attr) != 0) return 0;
  void* low = nullptr;
  std::size_t size = 0;
  const int e = pthread_attr_getstack(&attr, &low, &size);
  pthread_attr_destroy(&attr);
  if (e != 0) return 0;
  // The frame address, not a local's: under ASan a local may live on a fake stack in the heap.
  const auto sp = reinterpret_cast<std::uintptr_t>(__builtin_frame_address(0)),
             base = reinterpret_cast<std::uintptr_t>(low);
  return sp > base && sp - base <= size ? sp - base : 0;
}
}  // namespace

Status set_default_thread_stack(std::size_t bytes) {
  if (bytes < static_cast<std::size_t>(PTHREAD_STACK_MIN))
    return Error{"thread stack of " + std::to_string(bytes) + " bytes is below PTHREAD_STACK_MIN (" +
                 std::to_string(PTHREAD_STACK_MIN) + ")"};
  const std::size_t before = default_thread_stack();
  auto set = [](std::size_t size) {
    pthread_attr_t attr;
    int e = pthread_getattr_default_np(&attr);
    if (e == 0) {
      e = pthread_attr_setstacksize(&attr, size);
      if (e == 0) e = pthread_setattr_default_np(&attr);
      pthread_attr_destroy(&attr);
    }
    return e;
  };
  int e = set(bytes);
  if (e == 0) {
    // glibc takes the static TLS of every loaded library out of each stack (ThreadSanitizer's is
    // ~0.8 MB), so a size can be accepted here and still fail every pthread_create: try one now.
    pthread_t t;
    e = pthread_create(
        &t, nullptr, [](void*) -> void* { return nullptr; }, nullptr);
    if (e == 0)
      pthread_join(t, nullptr);
    else if (before)
      set(before);
  }
  if (e != 0) return Error{"cannot use a thread stack of " + std::to_string(bytes) + " bytes: " + std::strerror(e)};
  return Ok{};
}

std::size_t default_thread_stack() {
  pthread_attr_t attr;
  if (pthread_getattr_default_np(&attr) != 0) return 0;
  std::size_t size = 0;
  pthread_attr_getstacksize(&attr, &size);
  pthread_attr_destroy(&attr);
  return size;
}

RtReport HapticLoop::apply_realtime(const HapticLoopConfig& c) {
  RtReport r;
  if (c.lock_memory) {
    r.mlock.requested = true;
    r.mlock.applied = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    if (!r.mlock.applied) r.mlock.error = errno;
  }
  if (c.cpu >= 0) {
    r.affinity.requested = true;
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(c.cpu, &set);
    r.affinity.error = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
    r.affinity.applied = r.affinity.error == 0;
  }
  if (c.fifo_priority > 0) {
    r.fifo.requested = true;
    sched_param sp{};
    sp.sched_priority = c.fifo_priority;
    r.fifo.error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    r.fifo.applied = r.fifo.error == 0;
  }
  if (c.prefault_stack_bytes > 0) {
    r.prefault.requested = true;
    // Touching more stack than the thread has would crash: refuse instead, and say how much is left.
    const std::size_t left = stack_left_here();
    if (left >= kPrefaultStackMargin && c.prefault_stack_bytes <= left - kPrefaultStackMargin) {
      prefault_stack(c.prefault_stack_bytes);
      r.prefault.applied = true;
    } else {
      r.prefault.error = left ? ENOMEM : ENOTSUP;  // ENOTSUP: the thread's stack bounds could not be read
      r.stack_left = left;
    }
  }
  return r;
}

HapticLoop::HapticLoop(const HapticLoopConfig& config)
    : config_(config), period_ns_(static_cast<std::int64_t>(std::llround(1e9 / config.rate_hz))) {
  ST_ASSERT(check(config).empty(), "a HapticLoop's config passes check() (haptic_loop.hpp)");
}

HapticLoop::~HapticLoop() { stop(); }

void HapticLoop::loop(TickHandler& handler) {
  // Everything below the first sleep is the tick path: no allocation, lock, log or syscall
  // besides clock_nanosleep (clock reads go through the vDSO).
  DeadlineSchedule sched(now_ns() + period_ns_, period_ns_);
  TickInfo info;
  info.period_ns = period_ns_;
  std::uint64_t ticks = 0, misses = 0;
  while (!stop_.load(std::memory_order_relaxed)) {
    if (config_.max_periods && sched.index() >= config_.max_periods) break;
    const timespec ts = to_timespec(sched.deadline_ns());
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {}
    const std::int64_t woke = now_ns();
    stats_.wake_latency.record(woke - sched.deadline_ns());
    const std::uint64_t skipped = sched.on_wake(woke);
    if (skipped) {
      misses += skipped;
      misses_.store(misses, std::memory_order_relaxed);
      if (config_.max_periods && sched.index() >= config_.max_periods) {
        // Skipped past the end: the run is over; count only deadlines inside it.
        misses -= sched.index() - config_.max_periods;
        misses_.store(misses, std::memory_order_relaxed);
        break;
      }
    }
    info.tick = ticks;
    info.deadline_index = sched.index();
    info.deadline_ns = sched.deadline_ns();
    info.woke_ns = woke;
    handler.tick(info);
    ++ticks;
    ticks_.store(ticks, std::memory_order_relaxed);
    sched.advance();
    const std::int64_t done = now_ns();
    if (done > sched.deadline_ns()) ++stats_.overruns;
    stats_.tick_compute.record(done - woke);
  }
  stats_.ticks = ticks;
  stats_.misses = misses;
}

Result<RtReport> HapticLoop::run(TickHandler& handler) {
  if (std::string e = check(config_); !e.empty()) return Error{e};
  RtReport r = apply_realtime(config_);
  if (config_.strict && !r.all_applied()) return Error{"haptic loop: " + r.describe()};
  running_.store(true, std::memory_order_release);
  loop(handler);
  running_.store(false, std::memory_order_release);
  return r;
}

Result<RtReport> HapticLoop::start(TickHandler& handler) {
  if (std::string e = check(config_); !e.empty()) return Error{e};
  if (thread_.joinable()) return Error{"haptic loop: already started"};
  stop_.store(false, std::memory_order_relaxed);
  std::promise<RtReport> setup;
  std::future<RtReport> report = setup.get_future();
  running_.store(true, std::memory_order_release);
  // The thread owns the promise: destroying it here while set_value() still runs would race.
  thread_ = std::thread([this, &handler, setup = std::move(setup)]() mutable {
    RtReport r = apply_realtime(config_);
    const bool go = !(config_.strict && !r.all_applied());
    setup.set_value(r);
    if (go) loop(handler);
    running_.store(false, std::memory_order_release);
  });
  RtReport r = report.get();
  if (config_.strict && !r.all_applied()) {
    thread_.join();
    return Error{"haptic loop: " + r.describe()};
  }
  return r;
}

void HapticLoop::stop() {
  stop_.store(true, std::memory_order_relaxed);
  if (thread_.joinable()) thread_.join();
}

}  // namespace st::rt
