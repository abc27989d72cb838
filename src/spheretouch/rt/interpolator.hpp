// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Interpolator: the force between contact updates (paper §3.7). The collision side publishes a
/// ContactModel every few to hundreds of milliseconds; the haptic tick needs a force every 1 ms
/// from the device pose it has now. Three selectable methods:
///  * hold:  the force of the newest model, F = law(PD)·FD (zero-order hold; the baseline).
///  * paper: B = A + D (§3.7): A = law(PD)·FD at the model, D the probe's movement since, turned
///           into force by a gain (N/mm), B = A - gain·D, with |D| capped (so B cannot grow while
///           updates stop) and B's component against FD removed (a surface never pulls).
///  * plane: PD recomputed every tick against the newest local contact plane,
///           PD(t) = (plane_point - pose(t)·probe_point)·FD, F = law(PD(t))·FD; a new model is
///           cross-faded in: at its arrival the old and the new model are evaluated at the SAME
///           pose (the current one), and their difference decays linearly over crossfade_ns, or
///           kCrossfadeRounds recent intervals between models if that is shorter, so the
///           cross-fade hides only what the models disagree on, never the probe's motion, and a
///           fast crossing follows the geometry. A "no contact" model after one in contact ends the contact: the old
///           model, still evaluated at each tick's pose, fades out over kReleaseFadeNs, never rising.
/// In every mode: a model older than stale_timeout_ns (no update received) fades the force
/// linearly to zero over fade_ns; optional damping -c·(v·FD)·FD never makes the force pull;
/// every input is checked for finiteness and a bad one yields zero force, counted.
#pragma once
#include <spheretouch/abi.hpp>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <string_view>

#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/constants.hpp>
#include <spheretouch/rt/force_law.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Interpolation method.
enum class InterpMode { hold, paper, plane };
/// "hold" | "paper" | "plane".
Result<InterpMode> parse_interp_mode(std::string_view name);
/// The name parse_interp_mode() accepts.
const char* to_string(InterpMode mode);

/// Interpolation settings; the initializers (= DefaultInterpolatorConfig()) are the documented defaults.
struct InterpolatorConfig {
  InterpMode mode = InterpMode::plane;                     ///< method
  std::int64_t stale_timeout_ns = kDefaultStaleTimeoutNs;  ///< no update for this long: start fading, ns
  std::int64_t fade_ns = kDefaultFadeNs;                   ///< fade duration to zero, ns (0 = cut at once)
  std::int64_t crossfade_ns = kDefaultCrossfadeNs;       ///< plane: cross-fade to a new model, ns (0 = switch at once)
  double paper_gain_N_per_mm = kDefaultPaperGainNPerMm;  ///< paper: force per mm of probe movement, N/mm
  double paper_max_move_mm = kDefaultPaperMaxMoveMm;     ///< paper: cap on |D|, mm
  double damping_N_s_per_mm = 0;  ///< optional damping along FD while in contact, N·s/mm (0 = off)
};
/// plane, 200 ms stale timeout, 100 ms fade, 10 ms cross-fade, paper gain 0.5 N/mm capped at
/// 2 mm, no damping.
InterpolatorConfig DefaultInterpolatorConfig();

/// What the last force() computed, for telemetry.
struct InterpState {
  double penetration_mm = 0;  ///< PD used (model PD, or recomputed for plane)
  double fade = 0;            ///< stale-fade factor in [0, 1]
  double raw_force_N = 0;     ///< |force| before fade
  bool in_contact = false;    ///< the newest model is in contact
};

/// Per-servo interpolator. Tick-path safe: noexcept, no allocation.
class Interpolator {
 public:
  Interpolator(const ForceLaw& law, const InterpolatorConfig& config);  ///< config must pass check()
  /// Empty when the config is usable, else a message naming the bad field.
  static std::string check(const InterpolatorConfig& config);

  /// A new model arrived at now_ns (local receive time: staleness counts from here).
  /// A model with non-finite fields or a non-unit FD is treated as "no contact" and counted.
  void on_model(const geom::ContactModel& model, std::int64_t now_ns) noexcept;
  /// Force, N, object frame, for the probe at `pose` (probe → object) at now_ns. Finite,
  /// magnitude <= the law's max force + damping's share (the Saturator caps the rest).
  Eigen::Vector3d force(const Eigen::Isometry3d& pose, std::int64_t now_ns) noexcept;

  const InterpState& state() const noexcept { return state_; }          ///< last force()'s details
  std::uint64_t rejected_models() const noexcept { return rejected_; }  ///< bad models seen
  std::uint64_t bad_poses() const noexcept { return bad_poses_; }       ///< non-finite poses seen
  std::uint64_t model_seq() const noexcept { return model_.seq; }       ///< newest model's seq
  std::int64_t received_ns() const noexcept { return received_ns_; }    ///< when it arrived
  const InterpolatorConfig& config() const noexcept { return c_; }      ///< settings
  /// The contact normal FD of the model in use (unit, object frame), zero when not in contact.
  const Eigen::Vector3d& normal() const noexcept { return fd_; }

  /// The point torques are taken about (the device's tool centre point), probe file coordinates,
  /// mm. Default: the probe's origin.
  void set_tool_point(const Eigen::Vector3d& tcp_mm) noexcept { tcp_ = tcp_mm; }
  /// The moment of the last force() output about the tool point, N·m, object frame: the force
  /// acting at the model's pressure point (ContactModel::pressure_point, carried with the probe
  /// between models), τ = (pressure point − tool point) × F. Continuous in time: a new model's
  /// lever arm is cross-faded in like its force; zero when the force acts through the tool point.
  const Eigen::Vector3d& torque_Nm() const noexcept { return torque_; }
  /// The lever arm of the last force() output: pressure point − tool point, object frame, mm (zero
  /// without a force). The servo takes the moment of the force it finally commands with it.
  const Eigen::Vector3d& lever_mm() const noexcept { return lever_out_; }
  /// The recent interval between models (the collision period as the servo sees it), ns; 0 before
  /// two models arrived.
  double model_interval_ns() const noexcept { return interval_ns_; }

 private:
  Eigen::Vector3d contact_force(const Eigen::Isometry3d& pose, double& pd_mm) const noexcept;
  /// The cross-fade's length now, ns: crossfade_ns, or kCrossfadeRounds recent model intervals.
  double crossfade_span() const noexcept;
  ForceLaw law_;
  InterpolatorConfig c_;
  geom::ContactModel model_{};  ///< newest accepted model
  bool have_model_ = false;
  bool contact_ = false;                                  ///< model_ is in contact
  Eigen::Vector3d fd_{Eigen::Vector3d::Zero()};           ///< FD
  Eigen::Vector3d probe_point_{Eigen::Vector3d::Zero()};  ///< probe file coordinates
  Eigen::Vector3d plane_point_{Eigen::Vector3d::Zero()};  ///< object frame
  Eigen::Vector3d anchor_{Eigen::Vector3d::Zero()};       ///< probe_point at the model's pose, object frame
  Eigen::Vector3d force_a_{Eigen::Vector3d::Zero()};      ///< A = law(PD)·FD
  Eigen::Vector3d offset_{Eigen::Vector3d::Zero()};       ///< plane: jump at the last arrival, decaying
  Eigen::Vector3d tcp_{Eigen::Vector3d::Zero()};          ///< tool point, probe file coordinates
  Eigen::Vector3d lever_{Eigen::Vector3d::Zero()};        ///< pressure point − tool point, probe frame (newest model)
  Eigen::Vector3d lever_from_{Eigen::Vector3d::Zero()};   ///< the lever in use when the newest model arrived
  Eigen::Vector3d last_lever_{Eigen::Vector3d::Zero()};   ///< the lever used at the last force()
  bool have_lever_ = false;                               ///< last_lever_ is a contact's
  Eigen::Vector3d torque_{Eigen::Vector3d::Zero()};       ///< last force()'s torque, N·m
  Eigen::Vector3d lever_out_{Eigen::Vector3d::Zero()};    ///< last force()'s lever arm, object frame, mm
  // The model before the newest one (plane cross-fade: both are evaluated at the same pose).
  bool prev_contact_ = false;
  Eigen::Vector3d prev_fd_{Eigen::Vector3d::Zero()}, prev_probe_point_{Eigen::Vector3d::Zero()},
      prev_plane_point_{Eigen::Vector3d::Zero()};
  Eigen::Vector3d prev_offset_{Eigen::Vector3d::Zero()};  ///< offset_ still applied when the newest model arrived
  double prev_weight_ = 0;                                ///< its remaining weight then
  double prev_fade_ = 0;                                  ///< the stale fade of the last output
  Eigen::Vector3d last_out_{Eigen::Vector3d::Zero()};     ///< last force() output (after fade)
  Eigen::Vector3d last_point_{Eigen::Vector3d::Zero()};   ///< probe point, previous tick (damping)
  bool pending_offset_ = false;                           ///< plane: offset_ to be taken at the next force()
  double interval_ns_ = 0;        ///< plane: recent interval between models (exponential average), ns; 0 = none yet
  bool releasing_ = false;        ///< plane: a no-contact model followed one in contact; the old one fades out
  std::int64_t release_ns_ = 0;   ///< when that no-contact model arrived
  bool have_last_point_ = false;  ///< last_point_ is valid (damping)
  double velocity_fd_ = 0;        ///< filtered probe speed along FD, mm/s
  std::int64_t last_ns_ = 0;      ///< previous force() time
  std::int64_t received_ns_ = 0;  ///< newest model's arrival
  std::uint64_t rejected_ = 0, bad_poses_ = 0;
  InterpState state_;
};

}  // namespace st::rt
