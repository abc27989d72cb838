// TEMPORARY tri_tri_overlap for developing the collision core on branch `collide` until the exact
// test of branch `tri` lands. NOT EXACT: Möller 1997 ("A fast triangle-triangle intersection
// test", JGT 2(2)) without its epsilon, guarded by an exact AABB overlap check so it never
// accepts a pair whose boxes are disjoint. Delete this file (and its meson line) when merging `tri`.
#include <algorithm>
#include <cmath>

#include "geom/tri_tri.hpp"

namespace st::geom {
namespace {

double orient2(const double* a, const double* b, const double* c) {
  return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}
bool on_seg(const double* a, const double* b, const double* p) {
  return std::min(a[0], b[0]) <= p[0] && p[0] <= std::max(a[0], b[0]) && std::min(a[1], b[1]) <= p[1] &&
         p[1] <= std::max(a[1], b[1]);
}
bool seg_seg(const double* a, const double* b, const double* c, const double* d) {
  const double d1 = orient2(c, d, a), d2 = orient2(c, d, b), d3 = orient2(a, b, c), d4 = orient2(a, b, d);
  if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) return true;
  if (d1 == 0 && on_seg(c, d, a)) return true;
  if (d2 == 0 && on_seg(c, d, b)) return true;
  if (d3 == 0 && on_seg(a, b, c)) return true;
  if (d4 == 0 && on_seg(a, b, d)) return true;
  return false;
}
bool in_tri(const double (*t)[2], const double* p) {
  const double a = orient2(t[0], t[1], p), b = orient2(t[1], t[2], p), c = orient2(t[2], t[0], p);
  return (a >= 0 && b >= 0 && c >= 0) || (a <= 0 && b <= 0 && c <= 0);
}

bool coplanar(const Vec3& n, const Vec3* v, const Vec3* u) {
  int i0 = 0, i1 = 1;
  const Vec3 a = n.cwiseAbs();
  if (a.x() >= a.y() && a.x() >= a.z()) { i0 = 1; i1 = 2; }
  else if (a.y() >= a.z()) { i0 = 0; i1 = 2; }
  double V[3][2], U[3][2];
  for (int k = 0; k < 3; ++k) { V[k][0] = v[k][i0]; V[k][1] = v[k][i1]; U[k][0] = u[k][i0]; U[k][1] = u[k][i1]; }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (seg_seg(V[i], V[(i + 1) % 3], U[j], U[(j + 1) % 3])) return true;
  return in_tri(U, V[0]) || in_tri(V, U[0]);
}

bool intervals(double vv0, double vv1, double vv2, double d0, double d1, double d2, double& a, double& b) {
  auto isect = [&](double w0, double w1, double w2, double e0, double e1, double e2) {
    a = w0 + (w1 - w0) * e0 / (e0 - e1);
    b = w0 + (w2 - w0) * e0 / (e0 - e2);
  };
  if (d0 * d1 > 0) isect(vv2, vv0, vv1, d2, d0, d1);
  else if (d0 * d2 > 0) isect(vv1, vv0, vv2, d1, d0, d2);
  else if (d1 * d2 > 0 || d0 != 0) isect(vv0, vv1, vv2, d0, d1, d2);
  else if (d1 != 0) isect(vv1, vv0, vv2, d1, d0, d2);
  else if (d2 != 0) isect(vv2, vv0, vv1, d2, d0, d1);
  else return false;  // coplanar
  if (a > b) std::swap(a, b);
  return true;
}

}  // namespace

bool tri_tri_overlap(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1,
                     const Vec3& b2) {
  for (int k = 0; k < 3; ++k) {
    if (std::max({a0[k], a1[k], a2[k]}) < std::min({b0[k], b1[k], b2[k]})) return false;
    if (std::max({b0[k], b1[k], b2[k]}) < std::min({a0[k], a1[k], a2[k]})) return false;
  }
  const Vec3 v[3] = {a0, a1, a2}, u[3] = {b0, b1, b2};
  const Vec3 n1 = (a1 - a0).cross(a2 - a0);
  const double du0 = n1.dot(b0 - a0), du1 = n1.dot(b1 - a0), du2 = n1.dot(b2 - a0);
  if (du0 * du1 > 0 && du0 * du2 > 0) return false;
  const Vec3 n2 = (b1 - b0).cross(b2 - b0);
  const double dv0 = n2.dot(a0 - b0), dv1 = n2.dot(a1 - b0), dv2 = n2.dot(a2 - b0);
  if (dv0 * dv1 > 0 && dv0 * dv2 > 0) return false;
  const Vec3 d = n1.cross(n2);
  const Vec3 ad = d.cwiseAbs();
  int idx = 0;
  if (ad.y() > ad[idx]) idx = 1;
  if (ad.z() > ad[idx]) idx = 2;
  if (ad[idx] == 0) return coplanar(n1.squaredNorm() > 0 ? n1 : n2, v, u);
  double i0, i1, j0, j1;
  if (!intervals(a0[idx], a1[idx], a2[idx], dv0, dv1, dv2, i0, i1)) return coplanar(n1, v, u);
  if (!intervals(b0[idx], b1[idx], b2[idx], du0, du1, du2, j0, j1)) return coplanar(n1, v, u);
  return !(i1 < j0 || j1 < i0);
}

}  // namespace st::geom
