// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Device: what the haptic loop talks to each tick (a PHANToM through OpenHaptics' HD API, or the
/// SimulatedDevice). Poses and forces are in the object's frame (the haptic side's world):
/// the pose maps probe file coordinates to object file coordinates, mm; forces are N. Mapping the
/// device's own workspace onto the object is the implementation's job. Both calls run on the
/// tick path: noexcept, no allocation, no blocking.
#pragma once
#include <spheretouch/abi.hpp>
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>

namespace st::inline SPHERETOUCH_ABI::rt {

/// A haptic device seen from the servo loop.
class Device {
 public:
  virtual ~Device() = default;
  /// The probe pose at now_ns; false when the device cannot deliver one (the servo then commands
  /// zero force and counts the failure).
  virtual bool read_pose(std::int64_t now_ns, Eigen::Isometry3d& pose) noexcept = 0;
  /// Commands a force (N, object frame), already finite and saturated by the servo.
  virtual void command_force(std::int64_t now_ns, const Eigen::Vector3d& force_N) noexcept = 0;
  /// The device's peak force, N (the servo's saturation must not exceed it).
  virtual double max_force_N() const noexcept = 0;
};

}  // namespace st::rt
