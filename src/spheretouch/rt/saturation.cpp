// SPDX-License-Identifier: BSD-3-Clause
#include <spheretouch/rt/saturation.hpp>

#include <algorithm>
#include <cmath>
#include <sstream>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/rt/constants.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

SaturationConfig DefaultSaturationConfig() { return SaturationConfig{}; }

std::string Saturator::check(const SaturationConfig& c) {
  std::ostringstream os;
  if (!(std::isfinite(c.peak_N) && c.peak_N > 0))
    os << "saturation: peak_N = " << c.peak_N << ", expected a finite value > 0";
  else if (c.sustained && !(std::isfinite(c.continuous_N) && c.continuous_N > 0 && c.continuous_N <= c.peak_N))
    os << "saturation: continuous_N = " << c.continuous_N << ", expected in (0, peak_N = " << c.peak_N << "]";
  else if (c.sustained && !(std::isfinite(c.tau_s) && c.tau_s > 0))
    os << "saturation: tau_s = " << c.tau_s << ", expected > 0";
  else if (c.sustained && !(c.onset > 0 && c.onset < 1))
    os << "saturation: onset = " << c.onset << ", expected in (0, 1)";
  return os.str();
}

Saturator::Saturator(const SaturationConfig& config) : c_(config), ceiling_(config.peak_N) {
  ST_ASSERT(check(config).empty(), "a Saturator's config passes check() (saturation.hpp)");
}

double Saturator::rms_N() const noexcept { return std::sqrt(mean_sq_); }

Eigen::Vector3d Saturator::apply(const Eigen::Vector3d& f, double dt_s) noexcept {
  Eigen::Vector3d out = f;
  double mag = f.norm();
  if (!std::isfinite(mag)) {
    ++nonfinite_;
    out.setZero();
    mag = 0;
  }
  limited_ = mag > ceiling_;
  if (limited_) {
    out *= ceiling_ / mag;
    mag = ceiling_;
  }
  if (c_.sustained) {
    const double dt = std::isfinite(dt_s) ? std::clamp(dt_s, 0.0, c_.tau_s) : 0.0;
    mean_sq_ += (mag * mag - mean_sq_) * (dt / c_.tau_s);
    // Ceiling falls linearly from peak (RMS = onset·continuous) to continuous (RMS = continuous):
    // continuous, and a long push settles exactly at RMS = continuous_N.
    const double lo = c_.onset * c_.continuous_N;
    const double s = std::clamp((std::sqrt(mean_sq_) - lo) / (c_.continuous_N - lo), 0.0, 1.0);
    ceiling_ = c_.peak_N - (c_.peak_N - c_.continuous_N) * s;
  }
  return out;
}

}  // namespace st::rt
