// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/tri_tri.*: hand cases for every contact type (general, coplanar, touching,
// degenerate), each in all 6×6 vertex orders × both argument orders and under exact and inexact
// scalings/translations; one-ulp perturbations that flip the answer; random integer-grid pairs.
// Expected values come from the case table, and always also from an independent exact reference
// (origin in the hull of the vertex differences, big integers: exact_ref.hpp).
#include <spheretouch/geom/tri_tri.hpp>

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "exact_ref.hpp"
#include "test_util.hpp"

using st::geom::tri_tri_overlap;
using st::geom::Vec3;
using Tri3 = std::array<Vec3, 3>;

namespace {

struct Case {
  const char* name;
  Tri3 p, q;
  bool want;
};

/// Hand cases on small dyadic coordinates (so translations by ≤ 2^20 and 2^k scalings are exact).
std::vector<Case> hand_cases() {
  const Tri3 base{Vec3(0, 0, 0), Vec3(4, 0, 0), Vec3(0, 4, 0)};  // in z = 0, x,y ≥ 0, x+y ≤ 4
  const Tri3 small{Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(0, 2, 0)};
  return {
      // General position.
      {"parallel planes", base, {Vec3(0, 0, 1), Vec3(4, 0, 1), Vec3(0, 4, 1)}, false},
      {"far apart", base, {Vec3(5, 5, 5), Vec3(6, 5, 5), Vec3(5, 6, 7)}, false},
      {"piercing", base, {Vec3(1, 1, -1), Vec3(1, 1, 1), Vec3(2, 1, 1)}, true},
      {"piercing, one vertex through", base, {Vec3(1, 1, -1), Vec3(3, 3, 2), Vec3(-3, 2, 2)}, true},
      {"planes cross, intervals disjoint", small, {Vec3(4, 4, -1), Vec3(4, 4, 1), Vec3(2, 2, 0)}, false},
      {"planes cross, intervals touch (vertex on edge)", small, {Vec3(4, 4, -1), Vec3(4, 4, 1), Vec3(1, 1, 0)}, true},
      {"planes cross, intervals overlap", small, {Vec3(4, 4, -1), Vec3(4, 4, 1), Vec3(0.5, 0.5, 0)}, true},
      {"planes cross, one-sided gap", small, {Vec3(3, 3, -1), Vec3(3, 3, 1), Vec3(-1, -1, 0.5)}, true},
      {"interval ends meet at a crossing point", small, {Vec3(1, 1, -1), Vec3(1, 1, 1), Vec3(3, 3, 0)}, true},
      {"edge crosses edge (3D)",
       {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, 0, 1)},
       {Vec3(0, -1, 0), Vec3(0, 1, 0), Vec3(0, 0, -1)},
       true},
      {"cut passes beside the face (3D)",
       {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, 0, 1)},
       {Vec3(0.5, -1, 1), Vec3(0.5, 1, 1), Vec3(3, 0, -1)},
       false},
      {"edge through face (3D)",
       {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, 0, 1)},
       {Vec3(0.25, -1, 0.25), Vec3(0.25, 1, 0.25), Vec3(3, 0, -1)},
       true},
      {"edge beside edge (3D, apart)",
       {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, 0, 1)},
       {Vec3(2, -1, 0), Vec3(2, 1, 0), Vec3(2, 0, -1)},
       false},
      {"edge end on edge (3D T)",
       {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, 0, 1)},
       {Vec3(0, 0, 0), Vec3(0, 1, -1), Vec3(0, -1, -1)},
       true},
      {"vertex on face", base, {Vec3(1, 1, 0), Vec3(1, 1, 2), Vec3(2, 1, 3)}, true},
      {"vertex on face from below", base, {Vec3(1, 1, 0), Vec3(1, 1, -2), Vec3(2, 1, -3)}, true},
      {"vertex in plane, outside face", base, {Vec3(3, 3, 0), Vec3(3, 3, 2), Vec3(4, 3, 3)}, false},
      {"vertex on edge", base, {Vec3(2, 2, 0), Vec3(2, 2, 2), Vec3(3, 2, 3)}, true},
      {"vertex on vertex", base, {Vec3(4, 0, 0), Vec3(5, 0, 2), Vec3(5, 1, 3)}, true},
      {"hinge (shared edge)", {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}, {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 0, 1)}, true},
      {"shared vertex only", {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}, {Vec3(0, 0, 0), Vec3(-1, 0, 1), Vec3(0, -1, 1)}, true},
      {"shared vertex, other crosses plane",
       {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)},
       {Vec3(0, 0, 0), Vec3(-1, -1, 1), Vec3(-1, -1, -1)},
       true},
      {"identical", base, base, true},
      // Coplanar.
      {"coplanar overlap", base, {Vec3(1, 1, 0), Vec3(5, 1, 0), Vec3(1, 5, 0)}, true},
      {"coplanar containment", base, {Vec3(1, 1, 0), Vec3(2, 1, 0), Vec3(1, 2, 0)}, true},
      {"coplanar contained in other", {Vec3(1, 1, 0), Vec3(2, 1, 0), Vec3(1, 2, 0)}, base, true},
      {"coplanar star of David",
       {Vec3(0, 0, 0), Vec3(4, 0, 0), Vec3(2, 3, 0)},
       {Vec3(0, 2, 0), Vec3(4, 2, 0), Vec3(2, -1, 0)},
       true},
      {"coplanar shared edge, opposite sides",
       {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)},
       {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, -1, 0)},
       true},
      {"coplanar vertex on edge", small, {Vec3(1, 1, 0), Vec3(3, 1, 0), Vec3(1, 3, 0)}, true},
      {"coplanar edge along edge", small, {Vec3(1, 1, 0), Vec3(3, -1, 0), Vec3(3, 1, 0)}, true},
      {"coplanar vertex on vertex", small, {Vec3(2, 0, 0), Vec3(3, 0, 0), Vec3(3, 1, 0)}, true},
      {"coplanar collinear edges apart", small, {Vec3(3, 0, 0), Vec3(4, 0, 0), Vec3(4, 1, 0)}, false},
      {"coplanar close but apart", small, {Vec3(2, 1, 0), Vec3(3, 1, 0), Vec3(2, 2, 0)}, false},
      {"coplanar in tilted plane, touching",
       {Vec3(0, 0, 0), Vec3(2, -2, 0), Vec3(2, 0, -2)},
       {Vec3(2, -1, -1), Vec3(4, -3, -1), Vec3(4, -1, -3)},
       true},
      {"coplanar in tilted plane, apart",
       {Vec3(0, 0, 0), Vec3(2, -2, 0), Vec3(2, 0, -2)},
       {Vec3(3, -1, -2), Vec3(4, -3, -1), Vec3(4, -1, -3)},
       false},
      // Degenerate: segments (collinear or repeated vertex) and points.
      {"segment pierces face", base, {Vec3(1, 1, -1), Vec3(1, 1, 1), Vec3(1, 1, 0.5)}, true},
      {"segment misses face", base, {Vec3(5, 5, -1), Vec3(5, 5, 1), Vec3(5, 5, 0)}, false},
      {"segment ends on face", base, {Vec3(1, 1, 0), Vec3(1, 1, 2), Vec3(1, 1, 2)}, true},
      {"segment ends above face", base, {Vec3(1, 1, 0.25), Vec3(1, 1, 2), Vec3(1, 1, 2)}, false},
      {"segment through edge", base, {Vec3(2, 2, -1), Vec3(2, 2, 1), Vec3(2, 2, 1)}, true},
      {"segment in plane across edge", base, {Vec3(3, 3, 0), Vec3(1, 1, 0), Vec3(1, 1, 0)}, true},
      {"segment in plane, inside", base, {Vec3(1, 1, 0), Vec3(2, 1, 0), Vec3(1.5, 1, 0)}, true},
      {"segment in plane, outside", base, {Vec3(3, 3, 0), Vec3(5, 1, 0), Vec3(4, 2, 0)}, false},
      {"segment in plane, passes beside vertex", base, {Vec3(5, -1, 0), Vec3(5, 1, 0), Vec3(5, 0, 0)}, false},
      {"segment in plane, touches vertex", base, {Vec3(4, -1, 0), Vec3(4, 1, 0), Vec3(4, 0, 0)}, true},
      {"segment on edge's line, beyond", base, {Vec3(5, 0, 0), Vec3(6, 0, 0), Vec3(5.5, 0, 0)}, false},
      {"segment on edge's line, overlapping", base, {Vec3(3, 0, 0), Vec3(6, 0, 0), Vec3(5, 0, 0)}, true},
      {"segment parallel to plane", base, {Vec3(1, 1, 1), Vec3(2, 1, 1), Vec3(2, 1, 1)}, false},
      {"point on face", base, {Vec3(1, 1, 0), Vec3(1, 1, 0), Vec3(1, 1, 0)}, true},
      {"point on edge", base, {Vec3(2, 2, 0), Vec3(2, 2, 0), Vec3(2, 2, 0)}, true},
      {"point on vertex", base, {Vec3(0, 4, 0), Vec3(0, 4, 0), Vec3(0, 4, 0)}, true},
      {"point above face", base, {Vec3(1, 1, 1), Vec3(1, 1, 1), Vec3(1, 1, 1)}, false},
      {"point in plane, outside", base, {Vec3(3, 3, 0), Vec3(3, 3, 0), Vec3(3, 3, 0)}, false},
      {"segments cross (coplanar)",
       {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(1, 0, 0)},
       {Vec3(0, -1, 0), Vec3(0, 1, 0), Vec3(0, 0, 0)},
       true},
      {"segments skew", {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(1, 0, 0)}, {Vec3(0, -1, 1), Vec3(0, 1, 1), Vec3(0, 0, 1)}, false},
      {"segments T", {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, 0, 0)}, {Vec3(0.5, 0, 0), Vec3(0.5, 1, 1), Vec3(0.5, 1, 1)}, true},
      {"segments coplanar, apart",
       {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(1, 0, 0)},
       {Vec3(2, -1, 0), Vec3(2, 1, 0), Vec3(2, 1, 0)},
       false},
      {"segments parallel", {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(1, 0, 0)}, {Vec3(-1, 1, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)}, false},
      {"segments collinear overlapping",
       {Vec3(-1, -1, -1), Vec3(1, 1, 1), Vec3(0, 0, 0)},
       {Vec3(0.5, 0.5, 0.5), Vec3(3, 3, 3), Vec3(3, 3, 3)},
       true},
      {"segments collinear touching",
       {Vec3(-1, -1, -1), Vec3(1, 1, 1), Vec3(0, 0, 0)},
       {Vec3(1, 1, 1), Vec3(3, 3, 3), Vec3(3, 3, 3)},
       true},
      {"segments collinear apart",
       {Vec3(-1, -1, -1), Vec3(1, 1, 1), Vec3(0, 0, 0)},
       {Vec3(1.5, 1.5, 1.5), Vec3(3, 3, 3), Vec3(2, 2, 2)},
       false},
      {"point on segment",
       {Vec3(-1, 2, 0), Vec3(1, 0, 2), Vec3(0, 1, 1)},
       {Vec3(0.5, 0.5, 1.5), Vec3(0.5, 0.5, 1.5), Vec3(0.5, 0.5, 1.5)},
       true},
      {"point beyond segment end",
       {Vec3(-1, 2, 0), Vec3(1, 0, 2), Vec3(0, 1, 1)},
       {Vec3(2, -1, 3), Vec3(2, -1, 3), Vec3(2, -1, 3)},
       false},
      {"point beside segment",
       {Vec3(-1, 2, 0), Vec3(1, 0, 2), Vec3(0, 1, 1)},
       {Vec3(0.5, 0.5, 1), Vec3(0.5, 0.5, 1), Vec3(0.5, 0.5, 1)},
       false},
      {"points equal", {Vec3(1, 2, 3), Vec3(1, 2, 3), Vec3(1, 2, 3)}, {Vec3(1, 2, 3), Vec3(1, 2, 3), Vec3(1, 2, 3)}, true},
      {"points differ", {Vec3(1, 2, 3), Vec3(1, 2, 3), Vec3(1, 2, 3)}, {Vec3(1, 2, 3.5), Vec3(1, 2, 3.5), Vec3(1, 2, 3.5)}, false},
      {"all at the origin", {Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(0, 0, 0)}, {Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(0, 0, 0)}, true},
  };
}

constexpr int kPerm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};

/// Number of the 72 orderings (6 × 6 vertex orders × 2 argument orders) that disagree with want.
int disagreements(const Tri3& p, const Tri3& q, bool want) {
  int bad = 0;
  for (const auto& a : kPerm)
    for (const auto& b : kPerm) {
      const Vec3 &p0 = p[a[0]], &p1 = p[a[1]], &p2 = p[a[2]];
      const Vec3 &q0 = q[b[0]], &q1 = q[b[1]], &q2 = q[b[2]];
      bad += tri_tri_overlap(p0, p1, p2, q0, q1, q2) != want;
      bad += tri_tri_overlap(q0, q1, q2, p0, p1, p2) != want;
    }
  return bad;
}

template <class F>
Tri3 map(const Tri3& t, F f) {
  return {f(t[0]), f(t[1]), f(t[2])};
}

}  // namespace

TEST_CASE("tri_tri: hand cases agree with the exact reference") {
  for (const Case& c : hand_cases()) {
    CAPTURE(std::string(c.name));
    CHECK(st::test::ref_overlap_doubles(c.p, c.q) == c.want);  // the table itself is right
    CHECK(disagreements(c.p, c.q, c.want) == 0);
  }
}

TEST_CASE("tri_tri: hand cases under exact transforms (translate ≤ 2^20, then scale by 2^k)") {
  const double shifts[] = {0.0, 1.0, 1e6, -777777.0, 1048576.0};
  const int exps[] = {-400, -200, -60, -20, -1, 0, 1, 7, 20, 60, 200, 400, 1000};
  for (const Case& c : hand_cases()) {
    CAPTURE(std::string(c.name));
    for (double t : shifts)
      for (int e : exps) {
        CAPTURE(t);
        CAPTURE(e);
        const auto f = [&](const Vec3& v) {
          const Vec3 w = v + Vec3(t, -t, 0.5 * t);
          return Vec3(std::scalbn(w.x(), e), std::scalbn(w.y(), e), std::scalbn(w.z(), e));
        };
        CHECK(disagreements(map(c.p, f), map(c.q, f), c.want) == 0);
      }
  }
}

TEST_CASE("tri_tri: hand cases under inexact transforms (scale 10^k, translate to 1e6)") {
  // Rounding may make a touching pair overlap or separate: the reference decides per instance.
  const double shifts[] = {0.0, 0.1, -1e6, 1e6 / 3};
  int flipped = 0, total = 0;
  for (const Case& c : hand_cases()) {
    CAPTURE(std::string(c.name));
    for (int k = -6; k <= 6; ++k)
      for (double t : shifts) {
        const double s = std::pow(10.0, k);
        const auto f = [&](const Vec3& v) { return Vec3(v * s + Vec3(t, 2 * t, -t)); };
        const Tri3 p = map(c.p, f), q = map(c.q, f);
        const bool want = st::test::ref_overlap_doubles(p, q);
        flipped += want != c.want;
        ++total;
        CAPTURE(k);
        CAPTURE(t);
        CHECK(disagreements(p, q, want) == 0);
      }
  }
  MESSAGE("inexact transforms: ", flipped, " of ", total, " instances changed answer by rounding");
}

TEST_CASE("tri_tri: one-ulp perturbations flip touching pairs") {
  // Each builder returns the pair for a parameter nudged by d ulps (d = 0 touches).
  struct Flip {
    const char* name;
    std::function<std::pair<Tri3, Tri3>(double c, int d)> make;
    bool below, at, above;  // expected for d = -1, 0, +1
  };
  const std::vector<Flip> flips = {
      {"vertex on face (apex height)",
       [](double c, int d) {
         const Tri3 p{Vec3(0, 0, c), Vec3(4, 0, c), Vec3(0, 4, c)};
         const Tri3 q{Vec3(1, 1, st::test::nudge(c, d)), Vec3(1, 2, c + 1), Vec3(2, 1, c + 1)};
         return std::make_pair(p, q);
       },
       true, true, false},
      {"edge on edge (3D)",
       [](double c, int d) {
         const Tri3 p{Vec3(-1, 0, c), Vec3(1, 0, c), Vec3(0, 0, c + 1)};
         const Tri3 q{Vec3(0, -1, st::test::nudge(c, d)), Vec3(0, 1, st::test::nudge(c, d)), Vec3(0, 0, c - 1)};
         return std::make_pair(p, q);
       },
       false, true, true},
      {"coplanar vertex on edge (in-plane)",
       [](double c, int d) {
         const Tri3 p{Vec3(0, c, 5), Vec3(2, c, 5), Vec3(0, c + 2, 5)};
         const Tri3 q{Vec3(1, st::test::nudge(c, d), 5), Vec3(0, c - 2, 5), Vec3(2, c - 2, 5)};
         return std::make_pair(p, q);
       },
       false, true, true},
      {"near-coplanar: apex on edge, rest one ulp above the plane",
       [](double c, int d) {
         const double up = st::test::nudge(c, 1);
         const Tri3 p{Vec3(0, 0, c), Vec3(2, 0, c), Vec3(0, 2, c)};
         const Tri3 q{Vec3(1, st::test::nudge(0.0 + c, d) - c, c), Vec3(0, -2, up), Vec3(2, -2, up)};
         return std::make_pair(p, q);
       },
       false, true, true},
      {"vertex on vertex",
       [](double c, int d) {
         const Tri3 p{Vec3(c, c, c), Vec3(c + 1, c, c), Vec3(c, c + 1, c)};
         const Tri3 q{Vec3(c, c, st::test::nudge(c, d)), Vec3(c - 1, c, c + 1), Vec3(c, c - 1, c + 1)};
         return std::make_pair(p, q);
       },
       false, true, false},  // pushed through, Q's cut lies outside P's corner
      {"segment end on face",
       [](double c, int d) {
         const Tri3 p{Vec3(0, 0, c), Vec3(4, 0, c), Vec3(0, 4, c)};
         const Tri3 q{Vec3(1, 1, st::test::nudge(c, d)), Vec3(1, 1, c + 2), Vec3(1, 1, c + 2)};
         return std::make_pair(p, q);
       },
       true, true, false},
      {"point on face",
       [](double c, int d) {
         const Tri3 p{Vec3(0, 0, c), Vec3(4, 0, c), Vec3(0, 4, c)};
         const Vec3 v(1, 1, st::test::nudge(c, d));
         return std::make_pair(p, Tri3{v, v, v});
       },
       false, true, false},
      {"collinear segments end to end",
       [](double c, int d) {
         const Vec3 a(c, 0, 0), b(c + 1, 0, 0);
         const Tri3 p{Vec3(c - 1, 0, 0), a, a};
         return std::make_pair(p, Tri3{Vec3(st::test::nudge(c, d), 0, 0), b, b});
       },
       true, true, false},
  };
  // The tilted plane x + y + z = 3c: P lies in it, Q's apex is nudged off it along x.
  const auto tilted = [](double c, int d) {
    const Vec3 o(c, c, c);
    const Tri3 p{o, o + Vec3(2, -2, 0), o + Vec3(2, 0, -2)};
    const Vec3 apex = o + Vec3(1, -1, 0);  // on P's edge
    const Tri3 q{Vec3(st::test::nudge(apex.x(), d), apex.y(), apex.z()), o + Vec3(4, 1, 1), o + Vec3(3, 3, 0)};
    return std::make_pair(p, q);
  };
  // Exact 2^k scalings keep every ulp relation; 2^±250 also exercise the rescaling path.
  const double heights[] = {1.0, 3.0, 1e6, 12345.678, 1e-3};
  for (double c : heights)
    for (int e : {0, -250, 250}) {
      CAPTURE(c);
      CAPTURE(e);
      const auto scaled = [e](const Tri3& t) {
        return map(
            t, [e](const Vec3& v) { return Vec3(std::scalbn(v.x(), e), std::scalbn(v.y(), e), std::scalbn(v.z(), e)); });
      };
      for (const Flip& f : flips) {
        CAPTURE(std::string(f.name));
        const bool want[3] = {f.below, f.at, f.above};
        for (int d = -1; d <= 1; ++d) {
          CAPTURE(d);
          const auto [p, q] = f.make(c, d);
          CHECK(st::test::ref_overlap_doubles(p, q) == want[d + 1]);
          CHECK(disagreements(scaled(p), scaled(q), want[d + 1]) == 0);
        }
      }
      // Below the plane the cut of Q ends exactly on P's edge (a single shared point). Needs
      // c ± small integers to be exact, so that the apex is really on P's edge.
      if (c - 1 + 1 != c || c + 4 - 4 != c) continue;
      for (int d = -1; d <= 1; ++d) {
        CAPTURE(d);
        const auto [p, q] = tilted(c, d);
        CHECK(st::test::ref_overlap_doubles(p, q) == (d <= 0));
        CHECK(disagreements(scaled(p), scaled(q), d <= 0) == 0);
      }
    }
}

namespace {

using I3 = st::test::V3<std::int64_t>;
using ITri = std::array<I3, 3>;

/// Random triangle pairs on a small integer grid, biased towards the special cases: shared
/// vertices, vertices on the other's edges (grid step 2 makes midpoints integral), coplanar
/// pairs in tilted planes, repeated and collinear vertices.
struct GridGen {
  std::mt19937_64 rng;
  explicit GridGen(std::uint64_t seed) : rng(seed) {}
  int pick(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); }
  I3 point(int r) { return {pick(-r, r), pick(-r, r), pick(-r, r)}; }
  static I3 add(const I3& a, const I3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
  static I3 mul(std::int64_t k, const I3& a) { return {k * a[0], k * a[1], k * a[2]}; }

  std::pair<ITri, ITri> pair() {
    ITri p, q;
    const int kind = pick(0, 5);
    const int r = pick(1, 3);
    for (auto& v : p) v = point(r);
    for (auto& v : q) v = point(r);
    switch (kind) {
      case 0:
        break;  // plain random (r = 1 alone gives many degeneracies)
      case 1:   // share one or two vertices
        q[0] = p[pick(0, 2)];
        if (pick(0, 1)) q[1] = p[pick(0, 2)];
        break;
      case 2:  // q's vertices on p's edges or at p's vertices (coordinates doubled)
        for (auto& v : p) v = mul(2, v);
        for (auto& v : q) v = mul(2, v);
        for (int i = 0; i < pick(1, 3); ++i) {
          const I3& a = p[pick(0, 2)];
          const I3& b = p[pick(0, 2)];
          q[i] = {(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2};
        }
        break;
      case 3: {  // both in one plane o + i·u + j·v (often tilted)
        const I3 o = point(2), u = point(1), w = point(1);
        for (auto* t : {&p, &q})
          for (auto& v : *t) v = add(o, add(mul(pick(-2, 2), u), mul(pick(-2, 2), w)));
        break;
      }
      case 4:  // degenerate: repeated or collinear vertices
        if (pick(0, 1))
          p[1] = p[pick(0, 1) ? 0 : 2];
        else
          p[2] = add(p[0], mul(pick(-2, 2), add(p[1], mul(-1, p[0]))));
        if (pick(0, 2) == 0) q[0] = q[1] = q[2];
        break;
      case 5:  // coplanar-ish: q in p's plane through a shared vertex, plus one point off it
        q[0] = p[0];
        q[1] = add(p[0], add(mul(pick(-1, 1), add(p[1], mul(-1, p[0]))), mul(pick(-1, 1), add(p[2], mul(-1, p[0])))));
        break;
    }
    return {p, q};
  }
};

Vec3 to_vec(const I3& v) { return {double(v[0]), double(v[1]), double(v[2])}; }

bool degenerate(const ITri& t) {
  return st::test::is_zero(st::test::cross(st::test::sub(t[1], t[0]), st::test::sub(t[2], t[0])));
}

}  // namespace

TEST_CASE("tri_tri: random integer-grid pairs against the exact reference") {
  GridGen g(20240611);
  std::mt19937_64 rng(7);
  constexpr int kCases = 60000;
  int yes = 0, degen = 0, coplanar = 0, coplanar_yes = 0, failures = 0;
  for (int n = 0; n < kCases; ++n) {
    const auto [ip, iq] = g.pair();
    const bool want = st::test::ref_overlap(ip, iq);
    yes += want;
    const bool dg = degenerate(ip) || degenerate(iq);
    degen += dg;
    if (!dg) {
      const auto nrm = st::test::cross(st::test::sub(ip[1], ip[0]), st::test::sub(ip[2], ip[0]));
      bool cop = true;
      for (const auto& v : iq) cop = cop && st::test::dot(nrm, st::test::sub(v, ip[0])) == 0;
      coplanar += cop;
      coplanar_yes += cop && want;
    }
    // A random vertex order of each, a random argument order, a random exact transform.
    const auto& a = kPerm[rng() % 6];
    const auto& b = kPerm[rng() % 6];
    const int e = int(rng() % 121) - 60;
    const Vec3 t(double(rng() % 2000001) - 1e6, double(rng() % 2001) - 1000, 0.0);
    const auto f = [&](const I3& v) {
      const Vec3 w = to_vec(v) + t;
      return Vec3(std::scalbn(w.x(), e), std::scalbn(w.y(), e), std::scalbn(w.z(), e));
    };
    const Vec3 p0 = f(ip[a[0]]), p1 = f(ip[a[1]]), p2 = f(ip[a[2]]);
    const Vec3 q0 = f(iq[b[0]]), q1 = f(iq[b[1]]), q2 = f(iq[b[2]]);
    const bool got = rng() % 2 ? tri_tri_overlap(p0, p1, p2, q0, q1, q2) : tri_tri_overlap(q0, q1, q2, p0, p1, p2);
    if (got != want && ++failures <= 10) {
      auto str = [](const I3& v) {
        std::ostringstream os;
        os << '(' << v[0] << ',' << v[1] << ',' << v[2] << ')';
        return os.str();
      };
      FAIL_CHECK("case ", n, ": P ", str(ip[0]), str(ip[1]), str(ip[2]), " Q ", str(iq[0]), str(iq[1]), str(iq[2]),
                 " want ", want);
    }
  }
  CHECK(failures == 0);
  MESSAGE(kCases, " grid pairs: ", yes, " overlapping, ", degen, " with a degenerate triangle, ", coplanar,
          " coplanar (", coplanar_yes, " overlapping)");
  // The generator must reach every regime, or a pass would prove little.
  CHECK(yes > kCases / 5);
  CHECK(kCases - yes > kCases / 5);
  CHECK(degen > kCases / 10);
  CHECK(coplanar > kCases / 20);
  CHECK(coplanar_yes > kCases / 50);
  CHECK(coplanar - coplanar_yes > kCases / 100);
}

TEST_CASE("tri_tri: rotated grid pairs (near-touching doubles) against the big-integer reference") {
  // A rotation by a random unit quaternion rounds every coordinate: contacts that were exact
  // become ulp-close calls in arbitrary directions, which the exact stage must decide.
  GridGen g(99);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  constexpr int kCases = 3000;
  int yes = 0, failures = 0;
  for (int n = 0; n < kCases; ++n) {
    const auto [ip, iq] = g.pair();
    const Eigen::Quaterniond rot = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized();
    const double s = std::pow(10.0, int(rng() % 13) - 6);
    const Vec3 t = Vec3(u(rng), u(rng), u(rng)) * (rng() % 2 ? 1e6 : 1.0);
    const auto f = [&](const I3& v) { return Vec3(rot * (to_vec(v) * s) + t); };
    const Tri3 p = {f(ip[0]), f(ip[1]), f(ip[2])}, q = {f(iq[0]), f(iq[1]), f(iq[2])};
    const bool want = st::test::ref_overlap_doubles(p, q);
    yes += want;
    const auto& a = kPerm[rng() % 6];
    const auto& b = kPerm[rng() % 6];
    const bool got = tri_tri_overlap(p[a[0]], p[a[1]], p[a[2]], q[b[0]], q[b[1]], q[b[2]]);
    const bool got_swapped = tri_tri_overlap(q[b[0]], q[b[1]], q[b[2]], p[a[0]], p[a[1]], p[a[2]]);
    if ((got != want || got_swapped != want) && ++failures <= 10)
      FAIL_CHECK("case ", n, " disagrees with the reference (want ", want, ")");
  }
  CHECK(failures == 0);
  CHECK(yes > kCases / 5);
  CHECK(kCases - yes > kCases / 5);
}

TEST_CASE("tri_tri: offsets far below the other coordinates' ulp are still seen exactly") {
  // Exactness holds while nonzero magnitudes are ≥ 2^-306 of the largest (tri_tri.hpp).
  for (double tiny : {1e-20, 1e-80, 0x1p-300}) {
    CAPTURE(tiny);
    const Tri3 p{Vec3(0, 0, 0), Vec3(4, 0, 0), Vec3(0, 4, 0)};
    for (double z : {-tiny, 0.0, tiny}) {
      const Tri3 q{Vec3(1, 1, z), Vec3(1, 2, 1), Vec3(2, 1, 1)};
      CHECK(st::test::ref_overlap_doubles(p, q) == (z <= 0));
      CHECK(disagreements(p, q, z <= 0) == 0);
    }
    // In-plane: a vertex a tiny distance outside / on / inside an edge.
    for (double y : {-tiny, 0.0, tiny}) {
      const Tri3 q{Vec3(1, y, 0), Vec3(0, -2, 0), Vec3(2, -2, 0)};
      CHECK(disagreements(p, q, y >= 0) == 0);
    }
  }
}

TEST_CASE("tri_tri: non-finite input is rejected, never reported as contact") {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  for (double bad : {double(NAN), double(INFINITY), -double(INFINITY)}) {
    CHECK_FALSE(tri_tri_overlap(a, b, c, Vec3(bad, 0, 0), b, c));
    CHECK_FALSE(tri_tri_overlap(Vec3(0, bad, 0), b, c, a, b, c));
  }
}
