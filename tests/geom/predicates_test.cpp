// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/predicates.*: every sign against an exact big-integer determinant
// (exact_ref.hpp), on inputs built to be degenerate or within a few ulps of it, at scales from
// 2^-280 to 2^280, so that both the filter and the exact stage decide many calls.
#include <spheretouch/geom/predicates.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <random>

#include "exact_ref.hpp"
#include "test_util.hpp"

using st::geom::orient2d;
using st::geom::orient3d;
using st::geom::Vec3;
namespace detail = st::geom::detail;

namespace {

/// Random configurations: generic, collinear/coplanar by construction (rounded), ulp-perturbed,
/// integer-grid (exactly degenerate), translated far from the origin, scaled by 2^k.
struct Gen {
  std::mt19937_64 rng{12345};
  double uni(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); }
  int pick(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); }

  Vec3 point() { return {uni(-1, 1), uni(-1, 1), uni(-1, 1)}; }
  Vec3 grid() { return {double(pick(-3, 3)), double(pick(-3, 3)), double(pick(-3, 3))}; }

  /// Four points a,b,c,d; d is (nearly) in the plane of a,b,c for most kinds.
  std::array<Vec3, 4> config3() {
    const int kind = pick(0, 5);
    std::array<Vec3, 4> p;
    if (kind == 5) {  // exactly coplanar: dyadic points and small integer combinations
      for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) p[i][k] = std::ldexp(pick(-1000, 1000), -pick(0, 12));
      p[3] = p[0] + pick(-3, 3) * (p[1] - p[0]) + pick(-3, 3) * (p[2] - p[0]);
    } else if (kind == 0) {
      for (auto& v : p) v = point();
    } else if (kind == 1) {
      for (auto& v : p) v = grid();
    } else {
      p[0] = point();
      p[1] = point();
      p[2] = point();
      const double s = uni(-2, 2), t = uni(-2, 2);
      p[3] = p[0] + s * (p[1] - p[0]) + t * (p[2] - p[0]);  // rounded: near the plane
      if (kind == 3)
        for (int k = 0; k < 3; ++k) p[3][k] = st::test::nudge(p[3][k], pick(-2, 2));
      if (kind == 4) p[2] = p[0] + uni(-2, 2) * (p[1] - p[0]);  // near-collinear base
    }
    // Translate (exactly representable shift is not required: the reference sees the doubles).
    if (pick(0, 2) == 0) {
      const Vec3 t(uni(-1e6, 1e6), uni(-1e6, 1e6), uni(-1e6, 1e6));
      for (auto& v : p) v += t;
    }
    const int e = pick(0, 3) == 0 ? pick(-280, 280) : 0;
    for (auto& v : p)
      for (int k = 0; k < 3; ++k) v[k] = std::scalbn(v[k], e);
    return p;
  }
};

}  // namespace

TEST_CASE("orient2d: hand cases and sign conventions") {
  CHECK(orient2d(0, 0, 1, 0, 0, 1) == 1);
  CHECK(orient2d(0, 0, 0, 1, 1, 0) == -1);
  CHECK(orient2d(0, 0, 1, 1, 2, 2) == 0);
  // Collinear in exact arithmetic but not on a naive evaluation: 0.1 is not 1/10.
  CHECK(orient2d(0.1, 0.1, 0.2, 0.2, 0.3, 0.3) == st::test::ref_orient2d(0.1, 0.1, 0.2, 0.2, 0.3, 0.3));
  // A point one ulp off a long line, far from the origin.
  const double big = 1e6;
  CHECK(orient2d(big, big, big + 1, big + 1, st::test::nudge(big + 3, 1), big + 3) == -1);
  CHECK(orient2d(big, big, big + 1, big + 1, st::test::nudge(big + 3, -1), big + 3) == 1);
  CHECK(orient2d(big, big, big + 1, big + 1, big + 3, big + 3) == 0);
  // Huge and tiny magnitudes (overflow of the filter, subnormal-free exact stage).
  CHECK(orient2d(0, 0, 1e300, 1e300, 2e300, st::test::nudge(2e300, 1)) == 1);
  CHECK(orient2d(0, 0, 1e-300, 1e-300, 2e-300, st::test::nudge(2e-300, -1)) == -1);
  CHECK(orient2d(0, 0, 1e-300, 1e-300, 2e-300, 2e-300) == 0);
  CHECK(orient2d(NAN, 0, 1, 0, 0, 1) == 0);
}

TEST_CASE("orient3d: hand cases and sign conventions") {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  CHECK(orient3d(a, b, c, Vec3(0, 0, 1)) == 1);
  CHECK(orient3d(a, b, c, Vec3(0, 0, -1)) == -1);
  CHECK(orient3d(a, c, b, Vec3(0, 0, 1)) == -1);
  CHECK(orient3d(a, b, c, Vec3(5, 7, 0)) == 0);
  // One ulp above / below a plane through far-away points.
  const Vec3 o(1e6, -1e6, 1e6);
  const Vec3 x = o + Vec3(1, 0, 0), y = o + Vec3(0, 1, 0);
  const Vec3 on = o + Vec3(3, 5, 0);
  CHECK(orient3d(o, x, y, on) == 0);
  CHECK(orient3d(o, x, y, Vec3(on.x(), on.y(), st::test::nudge(on.z(), 1))) == 1);
  CHECK(orient3d(o, x, y, Vec3(on.x(), on.y(), st::test::nudge(on.z(), -1))) == -1);
  // Beyond the filter's range (2^300) and far below it.
  const double h = 0x1p400, l = 0x1p-400;
  CHECK(orient3d(h * a, h * b, h * c, Vec3(h, h, 0x1p100)) == 1);
  CHECK(orient3d(l * a, l * b, l * c, Vec3(l, l, -l)) == -1);
  CHECK(orient3d(h * a, h * b, h * c, Vec3(3 * h, 5 * h, 0)) == 0);
  CHECK(orient3d(Vec3(INFINITY, 0, 0), b, c, a) == 0);
}

TEST_CASE("orient2d/orient3d agree with the exact big-integer determinant (random)") {
  Gen g;
  int count[3] = {0, 0, 0};
  constexpr int kCases = 20000;
  for (int i = 0; i < kCases; ++i) {
    const auto p = g.config3();
    const int want3 = st::test::ref_orient3d(p[0], p[1], p[2], p[3]);
    ++count[want3 + 1];
    REQUIRE(orient3d(p[0], p[1], p[2], p[3]) == want3);
    REQUIRE(st::geom::detail::orient3d_exact(p[0], p[1], p[2], p[3]) == want3);
    // Argument permutations: an odd permutation negates the sign.
    REQUIRE(orient3d(p[1], p[0], p[2], p[3]) == -want3);
    REQUIRE(orient3d(p[3], p[1], p[2], p[0]) == -want3);
    REQUIRE(orient3d(p[1], p[2], p[0], p[3]) == want3);
    // 2D on the (x, y) of the first three points, and with the near-collinear fourth point.
    for (const auto& t : {std::array<int, 3>{0, 1, 2}, std::array<int, 3>{0, 1, 3}}) {
      const Vec3 &u = p[t[0]], &v = p[t[1]], &w = p[t[2]];
      const int want2 = st::test::ref_orient2d(u.x(), u.y(), v.x(), v.y(), w.x(), w.y());
      REQUIRE(orient2d(u.x(), u.y(), v.x(), v.y(), w.x(), w.y()) == want2);
      REQUIRE(st::geom::detail::orient2d_exact(u.x(), u.y(), v.x(), v.y(), w.x(), w.y()) == want2);
      REQUIRE(orient2d(v.x(), v.y(), u.x(), u.y(), w.x(), w.y()) == -want2);
    }
  }
  // The generator must produce every sign in quantity, or the test would prove little.
  CHECK(count[0] > kCases / 10);
  CHECK(count[1] > kCases / 20);
  CHECK(count[2] > kCases / 10);
}

TEST_CASE("orient2d: collinear points one ulp apart, all along a long line") {
  // Points (x, 3x/7) rounded: the exact sign comes from the rounding of each y.
  int nonzero = 0;
  for (int i = 1; i < 2000; ++i) {
    const double x1 = 1e6 + i, x2 = 1e6 + 2 * i + 0.5;
    const double ax = 1e6, ay = 3e6 / 7, bx = x1, by = 3 * x1 / 7, cx = x2, cy = 3 * x2 / 7;
    const int want = st::test::ref_orient2d(ax, ay, bx, by, cx, cy);
    nonzero += want != 0;
    REQUIRE(orient2d(ax, ay, bx, by, cx, cy) == want);
  }
  CHECK(nonzero > 1000);
}
