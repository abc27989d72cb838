// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// PoseFeedDevice: a Device whose poses another thread pushes at its own rate (the live view's
/// page: `[device] kind = "browser"`), upsampled to the servo's 1 kHz: each tick interpolates from
/// the previous pose to the newest over the interval at which they arrived (translation linearly,
/// rotation by slerp, as Trajectory::at does), so a 30-60 Hz source moves the probe without steps,
/// one source period behind. Offers are checked (finite, unit quaternion, within range) before they
/// reach the servo; the servo reads a triple buffer and never waits. The force commanded is kept
/// for display only (a browser cannot render it).
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstdint>

#include <spheretouch/rt/device.hpp>
#include <spheretouch/rt/triple_buffer.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// A Device moved by poses another thread offers (the live view's page), upsampled to the servo rate.
class PoseFeedDevice final : public Device {
 public:
  /// `grip`: probe file coordinates -> the tool frame (fingertip at the origin); `home`: the tip's
  /// position before the first offer, object mm; `max_abs_mm`: offers beyond are refused.
  PoseFeedDevice(const Eigen::Isometry3d& grip, const Eigen::Vector3d& home, double max_force_N, double max_abs_mm = 1e6);
  /// One writer thread: the tool tip (object mm) and orientation sampled at now_ns. False (and
  /// counted) for a non-finite, out-of-range or non-unit (|q| off by > 1e-3) pose.
  bool offer(const Eigen::Vector3d& tip, const Eigen::Quaterniond& q, std::int64_t now_ns) noexcept;
  bool read_pose(std::int64_t now_ns, Eigen::Isometry3d& pose) noexcept override;
  void command_force(std::int64_t now_ns, const Eigen::Vector3d& force_N) noexcept override;
  double max_force_N() const noexcept override { return max_force_N_; }
  const Eigen::Vector3d& home() const { return home_; }  ///< the tip's position before the first offer, object mm
  std::uint64_t offers() const { return offers_.load(std::memory_order_relaxed); }    ///< poses taken
  std::uint64_t refused() const { return refused_.load(std::memory_order_relaxed); }  ///< poses refused

 private:
  struct Span {
    double a[7], b[7];  // tip x y z, quaternion w x y z: from, to
    std::int64_t ta = 0, tb = 0;
    bool any = false;
  };
  Eigen::Isometry3d grip_;
  Eigen::Vector3d home_;
  double max_force_N_, max_abs_mm_;
  TripleBuffer<Span> spans_;
  Span last_{};  // writer side: the newest span published
  std::atomic<std::uint64_t> offers_{0}, refused_{0};
};

}  // namespace st::rt
