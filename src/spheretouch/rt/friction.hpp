// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Friction: Coulomb friction with stick and slip, rendered at the servo rate (1 kHz) on the
/// contact plane the interpolator gives.
///
/// The model is a stick point (a friction proxy) on the contact plane, in the object's frame: the
/// probe's tool point is tied to it by a tangential spring (Hayward & Armstrong 2000, "A new
/// computational model of friction applied to haptic rendering"; Salcudean & Vlaar 1997, "On the
/// emulation of stiff walls and static friction with a magnetically levitated input/output device").
///  * **Stick.** The stick point stays put; the force is the spring's, −k·d (d the tool point's
///    tangential offset from it), with Colgate's minimum damping for a sampled spring
///    (margin·k·T/2 on the tangential velocity) so the spring held for a period T stays passive.
///  * **Break-away.** When k·|d| would exceed μs·Fn the contact slips.
///  * **Slip.** The stick point is dragged behind the tool point so that the force is exactly
///    μd·Fn, opposing the motion. Once the tool point stops moving away from the stick point (it
///    stops or turns back), the contact sticks again. μs >= μd gives the stick-slip hysteresis.
/// The stick point lives in the object's frame, not in a contact model: a new collision round
/// (a new contact plane) does not move it; each tick the offset is taken in the current plane.
/// Energy: while stuck the spring is conservative (plus damping); every slip moves the stick
/// point toward the tool point, which only releases stored energy; a falling Fn shrinks the cone
/// and slips, never pushes. So the friction force never injects energy beyond the sampled
/// spring's, which the damping covers. Why a stick point rather than CHAI3D's friction cone on
/// the proxy: the servo's normal force comes from the contact model (the proxy here is a
/// display), and a stick point needs nothing but the tool point, the plane and Fn, all of which
/// the servo has every tick; the two are equivalent for a point contact.
/// Tick-path safe: noexcept, no allocation.
#pragma once
#include <spheretouch/abi.hpp>
#include <Eigen/Core>
#include <cstdint>
#include <string>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Friction of a material (μs = μd = 0: none, and the servo's force is what it was without).
struct FrictionConfig {
  double static_mu = 0;           ///< μs: the contact slips when the tangential force would exceed μs·Fn
  double dynamic_mu = 0;          ///< μd <= μs: the force while slipping is μd·Fn
  double stiffness_N_per_mm = 0;  ///< the stick spring, N/mm (0: the force law's steepest slope)
  double damping_margin = 2.0;    ///< stick damping = margin · k·T/2 (Colgate's bound; 0 = none)
};
/// Empty when the config is usable (0 <= μd <= μs <= 10, finite stiffness >= 0, margin in [0, 100]), else a message naming the field.
std::string check(const FrictionConfig& c);

/// Counters.
struct FrictionStats {
  std::uint64_t stuck_ticks = 0;    ///< ticks in contact, stuck
  std::uint64_t sliding_ticks = 0;  ///< ticks in contact, slipping
  std::uint64_t breakaways = 0;     ///< stick -> slip
  std::uint64_t sticks = 0;         ///< slip -> stick
};

/// One per servo.
class Friction {
 public:
  /// `law_stiffness_N_per_mm` replaces a stiffness of 0; `period_s` is the servo period.
  Friction(const FrictionConfig& config, double law_stiffness_N_per_mm, double period_s);
  /// True when μs or μd is above zero.
  bool enabled() const noexcept { return config_.static_mu > 0 || config_.dynamic_mu > 0; }
  /// The friction force (N, object frame) on the tool point at `p_mm` (object frame) in contact
  /// with the plane of unit normal `n` under normal force `fn_N`; `dt_s` since the last tick. A
  /// call with fn_N <= 0 (or a non-finite input) ends the contact: no stick point, zero force.
  Eigen::Vector3d apply(const Eigen::Vector3d& p_mm, const Eigen::Vector3d& n, double fn_N, double dt_s) noexcept;
  bool stuck() const noexcept { return in_contact_ && stuck_; }              ///< in contact and sticking
  bool sliding() const noexcept { return in_contact_ && !stuck_; }           ///< in contact and slipping
  const Eigen::Vector3d& stick_point_mm() const noexcept { return stick_; }  ///< valid while in contact
  const FrictionStats& stats() const noexcept { return stats_; }             ///< counters
  double stiffness_N_per_mm() const noexcept { return k_; }                  ///< the stick spring in use

 private:
  FrictionConfig config_;
  double k_;  // N/mm
  double b_;  // N·s/mm, stick damping
  double period_s_;
  bool in_contact_ = false, stuck_ = true;
  Eigen::Vector3d stick_{Eigen::Vector3d::Zero()};   // mm, object frame
  Eigen::Vector3d last_p_{Eigen::Vector3d::Zero()};  // mm
  Eigen::Vector3d last_d_{Eigen::Vector3d::Zero()};  // the tangential offset last tick, mm
  Eigen::Vector3d v_{Eigen::Vector3d::Zero()};       // filtered tangential velocity, mm/s
  FrictionStats stats_;
};

}  // namespace st::rt
