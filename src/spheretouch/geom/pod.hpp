// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Trivially copyable mirrors of the Eigen types, for values that cross threads or processes
/// by plain copy (TripleBuffer, shared memory, telemetry). Eigen's own types have user-provided
/// copy constructors, so they are not trivially copyable; convert at the edges with the helpers.
#pragma once
#include <spheretouch/abi.hpp>
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <type_traits>

namespace st::inline SPHERETOUCH_ABI::geom {

/// A 3-vector of doubles, plain data.
struct PodVec3 {
  ///@{
  double x = 0, y = 0, z = 0;  ///< components
  ///@}
};

/// A rigid transform, plain data: rotation row-major r[3*row+col], translation t.
struct PodPose {
  double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< rotation, row-major
  double t[3] = {0, 0, 0};                    ///< translation, mm
};

static_assert(std::is_trivially_copyable_v<PodVec3> && sizeof(PodVec3) == 24);
static_assert(std::is_trivially_copyable_v<PodPose> && sizeof(PodPose) == 96);

/// PodVec3 from an Eigen vector.
inline PodVec3 to_pod(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
/// Eigen vector from a PodVec3.
inline Eigen::Vector3d to_eigen(const PodVec3& v) { return {v.x, v.y, v.z}; }

/// PodPose from an isometry (its linear part is copied as is).
inline PodPose to_pod(const Eigen::Isometry3d& p) {
  PodPose q;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) q.r[3 * i + j] = p.linear()(i, j);
    q.t[i] = p.translation()(i);
  }
  return q;
}
/// Isometry from a PodPose.
inline Eigen::Isometry3d to_eigen(const PodPose& q) {
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) p.linear()(i, j) = q.r[3 * i + j];
    p.translation()(i) = q.t[i];
  }
  return p;
}

/// True when every component is finite.
inline bool finite(const PodVec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
/// True when every entry is finite.
inline bool finite(const PodPose& q) {
  for (double d : q.r)
    if (!std::isfinite(d)) return false;
  for (double d : q.t)
    if (!std::isfinite(d)) return false;
  return true;
}

}  // namespace st::geom
