// SPDX-License-Identifier: BSD-3-Clause
// The multi-plane depth of a concave contact (contact_planes.hpp).
#include <spheretouch/geom/contact_planes.hpp>

#include <Eigen/Dense>
#include <cassert>
#include <cmath>
#include <limits>

namespace st::inline SPHERETOUCH_ABI::geom {

void PlaneClusters::add(const Vec3& normal, const Vec3& centroid) {
  assert(std::abs(normal.norm() - 1) < 1e-6);
  for (int k = 0; k < n; ++k) {
    PlaneCluster& p = c[k];
    const double cos = normal.dot(p.normal);
    if (cos > kPlanarCos) {
      // Coplanar: the same face split, or another face of the same CAD face. Parallel but off
      // the plane (a step, a plate's other side) is not one plane.
      if (std::abs(p.normal.dot(centroid) - p.offset) > 1e-6 * (1 + centroid.norm())) {
        overflow = true;
        return;
      }
      ++p.faces;
      p.centroid += (centroid - p.centroid) / double(p.faces);
      return;
    }
    if (cos > kApartCos) {  // turned a little: a curved surface's facets
      overflow = true;
      return;
    }
  }
  if (n == kMaxPlanes) {
    overflow = true;
    return;
  }
  PlaneCluster& p = c[n++];
  p.normal = normal;
  p.centroid = centroid;
  p.offset = normal.dot(centroid);
  p.faces = 1;
}

bool PlaneClusters::concave(double slack_mm) const {
  if (n < 2 || overflow) return false;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      if (i != j && !(c[i].normal.dot(c[j].centroid) - c[i].offset > slack_mm)) return false;
  return true;
}

Vec3 smallest_clearing(const std::array<Vec3, 4>& normal, const std::array<double, 4>& depth, int n, bool& ok) {
  assert(n >= 0 && n <= 4);
  ok = true;
  bool any = false;
  for (int i = 0; i < n; ++i) any |= depth[i] > 0;
  if (!any) return Vec3::Zero();
  // Every active set S of one to three planes: t = N_Sᵀ λ with N_S t = d_S; a KKT point has
  // λ >= 0 and keeps every other plane. The projection onto a convex polyhedron is the shortest
  // of them.
  double best = std::numeric_limits<double>::infinity();
  Vec3 best_t = Vec3::Zero();
  auto consider = [&](const int* S, int k) {
    Eigen::Matrix3d G = Eigen::Matrix3d::Identity();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    for (int a = 0; a < k; ++a) {
      b(a) = depth[S[a]];
      for (int c = 0; c < k; ++c) G(a, c) = normal[S[a]].dot(normal[S[c]]);
    }
    using Small = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 3, 3>;  // no heap
    using SmallVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 3, 1>;
    const Small Gk = G.topLeftCorner(k, k);
    if (!(std::abs(Gk.determinant()) > 1e-9)) return;  // dependent normals: a smaller set covers it
    const SmallVec lambda = Gk.ldlt().solve(SmallVec(b.head(k)));
    Vec3 t = Vec3::Zero();
    for (int a = 0; a < k; ++a) {
      if (lambda(a) < -1e-12) return;
      t += lambda(a) * normal[S[a]];
    }
    for (int i = 0; i < n; ++i)
      if (normal[i].dot(t) < depth[i] - 1e-9 * (1 + std::abs(depth[i]))) return;
    if (t.norm() < best) best = t.norm(), best_t = t;
  };
  for (int i = 0; i < n; ++i) {
    const int s1[1] = {i};
    consider(s1, 1);
    for (int j = i + 1; j < n; ++j) {
      const int s2[2] = {i, j};
      consider(s2, 2);
      for (int k = j + 1; k < n; ++k) {
        const int s3[3] = {i, j, k};
        consider(s3, 3);
      }
    }
  }
  if (!std::isfinite(best)) {
    ok = false;
    return Vec3::Zero();
  }
  return best_t;
}

}  // namespace st::geom
