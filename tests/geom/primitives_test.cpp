// SPDX-License-Identifier: BSD-3-Clause
// Tests for src/spheretouch/geom/primitives.*: generated meshes are closed, manifold and outward-oriented.
#include <spheretouch/geom/primitives.hpp>

#include "test_util.hpp"

using namespace st::geom;

namespace {
double signed_volume(const Mesh& m) {
  double v = 0;
  for (const Tri& t : m.faces) v += m.local[t[0]].dot(m.local[t[1]].cross(m.local[t[2]])) / 6;
  return v;
}
}  // namespace

TEST_CASE("icosphere: 20 f^2 faces on the sphere, closed, outward") {
  for (int f : {1, 2, 7}) {
    const Mesh m = make_icosphere(5, f);
    CHECK(m.num_faces() == std::size_t(20 * f * f));
    CHECK(m.topology().closed());
    CHECK(m.topology().manifold());
    CHECK(m.degenerate_faces().empty());
    for (const Vec3& p : m.local) CHECK(std::abs((m.origin + p).norm() - 5) < 1e-12);
    CHECK(signed_volume(m) > 0);
  }
}

TEST_CASE("box and capsule are closed, manifold, outward; capsule tip where documented") {
  const Mesh b = make_box(Vec3(1, 2, 3));
  CHECK(b.topology().closed());
  CHECK(b.topology().manifold());
  CHECK(std::abs(signed_volume(b) - 6) < 1e-12);
  const Mesh c = make_capsule(2, 10, 16);
  CHECK(c.topology().closed());
  CHECK(c.topology().manifold());
  CHECK(signed_volume(c) > 0);
  CHECK(std::abs(c.bounds().hi.z() - 7) < 1e-12);
}
