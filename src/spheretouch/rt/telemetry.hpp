// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Telemetry: each haptic tick pushes one fixed-size sample into a lock-free SPSC queue; a writer
/// thread drains it to a CSV file. A full queue drops the sample and counts it; the count is in
/// stats(), in the file's last line and in the writer's summary — drops are never silent.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>

#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/constants.hpp>
#include <spheretouch/rt/spsc_queue.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Bits of a servo tick's flags (TelemetrySample::flags, ServoStatus::flags, the telemetry CSV).
inline constexpr std::uint32_t kTickInContact = 1u << 0;  ///< the interpolated model was in contact
inline constexpr std::uint32_t kTickSaturated = 1u << 1;  ///< the saturator limited the force
inline constexpr std::uint32_t kTickNoPose = 1u << 2;     ///< the device gave no pose this tick
inline constexpr std::uint32_t kTickStuck = 1u << 3;      ///< friction: in contact, sticking
inline constexpr std::uint32_t kTickSliding = 1u << 4;    ///< friction: in contact, slipping

/// One tick, plain data (128 bytes).
struct TelemetrySample {
  std::uint64_t tick = 0;         ///< tick number
  std::int64_t t_ns = 0;          ///< tick wake-up, CLOCK_MONOTONIC ns
  std::int64_t latency_ns = 0;    ///< wake-up minus deadline
  std::uint64_t pose_seq = 0;     ///< pose sample published this tick (0 = none)
  std::uint64_t model_seq = 0;    ///< newest contact model used
  std::int64_t model_age_ns = 0;  ///< now minus that model's pose sampling time
  double position_mm[3] = {};     ///< probe origin, object frame
  double force_N[3] = {};         ///< commanded force
  double penetration_mm = 0;      ///< PD used
  double fade = 0;                ///< stale-fade factor
  double ceiling_N = 0;           ///< saturation ceiling
  std::uint32_t flags = 0;        ///< kTickInContact | kTickSaturated | kTickNoPose | kTickStuck | kTickSliding
  std::uint32_t misses = 0;       ///< loop misses so far (low 32 bits)
  /// The proxy: where the probe would rest outside the object, object frame (position_mm moved
  /// out by PD along the contact normal FD while in contact; position_mm otherwise).
  double proxy_mm[3] = {};
  /// The torque about the tool centre point, N·m, object frame (commanded to 6-DOF devices; for
  /// 3-DOF ones what the contact's moment is).
  double torque_Nm[3] = {};
};
static_assert(std::is_trivially_copyable_v<TelemetrySample> && sizeof(TelemetrySample) == 176);

/// Counters of a telemetry stream.
struct TelemetryStats {
  std::uint64_t pushed = 0;   ///< samples accepted by the queue
  std::uint64_t dropped = 0;  ///< samples refused because the queue was full
  std::uint64_t written = 0;  ///< samples written to the file
};

/// Queue plus writer thread. push() is the tick-path side.
class Telemetry {
 public:
  /// Opens `path` for writing (CSV with a header line) and starts the writer thread.
  static Result<std::unique_ptr<Telemetry>> open(const std::string& path, std::size_t capacity = kDefaultTelemetryCapacity);
  /// A telemetry stream without a file or thread: samples are queued and drained by drain_to()
  /// (tests and benchmarks that want to look at them).
  explicit Telemetry(std::size_t capacity);
  ~Telemetry();  ///< stops the writer after draining; writes the drop count
  Telemetry(const Telemetry&) = delete;
  Telemetry& operator=(const Telemetry&) = delete;

  /// Producer: queues one sample; on a full queue counts a drop. Wait-free, no allocation.
  void push(const TelemetrySample& s) noexcept {
    if (queue_.try_push(s))
      pushed_.fetch_add(1, std::memory_order_relaxed);
    else
      dropped_.fetch_add(1, std::memory_order_relaxed);
  }
  /// Consumer (only without a writer thread): pops up to max samples into out; returns how many.
  std::size_t drain_to(TelemetrySample* out, std::size_t max) noexcept;
  /// Stops the writer thread after it has drained the queue, closes the file. Idempotent.
  void close();
  /// Empty while every write, the flush and the close succeeded; else the first failure, naming
  /// the file and the system's reason ("runs/x/ticks.csv: write failed: No space left on device").
  /// After a failure the writer stops writing (samples are then counted as not written).
  std::string error() const;
  /// Counters (any thread).
  TelemetryStats stats() const;

 private:
  void writer_loop();
  void write(const TelemetrySample& s);
  SpscQueue<TelemetrySample> queue_;
  std::atomic<std::uint64_t> pushed_{0}, dropped_{0}, written_{0};
  std::atomic<bool> stop_{false};
  std::FILE* file_ = nullptr;
  std::string path_;
  std::string error_;  ///< first failure (written by the writer thread, read after close())
  std::atomic<bool> failed_{false};
  std::thread writer_;
};

}  // namespace st::rt
