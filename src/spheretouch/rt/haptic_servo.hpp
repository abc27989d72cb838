// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// HapticServo: the haptic thread's tick, as a TickHandler for HapticLoop:
/// read the device pose → publish it → take the newest ContactSet if one arrived → per touched
/// object: interpolate its force, guard it, add its friction → saturate the sum → command the
/// device → push one telemetry sample. Everything it touches is preallocated; the tick takes no
/// lock and never waits.
///
/// A scene of several objects (set_objects()): each object has its own channel (interpolator with
/// its material's law and damping, passivity guard, friction), fed by that object's models in the
/// ContactSet; the forces add and the saturator acts on the sum. Each channel's guard keeps its
/// own contact passive (it observes the force that channel commanded), so the sum is passive too:
/// the energy the sum puts into the hand is the sum of the channels' energies, each at most zero
/// (stronger than one guard on the sum, which would let one contact's injection hide behind
/// another's dissipation). A channel is ticked from its first model on; objects never touched cost
/// nothing.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <vector>

#include <spheretouch/geom/contact.hpp>
#include <spheretouch/rt/constants.hpp>
#include <spheretouch/rt/device.hpp>
#include <spheretouch/rt/friction.hpp>
#include <spheretouch/rt/haptic_loop.hpp>
#include <spheretouch/rt/interpolator.hpp>
#include <spheretouch/rt/passivity.hpp>
#include <spheretouch/rt/pose_sample.hpp>
#include <spheretouch/rt/saturation.hpp>
#include <spheretouch/rt/shm_status.hpp>
#include <spheretouch/rt/telemetry.hpp>
#include <spheretouch/rt/triple_buffer.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Counters of a servo (read after the loop stopped, or racily for display).
struct ServoStats {
  std::uint64_t ticks = 0;          ///< ticks served
  std::uint64_t models = 0;         ///< contact sets taken
  std::uint64_t bad_objects = 0;    ///< models naming an object the servo has no material for (ignored)
  std::uint64_t pose_failures = 0;  ///< device could not deliver a pose (zero force commanded)
  std::uint64_t saturated = 0;      ///< ticks where the saturator cut the force
};

/// The wrench a servo renders ([device] dof, torque_limit_nm, tcp_mm in a scene).
struct WrenchConfig {
  int dof = 3;  ///< 3: force only (the torque is computed and reported, not commanded); 6: force and torque
  double torque_limit_Nm = 0.0;  ///< 6-DOF: torque ceiling, N·m (lowered to the device's max_torque_Nm())
  Eigen::Vector3d tcp_mm{Eigen::Vector3d::Zero()};  ///< tool centre point, probe file coordinates, mm
};
/// Empty when the config is usable, else a message naming the bad field.
std::string check(const WrenchConfig& config);

/// One object's material as the servo renders it (a scene's [force] / [object.material]).
struct ObjectMaterial {
  ForceLaw law;                   ///< force law and its constants
  double damping_N_s_per_mm = 0;  ///< damping along the contact normal (InterpolatorConfig::damping_N_s_per_mm)
  FrictionConfig friction;        ///< static and dynamic friction (none by default)
};

/// The servo tick. Construct it, hand it to HapticLoop::start()/run().
class HapticServo final : public TickHandler {
 public:
  /// All references must outlive the servo; telemetry may be null. The saturation peak is
  /// lowered to the device's max_force_N() if it is above it. `period_s` is the loop's period
  /// (it sizes the passivity guard's minimum damping).
  HapticServo(Device& device, TripleBuffer<PoseSample>& poses, TripleBuffer<geom::ContactSet>& models,
              const ForceLaw& law, const InterpolatorConfig& interp, SaturationConfig saturation, Telemetry* telemetry,
              const PassivityConfig& passivity = DefaultPassivityConfig(), double period_s = 1.0 / kDefaultRateHz);
  void tick(const TickInfo& info) noexcept override;
  /// Publish a ServoStatus every kStatusEveryTicks ticks into `status` (null = off). Set before
  /// the loop starts; the servo is the SeqLock's only writer.
  void publish_status_to(SeqLock<ServoStatus>* status) { status_ = status; }
  /// The wrench to render (config must pass check()); before the loop starts. Default: 3-DOF,
  /// torques about the probe's origin.
  void set_wrench(const WrenchConfig& config);
  /// The material's friction (config must pass check()); before the loop starts. Default: none.
  /// The friction force acts at the tool centre point (set_wrench), adds to the surface's force
  /// before saturation, and is passive on its own (friction.hpp); the passivity guard keeps
  /// observing the surface's part alone.
  void set_friction(const FrictionConfig& config);
  /// A scene of several objects: object i of the ContactSets is rendered with materials[i] (its
  /// own interpolator, passivity guard and friction; the constructor's interpolation settings but
  /// the material's law and damping). Replaces the single object of the constructor and
  /// set_friction(); before the loop starts. Every law and friction must be valid (check()).
  void set_objects(const std::vector<ObjectMaterial>& materials);
  std::size_t objects() const { return channels_.size(); }            ///< objects it renders (1 by default)
  const Friction& friction() const { return channels_[0].friction; }  ///< object 0's, for inspection
  /// Friction counters summed over the objects.
  FrictionStats friction_stats() const;
  /// Ticks the passivity controller acted, summed over the objects.
  std::uint64_t passivity_active_ticks() const;
  double peak_torque_Nm() const { return peak_torque_Nm_; }  ///< largest |torque| computed (after the loop)
  /// 6-DOF: the rotational energy observer, Σ τ·dθ the commanded torque put into the device since
  /// the contact began, mJ (the rotational passivity guard keeps it at or below zero).
  double rotational_energy_mJ() const { return rot_energy_mJ_; }
  std::uint64_t rotational_guard_ticks() const { return rot_guard_ticks_; }  ///< ticks the rotational guard acted
  const ServoStats& stats() const { return stats_; }                         ///< counters
  double peak_force_N() const { return peak_force_N_; }  ///< largest |force| commanded (after the loop)
  const Interpolator& interpolator() const { return channels_[0].interp; }  ///< object 0's, for inspection
  const Saturator& saturator() const { return sat_; }                       ///< for inspection
  const PassivityGuard& passivity() const { return channels_[0].guard; }    ///< object 0's, for inspection

 private:
  /// One object's rendering: its interpolator, guard and friction, and this tick's forces.
  struct Channel {
    Interpolator interp;
    PassivityGuard guard;
    Friction friction;
    double k_N_per_mm = 0;                             ///< its law's steepest slope
    bool live = false;                                 ///< has had a model: ticked every tick since
    Eigen::Vector3d guarded{Eigen::Vector3d::Zero()};  ///< this tick: the surface's force after the guard
    Eigen::Vector3d ft{Eigen::Vector3d::Zero()};       ///< this tick: the friction force
  };
  Channel make_channel(const ForceLaw& law, double damping_N_s_per_mm, const FrictionConfig& friction) const;
  Device& device_;
  TripleBuffer<PoseSample>& poses_;
  TripleBuffer<geom::ContactSet>& models_;
  InterpolatorConfig interp_config_;
  PassivityConfig passivity_config_;
  std::vector<Channel> channels_;  ///< one per object, sized before the loop starts
  std::size_t primary_ = 0;        ///< this tick's deepest touching object (telemetry, the rotational guard)
  Saturator sat_;
  Telemetry* telemetry_;
  SeqLock<ServoStatus>* status_ = nullptr;
  ServoStats stats_;
  double peak_force_N_ = 0;  ///< largest |force| commanded
  WrenchConfig wrench_;
  double torque_ceiling_Nm_ = 0;  ///< 6-DOF: min(torque_limit_Nm, the device's max_torque_Nm())
  double peak_torque_Nm_ = 0;     ///< largest |torque| computed
  /// The rotational guard (6-DOF, passivity enabled): the device's rotation last tick, its
  /// filtered angular velocity, the observer's energy and the torque last commanded.
  Eigen::Matrix3d last_rot_{Eigen::Matrix3d::Identity()};
  bool have_rot_ = false;
  Eigen::Vector3d omega_{Eigen::Vector3d::Zero()};  ///< rad/s
  Eigen::Vector3d last_tau_{Eigen::Vector3d::Zero()};
  double rot_energy_mJ_ = 0;
  std::uint64_t rot_guard_ticks_ = 0;
  bool passivity_on_ = true;
  double margin_ = 2.0;  ///< PassivityConfig::colgate_margin
  double period_s_ = 1e-3;
  /// 6-DOF: the torque to command for `tau` (N·m), the device at rotation R, dt_s after the last tick.
  Eigen::Vector3d guard_torque(const Eigen::Vector3d& tau, const Eigen::Matrix3d& R, bool in_contact, double dt_s) noexcept;
  std::uint64_t set_seq_ = 0;  ///< newest ContactSet's seq
  std::int64_t model_received_ns_ = 0;
  std::int64_t pose_ns_ = 0;  ///< sampling time of the newest published pose
  std::uint32_t model_contacts_ = 0;
  std::uint64_t pose_seq_ = 0;
  std::int64_t last_ns_ = 0;
  std::int64_t model_pose_ns_ = 0;  ///< pose_sampled_ns of the newest model
};

}  // namespace st::rt
