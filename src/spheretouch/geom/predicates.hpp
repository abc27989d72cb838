// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Exact orientation predicates on double inputs, the only arithmetic the triangle test uses.
/// A floating-point filter with Shewchuk's error bound decides almost every call; when it cannot,
/// the sign is computed exactly with expansion arithmetic (predicates.cpp). No epsilon anywhere.
#pragma once
#include <spheretouch/abi.hpp>
#include <cmath>

#include <spheretouch/geom/mesh.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// Sign of (b−a)×(c−a): +1 when a,b,c turn counter-clockwise, −1 clockwise, 0 collinear. Exact.
int orient2d(double ax, double ay, double bx, double by, double cx, double cy) noexcept;

/// Sign of ((b−a)×(c−a))·(d−a): +1 when d lies on the side the normal of a,b,c points to. Exact.
int orient3d(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) noexcept;

// Range of exactness (both predicates): every finite input is accepted and the filter never
// lies; the exact stage rescales its inputs by a power of two so that the largest magnitude m is
// in [1,2), and is exact when every nonzero coordinate is at least 2^-306·m (orient3d) or
// 2^-485·m (orient2d). Below that, products of the smallest terms would be subnormal and lose
// bits (see predicates.cpp). Non-finite input gives 0.

namespace detail {

/// Exact (expansion) evaluations on this thread so far: the costly path (~0.1–0.5 µs each) that
/// inputs on a plane or a line force; collide() counts them against its work budget.
inline thread_local std::uint64_t exact_evaluations = 0;

/// orient2d without the filter: always the exact expansion evaluation (tests compare both paths).
int orient2d_exact(double ax, double ay, double bx, double by, double cx, double cy) noexcept;
/// orient3d without the filter: always the exact expansion evaluation.
int orient3d_exact(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) noexcept;

/// Largest coordinate magnitude for which the inline orient3d filter below is valid: bounds
/// the absolute error that underflowing products can add (at most ~2^-770, see kOrient3dAbs).
inline constexpr double kFilterMaxAbs = 0x1p300;

// Shewchuk's stage-A error bounds (1997, §4.2, "ccwerrboundA"/"o3derrboundA") with ε = 2^-53,
// relative to the permanent computed from the same rounded differences. They hold whether or not
// the compiler contracts a*b+c into an fma (an fma skips a rounding, it never adds one).
inline constexpr double kEps = 0x1p-53;
inline constexpr double kOrient2dRel = (3.0 + 16.0 * kEps) * kEps;
inline constexpr double kOrient3dRel = (7.0 + 56.0 * kEps) * kEps;
// Absolute slack for products that underflow (each subnormal rounding errs by ≤ 2^-1075, and
// in orient3d a pair product's error is then multiplied by a difference ≤ 2^301).
inline constexpr double kOrient2dAbs = 0x1p-1070;
inline constexpr double kOrient3dAbs = 0x1p-760;

/// orient2d, filtered; exact for every finite input (the filter only needs no overflow, which
/// shows up as inf/NaN in the bound and sends the call to the exact stage).
inline int orient2d_filtered(double ax, double ay, double bx, double by, double cx, double cy) noexcept {
  const double l = (bx - ax) * (cy - ay);
  const double r = (by - ay) * (cx - ax);
  const double det = l - r;
  const double bound = kOrient2dRel * (std::abs(l) + std::abs(r)) + kOrient2dAbs;
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return orient2d_exact(ax, ay, bx, by, cx, cy);
}

/// Plane through a,b,c prepared for many exact orient3d(a,b,c,·) tests: the normal and the
/// permanent's cofactors are computed once. Precondition: all coordinates ≤ kFilterMaxAbs.
class PlaneSide {
 public:
  PlaneSide(const Vec3& a, const Vec3& b, const Vec3& c) noexcept : a_(a), b_(b), c_(c) {
    const double e1x = b.x() - a.x(), e1y = b.y() - a.y(), e1z = b.z() - a.z();
    const double e2x = c.x() - a.x(), e2y = c.y() - a.y(), e2z = c.z() - a.z();
    const double yz = e1y * e2z, zy = e1z * e2y, zx = e1z * e2x, xz = e1x * e2z;
    const double xy = e1x * e2y, yx = e1y * e2x;
    n_[0] = yz - zy;
    n_[1] = zx - xz;
    n_[2] = xy - yx;
    perm_[0] = std::abs(yz) + std::abs(zy);
    perm_[1] = std::abs(zx) + std::abs(xz);
    perm_[2] = std::abs(xy) + std::abs(yx);
  }
  /// orient3d(a,b,c,d), exact.
  int side(const Vec3& d) const noexcept {
    const double e3x = d.x() - a_.x(), e3y = d.y() - a_.y(), e3z = d.z() - a_.z();
    const double det = (e3x * n_[0] + e3y * n_[1]) + e3z * n_[2];
    const double perm = (std::abs(e3x) * perm_[0] + std::abs(e3y) * perm_[1]) + std::abs(e3z) * perm_[2];
    const double bound = kOrient3dRel * perm + kOrient3dAbs;
    if (det > bound) return 1;
    if (-det > bound) return -1;
    return orient3d_exact(a_, b_, c_, d);
  }

 private:
  const Vec3& a_;
  const Vec3& b_;
  const Vec3& c_;
  double n_[3];     // (b−a)×(c−a), rounded
  double perm_[3];  // |products| of each cofactor, for the error bound
};

/// orient3d, filtered. Precondition: all coordinates ≤ kFilterMaxAbs in magnitude.
inline int orient3d_bounded(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) noexcept {
  return PlaneSide(a, b, c).side(d);
}

}  // namespace detail
}  // namespace st::geom
