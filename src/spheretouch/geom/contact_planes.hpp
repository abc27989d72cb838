// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The depth of a contact against several planes at once: a probe in a crease, an inner corner or
/// a pocket must clear every wall, and the smallest translation that does is not along the patch's
/// summed normal. The colliding faces are grouped into planar clusters; where the clusters face
/// each other (a concave contact), the way out is the smallest t with n_i·t >= d_i for every
/// cluster's normal n_i and depth d_i: the multi-plane god-object of Zilles & Salisbury (1995) and
/// the constraint-based proxy of Ortega, Redon & Coquillart (2007), here a QP of up to four
/// half-spaces solved by enumerating active sets. Internal to src/spheretouch/geom (the patch model).
#pragma once
#include <spheretouch/abi.hpp>
#include <array>
#include <cstdint>

#include <spheretouch/geom/mesh.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// A set of colliding faces that lie in one plane (to within kPlanarCos).
struct PlaneCluster {
  Vec3 normal{Vec3::Zero()};    ///< unit normal (of its first face)
  Vec3 centroid{Vec3::Zero()};  ///< mean of its faces' centroids
  double offset = 0;            ///< normal · centroid
  std::uint32_t faces = 0;      ///< faces in it
};

/// Up to kMaxPlanes clusters of a contact's faces.
struct PlaneClusters {
  static constexpr int kMaxPlanes = 4;       ///< the QP's half-spaces at most (contact_planes.cpp)
  std::array<PlaneCluster, kMaxPlanes> c{};  ///< the clusters, [0, n) in use
  int n = 0;                                 ///< clusters found
  bool overflow = false;  ///< a face fitted none and there was no room: not a few planes (a curved patch)
  void clear() { n = 0, overflow = false; }  ///< empties, for the next contact
  /// Adds a face (unit normal, centroid): it joins the cluster whose plane it lies in, else opens
  /// one. A face whose normal is within kPlanarCos of a cluster's but off its plane, or turned less
  /// than kApartCos from it without being in it, makes the patch curved (overflow).
  void add(const Vec3& normal, const Vec3& centroid);
  /// True when there are 2..kMaxPlanes clusters, no overflow, and every two face each other
  /// (each one's centroid lies above the other's plane by more than `slack_mm`): a concave
  /// contact whose way out is constrained by every plane.
  bool concave(double slack_mm) const;
};

/// Faces in one cluster have normals within this cosine of each other (~2.6°): planar CAD faces
/// and their splits, not the facets of a curved surface.
inline constexpr double kPlanarCos = 0.999;
/// Clusters count as separate walls only when their normals are more than ~30° apart; closer
/// than that (and not coplanar) the patch is a curved surface, where the summed normal is right.
inline constexpr double kApartCos = 0.866;

/// The smallest translation t with normal_i · t >= depth_i for i < n (n <= 4, unit normals), by
/// enumerating active sets of one to three planes (KKT: multipliers >= 0, every plane kept);
/// zero when no depth is positive. `ok` is false when no active set is feasible (normals that
/// leave no way out, e.g. opposite walls both penetrated more than their gap allows).
Vec3 smallest_clearing(const std::array<Vec3, 4>& normal, const std::array<double, 4>& depth, int n, bool& ok);

}  // namespace st::geom
