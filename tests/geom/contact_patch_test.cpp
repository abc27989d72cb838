// SPDX-License-Identifier: BSD-3-Clause
// Tests the patch contact model of src/spheretouch/geom/contact.* (contact_patch.cpp) against analytic
// shapes with known depth and normal: a sphere pressed into a box's face, edge and corner, into a
// sphere and into a concave crease; pulled out; slid over and around an edge; pushed through a
// 1 mm plate (no pop-through); bad input. Pairs come from the exact brute-force reference.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <limits>
#include <vector>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include "analytic_shapes.hpp"
#include "test_models.hpp"

using namespace st::geom;

namespace {
constexpr double kPi = 3.14159265358979323846;

using st::test::pose_at;
ContactModel model_at(ContactBuilder& b, const Mesh& probe, const Mesh& object, const Pose& p) {
  const std::vector<FacePair> pairs = st::test::brute_force(probe, object, p);
  return b.build(probe, object, p, pairs);
}
double angle_deg(const Vec3& a, const Vec3& b) {
  const double c = a.normalized().dot(b.normalized());
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / kPi;
}
Vec3 fd(const ContactModel& m) { return to_eigen(m.force_dir); }
// Depth of the model's probe point below its local contact plane at pose p.
double depth_below_plane(const ContactModel& m, const Pose& p) {
  return (to_eigen(m.plane_point) - p * to_eigen(m.probe_point)).dot(to_eigen(m.force_dir));
}
bool finite_model(const ContactModel& m) {
  return finite(m.force_dir) && finite(m.plane_point) && finite(m.probe_point) && finite(m.contact_point) &&
         std::isfinite(m.penetration_mm) && m.penetration_mm >= 0;
}
using st::test::ball10;  // analytic_shapes.hpp
using st::test::box40;
using st::test::kDepthTol;
// Two 10 mm balls (ball10's mesh) 30 mm apart along x, centred on the origin.
Mesh make_dumbbell() {
  Mesh dumbbell;
  for (double x : {-15.0, 15.0}) {
    const Mesh& ball = ball10();
    const auto base = std::uint32_t(dumbbell.local.size());
    for (const Vec3& v : ball.local) dumbbell.local.push_back(ball.origin + v + Vec3(x, 0, 0));
    for (const Tri& t : ball.faces) dumbbell.faces.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  return dumbbell;
}
}  // namespace

TEST_CASE("contact patch: the default model is patch; names parse") {
  CHECK(DefaultContactConfig().model == ContactModelKind::patch);
  CHECK(parse_contact_model("paper").value() == ContactModelKind::paper);
  CHECK(parse_contact_model("patch").value() == ContactModelKind::patch);
  const auto bad = parse_contact_model("nearest");
  REQUIRE_FALSE(bad.ok());
  CHECK(st::test::contains(bad.error(), "expected patch or paper"));
  ContactConfig c;
  c.hold_margin_mm = -1;
  CHECK(st::test::contains(check(c), "hold_margin_mm"));
  CHECK(check(DefaultContactConfig()).empty());
}

TEST_CASE("contact patch: sphere pressed into a box face: FD = +z, PD = depth from 0.5 to 10 mm") {
  for (const Vec3& offset : {Vec3(0, 0, 0), Vec3(1e6, -2e6, 3e5)}) {
    Mesh box = box40();
    box.origin += offset;  // the same box far from the origin: nothing may lose precision
    for (double d : {0.5, 1.0, 2.0, 5.0, 10.0}) {
      CAPTURE(d);
      CAPTURE(offset.norm());
      ContactBuilder b;
      const Pose p = pose_at(offset + Vec3(1.3, -2.1, 30.0 - d));
      const ContactModel m = model_at(b, ball10(), box, p);
      REQUIRE(m.in_contact());
      CHECK(m.kind == std::uint32_t(ContactModelKind::patch));
      CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1e-6);
      CHECK(std::abs(m.penetration_mm - d) <= kDepthTol);
      CHECK(m.penetration_mm <= d + 1e-9);  // vertices lie on the sphere: never deeper than it
      CHECK(depth_below_plane(m, p) == doctest::Approx(m.penetration_mm).epsilon(1e-9));
      CHECK(m.inside_probe_vertices > 0);
      CHECK((m.flags & (kHeld | kNormalFallback | kBadInput)) == 0);
    }
  }
}

TEST_CASE("contact patch: tiny and huge scales: PD and the plane scale with the meshes, FD does not") {
  // The same press (2 mm into a 40 mm box with a 10 mm ball) at scales 1e-30 .. 1e30: the vector
  // area goes with the square of the scale and the segment kernel divides by products of
  // distances, so nothing may underflow, overflow or lose the direction.
  for (double s : {1e-30, 1e-9, 1e-6, 1e-3, 1.0, 1e3, 1e6, 1e9, 1e30}) {
    CAPTURE(s);
    const Mesh box = make_box({40 * s, 40 * s, 40 * s});
    const Mesh ball = make_icosphere(10 * s, 16);
    ContactBuilder b;
    for (int k = 0; k < 6; ++k) {  // a few rounds: the first and the ones with history
      const double d = 2.0 + 0.1 * k;
      const Pose p = pose_at(s * Vec3(1.3, -2.1, 30.0 - d));
      const ContactModel m = model_at(b, ball, box, p);
      REQUIRE(m.in_contact());
      CHECK(finite_model(m));
      CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1e-6);
      CHECK(std::abs(m.penetration_mm - d * s) <= kDepthTol * s);
      CHECK(depth_below_plane(m, p) == doctest::Approx(m.penetration_mm).epsilon(1e-9));
      CHECK((m.flags & (kHeld | kNormalFallback | kBadInput | kNormalsDisagree)) == 0);
    }
  }
}

TEST_CASE("contact patch: a second contact region is found when it appears, and PD follows it") {
  // A dumbbell (two 10 mm balls 30 mm apart) rocks on a box's top face: ball A held 1 mm deep,
  // ball B coming down from 2 mm above until it is the deeper (depth 1 + 30 sin θ). Both
  // patches lie on the top face, so FD = +z exactly; PD must reach B's depth within the rounds
  // that look for new regions (B appears outside the footprint A's patch had).
  const Mesh dumbbell = make_dumbbell();
  const Mesh box = make_box({100, 100, 40});  // top face z = 20, the balls well inside its edges
  ContactBuilder b;
  for (int k = 0; k <= 40; ++k) {
    const double theta = -0.1 + 0.0035 * k;  // rotation about y: A (x = −15) at height 15 sin θ
    Pose p = Pose::Identity();
    p.linear() = Eigen::AngleAxisd(theta, Vec3::UnitY()).toRotationMatrix();
    p.translation() = Vec3(0, 0, 29 - 15 * std::sin(theta));  // A's depth stays 1 mm
    const double depth_a = 1.0, depth_b = 1 + 30 * std::sin(theta);
    CAPTURE(k);
    const ContactModel m = model_at(b, dumbbell, box, p);
    REQUIRE(m.in_contact());
    CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1e-6);
    CHECK(m.penetration_mm <= std::max(depth_a, depth_b) + 1e-9);  // never deeper than the balls
    if (k >= 24)  // B touches from k = 20 (θ > −1/30): found within the 4 rounds between searches
      CHECK(std::abs(m.penetration_mm - std::max(depth_a, depth_b)) <= kDepthTol);
  }
}

TEST_CASE("contact patch: a region that lifts off and comes back is found again") {
  // The dumbbell of the test above rocks B down into contact (A held 1 mm deep), up out of it,
  // and down again until B is the deeper: B's faces collide again after they stopped, and must
  // count as new again (not as faces a search has seen), or B is not looked for.
  const Mesh dumbbell = make_dumbbell();
  const Mesh box = make_box({100, 100, 40});  // top face z = 20
  ContactBuilder b;
  int late = 0, wrong = 0;
  bool was_in = false, left = false;
  for (int k = 0; k <= 90; ++k) {
    // B's depth 1 + 30 sin θ: to 0.5 mm (k 20), out to -1 mm (k 35), then down to 2 mm (k 90).
    const double depth_b = k <= 20 ? -1 + 0.075 * k : (k <= 35 ? 0.5 - 0.1 * (k - 20) : -1 + 3.0 * (k - 35) / 55);
    const double theta = std::asin((depth_b - 1) / 30);
    Pose p = Pose::Identity();
    p.linear() = Eigen::AngleAxisd(theta, Vec3::UnitY()).toRotationMatrix();
    p.translation() = Vec3(0, 0, 29 - 15 * std::sin(theta));  // A's depth stays 1 mm
    CAPTURE(k);
    const ContactModel m = model_at(b, dumbbell, box, p);
    REQUIRE(m.in_contact());
    CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1e-6);
    was_in |= depth_b > 0.3;
    left |= was_in && depth_b < -0.5;
    if (left && depth_b > 1.1) {
      ++late;
      wrong += std::abs(m.penetration_mm - depth_b) > kDepthTol ? 1 : 0;
    }
  }
  INFO("rounds with B back and the deeper: " << late << ", PD wrong in " << wrong);
  CHECK(late >= 15);
  CHECK(wrong == 0);
}

TEST_CASE("contact patch: a small region appearing next to a large one is found (grouped apart from it)") {
  // A finely meshed 20 mm ball A slides along y, 1 mm deep in a flat block's top face (z = 20;
  // ~110 colliding faces, the same ones all along: the probe only translates), while a coarse
  // 5 mm ball B (80 faces, at most ~15 colliding) slides up a ramp beside it (a block tilted 0.1
  // rad about x) until it is the deeper. Each search for new regions then sees only B's few new
  // faces, and groups just those: they touch none of A's and must make a group of their own, or B
  // is taken for part of A's region and found only when the patrol's climb comes by (tens of
  // rounds on). PD must be, within the 4 rounds between searches after B touches, the
  // largest distance a probe vertex travels along FD to leave the block or the ramp.
  Mesh probe;
  auto add = [](Mesh& m, const Mesh& part, const Pose& at) {
    const auto base = std::uint32_t(m.local.size());
    for (const Vec3& v : part.local) m.local.push_back(at * (part.origin + v));
    for (const Tri& t : part.faces) m.faces.push_back({t[0] + base, t[1] + base, t[2] + base});
  };
  add(probe, make_icosphere(20, 32), pose_at({-25, 0, 0}));  // A
  add(probe, make_icosphere(5, 2), pose_at({25, 0, -14}));   // B: its centre 14 mm below A's
  const std::size_t a_vertices = probe.local.size() - 42;    // B (frequency 2) has 42 vertices
  constexpr double kRamp = 0.1;                              // rad
  const Vec3 ramp_n(0, -std::sin(kRamp), std::cos(kRamp));   // the ramp's top face normal
  double b_low = 1e9;  // B's lowest vertex, probe frame (its coarse mesh has none at the pole)
  for (std::size_t v = a_vertices; v < probe.local.size(); ++v)
    b_low = std::min(b_low, (probe.origin + probe.local[v]).z());
  const Vec3 ramp_at(25, 0, 39 + b_low - 0.5);  // a point of that face: 0.5 mm under B's path at y = 0
  Mesh object;
  add(object, make_box({60, 400, 40}), pose_at({-25, 0, 0}));  // top face z = 20
  Pose ramp = Pose::Identity();
  ramp.linear() = Eigen::AngleAxisd(kRamp, Vec3::UnitX()).toRotationMatrix();
  ramp.translation() = ramp_at - ramp.linear() * Vec3(0, 0, 20);  // the tilted box's top face through ramp_at
  add(object, make_box({20, 400, 40}), ramp);
  ContactBuilder b;
  int touched = -1;  // the round B touched the ramp in
  bool b_deeper = false;
  for (int k = 0; k <= 28; ++k) {
    const Pose p = pose_at({0, 0.7 * k, 39});  // A's centre 19 mm above the block: 1 mm deep
    const ContactModel m = model_at(b, probe, object, p);
    REQUIRE(m.in_contact());
    const Vec3 d = fd(m);
    double depth_a = -1e9, depth_b = -1e9, pd = 0;  // deepest vertex of each ball, and along d
    for (std::size_t v = 0; v < probe.local.size(); ++v) {
      const Vec3 x = p * (probe.origin + probe.local[v]);
      if (v < a_vertices) {
        depth_a = std::max(depth_a, 20 - x.z());
        pd = std::max(pd, (20 - x.z()) / d.z());
      } else {
        depth_b = std::max(depth_b, ramp_n.dot(ramp_at - x));
        pd = std::max(pd, ramp_n.dot(ramp_at - x) / ramp_n.dot(d));
      }
    }
    if (depth_b > 0 && touched < 0) touched = k;
    b_deeper |= depth_b > depth_a + 0.1;
    CAPTURE(k);
    CHECK(angle_deg(d, Vec3::UnitZ()) < 6);  // between the block's and the ramp's normals
    if (touched >= 0 && k >= touched + 4) CHECK(m.penetration_mm == doctest::Approx(pd).epsilon(1e-6));
  }
  CHECK(touched > 0);
  CHECK(b_deeper);  // the test reached the rounds where only finding B gives the right depth
}

TEST_CASE("contact patch: a second peak rising inside a followed region is found (the patrol)") {
  // A peanut (an ellipsoid 40 x 20 x 20 mm with a waist: lobes A and B) lies on a block's top face
  // (z = 20), its deepest vertex held 4 mm deep, and rocks from A down (B up, out of contact) to B
  // slightly down. The pressed region spreads from A through the waist to B as one region, so no
  // group of colliding faces is ever new: B's lobe rises inside a followed region, as a second
  // local maximum of depth that only a climb from elsewhere on the patch reaches. Once B is the
  // deeper, PD must be found at B (the probe's deepest vertex, FD = +z: all faces of the patch
  // lie on the block's top face).
  Mesh peanut = make_icosphere(10, 16);
  for (Vec3& v : peanut.local) {
    const Vec3 x = peanut.origin + v;
    const double waist = 1 - 0.2 * std::exp(-x.x() * x.x() / 18);
    v = Vec3(2 * x.x(), waist * x.y(), waist * x.z()) - peanut.origin;
  }
  const Mesh block = make_box({200, 200, 40});  // top face z = 20
  ContactBuilder b;
  constexpr int kRounds = 400;
  int wrong_late = 0, late = 0;
  double worst_late = 0;
  for (int k = 0; k <= kRounds; ++k) {
    const double theta = 0.25 - 0.33 * k / kRounds;  // about y: B (x > 0) goes up for theta > 0
    Pose p = Pose::Identity();
    p.linear() = Eigen::AngleAxisd(theta, Vec3::UnitY()).toRotationMatrix();
    double low = 1e9;
    for (const Vec3& v : peanut.local) low = std::min(low, (p.linear() * (peanut.origin + v)).z());
    p.translation() = Vec3(0, 0, 16 - low);  // the deepest vertex 4 mm below z = 20
    const ContactModel m = model_at(b, peanut, block, p);
    CAPTURE(k);
    REQUIRE(m.in_contact());
    CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1e-6);
    CHECK(m.penetration_mm <= 4 + 1e-9);
    if (theta < -0.02) {  // B's lobe the deeper by ~0.4 mm or more
      ++late;
      worst_late = std::max(worst_late, 4 - m.penetration_mm);
      wrong_late += std::abs(m.penetration_mm - 4) > kDepthTol ? 1 : 0;
    }
  }
  INFO("rounds with B the deeper: " << late << ", of them PD wrong in " << wrong_late << " (worst " << worst_late
                                    << " mm short)");
  CHECK(late > 50);
  CHECK(wrong_late <= 10);
}

TEST_CASE("contact patch: a region whose remembered maximum was lost is looked for again") {
  // A dumbbell (two 10 mm balls 30 mm apart on its x axis) spins about that axis, 3 degrees a
  // round, on a box's top face: ball A held 2 mm deep, ball B 0.7 mm (under half A's depth, so
  // its maximum is climbed only now and then). The spin turns B's deepest vertex away within a
  // few rounds: B's remembered maximum is lost while its region stays, with no new region to
  // look for. Then the dumbbell rocks B down to 3 mm: PD must follow B once it is the deeper,
  // which only a search after the loss (or the much slower patrol) can give.
  const Mesh dumbbell = make_dumbbell();
  const Mesh box = make_box({100, 100, 40});  // top face z = 20
  ContactBuilder b;
  int late = 0, wrong = 0;
  for (int k = 0; k <= 90; ++k) {
    const double s = k < 40 ? -0.0433 : std::min(0.0333, -0.0433 + 0.0019 * (k - 40));  // sin of the rock
    const double theta = std::asin(s), phi = 3.0 * kPi / 180 * k;
    Pose p = Pose::Identity();
    p.linear() = (Eigen::AngleAxisd(theta, Vec3::UnitY()) * Eigen::AngleAxisd(phi, Vec3::UnitX())).toRotationMatrix();
    const Vec3 a_centre = p.linear() * Vec3(-15, 0, 0);
    p.translation() = Vec3(0, 0, 28) - Vec3(0, 0, a_centre.z());  // A's centre at z = 28: 2 mm deep
    double depth = 0;                                             // the deepest vertex below the top face
    for (const Vec3& v : dumbbell.local) depth = std::max(depth, 20 - (p * (dumbbell.origin + v)).z());
    const double depth_b = 2 + 30 * s;
    CAPTURE(k);
    const ContactModel m = model_at(b, dumbbell, box, p);
    REQUIRE(m.in_contact());
    CHECK(m.penetration_mm <= depth + 1e-9);
    if (depth_b > 2.2) {
      ++late;
      wrong += std::abs(m.penetration_mm - depth) > kDepthTol ? 1 : 0;
    }
  }
  INFO("rounds with B the deeper by 0.2 mm or more: " << late << ", PD wrong in " << wrong);
  CHECK(late >= 10);
  CHECK(wrong == 0);
}

TEST_CASE("contact patch: box edge and corner: FD on the bisector, PD = depth") {
  const Vec3 edge_dir = Vec3(1, 0, 1).normalized(), corner_dir = Vec3(1, 1, 1).normalized();
  for (double d : {0.5, 2.0, 5.0}) {
    CAPTURE(d);
    {
      ContactBuilder b;
      const Pose p = pose_at(Vec3(20, 0.37, 20) + (10 - d) * edge_dir);
      const ContactModel m = model_at(b, ball10(), box40(), p);
      REQUIRE(m.in_contact());
      CHECK(angle_deg(fd(m), edge_dir) < 1.0);
      CHECK(std::abs(m.penetration_mm - d) <= kDepthTol);
    }
    {
      ContactBuilder b;
      const Pose p = pose_at(Vec3(20, 20, 20) + (10 - d) * corner_dir);
      const ContactModel m = model_at(b, ball10(), box40(), p);
      REQUIRE(m.in_contact());
      CHECK(angle_deg(fd(m), corner_dir) < 1.0);
      CHECK(std::abs(m.penetration_mm - d) <= kDepthTol);
    }
  }
}

TEST_CASE("contact patch: sphere into sphere: FD radial, PD = r1 + r2 - distance") {
  const Mesh object = make_icosphere(20, 16);
  const Vec3 u = Vec3(1, 2, 3).normalized();
  for (double d : {0.5, 3.0, 10.0}) {
    CAPTURE(d);
    ContactBuilder b;
    const Pose p = pose_at((30.0 - d) * u);
    const ContactModel m = model_at(b, ball10(), object, p);
    REQUIRE(m.in_contact());
    CHECK(angle_deg(fd(m), u) < 1.0);
    CHECK(std::abs(m.penetration_mm - d) <= kDepthTol);
  }
}

TEST_CASE("contact patch: a builder that follows the probe gives the depth a fresh one finds at each pose") {
  // The following builder starts each vertex's exit walk where that vertex left the other body's
  // surface the round before, a fresh one from a face near it: the same surface point either way.
  // FD does not walk; it is compared as vectors (an angle from acos reads one rounding of the dot
  // product as 1e-6 degrees).
  const Mesh object = make_icosphere(20, 16);
  const Vec3 u = Vec3(1, 2, 3).normalized(), side = u.cross(Vec3::UnitZ()).normalized();
  ContactBuilder follow;
  for (int k = 0; k <= 200; ++k) {
    CAPTURE(k);
    const Pose p = pose_at((27.0 + 0.005 * k) * u + 0.05 * k * side);  // slides 10 mm, 1 mm shallower
    const ContactModel warm = model_at(follow, ball10(), object, p);
    ContactBuilder fresh;
    const ContactModel cold = model_at(fresh, ball10(), object, p);
    REQUIRE(warm.in_contact());
    REQUIRE(cold.in_contact());
    CHECK(warm.penetration_mm == doctest::Approx(cold.penetration_mm).epsilon(1e-12));
    CHECK((fd(warm) - fd(cold)).norm() < 1e-12);
  }
}

TEST_CASE("contact patch: force never rises while the probe is pulled out") {
  ContactBuilder b;
  double last = std::numeric_limits<double>::infinity();
  int in_contact = 0;
  for (double d = 8.0; d > -0.5; d -= 0.05) {
    const ContactModel m = model_at(b, ball10(), box40(), pose_at({0.2, 0.1, 30.0 - d}));
    if (!m.in_contact()) {
      CHECK(d < 0.05);  // contact ends only at the surface
      last = 0;
      continue;
    }
    ++in_contact;
    CHECK(m.penetration_mm <= last + 1e-9);
    last = m.penetration_mm;
  }
  CHECK(in_contact > 150);
}

TEST_CASE("contact patch: sliding over and around a box edge: no step, FD turns continuously") {
  // Straight over the edge at constant height: the sphere loses the top face gradually.
  {
    ContactBuilder b;
    ContactModel prev{};
    int steps = 0;
    for (double x = 10; x <= 27; x += 0.05) {
      const ContactModel m = model_at(b, ball10(), box40(), pose_at({x, 0, 27}));
      if (!m.in_contact()) break;
      REQUIRE(finite_model(m));
      if (prev.in_contact()) {
        CHECK(angle_deg(fd(m), fd(prev)) < 0.5);
        CHECK(std::abs(m.penetration_mm - prev.penetration_mm) < 0.05);
        ++steps;
      }
      prev = m;
    }
    CHECK(steps > 200);
    CHECK(fd(prev).x() > 0.5);  // it has turned toward the side by the time contact ends
  }
  // Around the edge at constant depth 3 mm. Where the ball is symmetric about the edge (45°) FD
  // is radial and PD exact; elsewhere FD is the intersection volume's gradient, which leans
  // toward the face with the larger share of the patch (a rounded edge), and PD is the way out
  // along it: never less than the shortest way out, and both turn without a step.
  {
    ContactBuilder b;
    ContactModel prev{};
    for (double a = 0; a <= 90.0; a += 0.5) {
      const Vec3 dir(std::sin(a * kPi / 180), 0, std::cos(a * kPi / 180));
      const ContactModel m = model_at(b, ball10(), box40(), pose_at(Vec3(20, 0, 20) + 7.0 * dir));
      REQUIRE(m.in_contact());
      CAPTURE(a);
      CHECK(m.penetration_mm >= 3.0 - kDepthTol);
      CHECK(m.penetration_mm <= 3.0 / std::cos(angle_deg(fd(m), dir) * kPi / 180) + kDepthTol);
      CHECK(angle_deg(fd(m), dir) < 35.0);
      if (std::abs(a - 45.0) < 1e-9) {
        CHECK(angle_deg(fd(m), dir) < 1.0);
        CHECK(std::abs(m.penetration_mm - 3.0) <= kDepthTol);
      }
      if (prev.in_contact()) {
        CHECK(angle_deg(fd(m), fd(prev)) < 1.5);
        CHECK(std::abs(m.penetration_mm - prev.penetration_mm) < 0.05);
      }
      prev = m;
    }
  }
}

TEST_CASE("contact patch: concave crease: FD between the walls, continuous across the valley") {
  // A V-shaped valley along y: walls z = |x| (normals (∓1, 0, 1)/√2), 40 mm long.
  Mesh v;
  v.name = "valley";
  v.local = {{-20, -20, 20}, {0, -20, 0}, {20, -20, 20}, {-20, 20, 20}, {0, 20, 0}, {20, 20, 20}};
  v.faces = {{0, 1, 4}, {0, 4, 3}, {1, 2, 5}, {1, 5, 4}};
  ContactBuilder b;
  ContactModel prev{};
  for (double x = -3; x <= 3; x += 0.05) {
    const ContactModel m = model_at(b, ball10(), v, pose_at({x, 0, 10 * std::sqrt(2.0) - 1.0}));
    REQUIRE(m.in_contact());
    REQUIRE(finite_model(m));
    CHECK(fd(m).z() > 0.7);
    if (std::abs(x) < 1e-9) CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1.0);
    // The walls' shares of the patch trade places within ~2 mm: FD turns up to ~55°/mm there,
    // in proportion to the step (no jump).
    if (prev.in_contact()) CHECK(angle_deg(fd(m), fd(prev)) < 4.0);
    prev = m;
  }
}

TEST_CASE("contact patch: pushed through a 1 mm plate and back: no pop-through, held past it") {
  const Mesh plate = make_box({60, 60, 1});  // top at z = +0.5
  const Mesh ball = make_icosphere(5, 12);
  ContactBuilder b;
  int held = 0, contacts = 0;
  auto step = [&](double cz) {
    const double depth = 0.5 - (cz - 5.0);  // below the plate's top (the side it entered by)
    const ContactModel m = model_at(b, ball, plate, pose_at({0.3, -0.2, cz}));
    CAPTURE(cz);
    REQUIRE(finite_model(m));
    if (depth <= 0.02) return;  // at or above the top: contact may or may not be reported
    REQUIRE(m.in_contact());    // never lost while below the entry surface
    ++contacts;
    CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1e-6);  // always out of the entry side
    CHECK(std::abs(m.penetration_mm - depth) <= kDepthTol);
    if (m.flags & kHeld) ++held;
  };
  for (double cz = 6.0; cz >= -20.0; cz -= 0.2) step(cz);
  for (double cz = -20.0; cz <= 6.0; cz += 0.2) step(cz);
  // Exact values, as a script gives them: at cz = -4.5 the ball's pole touches the top face from
  // inside the plate (a zero-area curve, whose rounding noise once pointed FD down).
  for (int i = 0; 6.0 - 0.1 * i >= -20.0; i += 2) step(6.0 - 0.1 * i);
  for (int i = 1; - 20 + 0.1 * i <= 6.0; i += 2) step(-20 + 0.1 * i);
  CHECK(contacts > 200);
  CHECK(held > 100);  // fully through (cz < -5.5) no face collides: the held plane carries it
}

TEST_CASE("contact patch: an open sheet is pushed against from either side, through and back, as a plate is") {
  // A 60 mm sheet at z = 0 wound +z (one surface: no inside, no thickness).
  Mesh sheet = st::test::grid(12);
  for (Vec3& v : sheet.local) v = Vec3(5 * v.x() - 30, 5 * v.y() - 30, 0);
  const Mesh ball = make_icosphere(5, 12);
  for (const double side : {+1.0, -1.0}) {
    CAPTURE(side);
    ContactBuilder b;
    int held = 0, contacts = 0;
    auto step = [&](double c) {  // the ball's centre at height side * c: depth 5 - c past the sheet
      const double depth = 5.0 - c;
      const ContactModel m = model_at(b, ball, sheet, pose_at({0.3, -0.2, side * c}));
      CAPTURE(c);
      REQUIRE(finite_model(m));
      if (depth <= 0.02) return;
      REQUIRE(m.in_contact());
      ++contacts;
      CHECK(angle_deg(fd(m), side * Vec3::UnitZ()) < 1e-6);  // out of the side it came from
      CHECK(std::abs(m.penetration_mm - depth) <= kDepthTol);
      if (m.flags & kHeld) ++held;
    };
    for (double c = 6.0; c >= -20.0; c -= 0.2) step(c);
    for (double c = -20.0; c <= 6.0; c += 0.2) step(c);
    CHECK(contacts > 200);
    CHECK(held > 100);
  }
}

TEST_CASE("contact patch: an open bowl, touched inside and outside, pushes toward the probe's side") {
  // The lower half of a sphere of radius 40 (faces whose centroid is below z = -2), wound outward.
  const Mesh full = make_icosphere(40, 24);
  Mesh bowl = full;
  bowl.faces.clear();
  for (const Tri& t : full.faces)
    if ((full.vertex(t[0]) + full.vertex(t[1]) + full.vertex(t[2])).z() / 3 < -2) bowl.faces.push_back(t);
  const Mesh ball = make_icosphere(5, 12);
  for (const double depth : {0.5, 1.0, 2.0}) {
    CAPTURE(depth);
    ContactBuilder inside, outside;
    const ContactModel in = model_at(inside, ball, bowl, pose_at({0, 0, -40 + 5 - depth}));
    const ContactModel out = model_at(outside, ball, bowl, pose_at({0, 0, -40 - 5 + depth}));
    REQUIRE(in.in_contact());
    REQUIRE(out.in_contact());
    CHECK(angle_deg(fd(in), Vec3::UnitZ()) < 0.5);    // up, into the bowl
    CHECK(angle_deg(fd(out), -Vec3::UnitZ()) < 0.5);  // down, away from it
    CHECK(std::abs(in.penetration_mm - depth) < 0.1);
    CHECK(std::abs(out.penetration_mm - depth) < 0.1);
  }
}

TEST_CASE("contact patch: a closed part beside an open one renders as it does alone; the back's pairs in any order") {
  Mesh sheet = st::test::grid(8);
  for (Vec3& v : sheet.local) v = Vec3(5 * v.x() + 100, 5 * v.y(), 0);  // well away from the box
  Mesh both = box40();
  const auto base = std::uint32_t(both.local.size());
  for (const Vec3& v : sheet.local) both.local.push_back(v - both.origin);
  for (const Tri& t : sheet.faces) both.faces.push_back({t[0] + base, t[1] + base, t[2] + base});
  ContactBuilder alone, beside;
  for (double z = 28.0; z >= 24.0; z -= 0.5) {  // the ball pressed into the box's top
    const Pose p = pose_at({1.0, 2.0, z});
    const ContactModel a = model_at(alone, ball10(), box40(), p), c = model_at(beside, ball10(), both, p);
    CAPTURE(z);
    CHECK(a.in_contact() == c.in_contact());
    CHECK(fd(a) == fd(c));
    CHECK(a.penetration_mm == c.penetration_mm);
  }
  // From under the sheet: the model of the back, whatever the pairs' order.
  const Pose under = pose_at({120.0, 20.0, -10.0 + 1.5});
  std::vector<FacePair> pairs = st::test::brute_force(ball10(), both, under);
  REQUIRE_FALSE(pairs.empty());
  ContactBuilder sorted, shuffled;
  const ContactModel m = sorted.build(ball10(), both, under, pairs);
  std::mt19937 rng(3);
  std::shuffle(pairs.begin(), pairs.end(), rng);
  const ContactModel n = shuffled.build(ball10(), both, under, pairs);
  CHECK(angle_deg(fd(m), -Vec3::UnitZ()) < 1e-6);
  CHECK(fd(m) == fd(n));
  CHECK(m.penetration_mm == n.penetration_mm);
}

TEST_CASE("contact patch: a mesh written as a soup (three corners per face) renders as the welded mesh, bit for bit") {
  // PLY and OFF are read as written, and many exporters write a corner once per face (or once per
  // side of a seam). The model walks the surface from corner to corner; before the builder joined
  // coincident corners, a ball soup pressed into a sphere soup was pushed inward (FD -z, PD < 0.7).
  using st::test::soup;
  Mesh sheet = st::test::grid(12);
  for (Vec3& v : sheet.local) v = Vec3(5 * v.x() - 30, 5 * v.y() - 30, -80);  // below the sphere
  const Mesh ball = make_icosphere(5, 8);
  Mesh object = make_icosphere(50, 24);
  const auto base = std::uint32_t(object.local.size());
  for (const Vec3& v : sheet.local) object.local.push_back(v - object.origin);
  for (const Tri& t : sheet.faces) object.faces.push_back({t[0] + base, t[1] + base, t[2] + base});
  const Mesh ball_soup = soup(ball), object_soup = soup(object);
  REQUIRE(object_soup.local.size() == 3 * object.faces.size());
  const SphereTree ball_tree = SphereTree::build(ball).value(), object_tree = SphereTree::build(object).value();
  CollideScratch scratch;
  CollideResult r;
  ContactBuilder welded, soups, probe_soup;
  int in_contact = 0, held = 0;
  auto step = [&](const Vec3& at, const Vec3& out) {
    const Pose p = pose_at(at);
    collide(ball, ball_tree, object, object_tree, p, DefaultCollideConfig(), scratch, r);
    const ContactModel a = welded.build(ball, object, p, r.pairs);
    const ContactModel b = soups.build(ball_soup, object_soup, p, r.pairs);
    const ContactModel c = probe_soup.build(ball_soup, object, p, r.pairs);
    CAPTURE(at);
    REQUIRE(finite_model(b));
    for (const ContactModel* m : {&b, &c}) {
      CHECK(fd(*m) == fd(a));
      CHECK(m->penetration_mm == a.penetration_mm);
      CHECK(m->flags == a.flags);
      CHECK(to_eigen(m->plane_point) == to_eigen(a.plane_point));
      CHECK(to_eigen(m->pressure_point) == to_eigen(a.pressure_point));
      CHECK(m->pairs == a.pairs);
      CHECK((m->deepest_probe_vertex < ball_soup.local.size()) == (a.deepest_probe_vertex < ball.local.size()));
      if (a.deepest_probe_vertex < ball.local.size() && m->deepest_probe_vertex < ball_soup.local.size())
        CHECK(ball_soup.local[m->deepest_probe_vertex] == ball.local[a.deepest_probe_vertex]);  // named in the soup's ids
    }
    if (a.in_contact()) {
      ++in_contact;
      held += (a.flags & kHeld) != 0;
      CHECK(fd(a).dot(out) > 0.9);  // and that is the right way
    }
  };
  for (double d = 0; d <= 9.5; d += 0.1) step({0.3, 0.2, 55 - d}, Vec3::UnitZ());  // pressed into the sphere
  for (double x = 0; x <= 10; x += 0.2) step({0.3 + x, 0.2, 52}, Vec3(0.3 + x, 0.2, 52).normalized());  // slid
  for (double k = 52; k <= 60; k += 0.2) step(k * Vec3(10.3, 0.2, 52).normalized(), Vec3(10.3, 0.2, 52).normalized());
  for (double z = -90; z <= -60; z += 0.2) step({0.4, -0.3, z}, -Vec3::UnitZ());  // the sheet from below, through it
  CHECK(in_contact > 200);
  CHECK(held > 20);
  CHECK(soups.bytes() > welded.bytes());  // the joined copies are counted
}

TEST_CASE(
    "contact patch: a face written twice is one (a double-sided sheet, box or fin); a wall two solids share stays") {
  // Double-sided geometry is often written as each face again the other way round; the two
  // cancelled (no force at all through such a sheet), and a face repeated the same way doubled.
  Mesh sheet = st::test::grid(12);
  for (Vec3& v : sheet.local) v = Vec3(5 * v.x() - 30, 5 * v.y() - 30, 0);
  std::mt19937 rng(9);
  auto twice = [&](const Mesh& m, int how) {  // 0: reversed after; 1: reversed first at random; 2: as a soup; 3: same way
    Mesh d = m;
    d.faces.clear();
    for (const Tri& t : m.faces) {
      const Tri back{t[0], t[2], t[1]}, again = how == 3 ? t : back;
      const bool swap = how == 1 && rng() % 2;
      d.faces.push_back(swap ? again : t);
      d.faces.push_back(swap ? t : again);
    }
    return how == 2 ? st::test::soup(d) : d;
  };
  const Mesh ball = make_icosphere(5, 12);
  const SphereTree ball_tree = SphereTree::build(ball).value();
  CollideScratch scratch;
  CollideResult r;
  auto model = [&](ContactBuilder& b, const Mesh& object, const SphereTree& tree, const Pose& p) {
    collide(ball, ball_tree, object, tree, p, DefaultCollideConfig(), scratch, r);
    return b.build(ball, object, p, r.pairs);
  };
  const SphereTree sheet_tree = SphereTree::build(sheet).value();
  for (int how = 0; how < 4; ++how) {
    const Mesh d = twice(sheet, how);
    const SphereTree tree = SphereTree::build(d).value();
    for (const double side : {+1.0, -1.0}) {
      CAPTURE(how);
      CAPTURE(side);
      ContactBuilder once, both;
      int contacts = 0, held = 0;
      auto step = [&](double c) {  // the ball's centre at height side * c: depth 5 - c past the sheet
        const Pose p = pose_at({0.3, -0.2, side * c});
        const ContactModel a = model(once, sheet, sheet_tree, p), m = model(both, d, tree, p);
        CAPTURE(c);
        REQUIRE(finite_model(m));
        CHECK(m.in_contact() == a.in_contact());
        if (!a.in_contact()) return;
        ++contacts;
        held += (m.flags & kHeld) != 0;
        CHECK(angle_deg(fd(m), side * Vec3::UnitZ()) < 1e-6);  // out of the side it came from
        CHECK(std::abs(m.penetration_mm - a.penetration_mm) < 1e-9);
      };
      for (double c = 6.0; c >= -20.0; c -= 0.2) step(c);
      for (double c = -20.0; c <= 6.0; c += 0.2) step(c);
      CHECK(contacts > 200);
      CHECK(held > 100);
    }
  }
  // A closed box written both ways round (in a random order): the box, pressed from above.
  const Mesh box = twice(box40(), 1);
  const SphereTree box_tree = SphereTree::build(box).value(), box40_tree = SphereTree::build(box40()).value();
  for (double depth : {0.5, 2.0, 4.0}) {
    CAPTURE(depth);
    ContactBuilder once, both;
    const Pose p = pose_at({1.3, -2.1, 25.0 - depth});
    const ContactModel a = model(once, box40(), box40_tree, p), m = model(both, box, box_tree, p);
    REQUIRE(m.in_contact());
    CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1e-6);
    CHECK(std::abs(m.penetration_mm - a.penetration_mm) < 1e-9);
    CHECK(std::abs(m.penetration_mm - depth) <= kDepthTol);
  }
  // Two cubes glued face to face (each closed: the wall between them written both ways, as voxels
  // and assemblies are): the wall stays inside, the top pushes straight up over it.
  Mesh glued = box40();
  for (const Vec3& v : box40().local) glued.local.push_back(v + Vec3(40, 0, 0));
  for (const Tri& t : box40().faces)
    glued.faces.push_back({t[0] + std::uint32_t(box40().local.size()), t[1] + std::uint32_t(box40().local.size()),
                           t[2] + std::uint32_t(box40().local.size())});
  const SphereTree glued_tree = SphereTree::build(glued).value();
  for (const double x : {20.0, 22.0})
    for (double depth = 0.5; depth <= 8.0; depth += 0.5) {
      CAPTURE(x);
      CAPTURE(depth);
      ContactBuilder b;
      const ContactModel m = model(b, glued, glued_tree, pose_at({x, 1.0, 25.0 - depth}));
      REQUIRE(m.in_contact());
      CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1e-6);
      CHECK(std::abs(m.penetration_mm - depth) <= kDepthTol);
    }
  // A fin written both ways standing on the box's edge (its rim partly free): a sheet, pushed
  // from either side.
  Mesh fin = box40();
  const auto f0 = std::uint32_t(fin.local.size());
  for (const Vec3& v : {Vec3(20, -20, 20), Vec3(20, 20, 20), Vec3(20, 20, 40), Vec3(20, -20, 40)})
    fin.local.push_back(v);
  for (const Tri& t : {Tri{f0, f0 + 1, f0 + 2}, Tri{f0, f0 + 2, f0 + 3}}) {
    fin.faces.push_back(t);
    fin.faces.push_back({t[0], t[2], t[1]});
  }
  const SphereTree fin_tree = SphereTree::build(fin).value();
  for (const double side : {+1.0, -1.0})
    for (double depth = 0.5; depth <= 3.0; depth += 0.5) {
      CAPTURE(side);
      CAPTURE(depth);
      ContactBuilder b;
      const ContactModel m = model(b, fin, fin_tree, pose_at({20 + side * (5 - depth), 1.0, 32.0}));
      REQUIRE(m.in_contact());
      CHECK(angle_deg(fd(m), side * Vec3::UnitX()) < 1e-6);
      CHECK(std::abs(m.penetration_mm - depth) <= kDepthTol);
    }
}

TEST_CASE("contact patch: bad input gives a finite model and a flag") {
  ContactBuilder b;
  const Pose good = pose_at({0, 0, 27});
  const std::vector<FacePair> pairs = st::test::brute_force(ball10(), box40(), good);
  REQUIRE_FALSE(pairs.empty());
  // Non-finite pose: no contact, flagged, history forgotten.
  (void)b.build(ball10(), box40(), good, pairs);
  REQUIRE(b.has_first_face());
  const ContactModel nan = b.build(ball10(), box40(), pose_at({0, 0, std::nan("")}), pairs);
  CHECK_FALSE(nan.in_contact());
  CHECK((nan.flags & kBadInput) != 0);
  CHECK(finite_model(nan));
  CHECK_FALSE(b.has_first_face());
  // A non-finite pose with pairs never seen before, then those pairs at a good pose: the faces
  // first counted in the bad round are read afresh (nothing left unfilled by it is reused), and
  // the following rounds give what a fresh builder gives.
  for (int k = 0; k < 4; ++k) {
    CAPTURE(k);
    const Pose p = pose_at({2.0 + 0.5 * k, 1.0, 27});
    const std::vector<FacePair> pk = st::test::brute_force(ball10(), box40(), p);
    if (k == 0) (void)b.build(ball10(), box40(), pose_at({0, std::nan(""), 27}), pk);
    const ContactModel after = b.build(ball10(), box40(), p, pk);
    ContactBuilder fresh;
    const ContactModel ref = fresh.build(ball10(), box40(), p, pk);
    REQUIRE(after.in_contact());
    CHECK(after.penetration_mm == doctest::Approx(ref.penetration_mm).epsilon(1e-12));
    CHECK((fd(after) - fd(ref)).norm() < 1e-12);
  }
  // Out-of-range indices are skipped and flagged; the rest still renders.
  std::vector<FacePair> bad = pairs;
  bad.push_back({999999, 0});
  bad.push_back({0, 999999});
  const ContactModel m = b.build(ball10(), box40(), good, bad);
  CHECK(m.in_contact());
  CHECK(m.skipped_pairs == 2);
  CHECK((m.flags & kBadInput) != 0);
  CHECK(finite_model(m));
  // Degenerate faces in the patch: a zero-area sliver lying in the top face.
  Mesh box = box40();
  const auto base = std::uint32_t(box.local.size());
  box.local.push_back({-15, 0, 20});  // crosses the ball's 7.1 mm circle in the top face
  box.local.push_back({0, 0, 20});
  box.local.push_back({15, 0, 20});
  box.faces.push_back({base, base + 1, base + 2});
  ContactBuilder b2;
  const std::vector<FacePair> with_sliver = st::test::brute_force(ball10(), box, good);
  const ContactModel s = b2.build(ball10(), box, good, with_sliver);
  REQUIRE(s.in_contact());
  CHECK((s.flags & kDegenerateSkipped) != 0);
  CHECK(finite_model(s));
  CHECK(angle_deg(fd(s), Vec3::UnitZ()) < 1e-6);
  CHECK(std::abs(s.penetration_mm - 3.0) <= kDepthTol);
  // Only degenerate faces colliding, no history: no direction to render.
  ContactBuilder b3;
  std::vector<FacePair> only_sliver;
  for (const FacePair& p : with_sliver)
    if (p.object == box.faces.size() - 1) only_sliver.push_back(p);
  REQUIRE_FALSE(only_sliver.empty());
  const ContactModel o = b3.build(ball10(), box, good, only_sliver);
  CHECK_FALSE(o.in_contact());
  CHECK(finite_model(o));
  // A mesh not validated: a face naming no vertex, in a soup with a face written twice (the joined
  // copy and the open parts are not made from it; the model skips the face).
  Mesh broken = st::test::soup(box40());
  broken.faces.push_back(broken.faces[0]);
  broken.faces.push_back({0, 1, 999999});
  ContactBuilder b4;
  const ContactModel k = b4.build(ball10(), broken, good, pairs);
  CHECK(finite_model(k));
}

TEST_CASE("contact patch: a hand on the elephant: finite, PD and FD consistent with the paper's contact set") {
  const Mesh& hand = *st::test::model_mesh("hand_L2.off");
  const Mesh& elephant = *st::test::model_mesh("elephant.off");
  // The hand's lowest vertex 2 mm below the elephant's highest, as in the built-in script.
  double hand_low = std::numeric_limits<double>::infinity(), top = -hand_low;
  Vec3 top_v = Vec3::Zero();
  for (std::uint32_t i = 0; i < hand.local.size(); ++i) hand_low = std::min(hand_low, hand.vertex(i).z());
  for (std::uint32_t i = 0; i < elephant.local.size(); ++i)
    if (elephant.vertex(i).z() > top) top = elephant.vertex(i).z(), top_v = elephant.vertex(i);
  Vec3 hand_tip = Vec3::Zero();
  for (std::uint32_t i = 0; i < hand.local.size(); ++i)
    if (hand.vertex(i).z() == hand_low) hand_tip = hand.vertex(i);
  ContactBuilder b;
  b.prepare(hand, elephant);
  ContactModel prev{};
  for (double s = 0; s <= 2.0; s += 0.1) {
    const Pose p = pose_at(top_v - hand_tip + Vec3(s, 0, -2.0));
    const ContactModel m = model_at(b, hand, elephant, p);
    REQUIRE(m.in_contact());
    REQUIRE(finite_model(m));
    CHECK(fd(m).z() > 0.5);  // the elephant's back faces up
    CHECK(m.penetration_mm > 0.5);
    CHECK(m.penetration_mm < 4.0);
    CHECK(depth_below_plane(m, p) == doctest::Approx(m.penetration_mm).epsilon(1e-9));
    if (prev.in_contact()) CHECK(angle_deg(fd(m), fd(prev)) < 3.0);
    prev = m;
  }
  CHECK(b.bytes() > 0);
}

namespace {
// Follows `poses` with two builders, one given each round's pairs as found, the other the same
// pairs shuffled (and one repeated): the models must be the same, bit for bit.
void check_order_free(const Mesh& probe, const Mesh& object, const std::vector<Pose>& poses, int& contact_rounds) {
  ContactBuilder a, b;
  std::mt19937 rng(7);
  for (const Pose& p : poses) {
    const std::vector<FacePair> pairs = st::test::brute_force(probe, object, p);
    std::vector<FacePair> shuffled = pairs;
    std::shuffle(shuffled.begin(), shuffled.end(), rng);
    if (!shuffled.empty()) shuffled.push_back(shuffled.front());
    const ContactModel ma = a.build(probe, object, p, pairs), mb = b.build(probe, object, p, shuffled);
    REQUIRE(ma.in_contact() == mb.in_contact());
    contact_rounds += ma.in_contact();
    CHECK(fd(ma) == fd(mb));
    CHECK(ma.penetration_mm == mb.penetration_mm);
    CHECK(to_eigen(ma.plane_point) == to_eigen(mb.plane_point));
    CHECK(to_eigen(ma.probe_point) == to_eigen(mb.probe_point));
    CHECK(ma.flags == (mb.flags & ~std::uint32_t(kBadInput)));
  }
}
}  // namespace

TEST_CASE("contact patch: the model is a function of the pair set, not of the pairs' order") {
  // A ball around the edge of a 12-face 200 mm box (faces far larger than the patch: a far vertex
  // of the first pair's face as the areas' origin inflated Σ|a| and froze FD), and the hand
  // sliding on the elephant (real rounds).
  const Mesh box = make_box({200, 200, 200});
  std::vector<Pose> around;
  for (double a = 0; a <= 90.0; a += 3) {
    const Vec3 dir(std::sin(a * kPi / 180), 0, std::cos(a * kPi / 180));
    around.push_back(pose_at(Vec3(100, 0, 100) + 8.0 * dir));
  }
  int rounds = 0;
  check_order_free(ball10(), box, around, rounds);
  CHECK(rounds == int(around.size()));
  // On the big faces FD turns without freezing and without a fallback.
  ContactBuilder b;
  ContactModel prev{};
  for (const Pose& p : around) {
    const ContactModel m = model_at(b, ball10(), box, p);
    REQUIRE(m.in_contact());
    CHECK((m.flags & (kNormalFallback | kNormalsDisagree)) == 0);
    if (prev.in_contact()) CHECK(angle_deg(fd(m), fd(prev)) < 4.0);  // 3° a step around the edge
    prev = m;
  }

  const Mesh& hand = *st::test::model_mesh("hand_L2.off");
  const Mesh& elephant = *st::test::model_mesh("elephant.off");
  double hand_low = std::numeric_limits<double>::infinity(), top = -hand_low;
  Vec3 top_v = Vec3::Zero(), hand_tip = Vec3::Zero();
  for (std::uint32_t i = 0; i < hand.local.size(); ++i)
    if (hand.vertex(i).z() < hand_low) hand_low = hand.vertex(i).z(), hand_tip = hand.vertex(i);
  for (std::uint32_t i = 0; i < elephant.local.size(); ++i)
    if (elephant.vertex(i).z() > top) top = elephant.vertex(i).z(), top_v = elephant.vertex(i);
  std::vector<Pose> slide;
  for (double s = 0; s <= 3.0; s += 0.25) slide.push_back(pose_at(top_v - hand_tip + Vec3(s, 0.3 * s, -3.0)));
  rounds = 0;
  check_order_free(hand, elephant, slide, rounds);
  CHECK(rounds == int(slide.size()));
}

TEST_CASE("contact patch: held under a thin plate while under the surface it entered, dropped once clear") {
  // A 100 mm plate of 12 faces (top at z = +0.5): the ball pushed through, slid 30 mm sideways
  // under it (far outside the entry patch's footprint), brought back up on the other side of a
  // face diagonal, and out: held all the way under the top, nothing once clear above it. The same
  // scene a thousand times smaller holds the same way, and past the plate's edge as far relative
  // to the ball (before, hold_margin_mm held it 1 mm past: 200 of its radii).
  for (const double s : {1.0, 1e-3}) {
    CAPTURE(s);
    const Mesh plate = make_box({100 * s, 100 * s, s});
    const Mesh ball = make_icosphere(5 * s, 12);
    ContactBuilder b;
    auto at = [&](double x, double z) { return model_at(b, ball, plate, pose_at({x * s, -0.2 * s, z * s})); };
    for (double z = 6; z >= -8; z -= 0.2) REQUIRE(at(0.3, z).in_contact() == (z < 5.5));
    int held = 0;
    for (double x = 0.3; x <= 30.3; x += 0.5) {
      const ContactModel m = at(x, -8);
      REQUIRE(m.in_contact());
      held += (m.flags & kHeld) != 0;
      CHECK(angle_deg(fd(m), Vec3::UnitZ()) < 1e-9);
      CHECK(std::abs(m.penetration_mm - 13.5 * s) <= kDepthTol * s);
    }
    CHECK(held == 61);
    for (double z = -8; z <= 5.0; z += 0.2) {
      const ContactModel m = at(30.3, z);
      CAPTURE(z);
      REQUIRE(m.in_contact());
      CHECK(fd(m).z() > 0.99);  // never the underside's plane
      CHECK(std::abs(m.penetration_mm - (0.5 - (z - 5)) * s) <= kDepthTol * s);
    }
    for (double z = 5.6; z <= 8; z += 0.2) CHECK_FALSE(at(30.3, z).in_contact());  // clear above: nothing held
    // Slid out past the plate's edge (x = 50): held within the margin (1 mm, a quarter of the
    // ball's radius at the small scale) of it, then dropped.
    for (double z = 6; z >= -8; z -= 0.2) (void)at(45, z);
    CHECK((at(45, -8).flags & kHeld) != 0);
    CHECK((at(50.5, -8).flags & kHeld) != 0);
    const ContactModel off = at(51.5, -8);
    CHECK_FALSE(off.in_contact());
  }
}

namespace {
// An L-shaped prism of 6 big faces a side: floor z = 10 (x in [10, 40]) and wall x = 10 (z in
// [10, 40]) meet in a concave crease along y (y in [-20, 20]).
Mesh make_crease() {
  const double xz[6][2] = {{0, 0}, {40, 0}, {40, 10}, {10, 10}, {10, 40}, {0, 40}};
  Mesh m;
  for (double y : {-20.0, 20.0}) {
    for (const auto& p : xz) m.local.push_back({p[0], y, p[1]});
    m.local.push_back({5, y, 5});  // the cap's centre (the L is star-shaped from it)
  }
  const std::uint32_t c0 = 6, c1 = 13;
  for (std::uint32_t i = 0; i < 6; ++i) {
    const std::uint32_t j = (i + 1) % 6;
    m.faces.push_back({c0, i, j});          // cap at y = -20 (normal -y)
    m.faces.push_back({c1, 7 + j, 7 + i});  // cap at y = +20
    m.faces.push_back({i, 7 + j, j});       // side quad, outward
    m.faces.push_back({i, 7 + i, 7 + j});
  }
  // Outward: the signed volume (Σ a·(b×c)/6) is positive.
  double volume = 0;
  for (const Tri& t : m.faces) volume += m.local[t[0]].dot(m.local[t[1]].cross(m.local[t[2]])) / 6;
  REQUIRE(volume == doctest::Approx(40 * 10 * 40 + 10 * 30 * 40));
  return m;
}
}  // namespace

TEST_CASE("contact patch: a concave crease: PD and FD are the smallest way out of both walls") {
  const Mesh crease = make_crease();
  REQUIRE(crease.validate());
  // The ball a mm into the wall and b mm into the floor: the way out is (a, 0, b).
  for (const auto& [a, b] : std::vector<std::pair<double, double>>{{3, 2}, {3.5, 0.5}, {0.5, 3.5}, {2, 2}}) {
    CAPTURE(a);
    CAPTURE(b);
    ContactBuilder builder;
    const ContactModel m = model_at(builder, ball10(), crease, pose_at({10 + 10 - a, 0, 10 + 10 - b}));
    REQUIRE(m.in_contact());
    CHECK((m.flags & kPlanes) != 0);
    CHECK(std::abs(m.penetration_mm - std::hypot(a, b)) < 0.02);
    CHECK(angle_deg(fd(m), Vec3(a, 0, b)) < 0.5);
    CHECK(depth_below_plane(m, pose_at({10 + 10 - a, 0, 10 + 10 - b})) == doctest::Approx(m.penetration_mm));
  }
  // On the floor alone (clear of the wall): one plane, the summed normal as before.
  ContactBuilder builder;
  const ContactModel f = model_at(builder, ball10(), crease, pose_at({30, 0, 18}));
  REQUIRE(f.in_contact());
  CHECK((f.flags & kPlanes) == 0);
  CHECK(std::abs(f.penetration_mm - 2.0) < 0.02);
  CHECK(angle_deg(fd(f), Vec3::UnitZ()) < 1e-6);
}

TEST_CASE("contact patch: PD never exceeds the exact directional depth along FD (coarse convex bodies)") {
  // A coarse ball (an icosahedron: big facets, sharp silhouette edges) pressed at random into the
  // edges and corners of a box: PD along FD must not exceed the exact directional depth, the
  // smallest t that separates the bodies moved by t·FD (bisection on the exact pairs). An edge
  // crossing below a silhouette edge of the other body lies outside it and must not count.
  const Mesh ico = make_icosphere(10, 1);
  const Mesh& box = box40();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  int checked = 0;
  for (int k = 0; k < 400; ++k) {
    Pose p = Pose::Identity();
    p.linear() = Eigen::AngleAxisd(kPi * u(rng), Vec3(u(rng), u(rng), u(rng)).normalized()).toRotationMatrix();
    p.translation() = Vec3(20 + 6 * u(rng), 20 + 6 * u(rng), 20 + 6 * u(rng));  // around the corner (20, 20, 20)
    ContactBuilder b;
    const ContactModel m = model_at(b, ico, box, p);
    if (!m.in_contact() || m.penetration_mm <= 0) continue;
    const Vec3 d = fd(m);
    auto apart = [&](double t) {
      Pose q = p;
      q.translation() += t * d;
      return st::test::brute_force(ico, box, q).empty();
    };
    double lo = 0, hi = 60;
    if (!apart(hi)) continue;  // not separable along FD within 60 mm (contained): no reference
    for (int it = 0; it < 50; ++it) (apart(0.5 * (lo + hi)) ? hi : lo) = 0.5 * (lo + hi);
    CAPTURE(k);
    CHECK(m.penetration_mm <= hi + 1e-6);
    ++checked;
  }
  CHECK(checked > 100);
}

TEST_CASE("contact patch: the pressure point is the patch's centre: flat press, end-on sphere, continuous sliding") {
  // A 20 mm box pressed 1 mm flat into the 40 mm box's top face (z = 20), away from its edges:
  // the intersection curve is the probe's 20 x 20 square at z = 20, its centroid under the probe's
  // centre, wherever the probe is and however the object is placed.
  const Mesh cube = make_box({20, 20, 20});
  for (const Vec3& offset : {Vec3(0, 0, 0), Vec3(1e5, -3e5, 2e5)}) {
    Mesh box = box40();
    box.origin += offset;
    ContactBuilder b;
    const Pose p = pose_at(offset + Vec3(3.25, -4.5, 29.0));
    const ContactModel m = model_at(b, cube, box, p);
    REQUIRE(m.in_contact());
    const Vec3 c = to_eigen(m.pressure_point);
    CHECK(c.x() == doctest::Approx(offset.x() + 3.25).epsilon(1e-12));
    CHECK(c.y() == doctest::Approx(offset.y() - 4.5).epsilon(1e-12));
    CHECK(c.z() == doctest::Approx(offset.z() + 20.0).epsilon(1e-12));
  }
  // Over the top face's edge (x = 20): the probe spans x in [5, 25]; the curve is the square's
  // part on the top face (x = 5 side, the y = ±10 sides to x = 20), the 1 mm drops down the side
  // face and the probe's bottom edge across it at z = 19. The object surface inside the probe is
  // the top face's 15 x 20 overlap (centre (12.5, 0, 20)) and the side face's 20 x 1 strip
  // (centre (20, 0, 19.5)); FD is their vector area's direction, and the pressure point is their
  // centroid seen along FD: the centres weighted by their areas along FD (up to a shift along FD,
  // which moves no torque).
  {
    ContactBuilder b;
    const ContactModel m = model_at(b, cube, box40(), pose_at(Vec3(15, 0, 29.0)));
    REQUIRE(m.in_contact());
    const Vec3 top_area(0, 0, 15 * 20), side_area(20 * 1, 0, 0);
    const Vec3 n = (top_area + side_area).normalized();
    REQUIRE(angle_deg(fd(m), n) < 1e-9);
    const double wt = top_area.dot(n), ws = side_area.dot(n);
    const Vec3 expect = (wt * Vec3(12.5, 0, 20) + ws * Vec3(20, 0, 19.5)) / (wt + ws);
    CHECK((to_eigen(m.pressure_point) - expect).cross(n).norm() < 1e-9);
  }
  // A capsule pressed end-on: its cap's rings are symmetric about its axis, so the curve's
  // centroid is on the axis (the force's line of action passes through the sphere's centre).
  {
    const Mesh capsule = make_capsule(8, 30, 32);
    ContactBuilder b;
    // The capsule's tip is at z = 15 + 8 = 23 (probe frame): pressed 0.7 mm, hanging down (+z up).
    Pose p = Pose::Identity();
    p.linear() = Eigen::AngleAxisd(kPi, Vec3::UnitX()).toRotationMatrix();
    p.translation() = Vec3(2.5, -1.0, 20.0 + 23.0 - 0.7);
    const ContactModel m = model_at(b, capsule, box40(), p);
    REQUIRE(m.in_contact());
    const Vec3 c = to_eigen(m.pressure_point);
    CHECK(std::abs(c.x() - 2.5) < 1e-9);
    CHECK(std::abs(c.y() + 1.0) < 1e-9);
  }
  // Sliding the flat press across the face edge in 0.05 mm steps: the pressure point moves across
  // FD in steps of the same order (no jump as faces enter and leave the patch; along FD it sits on
  // the contact plane, which moves no torque).
  {
    ContactBuilder b;
    Vec3 last = Vec3::Zero();
    double worst = 0;
    for (int i = 0; i <= 400; ++i) {
      const double x = 0.0 + 0.05 * i;  // probe centre from x = 0 to 20: its edge crosses the face's edge
      const ContactModel m = model_at(b, cube, box40(), pose_at(Vec3(x, 0, 29.0)));
      REQUIRE(m.in_contact());
      const Vec3 c = to_eigen(m.pressure_point);
      if (i > 0) worst = std::max(worst, (c - last).cross(fd(m)).norm());
      last = c;
    }
    CHECK(worst < 0.1);  // two steps' worth at most (the overlap's centre moves at half the speed)
  }
}
