// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// SimulatedDevice: a Device for tests, benchmarks and demos without hardware. The probe follows
/// a scripted trajectory of timed poses (from a file, or the built-in approach / press / slide /
/// release against a plane), optionally held by a virtual user: a spring-damper hand with mass
/// that pulls the probe toward the scripted pose while the commanded force pushes back, so the
/// rendered contact feeds back into the motion. Every commanded force is recorded into
/// preallocated storage; records past its capacity are counted, not lost silently.
#pragma once
#include <spheretouch/abi.hpp>
#include <string>
#include <vector>

#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/constants.hpp>
#include <spheretouch/rt/device.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// One scripted pose.
struct TimedPose {
  double t_s = 0;                                          ///< time from the script's start, s
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  ///< probe → object
};

/// A trajectory: poses with strictly increasing times, interpolated linearly (translation) and
/// by slerp (rotation), held at the ends.
struct Trajectory {
  std::vector<TimedPose> keys;  ///< at least one
  /// The pose at t_s.
  Eigen::Isometry3d at(double t_s) const;
  /// Time of the last key, s.
  double duration_s() const { return keys.empty() ? 0.0 : keys.back().t_s; }
};

/// Largest trajectory file read, bytes: 256 MiB holds ~1.5 million timed poses (an hour at
/// 400 Hz); anything larger is a mistake or an attack (/dev/zero).
inline constexpr std::uint64_t kMaxTrajectoryBytes = 256ull << 20;

/// Reads a trajectory file (a regular file of at most kMaxTrajectoryBytes): one pose per line, 17 numbers: t_s then a row-major 4×4 rigid
/// transform; '#' starts a comment. Errors
/// name the file and line (non-finite values, last row not 0 0 0 1, rotation not orthonormal
/// within 1e-6, times not strictly increasing).
Result<Trajectory> load_trajectory(const std::string& path);
/// Parses the same format from text; `name` is used in messages.
Result<Trajectory> parse_trajectory(const std::string& text, const std::string& name);

/// The built-in script against the plane through `surface` with outward normal `normal`
/// (probe origin positions, identity rotation): start 10 mm above, approach to the surface
/// in 1 s, press to `depth_mm` in 0.5 s, hold 0.5 s, slide `slide_mm` along the plane in 2 s,
/// release back to 10 mm above in 0.5 s, rest 0.5 s.
Trajectory builtin_press_slide(const Eigen::Vector3d& surface, const Eigen::Vector3d& normal, double depth_mm = 3.0,
                               double slide_mm = 20.0);

/// Virtual user holding the probe: m·a = k·(target − x) − c·v + F_commanded.
struct VirtualUser {
  bool enabled = false;               ///< false: the probe follows the script exactly
  double mass_kg = 0.1;               ///< stylus plus fingers
  double stiffness_N_per_mm = 0.3;    ///< grip stiffness, human fingertip range 0.2–1 N/mm
  double damping_N_s_per_mm = 0.005;  ///< damping ratio ≈ 0.46 with the above
};

/// One recorded tick.
struct ForceRecord {
  std::int64_t t_ns = 0;                              ///< command time
  Eigen::Vector3d position{Eigen::Vector3d::Zero()};  ///< probe origin, object frame, mm
  Eigen::Vector3d force_N{Eigen::Vector3d::Zero()};   ///< commanded force
};

/// Scripted device.
class SimulatedDevice final : public Device {
 public:
  /// `capacity` records are preallocated (0: commands are not recorded, nothing counts as
  /// dropped; long runs whose trace goes to telemetry); start time is the first read_pose() call.
  SimulatedDevice(Trajectory script, VirtualUser user = {}, std::size_t capacity = 1 << 16,
                  double max_force_N = kOmniPeakForceN);
  bool read_pose(std::int64_t now_ns, Eigen::Isometry3d& pose) noexcept override;
  void command_force(std::int64_t now_ns, const Eigen::Vector3d& force_N) noexcept override;
  double max_force_N() const noexcept override { return max_force_; }

  /// Commanded forces so far (the first `capacity` of them).
  const std::vector<ForceRecord>& records() const { return records_; }
  /// Commands that did not fit into the record storage.
  std::uint64_t dropped_records() const { return dropped_; }
  /// True once the script's end has passed.
  bool finished() const { return finished_; }
  /// Seconds since the first read_pose().
  double elapsed_s() const { return elapsed_s_; }
  /// Replay the script from the start each time it ends (long benchmarks); never finished().
  void set_repeat(bool repeat) { repeat_ = repeat; }

 private:
  Trajectory script_;
  VirtualUser user_;
  double max_force_;
  bool record_;
  std::vector<ForceRecord> records_;
  std::uint64_t dropped_ = 0;
  std::int64_t start_ns_ = -1, last_ns_ = -1;
  double elapsed_s_ = 0;
  bool finished_ = false;
  bool repeat_ = false;
  Eigen::Vector3d x_{Eigen::Vector3d::Zero()}, v_{Eigen::Vector3d::Zero()};  ///< hand state, mm, mm/s
  Eigen::Vector3d last_force_{Eigen::Vector3d::Zero()};
  Eigen::Isometry3d pose_{Eigen::Isometry3d::Identity()};
};

}  // namespace st::rt
