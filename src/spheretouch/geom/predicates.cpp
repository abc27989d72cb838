// SPDX-License-Identifier: BSD-3-Clause
// Exact stage of the orientation predicates: expansion arithmetic after J. R. Shewchuk,
// "Adaptive Precision Floating-Point Arithmetic and Fast Robust Geometric Predicates",
// Discrete & Computational Geometry 18:305–363, 1997 (our own code, not a copy of predicates.c).
//
// A value is kept as an *expansion*: doubles, nonoverlapping, sorted by increasing magnitude,
// whose exact sum is the value. Its sign is the sign of its largest component. Each determinant
// is written as a sum of monomials; every monomial of doubles is split exactly into doubles with
// Two-Product (via fma), and each double is added with Grow-Expansion (Shewchuk's Theorem 10),
// which needs only round-to-nearest. This is slower than Shewchuk's adaptive stages B–D, but it
// runs only when the filter in predicates.hpp cannot decide, i.e. for (near-)degenerate input.
//
// Exactness: inputs are first scaled by a power of two so the largest magnitude m lies in
// [1, 2); nothing can then overflow. Every nonzero coordinate ≥ 2^-306·m is a multiple of
// q = 2^-358·m' (m' the scaled max), so every term of the degree-3 determinant is a multiple of
// q³ ≥ 2^-1074 — representable, so Two-Product's error term is exact. (orient2d: degree 2, so
// the bound is 2^-485·m.) Smaller nonzero coordinates mix with subnormal products and may round.

// Exactness of Two-Sum / Two-Product breaks if the compiler fuses a*b+c across statements
// (GCC does by default in C++ with -march supporting FMA), so contraction is off in this file.
#if defined(__clang__)
#pragma clang fp contract(off)
#elif defined(__GNUC__)
#pragma GCC optimize("fp-contract=off")
#endif

#include <spheretouch/geom/predicates.hpp>

#if defined(__FAST_MATH__)
#error "predicates.cpp needs IEEE arithmetic: do not compile it with -ffast-math"
#endif

#include <algorithm>
#include <cmath>
#include <limits>

namespace st::inline SPHERETOUCH_ABI::geom {
namespace {

static_assert(std::numeric_limits<double>::is_iec559 && std::numeric_limits<double>::digits == 53,
              "expansion arithmetic assumes IEEE-754 binary64");

/// s + e = a + b exactly, |e| ≤ ulp(s)/2 (Knuth's Two-Sum; no ordering of |a|,|b| needed).
inline void two_sum(double a, double b, double& s, double& e) noexcept {
  s = a + b;
  const double bv = s - a;
  const double av = s - bv;
  e = (a - av) + (b - bv);
}

/// p + e = a·b exactly (no overflow, and e representable; see the header comment).
inline void two_product(double a, double b, double& p, double& e) noexcept {
  p = a * b;
  e = std::fma(a, b, -p);
}

/// Exact sum of doubles, grown one double at a time. N bounds the number of additions.
template <int N>
class Expansion {
 public:
  /// Adds b exactly: Grow-Expansion with zero elimination (Shewchuk 1997, Theorem 10).
  void add(double b) noexcept {
    if (b == 0.0) return;
    double q = b;
    int m = 0;
    for (int i = 0; i < n_; ++i) {  // writes c_[m] with m ≤ i: in place is safe
      double s, e;
      two_sum(q, c_[i], s, e);
      q = s;
      if (e != 0.0) c_[m++] = e;
    }
    if (q != 0.0) c_[m++] = q;
    n_ = m;
  }
  /// Sign of the exact sum: the sign of the largest component.
  int sign() const noexcept { return n_ == 0 ? 0 : (c_[n_ - 1] > 0.0 ? 1 : -1); }

 private:
  double c_[N + 1];
  int n_ = 0;
};

/// A double difference a − b held exactly as hi + lo.
struct Diff {
  double v[2];
};
inline Diff diff(double a, double b) noexcept {
  Diff d;
  two_sum(a, -b, d.v[1], d.v[0]);
  return d;
}

/// Adds sign·x·y exactly (4 terms x_i·y_j, each split into 2 doubles).
template <int N>
void add_product(Expansion<N>& acc, double sign, const Diff& x, const Diff& y) noexcept {
  for (double xi : x.v) {
    if (xi == 0.0) continue;
    for (double yj : y.v) {
      if (yj == 0.0) continue;
      double p, e;
      two_product(xi, yj, p, e);
      acc.add(sign * p);
      acc.add(sign * e);
    }
  }
}

/// Adds sign·x·y·z exactly (8 terms, each split into 4 doubles).
template <int N>
void add_product(Expansion<N>& acc, double sign, const Diff& x, const Diff& y, const Diff& z) noexcept {
  for (double xi : x.v) {
    if (xi == 0.0) continue;
    for (double yj : y.v) {
      if (yj == 0.0) continue;
      double p, e;
      two_product(xi, yj, p, e);
      for (double zk : z.v) {
        if (zk == 0.0) continue;
        double p1, e1, p2, e2;
        two_product(p, zk, p1, e1);
        two_product(e, zk, p2, e2);
        acc.add(sign * p1);
        acc.add(sign * e1);
        acc.add(sign * p2);
        acc.add(sign * e2);
      }
    }
  }
}

/// Scales all values by the power of two that brings the largest magnitude into [1, 2).
/// Returns false when there is nothing to scale (all zero) or an input is not finite.
template <std::size_t K>
bool normalise(double (&v)[K]) noexcept {
  double m = 0.0;
  for (double x : v) {
    if (!std::isfinite(x)) return false;
    m = std::max(m, std::abs(x));
  }
  if (m == 0.0) return false;
  const int e = std::ilogb(m);
  for (double& x : v) x = std::scalbn(x, -e);
  return true;
}

}  // namespace

namespace detail {

int orient2d_exact(double ax, double ay, double bx, double by, double cx, double cy) noexcept {
  ++exact_evaluations;
  double v[6] = {ax, ay, bx, by, cx, cy};
  if (!normalise(v)) return 0;
  const Diff e1x = diff(v[2], v[0]), e1y = diff(v[3], v[1]);
  const Diff e2x = diff(v[4], v[0]), e2y = diff(v[5], v[1]);
  Expansion<16> acc;  // 2 monomials × 4 products × 2 doubles
  add_product(acc, 1.0, e1x, e2y);
  add_product(acc, -1.0, e1y, e2x);
  return acc.sign();
}

int orient3d_exact(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) noexcept {
  ++exact_evaluations;
  double v[12] = {a.x(), a.y(), a.z(), b.x(), b.y(), b.z(), c.x(), c.y(), c.z(), d.x(), d.y(), d.z()};
  if (!normalise(v)) return 0;
  Diff e1[3], e2[3], e3[3];
  for (int k = 0; k < 3; ++k) {
    e1[k] = diff(v[3 + k], v[k]);
    e2[k] = diff(v[6 + k], v[k]);
    e3[k] = diff(v[9 + k], v[k]);
  }
  // det[e1; e2; e3] = e3 · (e1 × e2), expanded into its six monomials.
  Expansion<192> acc;  // 6 monomials × 8 products × 4 doubles
  add_product(acc, 1.0, e1[1], e2[2], e3[0]);
  add_product(acc, -1.0, e1[2], e2[1], e3[0]);
  add_product(acc, 1.0, e1[2], e2[0], e3[1]);
  add_product(acc, -1.0, e1[0], e2[2], e3[1]);
  add_product(acc, 1.0, e1[0], e2[1], e3[2]);
  add_product(acc, -1.0, e1[1], e2[0], e3[2]);
  return acc.sign();
}

}  // namespace detail

int orient2d(double ax, double ay, double bx, double by, double cx, double cy) noexcept {
  return detail::orient2d_filtered(ax, ay, bx, by, cx, cy);
}

int orient3d(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) noexcept {
  // The inline filter needs bounded inputs (its underflow slack); larger ones go exact.
  double m = 0.0;
  for (const Vec3* p : {&a, &b, &c, &d}) m += p->cwiseAbs().sum();  // NaN/inf propagate
  if (!(m <= detail::kFilterMaxAbs)) return detail::orient3d_exact(a, b, c, d);
  return detail::orient3d_bounded(a, b, c, d);
}

}  // namespace st::geom
