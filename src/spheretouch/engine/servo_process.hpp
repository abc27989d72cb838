// SPDX-License-Identifier: BSD-3-Clause
// The haptic servo as its own process (`spheretouch run --split`).
// The run (parent: collision thread, workers, status line, summary) creates the segment and
// re-executes itself as the hidden `spheretouch servo` subcommand: a fresh process with no
// inherited threads, no meshes and no trees, that owns the device, the haptic loop and the
// telemetry (ticks.csv). The servo's main thread is a non-real-time watcher: it ends the run at
// its duration, notices a silent collision side (the interpolator's stale timeout has faded the
// force to zero) and a dead parent (getppid() changes), says so, and keeps ticking to the end.
// Its results go to servo.txt in the run directory for the parent's summary.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <string>
#include <sys/types.h>

#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/shm_status.hpp>
#include <spheretouch/rt/simulated_device.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

/// What a servo reports at its end (servo.txt: one "key value" per line).
struct ServoResults {
  double seconds = 0;                                                             ///< loop wall time, s
  std::uint64_t ticks = 0, misses = 0, overruns = 0;                              ///< loop counters
  double wake_p99_us = 0;                                                         ///< wake-up latency p99, µs
  double peak_force_N = 0;                                                        ///< largest |force| commanded
  std::uint64_t models = 0;                                                       ///< contact models taken
  std::uint64_t telemetry_pushed = 0, telemetry_dropped = 0, device_dropped = 0;  ///< drops
  std::uint64_t silences = 0;       ///< episodes where the collision side went silent
  double longest_silence_ms = 0;    ///< longest such episode (so far, at the end)
  int collision_died = 0;           ///< 1: the collision process died during the run
  double collision_died_at_s = -1;  ///< when, s after the servo started
  int signal = 0;                   ///< stopped by this signal (0 = ran its duration)
};
/// Writes results as "key value" lines.
Status write_servo_results(const std::string& path, const ServoResults& r);
/// Reads what write_servo_results() wrote; errors name the file and line.
Result<ServoResults> read_servo_results(const std::string& path);

/// Watches the collision side from outside the tick path, through the servo's own status:
/// reports once per episode when no contact model arrived for the stale timeout and the force
/// has faded to zero, and when models resume.
class SilenceWatch {
 public:
  explicit SilenceWatch(std::int64_t stale_timeout_ns) : stale_ns_(stale_timeout_ns) {}
  /// Looks at a status snapshot at now_ns; returns a line to print ("" = nothing new).
  std::string poll(const rt::ServoStatus& st, std::int64_t now_ns);
  std::uint64_t episodes() const { return episodes_; }  ///< silences reported
  double longest_ms() const { return longest_ms_; }     ///< longest silence seen, ms
  bool silent() const { return silent_; }               ///< in an episode now

 private:
  std::int64_t stale_ns_;
  bool silent_ = false;
  std::uint64_t episodes_ = 0, last_seq_ = 0;
  std::int64_t since_ns_ = 0;
  double longest_ms_ = 0;
};

/// Writes a trajectory in the format load_trajectory() reads (t_s then 16 numbers a line).
Status write_trajectory(const std::string& path, const rt::Trajectory& t);

/// Arguments of the hidden `spheretouch servo` subcommand.
struct ServoArgs {
  std::string shm, scene, script, out;    ///< segment, scene file, trajectory file, run directory
  double duration_s = -1;                 ///< run length
  int parent = 0;                         ///< the collision process's pid (death detection)
  geom::Vec3 tcp_mm{geom::Vec3::Zero()};  ///< the tool centre point (the servo loads no meshes to find the tip)
};
/// Starts `spheretouch servo` (this executable, /proc/self/exe) with `a`; returns its pid.
Result<pid_t> spawn_servo(const ServoArgs& a);

}  // namespace st::engine
