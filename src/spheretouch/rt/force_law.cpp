// SPDX-License-Identifier: BSD-3-Clause
#include <spheretouch/rt/force_law.hpp>

#include <algorithm>
#include <cmath>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/rt/constants.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

ForceLawConfig DefaultForceLawConfig() { return ForceLawConfig{}; }

namespace {
bool positive_finite(double v) { return std::isfinite(v) && v > 0; }
}  // namespace

Result<ForceLaw> ForceLaw::make(const ForceLawConfig& c) {
  if (!positive_finite(c.max_force_N))
    return fail("force law: max_force_N = ", c.max_force_N, ", expected a finite value > 0");
  if (c.kind == LawKind::linear) {
    if (!positive_finite(c.spring_N_per_mm))
      return fail("force law: spring_N_per_mm = ", c.spring_N_per_mm, ", expected a finite value > 0");
    return ForceLaw(c);
  }
  if (!std::isfinite(c.a)) return fail("force law: a = ", c.a, ", expected a finite number");
  if (!positive_finite(c.b_N)) return fail("force law: b_N = ", c.b_N, ", expected a finite value > 0");
  if (!(std::isfinite(c.log_base) && c.log_base > 1.0))
    return fail("force law: log_base = ", c.log_base, ", expected a finite value > 1");
  if (!positive_finite(c.pd_unit_mm))
    return fail("force law: pd_unit_mm = ", c.pd_unit_mm, ", expected a finite value > 0");
  ForceLaw law(c);
  if (!positive_finite(law.x0_) || !positive_finite(law.k_))
    return fail("force law: a = ", c.a, ", log_base = ", c.log_base, ", pd_unit_mm = ", c.pd_unit_mm,
                " put the knee u·e/base^a at ", law.x0_, " mm; expected a finite positive knee");
  return law;
}

ForceLaw::ForceLaw() : ForceLaw(DefaultForceLawConfig()) {}

ForceLaw::ForceLaw(const ForceLawConfig& c) : c_(c) {
  if (c.kind == LawKind::linear) {
    x0_ = 0;
    k_ = c.spring_N_per_mm;
    return;
  }
  const double ln_base = std::log(c.log_base);
  inv_ln_base_ = 1.0 / ln_base;
  // Tangent from the origin: raw(x0) = x0·raw'(x0)  <=>  ln(x0/u) = 1 - a·ln β.
  x0_ = c.pd_unit_mm * std::exp(1.0 - c.a * ln_base);
  k_ = c.b_N * inv_ln_base_ / x0_;
}

double ForceLaw::raw_N(double pd_mm) const noexcept {
  if (c_.kind == LawKind::linear) return k_ * pd_mm;
  return c_.b_N * (std::log(pd_mm / c_.pd_unit_mm) * inv_ln_base_ + c_.a);
}

double ForceLaw::magnitude_N(double pd_mm) const noexcept {
  if (!(pd_mm > 0)) return 0.0;  // NaN, negative, zero, -Inf
  double f;
  if (c_.kind == LawKind::linear || pd_mm <= x0_) {
    f = k_ * pd_mm;  // +Inf·k = +Inf, clamped below
  } else {
    f = c_.b_N * (std::log(pd_mm / c_.pd_unit_mm) * inv_ln_base_ + c_.a);
  }
  // >= rather than >: k·PD underflows to 0 for a subnormal PD.
  ST_ASSERT(f >= 0, "the law is non-negative for PD > 0 (past the knee the log term exceeds its value there)");
  if (!(f > 0)) return 0.0;  // never NaN or negative, whatever a future law does
  return std::min(f, c_.max_force_N);
}

}  // namespace st::rt
