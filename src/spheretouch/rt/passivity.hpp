// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// PassivityGuard: keeps the rendered surface from injecting energy into the user's hand. A
/// sampled spring of stiffness k held for a period T gives back up to k·T/2 more than it took per
/// unit of velocity (Colgate & Schenkel 1997, "Passivity of a class of sampled-data systems");
/// contact models that change between collision rounds can inject more. Two stages, both along
/// the contact normal only (damping a slide sideways would feel like syrup):
///  1. Minimum damping b = colgate_margin · k·T/2, the rate-independent bound for the law's
///     steepest slope k at the servo period T.
///  2. Time-domain passivity control (Hannaford & Ryu 2002, "Time-domain passivity control of
///     haptic interfaces", IEEE T-RA 18(1)): an observer sums the energy the commanded force put
///     into the device, E = Σ F_k·(x_{k+1} − x_k) (exactly what a zero-order-hold force does on
///     the moving end effector). Ours acts on the energy the cycle would end with, E + F_n²/(2k)
///     (the surface still holds at least F_n²/(2k) to give back): when it is > 0 a damper
///     α = (E + F_n²/2k) / (4·T·v_n²), capped at max_damping, dissipates the excess over the next
///     four ticks, while there is still force to take it from; α lets go by at most 20 % a tick,
///     so the force it took comes back without a step (one-tick removal chattered on a fast
///     release). When contact ends, E keeps only a
///     positive debt (it restarts at 0 otherwise), so every contact cycle starts with no credit.
/// The guard never makes the force pull the probe into the object (the normal component stays
/// >= 0) and never raises it above the saturator's ceiling (it runs before the Saturator, and the
/// observer is fed the force actually commanded, after saturation). Tick-path safe: noexcept, no
/// allocation.
#pragma once
#include <spheretouch/abi.hpp>
#include <Eigen/Core>
#include <cstdint>
#include <string>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Guard settings; DefaultPassivityConfig() gives the documented defaults.
struct PassivityConfig {
  bool enabled = true;                   ///< false: the force passes unchanged
  double colgate_margin = 2.0;           ///< minimum damping = margin · k·T/2 (0 = no minimum damping)
  double max_damping_N_s_per_mm = 0.05;  ///< cap on the passivity controller's damper α, N·s/mm
};
/// Enabled, margin 2 (twice Colgate's bound), controller damping capped at 0.05 N·s/mm (about 3×
/// critical damping of a 0.1 kg hand on the law's steepest 0.59 N/mm: enough to take an excess
/// back within a few ticks; it acts only while there is one).
PassivityConfig DefaultPassivityConfig();

/// What the guard did on the last tick, for telemetry.
struct PassivityState {
  double energy_mJ = 0;  ///< observer: energy the surface put into the device since contact began, mJ (N·mm)
  double damping_N = 0;  ///< normal force the guard added (negative: it took force away), N
  bool active = false;   ///< the passivity controller (stage 2) acted
};

/// One per servo.
class PassivityGuard {
 public:
  /// `stiffness_N_per_mm` is the law's steepest slope, `period_s` the servo period.
  PassivityGuard(const PassivityConfig& config, double stiffness_N_per_mm, double period_s);
  /// Empty when the config is usable, else a message naming the bad field.
  static std::string check(const PassivityConfig& config);

  /// The force to command before saturation, for the model's force `f` (N) at end-effector
  /// position `x_mm` (object frame), contact normal `n` (unit, or zero when not in contact), `dt_s`
  /// after the previous tick. Feed what was finally commanded to commanded().
  Eigen::Vector3d apply(const Eigen::Vector3d& f, const Eigen::Vector3d& x_mm, const Eigen::Vector3d& n, double dt_s) noexcept;
  /// The force actually sent to the device this tick (after saturation): the observer's input.
  void commanded(const Eigen::Vector3d& f) noexcept { last_f_ = f.allFinite() ? f : Eigen::Vector3d::Zero(); }
  /// Forgets position and energy (a new session, a device re-home).
  void reset() noexcept;

  const PassivityState& state() const noexcept { return state_; }        ///< last apply()'s details
  double min_damping_N_s_per_mm() const noexcept { return b_min_; }      ///< stage 1 damping
  std::uint64_t active_ticks() const noexcept { return active_ticks_; }  ///< ticks stage 2 acted

 private:
  PassivityConfig c_;
  double b_min_;                                     ///< stage 1 damping, N·s/mm
  double k_;                                         ///< the law's steepest slope, N/mm (stored-energy estimate)
  double period_s_;                                  ///< nominal period, s (fallback for dt)
  Eigen::Vector3d last_x_{Eigen::Vector3d::Zero()};  ///< previous position, mm
  Eigen::Vector3d last_f_{Eigen::Vector3d::Zero()};  ///< previous commanded force, N
  double vn_ = 0;                                    ///< filtered normal velocity, mm/s (+ = leaving the surface)
  double energy_ = 0;                                ///< observer, mJ
  double alpha_ = 0;                                 ///< the controller's damper last tick, N·s/mm
  bool have_x_ = false;
  bool contact_ = false;  ///< previous tick was in contact
  std::uint64_t active_ticks_ = 0;
  PassivityState state_;
};

}  // namespace st::rt
