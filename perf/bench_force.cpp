// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench force: force rendering quality, replayed in simulated time (deterministic: no
// sleeping, no wall clock except the cost fields). For each scene, contact model and loop:
//  * the servo's own code (rt::HapticServo: interpolator, passivity guard, saturator) ticks at
//    1 kHz against an rt::SimulatedDevice following the scene's script, open loop (the probe
//    follows the script) or closed loop (rt::VirtualUser: a spring-damper hand with mass that
//    yields to the force);
//  * the collision side runs collide() + ContactBuilder::build() at the pose of every C-th tick
//    and delivers the model C ticks later (--collision-ticks C, default 2).
// Models: "patch" = [contact] model = patch with the passivity guard (the shipped default);
// "paper" = the paper's nearest-face model (§3.6) without the guard (the pipeline before #13).
// Metrics (per scene × model × loop): per-tick force change dF and direction change over the
// slide (or every contact tick where there is no slide), direction flips > 45° within 20 ms,
// energy the commanded force put into the hand per contact cycle (Σ F_k·(x_{k+1} − x_k), the
// work of a zero-order-hold force on the moving device, mJ = N·mm), RMS of the force at >= 30 Hz
// while holding still (DFT, Parseval), depth error against the analytic depth (box, sphere),
// pop-through on the 1 mm plate, and the collision + contact cost per round.
// A separate figure times the contact models at the perf poses (~100 to ~1,500 contacts).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <sstream>

#include <spheretouch/engine/scene.hpp>
#include "bench.hpp"
#include "bench_json.hpp"
#include "bench_tables_common.hpp"
#include <spheretouch/engine/distributed.hpp>
#include "force_scenes.hpp"
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/rt/haptic_servo.hpp>
#include <spheretouch/rt/interpolator.hpp>
#include <spheretouch/rt/simulated_device.hpp>

namespace st::bench {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDirMinN = 0.05;  // directions are compared only above this force, N
constexpr double kPopDepthMm = 0.5;
/// collide() as the run engine calls it without workers: exact, pairs sorted (the order the
/// workers' merge gives, so that the contact model does not depend on the worker count).
const geom::CollideConfig kEngineCollide = [] {
  geom::CollideConfig c;
  c.sort_pairs = true;
  return c;
}();  // a force vanishing deeper than this is a pop-through, mm

/// A scene: bodies, a script of probe poses and the windows the metrics look at.
struct ForceScene {
  std::string name;
  Body probe, object;
  rt::Trajectory script;
  double slide_t0 = 0, slide_t1 = 0;                   // dF / angle window, s (empty: every contact tick)
  double still_t0 = 0, still_t1 = 0;                   // holding still, s (empty: no still figure)
  std::function<double(const geom::Vec3&)> depth_ref;  // analytic depth of the probe at a position (null: unknown)
  bool plate = false;                                  // pop-through: device below the plate's top while over it
  // Generated scenes (a ball probe, force_scenes.hpp): the truth table's rows.
  TruthFn truth;        // the ball's smallest clearing translation at a centre (null: not a generated scene)
  double ball_mm = 0;   // the ball's radius
  std::string twin;     // the same scene on the other tessellation (coarse ↔ subdivided), for the direction check
  bool crease = false;  // a concave scene: no force above law(true depth) + 0.05 N
  double keep_t0 = 0, keep_t1 = 0;     // plate: slid under the plate; the force's share of its value at keep_t0
  geom::Vec3 tcp{geom::Vec3::Zero()};  // the tool centre point torques are taken about, probe file coordinates
  // Friction scenes: the material's friction, the face's outward normal (Fn and Ft are taken
  // against it) and the hold window (a steady tangential push below μs·Fn: creep).
  rt::FrictionConfig friction;
  Eigen::Vector3d face_n{Eigen::Vector3d::UnitZ()};
  double hold_t0 = 0, hold_t1 = 0;
};

/// A body of a generated mesh, its tree built with `tree` (default: the project's).
Body generated(const std::string& label, geom::Mesh mesh, const geom::TreeConfig& tree = geom::DefaultTreeConfig()) {
  Body b;
  b.label = label;
  b.mesh = std::move(mesh);
  auto t = geom::SphereTree::build(b.mesh, tree);
  if (!t) die("force", label + ": " + t.error());
  b.tree = std::move(t).value();
  return b;
}

/// Script builder: keys of probe positions (identity orientation) at increasing times.
struct Keys {
  rt::Trajectory tr;
  double t = 0;
  void at(const geom::Vec3& p) {  // the first key
    rt::TimedPose k;
    k.t_s = t;
    k.pose.translation() = p;
    tr.keys.push_back(k);
  }
  void to(const geom::Vec3& p, double dt) {  // move to p in dt seconds
    t += dt;
    at(p);
  }
  void hold(double dt) { to(tr.keys.back().pose.translation(), dt); }
  geom::Vec3 last() const { return tr.keys.back().pose.translation(); }
};

/// Ball (r 10 mm) on a 40 mm box's top face: presses, a slide on the face, a still hold.
ForceScene box_scene(bool quick) {
  ForceScene s;
  s.name = "box";
  s.object = generated("box40", geom::make_box({40, 40, 40}));  // top face z = +20
  s.probe = generated("ball10", geom::make_icosphere(10, 16));
  const double touch = 30;  // centre height at which the ball touches the face
  Keys k;
  k.at({-10, 0, touch + 5});
  for (double d : quick ? std::vector<double>{2, 10} : std::vector<double>{0.5, 2, 5, 10}) {
    k.to({-10, 0, touch - d}, 0.3);
    k.hold(0.3);
    k.to({-10, 0, touch + 0.5}, 0.3);
  }
  k.to({-10, 0, touch - 3}, 0.3);
  k.hold(0.2);
  s.slide_t0 = k.t;
  k.to({10, 0, touch - 3}, quick ? 1.0 : 2.0);  // 10 (quick: 20) mm/s on the face
  s.slide_t1 = k.t;
  k.hold(1.0);
  s.still_t0 = k.t - 0.8;
  s.still_t1 = k.t;
  k.to({10, 0, touch + 5}, 0.3);
  k.hold(0.3);
  s.script = k.tr;
  s.depth_ref = [](const geom::Vec3& c) { return std::max(0.0, 10.0 - (c.z() - 20.0)); };
  return s;
}

/// Ball (r 10) on a ball (R 20): presses along +z, a slide along a great circle, a still hold.
ForceScene sphere_scene(bool quick) {
  ForceScene s;
  s.name = "sphere";
  s.object = generated("ball20", geom::make_icosphere(20, 16));
  s.probe = generated("ball10", geom::make_icosphere(10, 16));
  auto on = [](double dist, double deg) {
    return geom::Vec3(dist * std::sin(deg * kPi / 180), 0, dist * std::cos(deg * kPi / 180));
  };
  Keys k;
  k.at(on(35, -15));
  for (double d : quick ? std::vector<double>{2, 10} : std::vector<double>{0.5, 2, 5, 10}) {
    k.to(on(30 - d, -15), 0.3);
    k.hold(0.3);
    k.to(on(30.5, -15), 0.3);
  }
  k.to(on(27, -15), 0.3);
  k.hold(0.2);
  s.slide_t0 = k.t;
  const double arc_s = 27 * 30 * kPi / 180 / 10.0;  // 30° at 10 mm/s
  for (int deg = -14; deg <= 15; ++deg) k.to(on(27, deg), arc_s / 30 * (quick ? 0.5 : 1.0));
  s.slide_t1 = k.t;
  k.hold(1.0);
  s.still_t0 = k.t - 0.8;
  s.still_t1 = k.t;
  k.to(on(35, 15), 0.3);
  k.hold(0.3);
  s.script = k.tr;
  s.depth_ref = [](const geom::Vec3& c) { return std::max(0.0, 30.0 - c.norm()); };
  return s;
}

/// A 1 mm plate (60 × 60 mm, top at z = +0.5) crossed by a fingertip ball (r 5) at 100 mm/s.
ForceScene plate_scene() {
  ForceScene s;
  s.name = "plate";
  s.object = generated("plate1", geom::make_box({60, 60, 1}));
  s.probe = generated("ball5", geom::make_icosphere(5, 12));
  Keys k;
  k.at({0.3, -0.2, 10.5});
  k.to({0.3, -0.2, -20.0}, 0.305);  // 100 mm/s down, through the plate
  k.hold(0.2);
  k.to({0.3, -0.2, 10.5}, 0.305);  // and back up
  k.hold(0.3);
  s.script = k.tr;
  s.plate = true;
  // Depth below the side it was entered by (the top), while over the plate.
  s.depth_ref = [](const geom::Vec3& c) { return std::max(0.0, 0.5 - (c.z() - 5.0)); };
  return s;
}

/// The hand on a model-set object: the built-in approach / press 3 mm / hold 0.5 s (still) /
/// slide 20 mm in 2 s (0.01 mm per tick) / release script.
ForceScene hand_scene(const std::string& name, const std::string& probe_path, const std::string& object_path) {
  ForceScene s;
  s.name = name;
  s.probe = load_body(probe_path);
  s.object = load_body(object_path);
  s.script = press_slide_script(s.probe.mesh, s.object.mesh, 5.0);
  s.still_t0 = 1.7;  // the press ends at 1.5 s; 0.2 s to settle
  s.still_t1 = 2.0;
  s.slide_t0 = 2.0;
  s.slide_t1 = 4.0;
  // Torques about the middle of the hand's bounding box (the palm: where a grip would hold it).
  const geom::Box bb = s.probe.mesh.bounds();
  s.tcp = 0.5 * (bb.lo + bb.hi);
  return s;
}

/// The hand scene with a twist: during the slide the hand also turns 10° about the vertical
/// through its tip and back (the rotational energy needs a rotation to measure).
ForceScene hand_twist_scene(const std::string& name, const std::string& probe_path, const std::string& object_path) {
  ForceScene s = hand_scene(name, probe_path, object_path);
  const rt::Trajectory base = s.script;
  geom::Vec3 tip_local = s.probe.mesh.vertex(0);  // the hand's lowest point (the script presses it down)
  for (std::uint32_t i = 0; i < s.probe.mesh.num_vertices(); ++i)
    if (s.probe.mesh.vertex(i).z() < tip_local.z()) tip_local = s.probe.mesh.vertex(i);
  rt::Trajectory tr;
  const double end = base.duration_s();
  for (int k = 0; k <= int(end * 100); ++k) {  // a key every 10 ms: the turn follows a smooth profile
    const double t = std::min(end, k * 0.01);
    Eigen::Isometry3d pose = base.at(t);
    const double u = std::clamp((t - s.slide_t0) / (s.slide_t1 - s.slide_t0), 0.0, 1.0);
    const double angle = (10.0 * kPi / 180.0) * std::sin(kPi * u);  // 0 -> 10° -> 0 over the slide
    const geom::Vec3 tip = pose * tip_local;
    Eigen::Isometry3d turn = Eigen::Isometry3d::Identity();
    turn.linear() = Eigen::AngleAxisd(angle, geom::Vec3::UnitZ()).toRotationMatrix();
    pose = Eigen::Translation3d(tip) * turn * Eigen::Translation3d(-tip) * pose;
    tr.keys.push_back({t, pose});
  }
  s.script = std::move(tr);
  return s;
}

// ---- Generated scenes: CAD-like solids and a ball probe, against the analytic truth ----

constexpr double kBallMm = 10;  // the generated scenes' ball radius (pocket: kPocketBallMm)
constexpr int kBallFrequency = 16;

/// Moves to p at `speed` mm/s.
void go(Keys& k, const geom::Vec3& p, double speed) { k.to(p, std::max((p - k.last()).norm() / speed, 1e-3)); }

/// Leaf size of the generated solids' trees (and the workers' in the worker-count check): small,
/// so that even the 12-face box has leaves enough to deal to 4 workers.
constexpr std::uint32_t kSolidLeafFaces = 2;

/// A ball probe on a generated solid.
ForceScene ball_scene(const std::string& name, geom::Mesh solid, double r) {
  ForceScene s;
  s.name = name;
  geom::TreeConfig tc = geom::DefaultTreeConfig();
  tc.leaf_faces = kSolidLeafFaces;
  const std::string label = solid.name;
  s.object = generated(label, std::move(solid), tc);
  s.probe = generated("ball", geom::make_icosphere(r, kBallFrequency));
  s.ball_mm = r;
  return s;
}

/// A box of 100 mm, faces split × split (1: the 12-face box), placed by `place`.
geom::Mesh box100(int split, const Eigen::Isometry3d& place = Eigen::Isometry3d::Identity()) {
  CellSolid c = CellSolid::empty({-50, 50}, {-50, 50}, {-50, 50});
  c.set(0, 0, 0, true);
  return cell_mesh(c, split, place, split == 1 ? "box12" : "box_split");
}

/// The path around a box edge at a constant depth: on the top face toward the edge at (50, ·, 50),
/// around it, down the side face (box frame, y = 0).
void around_edge(Keys& k, double depth, double speed, const Eigen::Isometry3d& place) {
  const double h = kBallMm - depth;
  go(k, place * geom::Vec3(30, 0, 50 + h), speed);
  go(k, place * geom::Vec3(50, 0, 50 + h), speed);
  for (int deg = 3; deg <= 90; deg += 3) {
    const double a = deg * kPi / 180;
    go(k, place * geom::Vec3(50 + h * std::sin(a), 0, 50 + h * std::cos(a)), speed);
  }
  go(k, place * geom::Vec3(50 + h, 0, 30), speed);
}

/// Box edge: the ball 2 mm deep slides over an edge of the 12-face box (split 1) or the same box
/// subdivided 16× (split 16), from the top face to the side at 10 mm/s.
ForceScene box_edge_scene(int split) {
  const std::string tag = split == 1 ? "box12" : "box16x";
  ForceScene s = ball_scene(tag + "_edge", box100(split), kBallMm);
  s.twin = (split == 1 ? "box16x" : "box12") + std::string("_edge");
  Keys k;
  k.at({30, 0, 50 + kBallMm + 5});
  k.to({30, 0, 50 + kBallMm - 2}, 0.3);
  k.hold(0.2);
  s.slide_t0 = k.t;
  around_edge(k, 2, 10, Eigen::Isometry3d::Identity());
  s.slide_t1 = k.t;
  go(k, {50 + kBallMm + 5, 0, 30}, 50);
  k.hold(0.1);
  s.script = k.tr;
  s.truth = [](const geom::Vec3& c) {
    return box_truth({-50, -50, -50}, {50, 50, 50}, Eigen::Isometry3d::Identity(), kBallMm, c);
  };
  return s;
}

/// Box corner: the ball pressed 3 mm onto a corner along the diagonal, held 1 s, released.
ForceScene box_corner_scene(int split) {
  const std::string tag = split == 1 ? "box12" : "box16x";
  ForceScene s = ball_scene(tag + "_corner", box100(split), kBallMm);
  s.twin = (split == 1 ? "box16x" : "box12") + std::string("_corner");
  const geom::Vec3 corner(50, 50, 50), diag = geom::Vec3(1, 1, 1).normalized();
  Keys k;
  k.at(corner + (kBallMm + 5) * diag);
  k.to(corner + (kBallMm - 3) * diag, 0.5);
  k.hold(1.0);
  s.still_t0 = k.t - 0.8;
  s.still_t1 = k.t;
  k.to(corner + (kBallMm + 5) * diag, 0.5);
  k.hold(0.1);
  s.script = k.tr;
  s.truth = [](const geom::Vec3& c) {
    return box_truth({-50, -50, -50}, {50, 50, 50}, Eigen::Isometry3d::Identity(), kBallMm, c);
  };
  return s;
}

/// A 90° ridge: the box turned 45° about y so an edge is a roof's crest at z = 0; the ball, 2 mm
/// deep, slides up one face, over the crest and down the other at `speed` mm/s.
ForceScene ridge_scene(int split, double speed) {
  Eigen::Isometry3d place = Eigen::Isometry3d::Identity();
  place.translate(geom::Vec3(0, 0, -50 * std::sqrt(2.0)));
  place.rotate(Eigen::AngleAxisd(-kPi / 4, geom::Vec3::UnitY()));
  char name[64];
  std::snprintf(name, sizeof name, "ridge%s_%g", split == 1 ? "12" : "16x", speed);
  ForceScene s = ball_scene(name, box100(split, place), kBallMm);
  std::snprintf(name, sizeof name, "ridge%s_%g", split == 1 ? "16x" : "12", speed);
  s.twin = name;
  Keys k;
  const double h = kBallMm - 2;
  // Start on the face before the crest (box frame: the top face, 40 mm from the edge).
  const geom::Vec3 start = place * geom::Vec3(10, 0, 50 + h);
  k.at(start + 5 * (place.linear() * geom::Vec3::UnitZ()));
  k.to(start, 0.3);
  k.hold(0.2);
  s.slide_t0 = k.t;
  go(k, place * geom::Vec3(30, 0, 50 + h), speed);
  around_edge(k, 2, speed, place);
  s.slide_t1 = k.t;
  go(k, place * geom::Vec3(50 + h + 5, 0, 30), 50);
  k.hold(0.1);
  s.script = k.tr;
  s.truth = [place](const geom::Vec3& c) { return box_truth({-50, -50, -50}, {50, 50, 50}, place, kBallMm, c); };
  return s;
}

/// A 90° crease (an L: floor z <= 0, wall x <= 0, coarse faces): the ball 2 mm into the floor
/// slides into the wall to 3 mm, holds, slides 30 mm along the crease, leaves.
ForceScene crease_scene(int split) {
  CellSolid c = CellSolid::empty({-50, 0, 50}, {-50, 50}, {-50, 0, 50});
  c.set(0, 0, 0, true);
  c.set(1, 0, 0, true);
  c.set(0, 0, 1, true);
  ForceScene s = ball_scene(split == 1 ? "crease" : "crease16x",
                            cell_mesh(c, split, Eigen::Isometry3d::Identity(), "crease"), kBallMm);
  s.crease = true;
  Keys k;
  k.at({25, -20, kBallMm + 5});
  k.to({25, -20, kBallMm - 2}, 0.3);
  k.hold(0.2);
  s.slide_t0 = k.t;
  go(k, {kBallMm - 3, -20, kBallMm - 2}, 10);  // into the wall
  k.hold(0.3);
  go(k, {kBallMm - 3, 10, kBallMm - 2}, 10);  // along the crease
  s.slide_t1 = k.t;
  go(k, {25, 10, kBallMm + 5}, 50);
  k.hold(0.1);
  s.script = k.tr;
  const std::vector<Wall> walls{{geom::Vec3::UnitZ(), 0}, {geom::Vec3::UnitX(), 0}};
  s.truth = [walls](const geom::Vec3& x) { return cavity_truth(walls, kBallMm, x); };
  return s;
}

/// Circles the last key's position in the plane ⊥ (1, 1, 1), radius r_mm, once in `seconds`:
/// in a three-face corner each wall's depth swings by ±0.82·r_mm (asymmetric contacts).
void circle_corner(Keys& k, double r_mm, double seconds) {
  const geom::Vec3 c = k.last(), u = geom::Vec3(1, -1, 0).normalized(), v = geom::Vec3(1, 1, -2).normalized();
  go(k, c + r_mm * u, 10);
  for (int deg = 5; deg <= 360; deg += 5) {
    const double a = deg * kPi / 180;
    k.to(c + r_mm * (std::cos(a) * u + std::sin(a) * v), seconds / 72);
  }
  go(k, c, 10);
}

/// An inner corner (a cube of 100 mm with one octant taken out: three faces of 50 mm meet at the
/// origin): the ball pressed 2 mm into each, held 1.5 s, circled (each wall 0.4 to 3.6 mm deep),
/// released.
ForceScene inner_corner_scene() {
  CellSolid c = CellSolid::empty({-50, 0, 50}, {-50, 0, 50}, {-50, 0, 50});
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j)
      for (int l = 0; l < 2; ++l) c.set(i, j, l, !(i == 1 && j == 1 && l == 1));
  ForceScene s = ball_scene("inner_corner", cell_mesh(c, 1, Eigen::Isometry3d::Identity(), "inner_corner"), kBallMm);
  s.crease = true;
  Keys k;
  const double out = kBallMm + 5, in = kBallMm - 2;
  k.at({out, out, out});
  k.to({in, in, in}, 0.5);
  k.hold(1.5);
  s.still_t0 = k.t - 1.0;
  s.still_t1 = k.t;
  circle_corner(k, 2.0, 2.0);
  k.to({out, out, out}, 0.5);
  k.hold(0.1);
  s.script = k.tr;
  const std::vector<Wall> walls{{geom::Vec3::UnitX(), 0}, {geom::Vec3::UnitY(), 0}, {geom::Vec3::UnitZ(), 0}};
  s.truth = [walls](const geom::Vec3& x) { return cavity_truth(walls, kBallMm, x); };
  return s;
}

constexpr double kPocketBallMm = 6;
/// A pocket (30 × 30 mm, 15 mm deep, in a 100 mm slab, coarse faces): a 6 mm ball pressed
/// 1.5 mm into a corner (floor and two walls), held 1.5 s, released; twice, circled in the
/// corner the second time (each face 0.5 to 2.5 mm deep).
ForceScene pocket_scene() {
  CellSolid c = CellSolid::empty({-50, -15, 15, 50}, {-50, -15, 15, 50}, {-50, 0, 15});
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      c.set(i, j, 0, true);
      c.set(i, j, 1, !(i == 1 && j == 1));
    }
  ForceScene s = ball_scene("pocket", cell_mesh(c, 1, Eigen::Isometry3d::Identity(), "pocket"), kPocketBallMm);
  s.crease = true;
  const double r = kPocketBallMm;
  auto at = [r](double gap) { return geom::Vec3(-15 + r + gap, -15 + r + gap, r + gap); };
  Keys k;
  k.at(at(3));
  for (int rep = 0; rep < 2; ++rep) {
    k.to(at(-1.5), 0.5);
    k.hold(1.5);
    if (rep == 0) s.still_t0 = k.t - 1.0, s.still_t1 = k.t;
    if (rep == 1) circle_corner(k, 1.2, 2.0);
    k.to(at(3), 0.5);
  }
  k.hold(0.1);
  s.script = k.tr;
  const std::vector<Wall> walls{{geom::Vec3::UnitX(), -15},
                                {geom::Vec3::UnitY(), -15},
                                {geom::Vec3::UnitZ(), 0},
                                {-geom::Vec3::UnitX(), -15},
                                {-geom::Vec3::UnitY(), -15}};
  s.truth = [walls](const geom::Vec3& x) { return cavity_truth(walls, kPocketBallMm, x); };
  return s;
}

/// A 1 mm plate (100 mm square, 12 faces, top at z = 0.5): a 5 mm ball pushed through at 50 mm/s,
/// slid 6 mm sideways under it at 10 mm/s, brought back up. The truth is a proxy's: the depth
/// below the top it entered, pointing up, until it is clear above.
ForceScene plate_through_scene() {
  CellSolid c = CellSolid::empty({-50, 50}, {-50, 50}, {-0.5, 0.5});
  c.set(0, 0, 0, true);
  ForceScene s = ball_scene("plate_through", cell_mesh(c, 1, Eigen::Isometry3d::Identity(), "plate1"), 5);
  Keys k;
  k.at({0.3, -0.2, 10});
  go(k, {0.3, -0.2, -8}, 50);  // through: the ball's top 2.5 mm under the plate
  k.hold(0.2);
  s.keep_t0 = k.t;
  go(k, {6.3, -0.2, -8}, 10);  // 6 mm sideways under the plate
  s.keep_t1 = k.t;
  k.hold(0.2);
  go(k, {6.3, -0.2, 10}, 50);  // back up, out above it
  k.hold(0.3);
  s.script = k.tr;
  s.plate = true;
  s.truth = [](const geom::Vec3& x) {
    Truth t;
    const double below = 0.5 - (x.z() - 5);  // the ball's lowest point under the top
    if (below > 0)
      t.depth_mm = below, t.normal = geom::Vec3::UnitZ();
    else
      t.clearance_mm = -below;
    return t;
  };
  return s;
}

/// A fast release: the ball pressed 3 mm into the subdivided box's top face, held, pulled straight
/// out at 300 mm/s.
ForceScene release_scene() {
  ForceScene s = ball_scene("release300", box100(16), kBallMm);
  Keys k;
  k.at({0, 0, 50 + kBallMm + 5});
  k.to({0, 0, 50 + kBallMm - 3}, 0.4);
  k.hold(0.5);
  go(k, {0, 0, 50 + kBallMm + 10}, 300);
  k.hold(0.2);
  s.script = k.tr;
  s.truth = [](const geom::Vec3& c) {
    return box_truth({-50, -50, -50}, {50, 50, 50}, Eigen::Isometry3d::Identity(), kBallMm, c);
  };
  return s;
}

/// The mesh as some files write it: "soup" (three corners of its own per face, as PLY and OFF
/// exporters often write them) or "twice" (each face again the other way round: double-sided
/// geometry). The faces keep their ids (a face written again comes right after its first), so the
/// scene renders as the mesh did.
geom::Mesh as_written(const geom::Mesh& m, const std::string& how) {
  geom::Mesh w;
  w.name = m.name + "_" + how;
  w.origin = m.origin;
  if (how == "soup") {
    for (const geom::Tri& t : m.faces) {
      const auto b = std::uint32_t(w.local.size());
      for (std::uint32_t v : t) w.local.push_back(m.local[v]);
      w.faces.push_back({b, b + 1, b + 2});
    }
  } else {
    w.local = m.local;
    for (const geom::Tri& t : m.faces) w.faces.push_back(t), w.faces.push_back({t[0], t[2], t[1]});
  }
  return w;
}

/// A cell solid as a voxel exporter writes it: every solid cell a closed cube of 12 triangles with
/// eight corners of its own, so two cells side by side both write the face between them (the
/// wall inside the solid, once each way round).
geom::Mesh voxel_mesh(const CellSolid& c, const char* name) {
  geom::Mesh m;
  m.name = name;
  for (int i = 0; i < c.cells(0); ++i)
    for (int j = 0; j < c.cells(1); ++j)
      for (int k = 0; k < c.cells(2); ++k) {
        if (!c.at(i, j, k)) continue;
        geom::Mesh cube = geom::make_box(
            {c.lines[0][i + 1] - c.lines[0][i], c.lines[1][j + 1] - c.lines[1][j], c.lines[2][k + 1] - c.lines[2][k]});
        const geom::Vec3 centre(0.5 * (c.lines[0][i] + c.lines[0][i + 1]), 0.5 * (c.lines[1][j] + c.lines[1][j + 1]),
                                0.5 * (c.lines[2][k] + c.lines[2][k + 1]));
        const auto b = std::uint32_t(m.local.size());
        for (std::uint32_t v = 0; v < cube.local.size(); ++v) m.local.push_back(cube.vertex(v) + centre);
        for (const geom::Tri& t : cube.faces) m.faces.push_back({t[0] + b, t[1] + b, t[2] + b});
      }
  return m;
}

/// A scene again with its object as some files write it (as_written, or voxels for the crease);
/// its twin is the scene as the bench writes it.
ForceScene written_scene(ForceScene s, geom::Mesh written) {
  s.twin = s.name;
  s.name += "_" + written.name.substr(written.name.rfind('_') + 1);
  geom::TreeConfig tc = geom::DefaultTreeConfig();
  tc.leaf_faces = kSolidLeafFaces;
  const std::string label = written.name;
  s.object = generated(label, std::move(written), tc);
  return s;
}

/// The generated scenes a name stands for ("meshes" = all of them).
constexpr double kFrictionMuS = 0.6, kFrictionMuD = 0.4;  // the friction scenes' material
constexpr double kFrictionFnN = 1.1;                      // their normal force in open loop, N

/// The depth at which the default force law gives f_N, mm (bisection; the law is monotone).
double depth_for_force(double f_N) {
  const rt::ForceLaw law;
  double lo = 0, hi = 100;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (law.magnitude_N(mid) < f_N ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

/// A ball (r 10) on the 40 mm box's top face (z = 20) with μs 0.6, μd 0.4, the stick spring the
/// law's steepest slope; the script starts pressed to 1.1 N (open loop) at (x0, 0).
ForceScene friction_scene(const std::string& name, Keys& k, double x0) {
  ForceScene s;
  s.name = name;
  s.object = generated("box40", geom::make_box({40, 40, 40}));
  s.probe = generated("ball10", geom::make_icosphere(10, 16));
  s.friction.static_mu = kFrictionMuS;
  s.friction.dynamic_mu = kFrictionMuD;
  const double z = 30 - depth_for_force(kFrictionFnN);
  k.at({x0, 0, 33});
  k.to({x0, 0, z}, 0.3);
  k.hold(0.3);
  s.depth_ref = [](const geom::Vec3& c) { return std::max(0.0, 10.0 - (c.z() - 20.0)); };
  return s;
}

/// Lifts the ball off the face and ends the script.
void friction_end(ForceScene& s, Keys& k) {
  k.hold(0.2);
  k.to({k.last().x(), 0, 33}, 0.3);
  k.hold(0.2);
  s.script = k.tr;
}

/// Slide 10 mm at `speed` mm/s, stop 0.5 s (stuck: buzz), slide back: a closed slide.
ForceScene friction_slide_scene(double speed) {
  Keys k;
  ForceScene s = friction_scene("friction_slide" + std::to_string(int(speed)), k, -10);
  s.slide_t0 = k.t;
  k.to({0, 0, k.last().z()}, 10 / speed);
  k.hold(0.5);
  s.still_t0 = k.t - 0.4;
  s.still_t1 = k.t;
  k.to({-10, 0, k.last().z()}, 10 / speed);
  s.slide_t1 = k.t;
  friction_end(s, k);
  return s;
}

/// Stop and go at 10 mm/s: 5 mm, stop, 5 mm, stop, back 10 mm.
ForceScene friction_stopgo_scene() {
  Keys k;
  ForceScene s = friction_scene("friction_stopgo", k, -10);
  const double z = k.last().z();
  s.slide_t0 = k.t;
  k.to({-5, 0, z}, 0.5);
  k.hold(0.5);
  s.still_t0 = k.t - 0.4;
  s.still_t1 = k.t;
  k.to({0, 0, z}, 0.5);
  k.hold(0.5);
  k.to({-10, 0, z}, 1.0);
  s.slide_t1 = k.t;
  friction_end(s, k);
  return s;
}

/// A steady tangential push of half μs·Fn (open loop: the stick spring stretched to it) held for
/// 1 s, then a ramp at 1 mm/s past the break-away.
ForceScene friction_hold_scene() {
  Keys k;
  ForceScene s = friction_scene("friction_hold", k, 0);
  const double z = k.last().z();
  const double stretch = 0.5 * kFrictionMuS * kFrictionFnN / rt::ForceLaw{}.max_stiffness_N_per_mm();
  k.to({stretch, 0, z}, 0.1);
  s.hold_t0 = k.t;
  k.hold(1.0);
  s.hold_t1 = k.t;
  s.still_t0 = s.hold_t0 + 0.2;
  s.still_t1 = s.hold_t1;
  s.slide_t0 = k.t;
  k.to({stretch + 3, 0, z}, 3.0);
  s.slide_t1 = k.t;
  friction_end(s, k);
  return s;
}

std::vector<ForceScene> generated_scenes(const std::string& n) {
  std::vector<ForceScene> out;
  const bool all = n == "meshes";
  if (all || n == "box_edge") out.push_back(box_edge_scene(1)), out.push_back(box_edge_scene(16));
  if (all || n == "box_corner") out.push_back(box_corner_scene(1)), out.push_back(box_corner_scene(16));
  if (all || n == "ridge")
    for (double v : {10.0, 300.0}) out.push_back(ridge_scene(1, v)), out.push_back(ridge_scene(16, v));
  if (all || n == "crease") out.push_back(crease_scene(1));
  if (all || n == "inner_corner") out.push_back(inner_corner_scene());
  if (all || n == "pocket") out.push_back(pocket_scene());
  if (all || n == "plate_through") out.push_back(plate_through_scene());
  if (all || n == "release") out.push_back(release_scene());
  if (all || n == "written") {  // the same solids as files write them
    out.push_back(written_scene(box_edge_scene(1), as_written(box100(1), "soup")));
    out.push_back(written_scene(box_edge_scene(16), as_written(box100(16), "twice")));
    CellSolid c = CellSolid::empty({-50, 0, 50}, {-50, 50}, {-50, 0, 50});  // crease_scene's L
    c.set(0, 0, 0, true);
    c.set(1, 0, 0, true);
    c.set(0, 0, 1, true);
    out.push_back(written_scene(crease_scene(1), voxel_mesh(c, "crease_voxels")));
  }
  return out;
}

struct Model {
  std::string name;
  geom::ContactConfig contact;
  rt::PassivityConfig passivity;
};

struct Tick {
  Eigen::Vector3d x, f;
  double pd = 0;
  Eigen::Vector3d tau{Eigen::Vector3d::Zero()};     ///< torque about the scene's tool point, N·m
  Eigen::Vector3d dtheta{Eigen::Vector3d::Zero()};  ///< the device's rotation to the next tick (axis · angle), rad
  /// Generated scenes: FD of a model built at this tick's own pose (what the geometry says now,
  /// with no latency or interpolation; zero when not in contact there).
  Eigen::Vector3d fd_now{Eigen::Vector3d::Zero()};
  bool stuck = false, sliding = false;  ///< the servo's friction state after the tick
};

/// One collision round's model, where it was computed.
struct Round {
  double t_s = 0;
  Eigen::Vector3d centre{Eigen::Vector3d::Zero()};  // the probe's origin (the ball's centre), object frame
  Eigen::Vector3d fd{Eigen::Vector3d::Zero()};
  double pd = 0;
  bool contact = false;
};

/// One replay; returns per-tick records and the per-round costs.
struct Replay {
  std::vector<Tick> ticks;
  std::vector<Round> rounds;
  std::vector<double> collide_us, contact_us, contacts;  // in-contact rounds
  /// Pair-order check: a second builder fed every round's pairs permuted (reversed, rotated by a
  /// third); the largest differences of FD (norm) and PD (mm) from the first.
  double order_fd_max = 0, order_pd_max = 0;
};

/// The replay's collision rounds: collide() in this thread (fleet null) or a scatter-gather round
/// over a fleet's workers.
Replay replay(const ForceScene& s, const Model& model, bool closed, int C, engine::Fleet* fleet = nullptr,
              bool order_check = false) {
  rt::VirtualUser user;
  user.enabled = closed;
  const int n = int(std::ceil(s.script.duration_s() * 1000.0)) + 1;
  rt::SimulatedDevice dev(s.script, user, std::size_t(n) + 1);
  auto poses = std::make_unique<rt::TripleBuffer<rt::PoseSample>>();
  auto models = std::make_unique<rt::TripleBuffer<geom::ContactSet>>();
  // Against the analytic truth the force is the contact model's: only the peak clamp, not the
  // thermal guard that pulls a sustained push down to the continuous force over seconds.
  rt::SaturationConfig sat = rt::DefaultSaturationConfig();
  if (s.truth) sat.sustained = false;
  rt::HapticServo servo(dev, *poses, *models, rt::ForceLaw{}, rt::DefaultInterpolatorConfig(), sat, nullptr,
                        model.passivity, 1e-3);
  servo.set_wrench({.dof = 3, .torque_limit_Nm = 0, .tcp_mm = s.tcp});
  servo.set_friction(s.friction);
  geom::ContactBuilder builder(model.contact), permuted(model.contact), instant(model.contact);
  geom::CollideResult r_now;
  builder.prepare(s.probe.mesh, s.object.mesh);
  std::vector<geom::ContactPair> perm;
  net::RoundResult round;
  geom::CollideScratch sc;
  geom::CollideResult r;
  Replay out;
  out.ticks.reserve(std::size_t(n));
  geom::ContactModel pending{};
  bool have_pending = false;
  std::uint64_t seq = 0;
  for (int k = 0; k < n; ++k) {
    const std::int64_t t = 1'000'000'000 + std::int64_t(k) * kTickNs;
    if (have_pending && k % C == 0) {
      models->write(geom::ContactSet::of(pending));
      have_pending = false;
    }
    rt::TickInfo info;
    info.tick = info.deadline_index = std::uint64_t(k);
    info.deadline_ns = info.woke_ns = t;
    info.period_ns = kTickNs;
    servo.tick(info);
    const rt::ForceRecord& rec = dev.records().back();
    out.ticks.push_back({rec.position, rec.force_N, servo.interpolator().state().penetration_mm});
    out.ticks.back().stuck = servo.friction().stuck();
    out.ticks.back().sliding = servo.friction().sliding();
    // The torque the servo takes (the commanded force's moment about the tool point) and the
    // script's rotation over the next tick (the user's hand turns as scripted).
    out.ticks.back().tau = 1e-3 * servo.interpolator().lever_mm().cross(rec.force_N);
    {
      const Eigen::Matrix3d r0 = s.script.at(double(k) * 1e-3).linear(), r1 = s.script.at(double(k + 1) * 1e-3).linear();
      const Eigen::AngleAxisd d(r1 * r0.transpose());
      out.ticks.back().dtheta = d.angle() * d.axis();
    }
    if (order_check) {  // a generated scene: the geometry's own FD at this tick's pose
      geom::Pose at = geom::Pose::Identity();
      at.translation() = rec.position;
      geom::collide(s.probe.mesh, s.probe.tree, s.object.mesh, s.object.tree, at, kEngineCollide, sc, r_now);
      const geom::ContactModel q = instant.build(s.probe.mesh, s.object.mesh, at, r_now.pairs);
      if (q.in_contact()) out.ticks.back().fd_now = geom::to_eigen(q.force_dir);
    }
    if (k % C == 0) {
      poses->update();
      const rt::PoseSample ps = poses->output();
      const geom::Pose pose = geom::to_eigen(ps.pose);
      const auto t0 = std::chrono::steady_clock::now();
      if (fleet) {
        fleet->client().round(seq + 1, pose, net::Clock::now() + std::chrono::seconds(10), round);
        if (!round.complete) die("force", s.name + ": a scatter-gather round came back incomplete");
        r.pairs.assign(round.pairs.begin(), round.pairs.end());
      } else {
        geom::collide(s.probe.mesh, s.probe.tree, s.object.mesh, s.object.tree, pose, kEngineCollide, sc, r);
      }
      const auto t1 = std::chrono::steady_clock::now();
      pending = builder.build(s.probe.mesh, s.object.mesh, pose, r.pairs);
      const auto t2 = std::chrono::steady_clock::now();
      if (order_check) {
        perm.assign(r.pairs.rbegin(), r.pairs.rend());
        std::rotate(perm.begin(), perm.begin() + std::ptrdiff_t(perm.size() / 3), perm.end());
        const geom::ContactModel q = permuted.build(s.probe.mesh, s.object.mesh, pose, perm);
        out.order_fd_max =
            std::max(out.order_fd_max, (geom::to_eigen(q.force_dir) - geom::to_eigen(pending.force_dir)).norm());
        out.order_pd_max = std::max(out.order_pd_max, std::abs(q.penetration_mm - pending.penetration_mm));
        if (q.in_contact() != pending.in_contact()) out.order_fd_max = std::max(out.order_fd_max, 1.0);
      }
      out.rounds.push_back({double(k) * 1e-3, pose.translation(), geom::to_eigen(pending.force_dir),
                            pending.penetration_mm, pending.in_contact()});
      pending.seq = ++seq;
      pending.pose_seq = ps.seq;
      pending.pose_sampled_ns = ps.sampled_ns;
      pending.published_ns = t;
      have_pending = true;
      if (!r.pairs.empty()) {
        out.collide_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
        out.contact_us.push_back(std::chrono::duration<double, std::micro>(t2 - t1).count());
        out.contacts.push_back(pending.contacts);
      }
    }
  }
  return out;
}

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / kPi;
}

/// RMS of the part of x (per component, linear trend removed) at >= f_lo Hz, samples at 1 kHz
/// (DFT, Parseval).
double rms_above(const std::vector<Eigen::Vector3d>& x, double f_lo) {
  const std::size_t N = x.size();
  if (N < 16) return 0;
  double power = 0;
  for (int c = 0; c < 3; ++c) {
    // Remove the least-squares line first: a slow drift (the saturator's thermal ceiling
    // settling) is not an oscillation, but a ramp's DFT leaks into every frequency.
    double st = 0, sy = 0, stt = 0, sty = 0;
    for (std::size_t i = 0; i < N; ++i) {
      const double t = double(i), y = x[i](c);
      st += t, sy += y, stt += t * t, sty += t * y;
    }
    const double den = double(N) * stt - st * st;
    const double slope = den != 0 ? (double(N) * sty - st * sy) / den : 0.0, icpt = (sy - slope * st) / double(N);
    for (std::size_t k = 1; k <= N / 2; ++k) {
      if (double(k) * 1000.0 / double(N) < f_lo) continue;
      double re = 0, im = 0;
      for (std::size_t i = 0; i < N; ++i) {
        const double ph = 2 * kPi * double(k) * double(i) / double(N);
        const double y = x[i](c) - (icpt + slope * double(i));
        re += y * std::cos(ph);
        im -= y * std::sin(ph);
      }
      power += (re * re + im * im) / (double(N) * double(N)) * (2 * k == N ? 1.0 : 2.0);
    }
  }
  return std::sqrt(power);
}

struct Figures {
  std::string scene, model, loop;
  double dF_p99 = 0, dF_max = 0, angle_p99 = 0, flips45_per_s = 0, energy_per_cycle = 0, energy_cycle_max = 0;
  double still_rms = -1, depth_err = -1, depth_err_rms = -1;
  int popthrough = -1, cycles = 0;
  double round_us_p50 = 0, collide_us_p50 = 0, contact_us_p50 = 0, contacts_p50 = 0;
  std::size_t ticks = 0, contact_ticks = 0;
  // The torque about the scene's tool point (N·m): its peak, per-tick step p99 (in the slide
  // window) and that step over the peak, per-tick direction change p99 (ticks above 5 % of the
  // peak), the rotational energy τ·dθ per contact cycle (mJ; mean and largest) with the
  // translational one added (the total, F·dx + τ·dθ), and its buzz (RMS above 30 Hz, holding still).
  double tau_peak = 0, dtau_p99 = 0, dtau_rel = 0, tau_dir_p99 = 0, rot_energy_per_cycle = 0, rot_energy_max = 0,
         total_energy_max = 0, tau_buzz = -1;
};

Figures measure(const ForceScene& s, const Replay& rp) {
  Figures fg;
  const auto& T = rp.ticks;
  fg.ticks = T.size();
  auto t_of = [](std::size_t i) { return double(i) * 1e-3; };
  const bool window = s.slide_t1 > s.slide_t0;
  for (const Tick& t : T) fg.tau_peak = std::max(fg.tau_peak, t.tau.norm());
  // Per tick (over the slide window): the force's and the torque's steps and turns.
  std::vector<double> dF, ang, dtau, tdir;
  int flips = 0;
  bool flipping = false;
  for (std::size_t i = 1; i < T.size(); ++i) {
    const bool on = T[i].f.norm() > 0 || T[i - 1].f.norm() > 0;
    if (T[i].f.norm() > 0) ++fg.contact_ticks;
    // Flips: direction against 20 ms earlier, counted once per event.
    bool flip = false;
    if (i >= 20 && T[i].f.norm() > kDirMinN && T[i - 20].f.norm() > kDirMinN)
      flip = angle_deg(T[i].f, T[i - 20].f) > 45;
    if (flip && !flipping) ++flips;
    flipping = flip;
    if (!on || (window && (t_of(i) < s.slide_t0 || t_of(i) > s.slide_t1))) continue;
    dF.push_back((T[i].f - T[i - 1].f).norm());
    if (T[i].f.norm() > kDirMinN && T[i - 1].f.norm() > kDirMinN) ang.push_back(angle_deg(T[i].f, T[i - 1].f));
    dtau.push_back((T[i].tau - T[i - 1].tau).norm());
    const double tau_min = 0.05 * fg.tau_peak;  // a turn of a torque near zero is noise
    if (T[i].tau.norm() > tau_min && T[i - 1].tau.norm() > tau_min) tdir.push_back(angle_deg(T[i].tau, T[i - 1].tau));
  }
  fg.dF_max = dF.empty() ? 0 : *std::max_element(dF.begin(), dF.end());
  fg.dF_p99 = quantile(dF, 0.99);
  fg.angle_p99 = quantile(ang, 0.99);
  fg.flips45_per_s = fg.contact_ticks ? flips / (double(fg.contact_ticks) * 1e-3) : 0;
  fg.dtau_p99 = quantile(dtau, 0.99);
  fg.dtau_rel = fg.tau_peak > 0 ? fg.dtau_p99 / fg.tau_peak : 0;
  fg.tau_dir_p99 = quantile(tdir, 0.99);
  // Energy per contact cycle (force on → off): the force's work F·dx (mJ: N·mm), the torque's
  // τ·dθ (J → mJ), and their sum.
  std::vector<double> cyc, rot, total;
  double e = 0, er = 0;
  bool on = false;
  for (std::size_t i = 0; i + 1 < T.size(); ++i) {
    const bool f_on = T[i].f.norm() > 0;
    if (f_on && !on) e = er = 0;
    if (f_on) {
      e += T[i].f.dot(T[i + 1].x - T[i].x);
      er += 1e3 * T[i].tau.dot(T[i].dtheta);
    }
    if (!f_on && on) cyc.push_back(e), rot.push_back(er), total.push_back(e + er);
    on = f_on;
  }
  if (on) cyc.push_back(e), rot.push_back(er), total.push_back(e + er);  // a cycle still open at the end
  fg.cycles = int(cyc.size());
  auto mean = [](const std::vector<double>& v) { return std::accumulate(v.begin(), v.end(), 0.0) / double(v.size()); };
  auto max = [](const std::vector<double>& v) { return *std::max_element(v.begin(), v.end()); };
  if (!cyc.empty()) {
    fg.energy_per_cycle = mean(cyc);
    fg.energy_cycle_max = max(cyc);
    fg.rot_energy_per_cycle = mean(rot);
    fg.rot_energy_max = max(rot);
    fg.total_energy_max = max(total);
  }
  if (s.still_t1 > s.still_t0) {  // holding still: what oscillates at >= 30 Hz
    std::vector<Eigen::Vector3d> f, tau;
    for (std::size_t i = std::size_t(s.still_t0 * 1000); i < std::min(T.size(), std::size_t(s.still_t1 * 1000)); ++i) {
      f.push_back(T[i].f);
      tau.push_back(T[i].tau);
    }
    fg.still_rms = rms_above(f, 30.0);
    fg.tau_buzz = rms_above(tau, 30.0);
  }
  if (s.depth_ref && !s.plate) {
    double worst = 0, sq = 0;
    std::size_t n = 0;
    for (const Tick& t : T) {
      const double ref = s.depth_ref(t.x);
      if (!(ref > 0 && ref <= 10.01) || !(t.f.norm() > 0)) continue;
      worst = std::max(worst, std::abs(t.pd - ref));
      sq += (t.pd - ref) * (t.pd - ref);
      ++n;
    }
    fg.depth_err = worst;
    fg.depth_err_rms = n ? std::sqrt(sq / double(n)) : 0;
  }
  if (s.depth_ref) {
    // Pop-through events: while the device is in (plate: below its top and over it), the force
    // starts pushing it toward the far side, or vanishes deeper than kPopDepthMm (half the plate:
    // past it a nearest-surface model pushes the probe on through). A force the passivity guard
    // takes away in the last tenths of a millimetre of a fast release is not a pop-through.
    fg.popthrough = 0;
    for (std::size_t i = 1; i < T.size(); ++i) {
      const double ref = s.depth_ref(T[i].x);
      const bool over = !s.plate || (std::abs(T[i].x.x()) < 30 && std::abs(T[i].x.y()) < 30);
      if (!over || !(ref > 0)) continue;
      const Eigen::Vector3d out = s.plate ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d(T[i].x.normalized());
      const double push_prev = s.plate ? T[i - 1].f.dot(out) : T[i - 1].f.norm();
      const double push = s.plate ? T[i].f.dot(out) : T[i].f.norm();
      const bool wrong_way = s.plate && push < -1e-9 && !(push_prev < -1e-9);
      const bool vanished = ref > kPopDepthMm && push_prev > 0 && !(push > 0);
      if (wrong_way || vanished) ++fg.popthrough;
    }
  }
  auto med = [](std::vector<double> v) { return quantile(v, 0.5); };
  std::vector<double> round;
  for (std::size_t i = 0; i < rp.collide_us.size(); ++i) round.push_back(rp.collide_us[i] + rp.contact_us[i]);
  fg.round_us_p50 = med(round);
  fg.collide_us_p50 = med(rp.collide_us);
  fg.contact_us_p50 = med(rp.contact_us);
  fg.contacts_p50 = med(rp.contacts);
  return fg;
}

/// A friction scene's figures: Fn and Ft against the face's normal, per tick.
struct FrictionFigures {
  std::string scene, loop;
  double ratio_mean = 0, ratio_p05 = 0, ratio_p95 = 0;  // Ft / (μd·Fn) on sliding ticks in the slide window
  std::size_t sliding_ticks = 0;
  double breakaway_ratio = 0;      // largest Ft / (μs·Fn) on a stuck tick before a break-away
  double cone_max = 0;             // largest Ft / (μs·Fn) on any tick with Fn > 0 (<= 1: inside the friction cone)
  int breakaways = 0, sticks = 0;  // stick -> slip, slip -> stick transitions while the probe moves on the face
  double energy_mJ = 0;            // Σ F·dx over the slide window (a closed slide: out and back)
  double stuck_buzz = -1;          // force RMS >= 30 Hz over the still window, N
  double stuck_share = 0;          // share of the still window's ticks that are stuck
  double hold_push = -1;           // hold window: mean Ft / (μs·Fn)
  double hold_creep = -1;          // hold window, after 0.2 s to settle: the probe's largest tangential move, mm
  double hold_offset = -1;         // hold window: mean tangential offset of the probe from where it stuck, mm (Ft / k)
};

FrictionFigures measure_friction(const ForceScene& s, const Replay& rp) {
  FrictionFigures ff;
  const auto& T = rp.ticks;
  const Eigen::Vector3d n = s.face_n;
  auto fn = [&](const Tick& t) { return t.f.dot(n); };
  auto ft = [&](const Tick& t) { return (t.f - t.f.dot(n) * n).norm(); };
  auto tangential = [&](const Eigen::Vector3d& v) { return Eigen::Vector3d(v - v.dot(n) * n); };
  auto in = [](std::size_t i, double t0, double t1) { return double(i) * 1e-3 >= t0 && double(i) * 1e-3 <= t1; };
  std::vector<double> ratio;
  for (std::size_t i = 1; i < T.size(); ++i) {
    if (T[i].f.dot(n) > 0) ff.cone_max = std::max(ff.cone_max, ft(T[i]) / (kFrictionMuS * fn(T[i])));
    // Transitions while the probe moves on the face (the slide window and its last 0.1 s: a lift,
    // where a falling Fn lets the contact slip and stick by turns, is not counted).
    if (!in(i, s.slide_t0, s.slide_t1 + 0.1)) continue;
    if (T[i].sliding && !T[i - 1].sliding && T[i - 1].stuck) {
      ++ff.breakaways;
      if (fn(T[i - 1]) > 0)
        ff.breakaway_ratio = std::max(ff.breakaway_ratio, ft(T[i - 1]) / (kFrictionMuS * fn(T[i - 1])));
    }
    if (T[i].stuck && T[i - 1].sliding) ++ff.sticks;
    if (!in(i, s.slide_t0, s.slide_t1)) continue;
    ff.energy_mJ += T[i - 1].f.dot(T[i].x - T[i - 1].x);
    if (T[i].sliding && fn(T[i]) > 0) ratio.push_back(ft(T[i]) / (kFrictionMuD * fn(T[i])));
  }
  ff.sliding_ticks = ratio.size();
  if (!ratio.empty()) {
    ff.ratio_mean = std::accumulate(ratio.begin(), ratio.end(), 0.0) / double(ratio.size());
    ff.ratio_p05 = quantile(ratio, 0.05);
    ff.ratio_p95 = quantile(ratio, 0.95);
  }
  if (s.still_t1 > s.still_t0) {
    std::vector<Eigen::Vector3d> f;
    std::size_t stuck = 0;
    for (std::size_t i = std::size_t(s.still_t0 * 1000); i < std::min(T.size(), std::size_t(s.still_t1 * 1000)); ++i) {
      f.push_back(T[i].f);
      stuck += T[i].stuck;
    }
    ff.stuck_buzz = rms_above(f, 30.0);
    ff.stuck_share = f.empty() ? 0 : double(stuck) / double(f.size());
  }
  if (s.hold_t1 > s.hold_t0) {
    double push = 0, offset = 0, creep = 0;
    std::size_t m = 0;
    const std::size_t i0 = std::size_t((s.hold_t0 + 0.2) * 1000), i1 = std::min(T.size(), std::size_t(s.hold_t1 * 1000));
    // Where the ball stuck: its position at the last tick before the push began to stretch the spring.
    const Eigen::Vector3d stuck_at = T[std::size_t((s.hold_t0 - 0.1) * 1000) - 1].x;
    for (std::size_t i = i0; i < i1; ++i, ++m) {
      if (fn(T[i]) > 0) push += ft(T[i]) / (kFrictionMuS * fn(T[i]));
      offset += tangential(T[i].x - stuck_at).norm();
      creep = std::max(creep, tangential(T[i].x - T[i0].x).norm());
    }
    ff.hold_push = m ? push / double(m) : 0;
    ff.hold_offset = m ? offset / double(m) : 0;
    ff.hold_creep = creep;
  }
  return ff;
}

/// A generated scene's figures against the analytic truth (force_scenes.hpp): force error, depth
/// overestimate, direction, steps, force while clear, what a thin plate keeps.
struct TruthFigures {
  double f_err_rms = 0, f_err_max = 0;          // |F − law(true depth)·n| over ticks in contact (either), N
  double over_law_max = 0;                      // max |F| − law(true depth), N
  double pd_over_max = 0;                       // max PD − true depth at the rounds' poses, mm
  double round_dir_p99 = 0, round_dir_max = 0;  // FD's change between in-contact rounds (slide window), deg
  double dir_err_p50 = 0, dir_err_p90 = 0, dir_err_max = 0;  // angle(F, true normal), deg
  double lag_p50 = 0, lag_p90 = 0;  // angle(F, FD of a model built at the tick's own pose): latency and interpolation, deg
  double step_max = 0;              // largest per-tick |ΔF|, N
  double clear01_max = 0, clear03_max = 0;      // max |F| while clear by >= 0.1 / 0.3 mm, N
  double keep_min = -1;                         // plate: min |F| / |F(keep_t0)| slid under it
  double twin_dir_p99 = -1, twin_dir_max = -1;  // direction against the other tessellation's, deg
  double order_fd = 0, order_pd = 0;            // pair-order check (Replay)
  int workers_identical = -1;                   // 1: the traces at every worker count equal 0 workers'
  std::string workers_checked;                  // the worker counts compared
};

TruthFigures measure_truth(const ForceScene& s, const Replay& rp) {
  TruthFigures tf;
  const rt::ForceLaw law;
  const auto& T = rp.ticks;
  double sq = 0;
  std::size_t n = 0;
  std::vector<double> dir_err, lag;
  for (std::size_t i = 0; i < T.size(); ++i) {
    const Truth tr = s.truth(T[i].x);
    const double fl = law.magnitude_N(tr.depth_mm);
    const double f = T[i].f.norm();
    if (i > 0) tf.step_max = std::max(tf.step_max, (T[i].f - T[i - 1].f).norm());
    if (tr.clearance_mm >= 0.1) tf.clear01_max = std::max(tf.clear01_max, f);
    if (tr.clearance_mm >= 0.3) tf.clear03_max = std::max(tf.clear03_max, f);
    if (!(tr.depth_mm > 0 || f > 0)) continue;
    const double e = (T[i].f - fl * tr.normal).norm();
    sq += e * e, ++n;
    tf.f_err_max = std::max(tf.f_err_max, e);
    tf.over_law_max = std::max(tf.over_law_max, f - fl);
    if (f > kDirMinN && tr.depth_mm > 0.05) dir_err.push_back(angle_deg(T[i].f, tr.normal));
    if (f > kDirMinN && T[i].fd_now.squaredNorm() > 0) lag.push_back(angle_deg(T[i].f, T[i].fd_now));
  }
  tf.lag_p50 = quantile(lag, 0.5);
  tf.lag_p90 = quantile(lag, 0.9);
  tf.f_err_rms = n ? std::sqrt(sq / double(n)) : 0;
  tf.dir_err_p50 = quantile(dir_err, 0.5);
  tf.dir_err_p90 = quantile(dir_err, 0.9);
  tf.dir_err_max = dir_err.empty() ? 0 : *std::max_element(dir_err.begin(), dir_err.end());
  const bool window = s.slide_t1 > s.slide_t0;
  std::vector<double> turn;
  for (std::size_t i = 0; i < rp.rounds.size(); ++i) {
    const Round& r = rp.rounds[i];
    if (!r.contact) continue;
    tf.pd_over_max = std::max(tf.pd_over_max, r.pd - s.truth(r.centre).depth_mm);
    if (i == 0 || !rp.rounds[i - 1].contact || (window && (r.t_s < s.slide_t0 || r.t_s > s.slide_t1))) continue;
    turn.push_back(angle_deg(r.fd, rp.rounds[i - 1].fd));
  }
  tf.round_dir_p99 = quantile(turn, 0.99);
  tf.round_dir_max = turn.empty() ? 0 : *std::max_element(turn.begin(), turn.end());
  if (s.keep_t1 > s.keep_t0) {
    const std::size_t i0 = std::size_t(s.keep_t0 * 1000), i1 = std::min(T.size(), std::size_t(s.keep_t1 * 1000));
    const double f0 = i0 < T.size() ? T[i0].f.norm() : 0;
    tf.keep_min = f0 > 0 ? 1e9 : 0;
    for (std::size_t i = i0; i < i1 && f0 > 0; ++i) tf.keep_min = std::min(tf.keep_min, T[i].f.norm() / f0);
  }
  tf.order_fd = rp.order_fd_max;
  tf.order_pd = rp.order_pd_max;
  return tf;
}

/// Direction of a scene's force against its twin's (the other tessellation), tick by tick over the
/// slide window where both push harder than kDirMinN.
void compare_twin(const ForceScene& s, const Replay& a, const Replay& b, TruthFigures& tf) {
  std::vector<double> d;
  const bool window = s.slide_t1 > s.slide_t0;
  for (std::size_t i = 0; i < std::min(a.ticks.size(), b.ticks.size()); ++i) {
    const double t = double(i) * 1e-3;
    if (window && (t < s.slide_t0 || t > s.slide_t1)) continue;
    if (a.ticks[i].f.norm() > kDirMinN && b.ticks[i].f.norm() > kDirMinN)
      d.push_back(angle_deg(a.ticks[i].f, b.ticks[i].f));
  }
  tf.twin_dir_p99 = quantile(d, 0.99);
  tf.twin_dir_max = d.empty() ? 0 : *std::max_element(d.begin(), d.end());
}

/// The same replay at each worker count (in-process workers, scatter-gather): 1 when every trace
/// equals `base` (0 workers) exactly, tick by tick. Counts the object's tree cannot give every
/// worker a block (a 12-face box is one leaf) are left out; `checked` lists the others.
int same_at_worker_counts(const ForceScene& s, const Model& m, int C, const Replay& base,
                          const std::vector<int>& counts, std::string& checked) {
  for (int w : counts) {
    engine::FleetSpec spec;
    spec.workers = w;
    spec.leaf_faces = kSolidLeafFaces;
    auto f = engine::start_fleet(spec, s.probe.mesh, s.object.mesh, s.object.tree);
    if (!f && f.error().find("gives " + std::to_string(w) + " workers a block each") != std::string::npos) continue;
    if (!f) die("force", s.name + ": " + f.error());
    checked += (checked.empty() ? "" : ",") + std::to_string(w);
    const Replay rp = replay(s, m, false, C, f.value().get());
    if (rp.ticks.size() != base.ticks.size()) return 0;
    for (std::size_t i = 0; i < rp.ticks.size(); ++i)
      if (rp.ticks[i].f != base.ticks[i].f || rp.ticks[i].x != base.ticks[i].x || rp.ticks[i].pd != base.ticks[i].pd) {
        std::fprintf(stderr, "force: %s with %d workers differs from 0 workers at tick %zu\n", s.name.c_str(), w, i);
        return 0;
      }
  }
  return 1;
}

void write_trace(const std::string& path, const Replay& rp, const ForceScene& s) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) die("force", path + ": cannot create");
  std::fputs("t_s,x,y,z,fx,fy,fz,f,pd_mm,depth_ref_mm\n", f);
  for (std::size_t i = 0; i < rp.ticks.size(); ++i) {
    const Tick& t = rp.ticks[i];
    std::fprintf(f, "%.3f,%.5f,%.5f,%.5f,%.6f,%.6f,%.6f,%.6f,%.5f,%.5f\n", double(i) * 1e-3, t.x.x(), t.x.y(), t.x.z(),
                 t.f.x(), t.f.y(), t.f.z(), t.f.norm(), t.pd,
                 s.depth_ref ? s.depth_ref(t.x)
                 : s.truth   ? s.truth(t.x).depth_mm
                             : std::nan(""));
  }
  if (std::fclose(f) != 0) die("force", path + ": write failed");
}

/// Contact model cost at the perf poses: cold (a fresh builder) and warm (after 100 rounds
/// sliding 0.01 mm per round into the pose), against collide() in the same loop. The warm rounds
/// repeat the pose, or with slide_mm > 0 move the probe that far along x each round, through it
/// (centred on it).
/// Analytic wrench checks: a probe pressed into a 200 mm box's top face (z = 100) at one pose,
/// the patch model built from every colliding pair, the interpolator's torque against the moment
/// the geometry gives.
struct WrenchCheck {
  std::string name;
  double torque_Nm = 0, analytic_Nm = 0, error_Nm = 0, rel_error = 0;
};
std::vector<WrenchCheck> wrench_checks() {
  const geom::Mesh plate = geom::make_box({200, 200, 200});
  auto run = [&](const std::string& name, const geom::Mesh& probe, const Eigen::Isometry3d& pose, const geom::Vec3& tcp,
                 const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& analytic) {
    geom::SphereTree pt = geom::SphereTree::build(probe).value(), ot = geom::SphereTree::build(plate).value();
    geom::CollideScratch sc;
    geom::CollideResult r;
    geom::collide(probe, pt, plate, ot, pose, kEngineCollide, sc, r);
    geom::ContactBuilder b;
    geom::ContactModel m = b.build(probe, plate, pose, r.pairs);
    if (!m.in_contact()) die("force", "wrench check " + name + ": no contact");
    m.seq = 1;
    m.pose = geom::to_pod(pose);
    rt::Interpolator in(rt::ForceLaw{}, rt::DefaultInterpolatorConfig());
    in.set_tool_point(tcp);
    in.on_model(m, 1'000'000);
    const Eigen::Vector3d f = in.force(pose, 2'000'000), want = analytic(f);
    WrenchCheck c;
    c.name = name;
    c.torque_Nm = in.torque_Nm().norm();
    c.analytic_Nm = want.norm();
    c.error_Nm = (in.torque_Nm() - want).norm();
    c.rel_error = c.analytic_Nm > 0 ? c.error_Nm / c.analytic_Nm : 0;
    return c;
  };
  std::vector<WrenchCheck> out;
  {
    // A 20 mm box pressed 1 mm flat, torques about a point on its top face 6 mm off its axis:
    // the force acts at the middle of the pressed square, τ = (−6, 0, −20) mm × F.
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Eigen::Vector3d(13, -7, 109);
    out.push_back(
        run("box_off_centre", geom::make_box({20, 20, 20}), pose, geom::Vec3(6, 0, 10),
            [](const Eigen::Vector3d& f) { return Eigen::Vector3d(1e-3 * Eigen::Vector3d(-6, 0, -20).cross(f)); }));
  }
  {
    // The same box over the face's edge (x = 100), torques about its centre: a uniform pressure on
    // the overlap x in [95, 100] of the top face acts at x = 97.5. The patch's FD also weighs the
    // 1 mm strip of the side face inside the box; the error shows that share.
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Eigen::Vector3d(105, 0, 109);
    out.push_back(
        run("box_over_edge", geom::make_box({20, 20, 20}), pose, geom::Vec3(0, 0, 0), [&](const Eigen::Vector3d& f) {
          return Eigen::Vector3d(1e-3 * (Eigen::Vector3d(97.5, 0, 100) - pose.translation()).cross(f));
        }));
  }
  {
    // A capsule's spherical end pressed end-on: about the end's centre no torque.
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = Eigen::AngleAxisd(kPi, geom::Vec3::UnitX()).toRotationMatrix();
    pose.translation() = Eigen::Vector3d(4, 2, 100 + 23 - 0.8);
    out.push_back(run("sphere_end_about_centre", geom::make_capsule(8, 30, 32), pose, geom::Vec3(0, 0, 15),
                      [](const Eigen::Vector3d&) { return Eigen::Vector3d::Zero(); }));
  }
  return out;
}

struct Cost {
  std::uint32_t contacts = 0;
  std::string model;
  double collide_us = 0;    ///< collide() median, timed in the warm loop (the rounds the contact model follows)
  double cold_us = 0;       ///< contact model, a fresh builder (no history), median
  double warm_us = 0;       ///< contact model with history, median
  double warm_mean_us = 0;  ///< and its mean (the rounds that look for new contact regions cost more)
};

std::vector<Cost> contact_cost(const Body& probe, const Body& object, const std::vector<TaggedPose>& poses,
                               const std::vector<Model>& models, int runs, double slide_mm) {
  std::vector<Cost> out;
  geom::CollideScratch sc;
  geom::CollideResult r;
  using clock = std::chrono::steady_clock;
  auto us = [](clock::time_point a, clock::time_point b) {
    return std::chrono::duration<double, std::micro>(b - a).count();
  };
  for (const TaggedPose& tp : poses) {
    for (const Model& m : models) {
      Cost c;
      c.model = m.name;
      std::vector<double> col, cold, warm;
      for (int k = 0; k < runs; ++k) {
        geom::ContactBuilder fresh(m.contact);
        fresh.prepare(probe.mesh, object.mesh);
        geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, tp.pose, kEngineCollide, sc, r);
        const auto t1 = clock::now();
        const geom::ContactModel cm = fresh.build(probe.mesh, object.mesh, tp.pose, r.pairs);
        const auto t2 = clock::now();
        cold.push_back(us(t1, t2));
        c.contacts = cm.contacts;
      }
      // Warm: the builder follows a slide onto the pose (history), each round a collide() then a
      // model, as in the collision thread; both timed here, so the share compares rounds alike
      // (collide() right after a fresh builder's set-up runs on evicted caches and looks slower).
      geom::ContactBuilder b(m.contact);
      b.prepare(probe.mesh, object.mesh);
      const double start = -0.5 * runs * slide_mm;  // the timed rounds' first offset
      for (int k = 0; k < 100 + runs; ++k) {
        geom::Pose p = tp.pose;
        p.translation().x() += start + double(k - 100) * (k < 100 ? 0.01 : slide_mm);
        const auto t0 = clock::now();
        geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, p, kEngineCollide, sc, r);
        const auto t1 = clock::now();
        (void)b.build(probe.mesh, object.mesh, p, r.pairs);
        const auto t2 = clock::now();
        if (k >= 100) {
          col.push_back(us(t0, t1));
          warm.push_back(us(t1, t2));
        }
      }
      c.collide_us = quantile(col, 0.5);
      c.cold_us = quantile(cold, 0.5);
      c.warm_us = quantile(warm, 0.5);
      c.warm_mean_us = std::accumulate(warm.begin(), warm.end(), 0.0) / double(warm.size());
      out.push_back(c);
    }
  }
  return out;
}

}  // namespace

void add_force(CLI::App& app) {
  struct Args {
    std::string scenes = "box,sphere,plate,hand_elephant,hand_armadillo,hand_elephant_twist,meshes,friction",
                models = "paper,patch", trace_dir, poses;
    std::string workers_check = "1,2,4";
    int collision_ticks = 2, cost_runs = 30;
    double cost_slide_mm = 0;
    bool json = false, quick = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "force",
      "Force rendering quality in simulated time: per scene, contact model (paper, patch) and loop (open, "
      "closed with the simulated hand): force steps, direction changes and flips, energy per contact "
      "cycle, oscillation while holding still, depth error, pop-through, cost per round");
  cmd->add_option("--scenes", a->scenes,
                  "box, sphere, plate, hand_elephant, hand_armadillo (model set); generated CAD-like solids with a "
                  "ball against the analytic truth: box_edge, box_corner, ridge, crease, inner_corner, pocket, "
                  "plate_through, release, written (box_edge and crease as files write them: a soup, each face "
                  "twice, voxels), or meshes (all of them); friction: a ball sliding on a box face with "
                  "μs 0.6, μd 0.4 at 1.1 N (2, 10, 50 mm/s, stop-and-go, a held push and a break-away ramp)")
      ->capture_default_str();
  cmd->add_option("--workers-check", a->workers_check,
                  "worker counts (in-process, scatter-gather) whose traces must equal 0 workers' on the generated "
                  "scenes (patch model, open loop); 'none' skips the check")
      ->capture_default_str();
  cmd->add_option("--models", a->models, "contact models: paper (no passivity guard), patch (the default, guarded)")
      ->capture_default_str();
  cmd->add_option("--collision-ticks", a->collision_ticks, "a collision round every C ticks, delivered C ticks later")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--trace-dir", a->trace_dir, "write force_<scene>_<model>_<loop>.csv (one line per tick) here");
  cmd->add_option("--poses", a->poses,
                  "pose file for the contact-cost figure (default perf/poses/hand_elephant.txt when present)");
  cmd->add_option("--cost-runs", a->cost_runs, "timed rounds per pose and model for the contact-cost figure")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  cmd->add_option("--cost-slide", a->cost_slide_mm,
                  "for the contact-cost figure, move the probe this many mm along x each timed round, through "
                  "each pose (0: the timed rounds repeat the pose)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd->add_flag("--quick", a->quick, "shorter scripts, fewer cost runs (CI smoke run)");
  cmd->add_flag("--json", a->json, "print one JSON object");
  cmd->callback([a] {
    std::vector<Model> models;
    std::stringstream ms(a->models);
    for (std::string m; std::getline(ms, m, ',');) {
      Model mm{m, geom::DefaultContactConfig(), rt::DefaultPassivityConfig()};
      auto kind = geom::parse_contact_model(m);
      if (!kind) die("force", "--models: " + kind.error());
      mm.contact.model = kind.value();
      mm.passivity.enabled = kind.value() == geom::ContactModelKind::patch;
      models.push_back(mm);
    }
    const std::string dir = engine::model_dir();
    std::vector<ForceScene> scenes;
    std::stringstream ss(a->scenes);
    for (std::string n; std::getline(ss, n, ',');) {
      std::fprintf(stderr, "force: loading scene %s\n", n.c_str());
      if (n == "box")
        scenes.push_back(box_scene(a->quick));
      else if (n == "sphere")
        scenes.push_back(sphere_scene(a->quick));
      else if (n == "plate")
        scenes.push_back(plate_scene());
      else if (n == "friction") {
        for (double v : {2.0, 10.0, 50.0}) scenes.push_back(friction_slide_scene(v));
        scenes.push_back(friction_stopgo_scene());
        scenes.push_back(friction_hold_scene());
      } else if (n == "hand_elephant" || n == "hand_armadillo" || n == "hand_elephant_twist") {
        const std::string obj = n == "hand_armadillo" ? "armadillo_L2.off" : "elephant.off";
        if (!std::filesystem::exists(dir + "/hand_L2.off") || !std::filesystem::exists(dir + "/" + obj)) {
          std::fprintf(stderr, "force: skipping %s: the model set is not in %s (scripts/models.sh)\n", n.c_str(),
                       dir.c_str());
          continue;
        }
        scenes.push_back(n == "hand_elephant_twist" ? hand_twist_scene(n, dir + "/hand_L2.off", dir + "/" + obj)
                                                    : hand_scene(n, dir + "/hand_L2.off", dir + "/" + obj));
      } else if (auto g = generated_scenes(n); !g.empty()) {
        for (ForceScene& x : g) scenes.push_back(std::move(x));
      } else {
        die("force",
            "--scenes: unknown scene '" + n +
                "' (box, sphere, plate, hand_elephant, hand_armadillo, hand_elephant_twist, box_edge, "
                "box_corner, ridge, crease, inner_corner, pocket, plate_through, release, written, meshes, friction)");
      }
    }
    std::vector<int> worker_counts;
    if (a->workers_check != "none") {
      for (int w : parse_int_list(a->workers_check, "--workers-check"))
        if (w < 1 || w > 64)
          die("force", "--workers-check: worker counts in 1..64, got " + std::to_string(w));
        else
          worker_counts.push_back(w);
    }
    if (!a->trace_dir.empty()) std::filesystem::create_directories(a->trace_dir);
    std::vector<Figures> all;
    struct TruthRow {
      std::size_t fig;  // its Figures in `all`
      TruthFigures tf;
      std::shared_ptr<Replay> rp;
    };
    std::vector<TruthRow> truth_rows;
    std::vector<FrictionFigures> friction_rows;
    for (const ForceScene& s : scenes)
      for (const Model& m : models)
        for (bool closed : {false, true}) {
          std::fprintf(stderr, "force: %s × %s, %s loop (%.1f s simulated)\n", s.name.c_str(), m.name.c_str(),
                       closed ? "closed" : "open", s.script.duration_s());
          auto rp = std::make_shared<Replay>(replay(s, m, closed, a->collision_ticks, nullptr, bool(s.truth)));
          Figures fg = measure(s, *rp);
          fg.scene = s.name;
          fg.model = m.name;
          fg.loop = closed ? "closed" : "open";
          all.push_back(fg);
          if (!a->trace_dir.empty())
            write_trace(a->trace_dir + "/force_" + s.name + "_" + m.name + "_" + fg.loop + ".csv", *rp, s);
          if ((s.friction.static_mu > 0 || s.friction.dynamic_mu > 0) && m.contact.model == geom::ContactModelKind::patch) {
            friction_rows.push_back(measure_friction(s, *rp));
            friction_rows.back().scene = s.name;
            friction_rows.back().loop = fg.loop;
          }
          if (!s.truth) continue;
          TruthRow row{all.size() - 1, measure_truth(s, *rp), rp};
          if (!closed && m.contact.model == geom::ContactModelKind::patch && !worker_counts.empty()) {
            std::fprintf(stderr, "force: %s × %s at %s workers\n", s.name.c_str(), m.name.c_str(),
                         a->workers_check.c_str());
            row.tf.workers_identical =
                same_at_worker_counts(s, m, a->collision_ticks, *rp, worker_counts, row.tf.workers_checked);
          }
          truth_rows.push_back(std::move(row));
        }
    // Each generated scene against its twin on the other tessellation (same model and loop).
    for (TruthRow& row : truth_rows) {
      const Figures& f = all[row.fig];
      const ForceScene* sc = nullptr;
      for (const ForceScene& s : scenes)
        if (s.name == f.scene) sc = &s;
      if (!sc || sc->twin.empty()) continue;
      for (const TruthRow& other : truth_rows)
        if (all[other.fig].scene == sc->twin && all[other.fig].model == f.model && all[other.fig].loop == f.loop)
          compare_twin(*sc, *row.rp, *other.rp, row.tf);
    }
    // Contact-model cost at the perf poses.
    std::vector<Cost> costs;
    std::string pose_file = a->poses;
    if (pose_file.empty() && std::filesystem::exists("perf/poses/hand_elephant.txt"))
      pose_file = "perf/poses/hand_elephant.txt";
    if (!pose_file.empty() && std::filesystem::exists(dir + "/hand_L2.off") &&
        std::filesystem::exists(dir + "/elephant.off")) {
      std::fprintf(stderr, "force: contact-model cost at the poses of %s\n", pose_file.c_str());
      const Body hand = load_body(dir + "/hand_L2.off"), elephant = load_body(dir + "/elephant.off");
      costs = contact_cost(hand, elephant, read_tagged_poses(pose_file), models, a->quick ? 5 : a->cost_runs,
                           a->cost_slide_mm);
    }
    auto num = [](double v) {
      char b[64];
      if (!std::isfinite(v)) return std::string("null");
      std::snprintf(b, sizeof b, "%.6g", v);
      return std::string(b);
    };
    if (a->json) {
      // Six significant digits, as the table shows them; null for a non-finite figure and for the
      // ones a scene does not have (negative).
      auto jnum = [](double v) { return std::isfinite(v) ? Json(round_sig(v, 6)) : Json(nullptr); };
      auto opt = [&](double v) { return v < 0 ? Json(nullptr) : jnum(v); };
      Json scene_rows = Json::array();
      for (const Figures& f : all)
        scene_rows.push_back({{"scene", f.scene},
                              {"model", f.model},
                              {"loop", f.loop},
                              {"dF_p99_N", jnum(f.dF_p99)},
                              {"dF_max_N", jnum(f.dF_max)},
                              {"angle_p99_deg", jnum(f.angle_p99)},
                              {"flips45_per_s", jnum(f.flips45_per_s)},
                              {"energy_per_cycle_mJ", jnum(f.energy_per_cycle)},
                              {"energy_cycle_max_mJ", jnum(f.energy_cycle_max)},
                              {"cycles", f.cycles},
                              {"still_rms_30hz_N", opt(f.still_rms)},
                              {"depth_err_mm", opt(f.depth_err)},
                              {"depth_err_rms_mm", opt(f.depth_err_rms)},
                              {"popthrough", f.popthrough < 0 ? Json(nullptr) : Json(f.popthrough)},
                              {"round_us_p50", jnum(f.round_us_p50)},
                              {"collide_us_p50", jnum(f.collide_us_p50)},
                              {"contact_us_p50", jnum(f.contact_us_p50)},
                              {"contacts_p50", jnum(f.contacts_p50)},
                              {"ticks", f.ticks},
                              {"contact_ticks", f.contact_ticks},
                              {"tau_peak_Nm", jnum(f.tau_peak)},
                              {"dtau_p99_Nm", jnum(f.dtau_p99)},
                              {"dtau_p99_over_peak", jnum(f.dtau_rel)},
                              {"tau_dir_p99_deg", jnum(f.tau_dir_p99)},
                              {"rot_energy_per_cycle_mJ", jnum(f.rot_energy_per_cycle)},
                              {"rot_energy_cycle_max_mJ", jnum(f.rot_energy_max)},
                              {"total_energy_cycle_max_mJ", jnum(f.total_energy_max)},
                              {"tau_buzz_30hz_Nm", opt(f.tau_buzz)}});
      Json truth = Json::array();
      for (const TruthRow& row : truth_rows) {
        const TruthFigures& t = row.tf;
        const Figures& f = all[row.fig];
        const Json identical = t.workers_identical < 0 ? Json(nullptr) : Json(t.workers_identical != 0);
        truth.push_back({{"scene", f.scene},
                         {"model", f.model},
                         {"loop", f.loop},
                         {"f_err_rms_N", jnum(t.f_err_rms)},
                         {"f_err_max_N", jnum(t.f_err_max)},
                         {"over_law_max_N", jnum(t.over_law_max)},
                         {"pd_over_max_mm", jnum(t.pd_over_max)},
                         {"round_dir_p99_deg", jnum(t.round_dir_p99)},
                         {"round_dir_max_deg", jnum(t.round_dir_max)},
                         {"dir_err_p50_deg", jnum(t.dir_err_p50)},
                         {"dir_err_p90_deg", jnum(t.dir_err_p90)},
                         {"dir_err_max_deg", jnum(t.dir_err_max)},
                         {"lag_p50_deg", jnum(t.lag_p50)},
                         {"lag_p90_deg", jnum(t.lag_p90)},
                         {"step_max_N", jnum(t.step_max)},
                         {"clear01_max_N", jnum(t.clear01_max)},
                         {"clear03_max_N", jnum(t.clear03_max)},
                         {"keep_min", opt(t.keep_min)},
                         {"twin_dir_p99_deg", opt(t.twin_dir_p99)},
                         {"twin_dir_max_deg", opt(t.twin_dir_max)},
                         {"order_fd", jnum(t.order_fd)},
                         {"order_pd_mm", jnum(t.order_pd)},
                         {"workers_identical", identical},
                         {"workers_checked", t.workers_checked},
                         {"energy_per_cycle_mJ", jnum(f.energy_per_cycle)},
                         {"still_rms_30hz_N", opt(f.still_rms)}});
      }
      Json cost = Json::array();
      for (const Cost& c : costs)
        cost.push_back({{"contacts", c.contacts},
                        {"model", c.model},
                        {"collide_us_p50", jnum(c.collide_us)},
                        {"contact_cold_us_p50", jnum(c.cold_us)},
                        {"contact_warm_us_p50", jnum(c.warm_us)},
                        {"contact_warm_us_mean", jnum(c.warm_mean_us)},
                        {"share_cold", jnum(c.cold_us / c.collide_us)},
                        {"share_warm", jnum(c.warm_us / c.collide_us)},
                        {"share_warm_mean", jnum(c.warm_mean_us / c.collide_us)}});
      Json wrench = Json::array();
      for (const WrenchCheck& w : wrench_checks())
        wrench.push_back({{"case", w.name},
                          {"torque_Nm", jnum(w.torque_Nm)},
                          {"analytic_Nm", jnum(w.analytic_Nm)},
                          {"error_Nm", jnum(w.error_Nm)},
                          {"rel_error", jnum(w.rel_error)}});
      Json friction = Json::array();
      for (const FrictionFigures& f : friction_rows)
        friction.push_back({{"scene", f.scene},
                            {"loop", f.loop},
                            {"static_mu", kFrictionMuS},
                            {"dynamic_mu", kFrictionMuD},
                            {"ratio_mean", jnum(f.ratio_mean)},
                            {"ratio_p05", jnum(f.ratio_p05)},
                            {"ratio_p95", jnum(f.ratio_p95)},
                            {"sliding_ticks", f.sliding_ticks},
                            {"breakaway_ratio", jnum(f.breakaway_ratio)},
                            {"cone_max", jnum(f.cone_max)},
                            {"breakaways", f.breakaways},
                            {"sticks", f.sticks},
                            {"energy_closed_slide_mJ", jnum(f.energy_mJ)},
                            {"stuck_buzz_30hz_N", opt(f.stuck_buzz)},
                            {"stuck_share", jnum(f.stuck_share)},
                            {"hold_push_over_static", opt(f.hold_push)},
                            {"hold_creep_mm", opt(f.hold_creep)},
                            {"hold_offset_mm", opt(f.hold_offset)}});
      print_json({{"collision_ticks", a->collision_ticks},
                  {"quick", a->quick},
                  {"wrench_checks", std::move(wrench)},
                  {"friction", std::move(friction)},
                  {"scenes", std::move(scene_rows)},
                  {"truth", std::move(truth)},
                  {"contact_cost_slide_mm", jnum(a->cost_slide_mm)},
                  {"contact_cost", std::move(cost)}});
      return;
    }
    std::printf("force rendering in simulated time, a collision round every %d ticks (delivered %d ticks later)\n",
                a->collision_ticks, a->collision_ticks);
    std::printf("%-15s %-6s %-6s %9s %9s %9s %8s %10s %10s %9s %9s %5s %9s %9s\n", "scene", "model", "loop", "dF_p99_N",
                "dF_max_N", "angle_p99", "flips/s", "E/cycle_mJ", "E_max_mJ", "still_N", "depth_err", "pop", "round_us",
                "contact_us");
    for (const Figures& f : all)
      std::printf("%-15s %-6s %-6s %9.4f %9.4f %9.3f %8.2f %10.4f %10.4f %9s %9s %5s %9.1f %9.1f\n", f.scene.c_str(),
                  f.model.c_str(), f.loop.c_str(), f.dF_p99, f.dF_max, f.angle_p99, f.flips45_per_s, f.energy_per_cycle,
                  f.energy_cycle_max, f.still_rms < 0 ? "-" : num(f.still_rms).c_str(),
                  f.depth_err < 0 ? "-" : num(f.depth_err).c_str(),
                  f.popthrough < 0 ? "-" : std::to_string(f.popthrough).c_str(), f.round_us_p50, f.contact_us_p50);
    std::printf(
        "\ntorque about the scene's tool point (hand scenes: the hand's bounding-box centre), N·m, mJ\n"
        "%-20s %-6s %-6s %10s %10s %9s %9s %10s %10s %10s %10s\n",
        "scene", "model", "loop", "tau_peak", "dtau_p99", "dtau/peak", "dir_p99", "Erot/cyc", "Erot_max", "Etot_max",
        "buzz");
    for (const Figures& f : all)
      std::printf("%-20s %-6s %-6s %10.5f %10.6f %9.4f %9.3f %10.5f %10.5f %10.5f %10s\n", f.scene.c_str(),
                  f.model.c_str(), f.loop.c_str(), f.tau_peak, f.dtau_p99, f.dtau_rel, f.tau_dir_p99, f.rot_energy_per_cycle,
                  f.rot_energy_max, f.total_energy_max, f.tau_buzz < 0 ? "-" : num(f.tau_buzz).c_str());
    if (!friction_rows.empty()) {
      std::printf(
          "\nfriction (patch model; ball on a box face, μs %.1f, μd %.1f, 1.1 N open loop): Ft/(μd·Fn) sliding (mean, "
          "p5-p95), break-away and largest Ft/(μs·Fn), transitions while moving, F·dx over the closed slide, buzz and "
          "stuck share holding still, the held push (Ft/(μs·Fn), creep, offset)\n"
          "%-18s %-6s %7s %15s %7s %7s %9s %9s %9s %6s %8s %9s %8s\n",
          kFrictionMuS, kFrictionMuD, "scene", "loop", "ratio", "p5-p95", "break", "cone", "brk/stk", "E_mJ", "buzz_N",
          "stuck", "push", "creep_mm", "off_mm");
      for (const FrictionFigures& f : friction_rows)
        std::printf("%-18s %-6s %7.4f %7.4f-%-7.4f %7.4f %7.4f %4d/%-4d %9.4f %9s %6.2f %8s %9s %8s\n", f.scene.c_str(),
                    f.loop.c_str(), f.ratio_mean, f.ratio_p05, f.ratio_p95, f.breakaway_ratio, f.cone_max, f.breakaways,
                    f.sticks, f.energy_mJ, f.stuck_buzz < 0 ? "-" : num(f.stuck_buzz).c_str(), f.stuck_share,
                    f.hold_push < 0 ? "-" : num(f.hold_push).c_str(), f.hold_creep < 0 ? "-" : num(f.hold_creep).c_str(),
                    f.hold_offset < 0 ? "-" : num(f.hold_offset).c_str());
    }
    std::printf("\nwrench checks (patch model, one pose each): |torque| against the analytic moment, N·m\n");
    for (const WrenchCheck& w : wrench_checks())
      std::printf("  %-24s torque %.6g, analytic %.6g, error %.3g (%.2f %%)\n", w.name.c_str(), w.torque_Nm,
                  w.analytic_Nm, w.error_Nm, 100 * w.rel_error);
    if (!truth_rows.empty()) {
      std::printf(
          "\ngenerated scenes against the analytic truth (ball probe: the smallest clearing translation); N, mm, deg\n"
          "%-16s %-6s %-6s %8s %8s %8s %8s %8s %8s %8s %8s %8s %8s %8s %8s %8s %8s %7s %7s\n",
          "scene", "model", "loop", "Ferr_rms", "Ferr_max", "over_law", "PD_over", "turn_p99", "dir_p90", "lag_p90",
          "step_max", "clear.1", "clear.3", "keep", "twin_p99", "E/cycle", "buzz", "order", "workers");
      for (const TruthRow& row : truth_rows) {
        const TruthFigures& t = row.tf;
        const Figures& f = all[row.fig];
        std::printf(
            "%-16s %-6s %-6s %8.4f %8.4f %8.4f %8.3f %8.3f %8.2f %8.2f %8.4f %8.4f %8.4f %8s %8s %8.4f %8s %7s %7s\n",
            f.scene.c_str(), f.model.c_str(), f.loop.c_str(), t.f_err_rms, t.f_err_max, t.over_law_max, t.pd_over_max,
            t.round_dir_p99, t.dir_err_p90, t.lag_p90, t.step_max, t.clear01_max, t.clear03_max,
            t.keep_min < 0 ? "-" : num(t.keep_min).c_str(), t.twin_dir_p99 < 0 ? "-" : num(t.twin_dir_p99).c_str(),
            f.energy_per_cycle, f.still_rms < 0 ? "-" : num(f.still_rms).c_str(),
            t.order_fd == 0 && t.order_pd == 0 ? "same" : num(std::max(t.order_fd, t.order_pd)).c_str(),
            t.workers_identical < 0 ? "-"
            : !t.workers_identical  ? "DIFF"
                                    : ("=" + t.workers_checked).c_str());
      }
    }
    if (!costs.empty()) {
      std::printf(
          "\ncontact model cost at the perf poses (median µs, warm mean beside; share = contact / collide() of the "
          "warm rounds, which %s)\n",
          a->cost_slide_mm > 0 ? ("slide " + num(a->cost_slide_mm) + " mm a round through the pose").c_str()
                               : "repeat the pose");
      std::printf("%8s %-6s %10s %10s %10s %10s %8s %8s %8s\n", "contacts", "model", "collide", "cold", "warm",
                  "warm mean", "cold %", "warm %", "mean %");
      for (const Cost& c : costs)
        std::printf("%8u %-6s %10.1f %10.1f %10.1f %10.1f %7.0f%% %7.0f%% %7.0f%%\n", c.contacts, c.model.c_str(),
                    c.collide_us, c.cold_us, c.warm_us, c.warm_mean_us, 100 * c.cold_us / c.collide_us,
                    100 * c.warm_us / c.collide_us, 100 * c.warm_mean_us / c.collide_us);
    }
  });
}

}  // namespace st::bench
