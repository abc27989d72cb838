// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/contact_planes.*: planar clusters of a contact's faces (a crease and an inner
// corner are concave, a box edge is not, a split face is one plane, a sphere's facets are not a
// few planes) and the smallest translation that clears several planes, against hand solutions.
#include <spheretouch/geom/contact_planes.hpp>

#include <doctest/doctest.h>

#include <cmath>

#include <spheretouch/geom/primitives.hpp>

using namespace st::geom;

namespace {
// Adds every face of m whose centroid satisfies `keep` to the clusters.
template <class Keep>
void add_faces(PlaneClusters& pc, const Mesh& m, Keep keep) {
  for (const Tri& t : m.faces) {
    const Vec3 a = m.vertex(t[0]), b = m.vertex(t[1]), c = m.vertex(t[2]);
    const Vec3 centroid = (a + b + c) / 3;
    if (keep(centroid)) pc.add((b - a).cross(c - a).normalized(), centroid);
  }
}
}  // namespace

TEST_CASE("contact planes: a crease and an inner corner are concave, a box edge is not") {
  PlaneClusters pc;
  // A crease: floor z = 0 (x in [0, 40]) and wall x = 0 (z in [0, 40]), two triangles each.
  pc.add(Vec3::UnitZ(), {10, 10, 0});
  pc.add(Vec3::UnitZ(), {30, 20, 0});
  pc.add(Vec3::UnitX(), {0, 10, 10});
  pc.add(Vec3::UnitX(), {0, 20, 30});
  CHECK(pc.n == 2);
  CHECK_FALSE(pc.overflow);
  CHECK(pc.c[0].faces == 2);
  CHECK(pc.concave(1e-6));
  // An inner corner: three walls facing into the octant x, y, z > 0.
  pc.clear();
  pc.add(Vec3::UnitX(), {0, 10, 10});
  pc.add(Vec3::UnitY(), {10, 0, 10});
  pc.add(Vec3::UnitZ(), {10, 10, 0});
  CHECK(pc.n == 3);
  CHECK(pc.concave(1e-6));
  // A box's edge: top and side faces of a 40 mm box near the edge x = z = 20.
  pc.clear();
  add_faces(pc, make_box({40, 40, 40}), [](const Vec3& c) { return c.z() > 19.9 || c.x() > 19.9; });
  CHECK(pc.n == 2);
  CHECK_FALSE(pc.concave(1e-6));
  // A face split in many: one plane. A sphere's facets: not a few planes.
  pc.clear();
  add_faces(pc, make_box({40, 40, 40}), [](const Vec3& c) { return c.z() > 19.9; });
  CHECK(pc.n == 1);
  CHECK_FALSE(pc.concave(1e-6));
  pc.clear();
  add_faces(pc, make_icosphere(10, 16), [](const Vec3& c) { return c.z() > 8; });
  CHECK(pc.overflow);
  CHECK_FALSE(pc.concave(1e-6));
  // Parallel planes at different heights (a step): not one plane, not a concave pair.
  pc.clear();
  pc.add(Vec3::UnitZ(), {0, 0, 0});
  pc.add(Vec3::UnitZ(), {5, 0, 1});
  CHECK(pc.overflow);
}

TEST_CASE("contact planes: the smallest translation that clears every plane") {
  const std::array<Vec3, 4> axes{Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ(), Vec3::Zero()};
  bool ok = false;
  // One plane: straight out.
  CHECK((smallest_clearing(axes, {0, 0, 2.5, 0}, 3, ok) - Vec3(0, 0, 2.5)).norm() < 1e-12);
  CHECK(ok);
  // A crease, 3 mm into the wall and 2 mm into the floor: both at once.
  CHECK((smallest_clearing(axes, {3, 0, 2, 0}, 3, ok) - Vec3(3, 0, 2)).norm() < 1e-12);
  // An inner corner 2 mm into each wall: |t| = 2√3 along the diagonal.
  const Vec3 t = smallest_clearing(axes, {2, 2, 2, 0}, 3, ok);
  CHECK(ok);
  CHECK(std::abs(t.norm() - 2 * std::sqrt(3.0)) < 1e-12);
  // Walls at 120° (normals 60° apart, a V-groove): the plane with the deeper reach alone
  // suffices when it also clears the other (its multiplier would be negative otherwise).
  const std::array<Vec3, 4> groove{Vec3(std::sin(0.5), 0, std::cos(0.5)), Vec3(-std::sin(0.5), 0, std::cos(0.5)),
                                   Vec3::Zero(), Vec3::Zero()};
  const Vec3 g = smallest_clearing(groove, {3, 0.5, 0, 0}, 2, ok);
  CHECK(ok);
  CHECK((g - 3 * groove[0]).norm() < 1e-12);
  CHECK(groove[1].dot(g) >= 0.5);
  // Nothing penetrated: no translation. Opposite walls both penetrated: no way out.
  CHECK(smallest_clearing(axes, {-1, 0, -2, 0}, 3, ok).norm() == 0);
  CHECK(ok);
  const std::array<Vec3, 4> slot{Vec3::UnitX(), -Vec3::UnitX(), Vec3::Zero(), Vec3::Zero()};
  (void)smallest_clearing(slot, {1, 1, 0, 0}, 2, ok);
  CHECK_FALSE(ok);
}
