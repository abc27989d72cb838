// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// <spheretouch/rt/device.hpp>: Device, what the servo talks to each tick: a vendor SDK's device
/// (OpenHaptics, Force Dimension's dhd, libnifalcon, CHAI3D's device layer), the UDP bridge, the
/// browser page or the SimulatedDevice. A program hands its own to the run engine with
/// engine::RunOptions::device (examples/custom_device.cpp).
///
/// The rules an implementation follows:
///  * **Frames and units.** The pose maps probe file coordinates to object file coordinates
///    (the haptic side's world), mm; forces are N in the object's frame. Mapping the device's
///    workspace onto the object (scale, offset, the grip on the probe) is the implementation's job.
///  * **The tick path.** read_pose() and command_force() run on the servo's thread once a tick
///    (1 kHz), read_pose() first: noexcept, no allocation, no lock, no blocking, no system call
///    that can sleep. A driver call that can block (USB, a socket) runs on a thread of its own
///    that hands the newest value over (a triple buffer, rt/triple_buffer.hpp).
///  * **The clock.** Either the engine's haptic thread calls the device (the default), or the
///    device's own servo callback calls engine::RunEngine::tick(), inside which both calls run
///    (engine::RunOptions::device_clocked): then the pose the callback just read becomes a force
///    before tick() returns.
///  * **No pose.** read_pose() returning false makes the servo command zero force that tick and
///    count it; return false rather than a stale or made-up pose.
///  * **Force.** command_force() gets a finite force, already saturated to max_force_N() (the
///    servo lowers its peak to it) and passed through the passivity guard; send it as it is.
///  * **Torque (6-DOF devices).** A device that renders torque overrides command_wrench() and
///    max_torque_Nm() (> 0); with the scene's `[device] dof = 6` the servo then calls
///    command_wrench() instead of command_force(), with the torque about the tool centre point
///    (`[device] tcp_mm`), N·m in the object's frame, finite and within max_torque_Nm().
///  * **Lifetime.** The device outlives the engine that uses it; the engine never deletes it.
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
  /// Commands a force and a torque about the tool centre point (N, N·m, object frame), finite and
  /// saturated. 6-DOF devices override it; the default sends the force alone (a 3-DOF device).
  virtual void command_wrench(std::int64_t now_ns, const Eigen::Vector3d& force_N, const Eigen::Vector3d& torque_Nm) noexcept {
    (void)torque_Nm;
    command_force(now_ns, force_N);
  }
  /// The device's peak torque, N·m; 0 (the default) for a device that renders no torque.
  virtual double max_torque_Nm() const noexcept { return 0.0; }
};

}  // namespace st::rt
