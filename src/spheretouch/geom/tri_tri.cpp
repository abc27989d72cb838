// SPDX-License-Identifier: BSD-3-Clause
// Triangle-triangle overlap built only on exact orient3d/orient2d (predicates.hpp).
//
// Non-coplanar, non-degenerate pairs follow P. Guigue, O. Devillers, "Fast and Robust
// Triangle-Triangle Overlap Test Using Orientation Predicates", JGT 8(1), 2003: reject when one
// triangle lies strictly on one side of the other's plane; otherwise both triangles cut the line
// L = plane(P) ∩ plane(Q) in intervals, and two more orient3d signs compare their ends.
// Our derivation of those signs (which also fixes the touching cases): for pa strictly above
// plane(Q), pb on or below it, qc strictly above plane(P), qd on or below it,
//   orient3d(pa,pb,qc,qd) = τ · (n_P·(qd−qc)) · (n_Q·(pb−pa)),
// where X = [pa,pb] ∩ plane(Q), Y = [qc,qd] ∩ plane(P) and Y − X = τ·(n_P×n_Q); the two last
// factors are negative, so the sign orders X and Y along L. With p1, q1 the vertices alone on
// their side and both triangles oriented so that p1 is above plane(Q) and q1 above plane(P),
// P∩L = [X13, X12] and Q∩L = [Y12, Y13] in that order along n_P×n_Q, so they overlap iff
//   orient3d(p1,p2,q1,q2) ≤ 0  and  orient3d(p1,p3,q1,q3) ≥ 0.
// A triangle touching the other's plane at one vertex only (signs +,+,0) cuts L in that vertex,
// which is then tested against the other triangle directly.
//
// Coplanar pairs and degenerate triangles (segments, points) are decided in the 2D projection
// that drops one axis; the axis is chosen where the triangle's exact projected orientation is
// nonzero, so the projection is injective on the plane and every 2D sign is the 3D truth.
// Coplanar convex sets are disjoint iff one has an edge with the other strictly outside its
// line (the edges of the Minkowski difference are edges of the two sets).
//
// Range: coordinates are used as given while their magnitudes sum to [2^-100, 2^300] (inside
// the filter's domain, predicates.hpp); otherwise all 18 are first scaled by one power of two,
// which changes no answer. Exactness then needs every nonzero coordinate ≥ 2^-306·max
// (predicates.cpp); non-finite input returns false.
#include <spheretouch/geom/tri_tri.hpp>

#include <algorithm>
#include <cmath>
#include <utility>

#include <spheretouch/geom/predicates.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {
namespace {

using detail::orient3d_bounded;
using detail::PlaneSide;

/// orient2d of a, b, c projected along axis k (dropping coordinate k, keeping (k+1, k+2)).
inline int orient2d_proj(const Vec3& a, const Vec3& b, const Vec3& c, int k) noexcept {
  const int u = (k + 1) % 3, v = (k + 2) % 3;
  return detail::orient2d_filtered(a[u], a[v], b[u], b[v], c[u], c[v]);
}

/// A projection axis on which triangle a,b,c keeps a nonzero orientation (its sign is the sign
/// of the normal's component k); axis −1 when the triangle has zero area.
struct Projection {
  int axis;
  int sign;
};

Projection projection(const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  // Try the axes by decreasing approximate |normal component|: the first usually decides.
  const Vec3 n = (b - a).cross(c - a).cwiseAbs();
  int order[3] = {0, 1, 2};
  if (n[order[1]] > n[order[0]]) std::swap(order[0], order[1]);
  if (n[order[2]] > n[order[1]]) std::swap(order[1], order[2]);
  if (n[order[1]] > n[order[0]]) std::swap(order[0], order[1]);
  for (int k : order) {
    const int s = orient2d_proj(a, b, c, k);
    if (s != 0) return {k, s};
  }
  return {-1, 0};
}

/// Point p, coplanar with the non-degenerate triangle a,b,c, lies in the closed triangle.
bool coplanar_point_in_tri(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, Projection pr) noexcept {
  return pr.sign * orient2d_proj(a, b, p, pr.axis) >= 0 && pr.sign * orient2d_proj(b, c, p, pr.axis) >= 0 &&
         pr.sign * orient2d_proj(c, a, p, pr.axis) >= 0;
}

/// Both non-degenerate triangles lie in one plane; pr is an injective projection for P.
bool coplanar_tri_tri(const Vec3 (&p)[3], const Vec3 (&q)[3], Projection pr) noexcept {
  const int k = pr.axis;
  const int sq = orient2d_proj(q[0], q[1], q[2], k);  // nonzero: Q has area, projection injective
  for (int i = 0; i < 3; ++i) {
    const Vec3& e0 = p[i];
    const Vec3& e1 = p[(i + 1) % 3];
    if (pr.sign * orient2d_proj(e0, e1, q[0], k) < 0 && pr.sign * orient2d_proj(e0, e1, q[1], k) < 0 &&
        pr.sign * orient2d_proj(e0, e1, q[2], k) < 0)
      return false;
  }
  for (int i = 0; i < 3; ++i) {
    const Vec3& e0 = q[i];
    const Vec3& e1 = q[(i + 1) % 3];
    if (sq * orient2d_proj(e0, e1, p[0], k) < 0 && sq * orient2d_proj(e0, e1, p[1], k) < 0 &&
        sq * orient2d_proj(e0, e1, p[2], k) < 0)
      return false;
  }
  return true;
}

/// Closed segment s0s1 (s0 ≠ s1) against the non-degenerate triangle t with projection pr.
bool segment_tri(const Vec3& s0, const Vec3& s1, const Vec3 (&t)[3], Projection pr) noexcept {
  const PlaneSide plane(t[0], t[1], t[2]);
  const int d0 = plane.side(s0), d1 = plane.side(s1);
  if (d0 * d1 > 0) return false;
  if (d0 == 0 && d1 == 0) {  // in the plane: the 2D separating-edge test
    const int k = pr.axis;
    for (int i = 0; i < 3; ++i) {
      const Vec3& e0 = t[i];
      const Vec3& e1 = t[(i + 1) % 3];
      if (pr.sign * orient2d_proj(e0, e1, s0, k) < 0 && pr.sign * orient2d_proj(e0, e1, s1, k) < 0) return false;
    }
    const int r0 = orient2d_proj(s0, s1, t[0], k), r1 = orient2d_proj(s0, s1, t[1], k), r2 = orient2d_proj(s0, s1, t[2], k);
    return !(r0 == r1 && r1 == r2 && r0 != 0);
  }
  // The line s0s1 crosses the plane in one point X of the segment. orient3d(s0,s1,ti,tj) has the
  // sign of the orientation of (X,ti,tj) times a common nonzero factor, so X is in the closed
  // triangle iff the three signs do not disagree.
  const int o0 = orient3d_bounded(s0, s1, t[0], t[1]);
  const int o1 = orient3d_bounded(s0, s1, t[1], t[2]);
  const int o2 = orient3d_bounded(s0, s1, t[2], t[0]);
  const bool pos = o0 > 0 || o1 > 0 || o2 > 0;
  const bool neg = o0 < 0 || o1 < 0 || o2 < 0;
  return !(pos && neg);
}

/// p lies on the line through s0 ≠ s1: (s1−s0)×(p−s0) = 0, whose components are the three
/// projected orientations.
bool collinear(const Vec3& s0, const Vec3& s1, const Vec3& p) noexcept {
  return orient2d_proj(s0, s1, p, 0) == 0 && orient2d_proj(s0, s1, p, 1) == 0 && orient2d_proj(s0, s1, p, 2) == 0;
}

/// Closed segment s0s1 (s0 ≠ s1) contains p.
bool point_on_segment(const Vec3& p, const Vec3& s0, const Vec3& s1) noexcept {
  if (!collinear(s0, s1, p)) return false;
  for (int k = 0; k < 3; ++k)  // on the line, inside the bounding box = on the segment
    if (p[k] < std::min(s0[k], s1[k]) || p[k] > std::max(s0[k], s1[k])) return false;
  return true;
}

/// Closed segments a0a1 and b0b1 (each with distinct ends) share a point.
bool segment_segment(const Vec3& a0, const Vec3& a1, const Vec3& b0, const Vec3& b1) noexcept {
  if (orient3d_bounded(a0, a1, b0, b1) != 0) return false;  // skew
  // Coplanar: find an axis whose projection is injective on the common plane.
  int k = -1;
  for (const Vec3* b : {&b0, &b1}) {
    for (int axis = 0; axis < 3 && k < 0; ++axis)
      if (orient2d_proj(a0, a1, *b, axis) != 0) k = axis;
    if (k >= 0) break;
  }
  if (k < 0) {  // all four collinear: compare intervals on an axis where the line is not flat
    int axis = 0;
    while (a0[axis] == a1[axis]) ++axis;  // a0 ≠ a1
    const double alo = std::min(a0[axis], a1[axis]), ahi = std::max(a0[axis], a1[axis]);
    const double blo = std::min(b0[axis], b1[axis]), bhi = std::max(b0[axis], b1[axis]);
    return alo <= bhi && blo <= ahi;
  }
  // Not all collinear, so the lines differ: the usual sign test needs no collinear special case.
  const int o1 = orient2d_proj(a0, a1, b0, k), o2 = orient2d_proj(a0, a1, b1, k);
  const int o3 = orient2d_proj(b0, b1, a0, k), o4 = orient2d_proj(b0, b1, a1, k);
  return o1 * o2 <= 0 && o3 * o4 <= 0;
}

/// What a possibly degenerate triangle is as a point set.
struct Shape {
  enum Kind { kPoint, kSegment, kTriangle } kind;
  Vec3 v[3];      // triangle: the vertices; segment: v[0], v[1]; point: v[0]
  Projection pr;  // triangle only
};

Shape classify(const Vec3 (&t)[3]) noexcept {
  Shape s{Shape::kTriangle, {t[0], t[1], t[2]}, projection(t[0], t[1], t[2])};
  if (s.pr.axis >= 0) return s;
  // Collinear. On an axis where the points differ, their order is their order on the line.
  for (int k = 0; k < 3; ++k) {
    if (t[0][k] == t[1][k] && t[1][k] == t[2][k]) continue;
    int lo = 0, hi = 0;
    for (int i = 1; i < 3; ++i) {
      if (t[i][k] < t[lo][k]) lo = i;
      if (t[i][k] > t[hi][k]) hi = i;
    }
    s.kind = Shape::kSegment;
    s.v[0] = t[lo];
    s.v[1] = t[hi];
    return s;
  }
  s.kind = Shape::kPoint;
  return s;
}

/// At least one triangle has zero area, or both lie in one plane.
bool degenerate_or_coplanar(const Vec3 (&p)[3], const Vec3 (&q)[3]) noexcept {
  Shape a = classify(p), b = classify(q);
  if (a.kind < b.kind) std::swap(a, b);  // a is the "larger" shape
  switch (a.kind) {
    case Shape::kTriangle:
      switch (b.kind) {
        case Shape::kTriangle:
          return coplanar_tri_tri(a.v, b.v, a.pr);
        case Shape::kSegment:
          return segment_tri(b.v[0], b.v[1], a.v, a.pr);
        case Shape::kPoint:
          return PlaneSide(a.v[0], a.v[1], a.v[2]).side(b.v[0]) == 0 &&
                 coplanar_point_in_tri(b.v[0], a.v[0], a.v[1], a.v[2], a.pr);
      }
      break;
    case Shape::kSegment:
      if (b.kind == Shape::kSegment) return segment_segment(a.v[0], a.v[1], b.v[0], b.v[1]);
      return point_on_segment(b.v[0], a.v[0], a.v[1]);
    case Shape::kPoint:
      return a.v[0] == b.v[0];
  }
  return false;  // unreachable
}

/// Index of a vertex with nonzero side whose two others are on the opposite closed side, or −1
/// when there is none (the sides are +,+,0 or −,−,0: the triangle touches the plane at a vertex).
inline int alone(const int (&s)[3]) noexcept {
  for (int i = 0; i < 3; ++i)
    if (s[i] != 0 && s[i] * s[(i + 1) % 3] <= 0 && s[i] * s[(i + 2) % 3] <= 0) return i;
  return -1;
}

inline int zero_index(const int (&s)[3]) noexcept { return s[0] == 0 ? 0 : (s[1] == 0 ? 1 : 2); }

/// The overlap test proper; all coordinates are within the filter's range.
bool overlap(const Vec3 (&p)[3], const Vec3 (&q)[3]) noexcept {
  const PlaneSide plane_p(p[0], p[1], p[2]);
  const int sq[3] = {plane_p.side(q[0]), plane_p.side(q[1]), plane_p.side(q[2])};
  if (sq[0] == sq[1] && sq[1] == sq[2] && sq[0] != 0) return false;  // Q strictly on one side
  const PlaneSide plane_q(q[0], q[1], q[2]);
  const int sp[3] = {plane_q.side(p[0]), plane_q.side(p[1]), plane_q.side(p[2])};
  if (sp[0] == sp[1] && sp[1] == sp[2] && sp[0] != 0) return false;  // P strictly on one side

  // All-zero signs: P has zero area (then every orient3d on it is 0), or Q lies in P's plane
  // (then both are coplanar or Q has zero area). Symmetrically for Q. Otherwise neither
  // triangle is degenerate and the planes cross in a line.
  if ((sq[0] == 0 && sq[1] == 0 && sq[2] == 0) || (sp[0] == 0 && sp[1] == 0 && sp[2] == 0))
    return degenerate_or_coplanar(p, q);

  const int ip = alone(sp);
  if (ip < 0) {  // P meets plane(Q) in one vertex only
    const Vec3& v = p[zero_index(sp)];
    return coplanar_point_in_tri(v, q[0], q[1], q[2], projection(q[0], q[1], q[2]));
  }
  const int iq = alone(sq);
  if (iq < 0) {
    const Vec3& w = q[zero_index(sq)];
    return coplanar_point_in_tri(w, p[0], p[1], p[2], projection(p[0], p[1], p[2]));
  }
  // Rotate the lone vertices first (keeps orientation), then flip the other triangle so that
  // each lone vertex is above the other's plane (swapping two vertices negates its sides).
  const Vec3* p1 = &p[ip];
  const Vec3* p2 = &p[(ip + 1) % 3];
  const Vec3* p3 = &p[(ip + 2) % 3];
  const Vec3* q1 = &q[iq];
  const Vec3* q2 = &q[(iq + 1) % 3];
  const Vec3* q3 = &q[(iq + 2) % 3];
  if (sp[ip] < 0) std::swap(q2, q3);
  if (sq[iq] < 0) std::swap(p2, p3);
  return orient3d_bounded(*p1, *p2, *q1, *q2) <= 0 && orient3d_bounded(*p1, *p3, *q1, *q3) >= 0;
}

/// Out-of-range magnitudes (huge, tiny, non-finite): rescale by one power of two, or give up.
[[gnu::noinline, gnu::cold]] bool overlap_rescaled(const Vec3 (&p)[3], const Vec3 (&q)[3]) noexcept {
  double m = 0.0;
  for (const Vec3& v : p) {
    if (!v.allFinite()) return false;
    m = std::max(m, v.cwiseAbs().maxCoeff());
  }
  for (const Vec3& v : q) {
    if (!v.allFinite()) return false;
    m = std::max(m, v.cwiseAbs().maxCoeff());
  }
  if (m == 0.0) return true;  // every vertex at the origin
  const int e = std::ilogb(m);
  const auto scale = [e](const Vec3& v) {
    return Vec3(std::scalbn(v.x(), -e), std::scalbn(v.y(), -e), std::scalbn(v.z(), -e));
  };
  const Vec3 ps[3] = {scale(p[0]), scale(p[1]), scale(p[2])};
  const Vec3 qs[3] = {scale(q[0]), scale(q[1]), scale(q[2])};
  return overlap(ps, qs);
}

}  // namespace

bool tri_tri_overlap(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1, const Vec3& b2) noexcept {
  const Vec3 p[3] = {a0, a1, a2};
  const Vec3 q[3] = {b0, b1, b2};
  // Sum of all |coordinates| (a tree, so the adds overlap): NaN and Inf propagate into it.
  const Vec3 s = ((a0.cwiseAbs() + a1.cwiseAbs()) + (a2.cwiseAbs() + b0.cwiseAbs())) + (b1.cwiseAbs() + b2.cwiseAbs());
  const double total = (s.x() + s.y()) + s.z();
  if (total <= detail::kFilterMaxAbs && total >= 0x1p-100) return overlap(p, q);
  return overlap_rescaled(p, q);
}

}  // namespace st::geom
