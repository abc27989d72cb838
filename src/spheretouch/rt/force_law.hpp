// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Force laws: force magnitude (N) from penetration depth (mm). The paper's eq. (1),
/// F = (log(PD) + a)·b, made finite, non-negative, continuous and device-safe; plus a linear
/// spring for comparison. magnitude_N() is the 1 kHz path: noexcept, no allocation, and for any
/// double input (NaN, ±Inf, negative, denormal) it returns a finite value in [0, max_force_N].
#pragma once
#include <spheretouch/abi.hpp>
#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/constants.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Which law.
enum class LawKind { log, linear };

/// Law parameters; the initializers (= DefaultForceLawConfig()) are the documented defaults.
struct ForceLawConfig {
  LawKind kind = LawKind::log;                    ///< paper eq. (1) or the linear spring
  double a = kPaperA;                             ///< eq. (1) constant a, dimensionless (paper: 3.0)
  double b_N = kPaperB;                           ///< eq. (1) constant b, N (paper: 0.8)
  double log_base = kDefaultLogBase;              ///< base of eq. (1)'s log, > 1
  double pd_unit_mm = kDefaultPdUnitMm;           ///< eq. (1) takes PD in this unit, mm (10 = centimetres)
  double spring_N_per_mm = kDefaultSpringNPerMm;  ///< linear law stiffness, N/mm
  double max_force_N = kOmniPeakForceN;           ///< saturation, N (device peak)
};
/// Paper constants, natural log, PD in cm (max stiffness 0.59 N/mm), Omni peak force 3.3 N.
ForceLawConfig DefaultForceLawConfig();

/// A validated force law. Log law, with x = PD and u = pd_unit_mm, β = log_base:
///   raw(x)  = b·(log_β(x/u) + a)              (eq. 1; negative below u·β^-a, -∞ at 0, NaN < 0)
///   F(x)    = k·x                      x <= x0   (line from the origin tangent to raw)
///           = raw(x)                   x >  x0
///   x0 = u·e/β^a, k = b/(x0·ln β) = raw(x0)/x0; then F is clamped to [0, max_force_N].
/// F is continuous, non-decreasing, and its steepest slope is k (the log's slope b/(x ln β)
/// falls for x > x0). Defaults: x0 = 1.353 mm, k = 0.591 N/mm, 3.3 N reached at 30.8 mm.
class ForceLaw {
 public:
  /// Checks the config; the error names the bad field.
  static Result<ForceLaw> make(const ForceLawConfig& config);
  /// A law from DefaultForceLawConfig() (always valid).
  ForceLaw();

  /// Force magnitude, N, for a penetration in mm. Finite and in [0, max_force_N] for any input;
  /// PD that is NaN or <= 0 gives 0, +Inf gives max_force_N.
  double magnitude_N(double pd_mm) const noexcept;
  /// The unmodified eq. (1), N (log law) or k·PD (linear): for comparison plots only.
  double raw_N(double pd_mm) const noexcept;
  /// Largest slope dF/dPD anywhere, N/mm (what the device must render stably).
  double max_stiffness_N_per_mm() const noexcept { return k_; }
  /// End of the linear segment, mm (0 for the linear law).
  double knee_mm() const noexcept { return x0_; }
  /// The parameters it was made from.
  const ForceLawConfig& config() const noexcept { return c_; }

 private:
  explicit ForceLaw(const ForceLawConfig& c);
  ForceLawConfig c_;
  double inv_ln_base_ = 1;  ///< 1 / ln β
  double x0_ = 0;           ///< knee, mm
  double k_ = 0;            ///< slope of the linear segment, N/mm
};

}  // namespace st::rt
