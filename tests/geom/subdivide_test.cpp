// SPDX-License-Identifier: BSD-3-Clause
// Tests for src/spheretouch/geom/subdivide.*: face counts, closedness kept, order rule, determinism, errors.
#include <spheretouch/geom/subdivide.hpp>

#include <cstring>

#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/primitives.hpp>
#include "test_util.hpp"

using namespace st;
using namespace st::geom;

TEST_CASE("Loop subdivision: 4x faces per level, closed and manifold kept") {
  const Mesh ico = make_icosphere(10, 2);
  for (int levels = 0; levels <= 3; ++levels) {
    Result<Mesh> r = loop_subdivide(ico, levels);
    REQUIRE(r.ok());
    CHECK(r.value().num_faces() == ico.num_faces() << (2 * levels));
    CHECK(r.value().topology().closed());
    CHECK(r.value().topology().manifold());
    // Euler characteristic of a sphere stays 2: V - E + F = 2 with E = 3F/2.
    CHECK(long(r.value().num_vertices()) - long(3 * r.value().num_faces() / 2) + long(r.value().num_faces()) == 2);
  }
}

TEST_CASE("Loop subdivision: face 4f+k keeps corner k of face f; old vertices keep their index") {
  const Mesh box = make_box(Vec3(2, 3, 4));
  Result<Mesh> r = loop_subdivide(box, 1);
  REQUIRE(r.ok());
  for (std::size_t f = 0; f < box.num_faces(); ++f)
    for (int k = 0; k < 3; ++k) CHECK(r.value().faces[4 * f + k][0] == box.faces[f][k]);
  // Middle faces use only new (edge) vertices.
  for (std::size_t f = 0; f < box.num_faces(); ++f)
    for (int k = 0; k < 3; ++k) CHECK(r.value().faces[4 * f + 3][k] >= box.num_vertices());
}

TEST_CASE("Loop subdivision is deterministic to the bit") {
  const Mesh m = make_icosphere(7, 3);
  Result<Mesh> a = loop_subdivide(m, 2), b = loop_subdivide(m, 2);
  REQUIRE(a.ok());
  REQUIRE(b.ok());
  REQUIRE(a.value().local.size() == b.value().local.size());
  CHECK(std::memcmp(a.value().local.data(), b.value().local.data(), a.value().local.size() * sizeof(Vec3)) == 0);
  CHECK(a.value().faces == b.value().faces);
}

TEST_CASE("Loop subdivision of a real mesh: hand 2,390 -> 38,240 faces in two levels") {
  Result<LoadedMesh> hand = load_mesh(st::test::model("hand.off"));
  REQUIRE(hand.ok());
  Result<Mesh> r = loop_subdivide(hand.value().mesh, 2);
  REQUIRE(r.ok());
  CHECK(r.value().num_faces() == 38240);
  CHECK(r.value().topology().closed());
  CHECK(r.value().topology().manifold());
}

TEST_CASE("Loop subdivision refuses open and non-manifold input with a clear error") {
  Mesh open = make_box(Vec3(1, 1, 1));
  open.faces.pop_back();
  Result<Mesh> r = loop_subdivide(open, 1);
  REQUIRE_FALSE(r.ok());
  CHECK(r.error().find("open mesh") != std::string::npos);

  Mesh fin = make_box(Vec3(1, 1, 1));  // a fin: a third face on an existing edge
  fin.local.push_back(Vec3(0, 0, 3));
  fin.faces.push_back({fin.faces[0][0], fin.faces[0][1], std::uint32_t(fin.local.size() - 1)});
  r = loop_subdivide(fin, 1);
  REQUIRE_FALSE(r.ok());
  CHECK(r.error().find("non-manifold edge") != std::string::npos);

  Mesh flipped = make_box(Vec3(1, 1, 1));
  std::swap(flipped.faces[0][1], flipped.faces[0][2]);
  r = loop_subdivide(flipped, 1);
  REQUIRE_FALSE(r.ok());
  CHECK(r.error().find("inconsistent orientation") != std::string::npos);
}
