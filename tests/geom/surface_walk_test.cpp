// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/surface_walk.*: the plane basis, the facing test, the face across an edge, the
// walk to the face over a point (a flat grid and a ball, against the plane's and the sphere's
// exit distance) and where it stops (faces that do not face d, too many steps), and near_face's
// margin past a face's edge.
#include <spheretouch/geom/surface_walk.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <vector>

#include <spheretouch/geom/primitives.hpp>
#include "test_models.hpp"

using namespace st::geom;

namespace {

using st::test::grid;

/// A walk over m along d (m's own vertices: no patch).
SurfaceWalk walk_over(const Mesh& m, const VertexFaces& vf, const Vec3& d) {
  SurfaceWalk w;
  w.mesh = &m;
  w.vf = &vf;
  w.set_direction(d);
  return w;
}

/// Whether x, seen along +z, lies in face f (closed).
bool over_face(const Mesh& m, std::uint32_t f, const Vec3& x) {
  const Vec3 a = m.local[m.faces[f][0]], b = m.local[m.faces[f][1]], c = m.local[m.faces[f][2]];
  auto side = [&](const Vec3& p, const Vec3& q) {
    return (q.x() - p.x()) * (x.y() - p.y()) - (q.y() - p.y()) * (x.x() - p.x());
  };
  return side(a, b) >= -1e-12 && side(b, c) >= -1e-12 && side(c, a) >= -1e-12;
}

}  // namespace

TEST_CASE("surface walk: the plane basis is orthonormal, u × w = d") {
  for (const Vec3& dir :
       {Vec3(0, 0, 1), Vec3(0, 0, -1), Vec3(1, 0, 0), Vec3(0.3, -0.5, 0.8), Vec3(-1, 2, -3), Vec3(0.59, 0.59, 0.55)}) {
    SurfaceWalk w;
    w.set_direction(dir.normalized());
    CHECK(w.u.norm() == doctest::Approx(1).epsilon(1e-15));
    CHECK(w.w.norm() == doctest::Approx(1).epsilon(1e-15));
    CHECK(std::abs(w.u.dot(w.d)) < 1e-15);
    CHECK(std::abs(w.w.dot(w.d)) < 1e-15);
    CHECK(std::abs(w.u.dot(w.w)) < 1e-15);
    CHECK((w.u.cross(w.w) - w.d).norm() < 1e-15);
  }
}

TEST_CASE("surface walk: a face faces d when turned less than acos(kFrontCos) from it") {
  const Vec3 a(0, 0, 0), b(1, 0, 0);
  for (double deg : {0.0, 30.0, 60.0, 84.0, 86.0, 90.0, 120.0}) {
    CAPTURE(deg);
    const double t = deg * 3.14159265358979323846 / 180;
    const Vec3 c(0, std::cos(t), std::sin(t));  // normal (b−a)×(c−a) turned deg from +z about x
    const double det = (b - a).cross(c - a).dot(Vec3::UnitZ());
    CHECK(SurfaceWalk::facing(det, a, b, c) == (std::cos(t) > kFrontCos));
  }
}

TEST_CASE("surface walk: the face across an edge") {
  const Mesh m = grid(3);
  const VertexFaces vf = VertexFaces::build(m);
  const SurfaceWalk w = walk_over(m, vf, Vec3::UnitZ());
  // Square (1, 1): faces 8 (v5, v6, v10) and 9 (v5, v10, v9); grid vertices are j·4 + i.
  CHECK(w.across(8, 5, 10) == 9);  // the diagonal
  CHECK(w.across(9, 10, 5) == 8);
  CHECK(w.across(8, 5, 6) == 3);           // square (1, 0)'s upper face, below
  CHECK(w.across(0, 0, 1) == UINT32_MAX);  // the grid's border
}

TEST_CASE("surface walk: over a flat grid, the face over a point and its height along d") {
  const Mesh m = grid(10, 2.0);
  const VertexFaces vf = VertexFaces::build(m);
  SurfaceWalk w = walk_over(m, vf, Vec3::UnitZ());
  for (const Vec3& x :
       {Vec3(7.3, 8.6, -1.5), Vec3(0.2, 0.1, 1.0), Vec3(9.9, 0.05, 2.5), Vec3(5.5, 5.5, 2.0), Vec3(3.0, 4.0, 0.0)}) {
    CAPTURE(x.transpose());
    std::uint32_t face = 0, last = UINT32_MAX;  // from the corner square, 10 or more squares away
    double dist = std::numeric_limits<double>::quiet_NaN();
    REQUIRE(w.exit(x, face, dist, 48, &last));
    CHECK(face < m.faces.size());
    CHECK(over_face(m, face, x));
    CHECK(last == face);
    CHECK(dist == doctest::Approx(2.0 - x.z()).epsilon(1e-12));  // <= 0: above the surface
  }
  // Too few steps: the walk gives up (and says where it got to).
  std::uint32_t face = 0, last = UINT32_MAX;
  double dist = 0;
  CHECK_FALSE(w.exit(Vec3(9.5, 9.5, 0), face, dist, 3, &last));
  CHECK(face == 0);
  CHECK(last < m.faces.size());
  // Past the grid's border there is no face to cross to.
  face = 0;
  CHECK_FALSE(w.exit(Vec3(12, 5, 0), face, dist));
}

TEST_CASE("surface walk: only faces that face d are walked") {
  const Mesh box = make_box({40, 40, 40});  // faces at ±20
  const VertexFaces vf = VertexFaces::build(box);
  SurfaceWalk w = walk_over(box, vf, Vec3::UnitZ());
  std::uint32_t top = UINT32_MAX, side = UINT32_MAX;
  for (std::uint32_t f = 0; f < box.faces.size(); ++f) {
    const Vec3 a = box.local[box.faces[f][0]], b = box.local[box.faces[f][1]], c = box.local[box.faces[f][2]];
    const Vec3 n = (b - a).cross(c - a).normalized();
    if (n.z() > 0.5 && top == UINT32_MAX) top = f;
    if (std::abs(n.x()) > 0.5 && side == UINT32_MAX) side = f;
  }
  REQUIRE(top != UINT32_MAX);
  REQUIRE(side != UINT32_MAX);
  // Under the top: found from either of its faces, 3 mm to travel up.
  std::uint32_t face = top;
  double dist = 0;
  REQUIRE(w.exit(Vec3(-15, 12, 17), face, dist));
  CHECK(dist == doctest::Approx(3).epsilon(1e-12));
  // A side face is a silhouette along +z: no walk starts on it.
  face = side;
  std::uint32_t last = UINT32_MAX;
  CHECK_FALSE(w.exit(Vec3(0, 0, 0), face, dist, 48, &last));
  CHECK(last == UINT32_MAX);
  // Past the top's edge the walk would turn onto a side face: it stops, `last` on the top.
  face = top;
  last = UINT32_MAX;
  CHECK_FALSE(w.exit(Vec3(25, 0, 10), face, dist, 48, &last));
  REQUIRE(last < box.faces.size());
  // near_face: within the margin past that face's edge, its plane extended; beyond it, not; and
  // never on a face that does not face d.
  double d_near = 0;
  CHECK(w.near_face(Vec3(20.5, 0, 10), last, 1.0, d_near));
  CHECK(d_near == doctest::Approx(10).epsilon(1e-12));  // the top plane z = 20, from z = 10
  CHECK_FALSE(w.near_face(Vec3(21.5, 0, 10), last, 1.0, d_near));
  CHECK_FALSE(w.near_face(Vec3(0, 0, 10), side, 1.0, d_near));
}

TEST_CASE("surface walk: inside a ball, the exit distance along d is the sphere's (to its facets)") {
  const double r = 10;
  const Mesh ball = make_icosphere(r, 16);  // vertex spacing ~0.7 mm: facets within ~0.01 mm of the sphere
  const VertexFaces vf = VertexFaces::build(ball);
  for (const Vec3& dir : {Vec3(0, 0, 1), Vec3(1, 1, 1), Vec3(-0.3, 0.8, -0.2)}) {
    const Vec3 d = dir.normalized();
    SurfaceWalk w = walk_over(ball, vf, d);
    for (const Vec3& x0 : {Vec3(0, 0, 0), Vec3(1, 2, 3), Vec3(-4, 0.5, -2)}) {
      const Vec3 x = ball.origin + x0;  // the ball's local frame
      CAPTURE(d.transpose());
      CAPTURE(x0.transpose());
      // Along d, |x0 + t d| = r: t = −x0·d + sqrt((x0·d)² − |x0|² + r²).
      const double xd = x0.dot(d), t = -xd + std::sqrt(xd * xd - x0.squaredNorm() + r * r);
      // Start from the facing face nearest a point 3 mm across from the exit point: a walk of a
      // few faces over the front of the ball.
      const Vec3 target = ball.origin + x0 + t * d + 3 * w.u;
      std::uint32_t start = UINT32_MAX;
      double best = std::numeric_limits<double>::infinity();
      for (std::uint32_t f = 0; f < ball.faces.size(); ++f) {
        const Vec3 a = ball.local[ball.faces[f][0]], b = ball.local[ball.faces[f][1]], c = ball.local[ball.faces[f][2]];
        const double gap = ((a + b + c) / 3 - target).norm();
        if (SurfaceWalk::facing((b - a).cross(c - a).dot(d), a, b, c) && gap < best) best = gap, start = f;
      }
      REQUIRE(start != UINT32_MAX);
      std::uint32_t face = start;
      double dist = 0;
      REQUIRE(w.exit(x, face, dist));
      CHECK(face != start);
      CHECK(dist <= t + 1e-9);  // facets lie inside the sphere
      CHECK(dist >= t - 0.02);
    }
  }
}
