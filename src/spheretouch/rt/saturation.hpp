// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Saturator: the last stage before the device. Caps the force at the device's peak force and,
/// optionally, pulls the ceiling down to the continuous force when the RMS force over the last
/// ~tau seconds approaches it (an I²t-style thermal guard; CHAI3D never clamps — we always do).
/// Non-finite input becomes zero force and is counted. apply() is tick-path safe.
#pragma once
#include <spheretouch/abi.hpp>
#include <Eigen/Core>
#include <cstdint>
#include <string>

#include <spheretouch/rt/constants.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Saturation settings; the initializers (= DefaultSaturationConfig()) are the Omni's: 3.3 N
/// peak, 0.88 N continuous, 10 s.
struct SaturationConfig {
  double peak_N = kOmniPeakForceN;              ///< hard ceiling, N
  bool sustained = true;                        ///< enable the sustained-force limit
  double continuous_N = kOmniContinuousForceN;  ///< RMS force the ceiling converges to under a long push, N
  double tau_s = kSustainedTauS;                ///< time constant of the RMS estimate, s
  double onset = kSustainedOnset;               ///< RMS / continuous_N at which the ceiling starts to fall, in (0, 1)
};
/// Omni: peak 3.3 N, sustained limit on, continuous 0.88 N, tau 10 s, onset 0.8.
SaturationConfig DefaultSaturationConfig();

/// Force limiter. One instance per servo loop.
class Saturator {
 public:
  explicit Saturator(const SaturationConfig& config);  ///< config must pass check()
  /// Empty when the config is usable, else a message naming the bad field.
  static std::string check(const SaturationConfig& config);
  /// The force to command for a requested force f (N), dt_s after the previous call.
  /// Finite, |result| <= ceiling_N() <= peak_N, same direction as f.
  Eigen::Vector3d apply(const Eigen::Vector3d& f, double dt_s) noexcept;
  double ceiling_N() const noexcept { return ceiling_; }                  ///< current ceiling, N
  double rms_N() const noexcept;                                          ///< RMS force estimate, N
  bool limited() const noexcept { return limited_; }                      ///< last apply() cut the force
  std::uint64_t nonfinite_inputs() const noexcept { return nonfinite_; }  ///< NaN/Inf requests zeroed

 private:
  SaturationConfig c_;
  double mean_sq_ = 0;  ///< exponential mean of |F|², N²
  double ceiling_;      ///< current ceiling, N
  bool limited_ = false;
  std::uint64_t nonfinite_ = 0;
};

}  // namespace st::rt
