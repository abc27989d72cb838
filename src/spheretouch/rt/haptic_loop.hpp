// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// HapticLoop: the servo loop. Ticks at absolute deadlines on
/// CLOCK_MONOTONIC (clock_nanosleep, TIMER_ABSTIME), so lateness never accumulates into drift.
/// A deadline whose tick cannot start before the next deadline is skipped and counted as a miss;
/// the loop never runs ticks back to back to catch up. Real-time settings (SCHED_FIFO,
/// affinity, mlockall, pre-faulted stack) are applied only when asked, and every refusal is
/// reported (unlike CHAI3D, which ignores a refused priority). The tick path takes no lock,
/// allocates nothing, logs nothing and makes no system call but the sleep (clock reads are vDSO).
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstdint>
#include <string>
#include <thread>

#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/constants.hpp>
#include <spheretouch/rt/histogram.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Loop settings; the initializers (= DefaultHapticLoopConfig()) give 1 kHz and no real-time requests.
struct HapticLoopConfig {
  double rate_hz = kDefaultRateHz;       ///< tick rate, Hz, in [kMinRateHz, kMaxRateHz]
  int fifo_priority = 0;                 ///< SCHED_FIFO priority 1..99; 0 = do not ask
  int cpu = -1;                          ///< pin the loop thread to this CPU; -1 = do not pin
  bool lock_memory = false;              ///< mlockall(MCL_CURRENT | MCL_FUTURE)
  std::size_t prefault_stack_bytes = 0;  ///< touch this much stack before the first tick; 0 = no
  bool strict = false;                   ///< any refused request makes start() fail
  std::uint64_t max_periods = 0;         ///< stop after this many deadlines (ticks + misses); 0 = run until stop()
};
/// 1 kHz, no real-time requests, not strict, run until stop().
HapticLoopConfig DefaultHapticLoopConfig();

/// What the tick handler is told each tick.
struct TickInfo {
  std::uint64_t tick = 0;            ///< ticks run before this one
  std::uint64_t deadline_index = 0;  ///< which period this tick serves (0-based, gaps = misses)
  std::int64_t deadline_ns = 0;      ///< the deadline it serves, CLOCK_MONOTONIC ns
  std::int64_t woke_ns = 0;          ///< when the loop woke for it
  std::int64_t period_ns = 0;        ///< loop period
};

/// The per-tick work. tick() runs on the loop thread and must obey the tick-path rules.
class TickHandler {
 public:
  virtual ~TickHandler() = default;
  /// One servo tick.
  virtual void tick(const TickInfo& info) noexcept = 0;
};

/// Outcome of one real-time request.
struct RtStep {
  bool requested = false;  ///< the config asked for it
  bool applied = false;    ///< the OS granted it
  int error = 0;           ///< errno of the refusal
};
/// Outcome of all real-time requests; describe() names each refusal and its reason.
struct RtReport {
  ///@{
  RtStep fifo, affinity, mlock, prefault;  ///< one per request
  ///@}
  bool all_applied() const;      ///< no requested step was refused
  std::string describe() const;  ///< "SCHED_FIFO 80: refused (Operation not permitted); ..."
  std::size_t stack_left = 0;    ///< bytes of the loop thread's stack below its frame, when a pre-fault was refused
};

/// Stack kept free below a pre-fault for the tick path and signal delivery.
inline constexpr std::size_t kPrefaultStackMargin = 64 * 1024;

/// Sets the stack size of every thread the process creates from now on with default attributes
/// (std::thread, libzmq's I/O threads): pthread_setattr_default_np. Under mlockall each thread's
/// stack is resident whole, so the glibc default (RLIMIT_STACK, 8 MiB) costs 8 MiB per thread.
/// Tries one thread with the new size (the static TLS of every loaded library comes out of each
/// stack: ThreadSanitizer's is ~0.8 MB); fails, naming the size and keeping the old default,
/// below PTHREAD_STACK_MIN, if glibc refuses, or if that thread cannot start.
Status set_default_thread_stack(std::size_t bytes);
/// The current default stack size for new threads, bytes.
std::size_t default_thread_stack();

/// Deadline bookkeeping, separate from the clock so tests can drive it with synthetic times.
class DeadlineSchedule {
 public:
  /// Deadlines first_deadline_ns + k · period_ns, k = 0, 1, ...
  DeadlineSchedule(std::int64_t first_deadline_ns, std::int64_t period_ns) noexcept
      : deadline_(first_deadline_ns), period_(period_ns) {}
  std::int64_t deadline_ns() const noexcept { return deadline_; }  ///< next deadline to serve
  std::uint64_t index() const noexcept { return index_; }          ///< its period number
  /// Woke at now for deadline_ns(): skips every deadline whose whole period has passed
  /// (now >= deadline + period) and returns how many were skipped (misses).
  std::uint64_t on_wake(std::int64_t now) noexcept {
    if (now - deadline_ < period_) return 0;
    const auto k = static_cast<std::uint64_t>((now - deadline_) / period_);
    deadline_ += static_cast<std::int64_t>(k) * period_;
    index_ += k;
    return k;
  }
  /// The tick for deadline_ns() is done: move to the next period.
  void advance() noexcept {
    deadline_ += period_;
    ++index_;
  }

 private:
  std::int64_t deadline_;
  std::int64_t period_;
  std::uint64_t index_ = 0;
};

/// Counters and histograms of a run. Histograms: read only after stop()/run() returned.
struct LoopStats {
  std::uint64_t ticks = 0;        ///< ticks run
  std::uint64_t misses = 0;       ///< deadlines skipped
  std::uint64_t overruns = 0;     ///< ticks whose work ended after the next deadline
  LatencyHistogram wake_latency;  ///< woke_ns - deadline_ns, ns
  LatencyHistogram tick_compute;  ///< time inside TickHandler::tick plus bookkeeping, ns
};

/// The servo loop. Either run() in the calling thread or start()/stop() its own thread.
class HapticLoop {
 public:
  explicit HapticLoop(const HapticLoopConfig& config);  ///< config must be valid (see check())
  ~HapticLoop();                                        ///< stops a running thread
  HapticLoop(const HapticLoop&) = delete;
  HapticLoop& operator=(const HapticLoop&) = delete;

  /// Empty when the config is usable, else a message naming the bad field.
  static std::string check(const HapticLoopConfig& config);
  /// Applies the requested real-time settings to the calling thread (and process, for mlock).
  static RtReport apply_realtime(const HapticLoopConfig& config);

  /// Applies the real-time requests, then ticks in the calling thread until stop() or
  /// max_periods; returns the real-time report (or an error when strict and refused).
  Result<RtReport> run(TickHandler& handler);
  /// Starts the loop thread; returns after its real-time setup with the report (or the error,
  /// when strict and refused, in which case no thread is left running).
  Result<RtReport> start(TickHandler& handler);
  /// Asks the loop to stop and joins its thread (if start() was used). Idempotent.
  void stop();
  /// True between start() and the loop's end.
  bool running() const { return running_.load(std::memory_order_acquire); }

  /// Ticks so far (safe to read from any thread while running).
  std::uint64_t ticks() const { return ticks_.load(std::memory_order_relaxed); }
  /// Misses so far (safe to read from any thread while running).
  std::uint64_t misses() const { return misses_.load(std::memory_order_relaxed); }
  /// The full statistics; call after the loop ended.
  const LoopStats& stats() const { return stats_; }
  /// Loop period, ns.
  std::int64_t period_ns() const { return period_ns_; }

 private:
  void loop(TickHandler& handler);
  HapticLoopConfig config_;
  std::int64_t period_ns_;
  LoopStats stats_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> running_{false};
  std::atomic<std::uint64_t> ticks_{0}, misses_{0};
  std::thread thread_;
};

}  // namespace st::rt
