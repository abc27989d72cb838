// SPDX-License-Identifier: BSD-3-Clause
// Test helpers shared by the rt suites.
#pragma once
#include <string>

#include <spheretouch/geom/contact.hpp>

/// The error of a Result, or "" when it holds a value (safe inside *_MESSAGE, which doctest
/// may evaluate on success too).
template <class R>
std::string err_of(const R& r) {
  return r.ok() ? std::string() : r.error();
}

/// A contact model against the wall z <= 0 (FD = +z, plane through the origin) for the probe at
/// `pose`, its probe point the probe's origin, PD `pd_mm`, the force acting at `pressure_point`
/// (object frame, mm); seq 1.
inline st::geom::ContactModel wall_contact(const Eigen::Isometry3d& pose, double pd_mm,
                                           const Eigen::Vector3d& pressure_point) {
  using st::geom::to_pod;
  st::geom::ContactModel m{};
  m.seq = 1;
  m.flags = st::geom::kInContact;
  m.pose = to_pod(pose);
  m.force_dir = to_pod(Eigen::Vector3d(0, 0, 1));
  m.probe_point = to_pod(Eigen::Vector3d(0, 0, 0));
  m.plane_point = to_pod(Eigen::Vector3d(0, 0, 0));
  m.contact_point = to_pod(pressure_point);
  m.pressure_point = to_pod(pressure_point);
  m.penetration_mm = pd_mm;
  return m;
}
