// SPDX-License-Identifier: BSD-3-Clause
// Point location on a body's surface seen along a direction (SurfaceWalk, surface_walk.hpp): the
// walk across edges over the faces that face the direction (Guibas & Stolfi 1985, the walk of
// their point location in a subdivision), and the test that a point lies near one face.
#include <spheretouch/geom/surface_walk.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/contact_patch.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

void SurfaceWalk::set_direction(const Vec3& dir) {
  ST_ASSERT(std::abs(dir.squaredNorm() - 1) < 1e-9, "the walk's direction is a unit vector");
  d = dir;
  // Any orthonormal basis of the plane ⊥ d with u × w = d.
  const Vec3 helper = std::abs(d.x()) < 0.6 ? Vec3::UnitX() : (std::abs(d.y()) < 0.6 ? Vec3::UnitY() : Vec3::UnitZ());
  u = d.cross(helper).normalized();
  w = d.cross(u);
}

bool SurfaceWalk::facing(double det, const Vec3& a, const Vec3& b, const Vec3& c) {
  return det > 0 && det * det > kFrontCos * kFrontCos * (b - a).cross(c - a).squaredNorm();
}

Vec3 SurfaceWalk::at(std::uint32_t v) { return patch ? patch->probe_point(v, *mesh) : mesh->local[v]; }

std::uint32_t SurfaceWalk::across(std::uint32_t f, std::uint32_t a, std::uint32_t b) const {
  ST_ASSERT(f < mesh->faces.size() && a + 1 < vf->first.size(), "an edge of a face of the mesh");
  for (std::uint32_t k = vf->first[a]; k < vf->first[a + 1]; ++k) {
    const std::uint32_t g = vf->faces[k];
    if (g == f) continue;
    const Tri& t = mesh->faces[g];
    if (t[0] == b || t[1] == b || t[2] == b) return g;
  }
  return UINT32_MAX;
}

bool SurfaceWalk::exit(const Vec3& x, std::uint32_t& face, double& dist, int max_steps, std::uint32_t* last) {
  const std::size_t nv = mesh->local.size();
  const double qu = x.dot(u), qw = x.dot(w), qh = x.dot(d);
  std::uint32_t f = face, prev = UINT32_MAX;
  for (int step = 0; step < max_steps && f != UINT32_MAX; ++step) {
    ST_ASSERT(f < mesh->faces.size(), "a walk starts from, and crosses to, faces of the mesh");
    const Tri& t = mesh->faces[f];
    if (t[0] >= nv || t[1] >= nv || t[2] >= nv) return false;
    const Vec3 a = at(t[0]), b = at(t[1]), c = at(t[2]);
    const double au = a.dot(u), aw = a.dot(w), bu = b.dot(u), bw = b.dot(w), cu = c.dot(u), cw = c.dot(w);
    const double e1u = bu - au, e1w = bw - aw, e2u = cu - au, e2w = cw - aw;
    // det = (b−a)×(c−a)·d (u × w = d): the projected area, > 0 when the face faces d. Only faces
    // turned less than acos(kFrontCos) from d are walked (never a silhouette or a back face).
    const double det = e1u * e2w - e2u * e1w;
    if (!facing(det, a, b, c)) return false;
    if (last) *last = f;
    const double pu = qu - au, pw = qw - aw;
    const double inv = 1 / det;
    const double b1 = (pu * e2w - e2u * pw) * inv, b2 = (e1u * pw - pu * e1w) * inv, b0 = 1 - b1 - b2;
    constexpr double kTol = 1e-9;  // closed triangles: a point over a shared edge is found from either side
    if (b0 >= -kTol && b1 >= -kTol && b2 >= -kTol) {
      face = f;
      const double h = b0 * a.dot(d) + b1 * b.dot(d) + b2 * c.dot(d);
      dist = h - qh;
      return true;
    }
    // Cross the edge facing the point (opposite the most negative coordinate), never straight
    // back; the second most negative if that one leads back.
    const double bc[3] = {b0, b1, b2};
    int i0 = 0;
    if (bc[1] < bc[i0]) i0 = 1;
    if (bc[2] < bc[i0]) i0 = 2;
    std::uint32_t next = across(f, t[(i0 + 1) % 3], t[(i0 + 2) % 3]);
    if (next == prev && next != UINT32_MAX) {
      const int j1 = (i0 + 1) % 3, j2 = (i0 + 2) % 3;
      const int i1 = bc[j1] < bc[j2] ? j1 : j2;
      next = bc[i1] < -kTol ? across(f, t[(i1 + 1) % 3], t[(i1 + 2) % 3]) : UINT32_MAX;
    }
    prev = f;
    f = next;
  }
  return false;
}

bool SurfaceWalk::near_face(const Vec3& x, std::uint32_t f, double margin, double& dist) {
  ST_ASSERT(f < mesh->faces.size(), "a face of the mesh");
  const Tri& t = mesh->faces[f];
  const std::size_t nv = mesh->local.size();
  if (t[0] >= nv || t[1] >= nv || t[2] >= nv) return false;
  const Vec3 p[3] = {at(t[0]), at(t[1]), at(t[2])};
  const Eigen::Vector2d q(x.dot(u), x.dot(w));
  Eigen::Vector2d c[3];
  for (int k = 0; k < 3; ++k) c[k] = {p[k].dot(u), p[k].dot(w)};
  const Eigen::Vector2d e1 = c[1] - c[0], e2 = c[2] - c[0], r = q - c[0];
  const double det = e1.x() * e2.y() - e2.x() * e1.y();
  if (!facing(det, p[0], p[1], p[2])) return false;
  const double b1 = (r.x() * e2.y() - e2.x() * r.y()) / det, b2 = (e1.x() * r.y() - r.x() * e1.y()) / det;
  const double b0 = 1 - b1 - b2;
  // Distance from q to the triangle in the plane ⊥ d: 0 inside, else to the nearest edge.
  double gap2 = 0;
  if (b0 < 0 || b1 < 0 || b2 < 0) {
    gap2 = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d a = c[k], e = c[(k + 1) % 3] - a;
      const double s = std::clamp((q - a).dot(e) / e.squaredNorm(), 0.0, 1.0);
      gap2 = std::min(gap2, (q - a - s * e).squaredNorm());
    }
  }
  if (!(gap2 <= margin * margin)) return false;
  dist = b0 * p[0].dot(d) + b1 * p[1].dot(d) + b2 * p[2].dot(d) - x.dot(d);  // the plane's height over x
  return std::isfinite(dist);
}

}  // namespace st::geom
