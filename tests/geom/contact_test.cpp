// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/contact.* for the paper's model (§3.6, [contact] model = "paper"): FD/PD/plane on
// a flat wall, first-contact recording and re-recording, zero contacts, degenerate faces,
// disagreeing normals, bad pairs, far-from-origin bodies. The patch model: contact_patch_test.cpp.
#include <spheretouch/geom/contact.hpp>

#include <doctest/doctest.h>

#include <vector>

using namespace st::geom;

namespace {
// 20 x 20 mm square at z = 0, outward normal +z (faces 0, 1), centred at `origin`.
Mesh wall(const Vec3& origin = Vec3::Zero()) {
  Mesh m;
  m.name = "wall";
  m.origin = origin;
  m.local = {{-10, -10, 0}, {10, -10, 0}, {10, 10, 0}, {-10, 10, 0}};
  m.faces = {{0, 1, 2}, {0, 2, 3}};
  return m;
}
// Tetrahedron with its tip (vertex 0) at the local origin pointing down -z, base 2 mm above.
Mesh tip() {
  Mesh m;
  m.name = "tip";
  m.local = {{0, 0, 0}, {1, 0, 2}, {-0.5, 0.866, 2}, {-0.5, -0.866, 2}};
  m.faces = {{0, 2, 1}, {0, 3, 2}, {0, 1, 3}, {1, 2, 3}};
  return m;
}
ContactConfig paper() {
  ContactConfig c = DefaultContactConfig();
  c.model = ContactModelKind::paper;
  return c;
}
Pose at(const Vec3& t) {
  Pose p = Pose::Identity();
  p.translation() = t;
  return p;
}
std::vector<ContactPair> tip_pairs(std::vector<std::uint32_t> object_faces) {
  std::vector<ContactPair> v;
  for (std::uint32_t pf : {0u, 1u, 2u})
    for (std::uint32_t of : object_faces) v.push_back({pf, of});
  return v;
}
// Depth of the model's probe point below its local contact plane at pose p.
double plane_depth(const ContactModel& m, const Pose& p) {
  return (to_eigen(m.plane_point) - p * to_eigen(m.probe_point)).dot(to_eigen(m.force_dir));
}
}  // namespace

TEST_CASE("contact paper: tip pressed into a wall gives FD = +z, PD = depth, plane consistent") {
  ContactBuilder b(paper());
  const Mesh w = wall(), t = tip();
  const auto pairs = tip_pairs({0, 1});
  // Tip right under face 1's centroid (-10/3, 10/3, 0): the tip is the nearest vertex.
  const Pose p = at({-10.0 / 3, 10.0 / 3, -0.5});
  const ContactModel m = b.build(t, w, p, pairs);
  REQUIRE(m.in_contact());
  CHECK(m.force_dir.z == doctest::Approx(1.0));
  CHECK(m.penetration_mm == doctest::Approx(0.5).epsilon(1e-12));
  CHECK(m.deepest_probe_vertex == 0);
  CHECK(m.nearest_probe_vertex == 0);
  CHECK((m.flags & kReplaned) != 0);
  CHECK(m.first_contact_face == m.nearest_object_face);
  CHECK(m.object_faces == 2);
  CHECK(m.probe_faces == 3);
  CHECK(m.contacts == 5);
  CHECK(m.pairs == 6);
  CHECK(m.contact_point.z == doctest::Approx(0.0).epsilon(1e-12));
  CHECK(m.contact_point.x == doctest::Approx(-10.0 / 3));
  CHECK(m.nearest_object_face == 1);
  CHECK(plane_depth(m, p) == doctest::Approx(m.penetration_mm).epsilon(1e-12));
  // Deeper: PD grows, the first face stays recorded (no replane).
  const ContactModel m2 = b.build(t, w, at({-10.0 / 3, 10.0 / 3, -0.8}), pairs);
  CHECK(m2.penetration_mm == doctest::Approx(0.8).epsilon(1e-12));
  CHECK((m2.flags & kReplaned) == 0);
  CHECK(m2.first_contact_face == m.first_contact_face);
}

TEST_CASE("contact paper: zero contacts end the contact; the next contact re-records the face") {
  ContactBuilder b(paper());
  const Mesh w = wall(), t = tip();
  (void)b.build(t, w, at({-5, -5, -0.2}), tip_pairs({1}));
  CHECK(b.has_first_face());
  const ContactModel none = b.build(t, w, at({0, 0, 5}), {});
  CHECK_FALSE(none.in_contact());
  CHECK(none.penetration_mm == 0.0);
  CHECK(none.force_dir.x == 0.0);
  CHECK(none.force_dir.z == 0.0);
  CHECK(none.contacts == 0);
  CHECK_FALSE(b.has_first_face());
  const ContactModel again = b.build(t, w, at({5, -5, -0.3}), tip_pairs({0}));
  CHECK((again.flags & kReplaned) != 0);
  CHECK(again.first_contact_face == 0);
}

TEST_CASE("contact paper: bodies far from the origin keep their precision") {
  ContactBuilder b(paper());
  const Vec3 far(1e6, -2e6, 3e5);
  const Mesh w = wall(far);
  const Mesh t = tip();
  const Pose p = at(far + Vec3(1.0, 1.0, -0.25));
  const ContactModel m = b.build(t, w, p, tip_pairs({0, 1}));
  REQUIRE(m.in_contact());
  CHECK(m.penetration_mm == doctest::Approx(0.25).epsilon(1e-9));
  CHECK(plane_depth(m, p) == doctest::Approx(0.25).epsilon(1e-6));
}

TEST_CASE("contact paper: degenerate object faces are skipped; all degenerate = no contact") {
  Mesh w = wall();
  w.local.push_back({0, 0, 0});
  w.local.push_back({1, 0, 0});
  w.local.push_back({2, 0, 0});  // collinear: face 2 is degenerate
  w.faces.push_back({4, 5, 6});
  ContactBuilder b(paper());
  const ContactModel m = b.build(tip(), w, at({0, 0, -0.1}), tip_pairs({0, 2}));
  REQUIRE(m.in_contact());
  CHECK((m.flags & kDegenerateSkipped) != 0);
  CHECK(m.degenerate_faces == 1);
  CHECK(m.object_faces == 2);
  CHECK(m.nearest_object_face == 0);
  const ContactModel d = b.build(tip(), w, at({0, 0, -0.1}), tip_pairs({2}));
  CHECK_FALSE(d.in_contact());
  CHECK(d.object_faces == 1);
  CHECK(d.contacts == 4);
}

TEST_CASE("contact paper: normals that disagree are flagged, FD follows the nearest face") {
  Mesh w = wall();
  // A face right under the tip, pointing -z (the underside of a thin wall).
  w.local.push_back({-1, -1, -0.05});
  w.local.push_back({-1, 1, -0.05});
  w.local.push_back({1, 0, -0.05});
  w.faces.push_back({4, 5, 6});
  ContactBuilder b(paper());
  const ContactModel m = b.build(tip(), w, at({-3, 3.5, -0.1}), tip_pairs({0, 1, 2}));
  REQUIRE(m.in_contact());
  CHECK((m.flags & kNormalsDisagree) != 0);
  CHECK(m.nearest_object_face == 1);  // centroid (-3.33, 3.33, 0) is nearest to the tip
  CHECK(m.force_dir.z == doctest::Approx(1.0));
}

TEST_CASE("contact paper: FD turning past the replane angle re-records the first face") {
  Mesh w;
  // Two faces meeting at a 90-degree edge: top (normal +z) and side (normal +x).
  w.local = {{-10, -10, 0}, {0, -10, 0}, {0, 10, 0}, {0, -10, -10}, {0, 10, -10}};
  w.faces = {{0, 1, 2}, {1, 3, 4}};
  {
    Vec3 c, n;
    const Tri& f = w.faces[1];
    n = (w.local[f[1]] - w.local[f[0]]).cross(w.local[f[2]] - w.local[f[0]]);
    REQUIRE(n.normalized().x() == doctest::Approx(1.0));
    (void)c;
  }
  ContactBuilder b(paper());
  const ContactModel top = b.build(tip(), w, at({-3, 0, -0.2}), tip_pairs({0}));
  REQUIRE(top.in_contact());
  CHECK(top.first_contact_face == 0);
  // Slid around the edge: nearest face is now the side; 90 > 60 degrees -> re-record.
  const ContactModel side = b.build(tip(), w, at({0.3, 0, -4}), tip_pairs({1}));
  REQUIRE(side.in_contact());
  CHECK(side.force_dir.x == doctest::Approx(1.0));
  CHECK((side.flags & kReplaned) != 0);
  CHECK(side.first_contact_face == 1);
  CHECK(side.penetration_mm >= 0.0);
}

TEST_CASE("contact paper: out-of-range pairs and non-finite poses are skipped and flagged") {
  ContactBuilder b(paper());
  const std::vector<ContactPair> pairs = {{0, 0}, {99, 0}, {0, 99}};
  const ContactModel m = b.build(tip(), wall(), at({0, 0, -0.1}), pairs);
  CHECK(m.skipped_pairs == 2);
  CHECK((m.flags & kBadInput) != 0);
  CHECK(m.in_contact());
  CHECK(m.pairs == 3);
  const ContactModel n = b.build(tip(), wall(), at({0, 0, std::nan("")}), pairs);
  CHECK_FALSE(n.in_contact());
  CHECK((n.flags & kBadInput) != 0);
}
