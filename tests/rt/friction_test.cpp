// SPDX-License-Identifier: BSD-3-Clause
// Friction (rt/friction.hpp): the stick point's stick, break-away, slip at μd·Fn and re-stick,
// exact in open loop; never outside the friction cone; energy over a closed path <= 0; a new
// contact plane does not move the stick point; bad input gives no force.
#include <cmath>
#include <vector>

#include "doctest/doctest.h"
#include <spheretouch/rt/friction.hpp>

namespace {

st::rt::FrictionConfig friction_test_config() {
  st::rt::FrictionConfig c;
  c.static_mu = 0.6;
  c.dynamic_mu = 0.4;
  c.stiffness_N_per_mm = 1.0;
  return c;
}

}  // namespace

TEST_CASE("friction: bad settings are refused naming the field") {
  st::rt::FrictionConfig c = friction_test_config();
  CHECK(st::rt::check(c).empty());
  c.dynamic_mu = 0.7;
  CHECK(st::rt::check(c).find("dynamic_friction: must not exceed static_friction") == 0);
  c = friction_test_config();
  c.static_mu = -1;
  CHECK(st::rt::check(c).find("static_friction") == 0);
  c = friction_test_config();
  c.stiffness_N_per_mm = NAN;
  CHECK(st::rt::check(c).find("friction_stiffness_n_per_mm") == 0);
  CHECK_FALSE(st::rt::Friction(st::rt::FrictionConfig{}, 1.0, 1e-3).enabled());
}

TEST_CASE("friction: stick, break-away at μs·Fn, slide at exactly μd·Fn, stick again when the tool stops") {
  const st::rt::FrictionConfig c = friction_test_config();
  st::rt::Friction fr(c, 0.5, 1e-3);
  CHECK(fr.stiffness_N_per_mm() == 1.0);
  const Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  const double fn = 1.1, dt = 1e-3, v = 10;  // N, s, mm/s
  Eigen::Vector3d p(0, 0, 0);
  double peak_stuck = 0;
  std::vector<double> sliding;
  for (int k = 0; k < 1000; ++k) {  // 1 s at 10 mm/s along x
    const Eigen::Vector3d f = fr.apply(p, n, fn, dt);
    CHECK(std::abs(f.z()) <= 1e-15);              // tangential only
    CHECK(f.norm() <= c.static_mu * fn + 1e-12);  // never outside the cone
    if (fr.stuck()) peak_stuck = std::max(peak_stuck, f.norm());
    if (fr.sliding()) sliding.push_back(-f.x());
    p.x() += v * dt;
  }
  CHECK(fr.stats().breakaways == 1);
  CHECK(peak_stuck > 0.6 * fn * 0.98);  // the spring held up to the break-away force
  REQUIRE(sliding.size() > 900);
  for (double t : sliding) CHECK(t == doctest::Approx(c.dynamic_mu * fn).epsilon(1e-9));
  // The tool stops: it sticks, and the force holds at μd·Fn with no motion.
  for (int k = 0; k < 100; ++k) {
    const Eigen::Vector3d f = fr.apply(p, n, fn, dt);
    if (k > 2) CHECK(fr.stuck());
    if (k > 50) {  // once the stick damping's filtered velocity has died out
      CHECK(-f.x() == doctest::Approx(c.dynamic_mu * fn).epsilon(1e-6));
    }
  }
  CHECK(fr.stats().sticks == 1);
  // A push below μs·Fn from there (a further 0.2 mm: k·d = 0.64 N < 0.66 N) holds it stuck.
  p.x() += 0.2;
  fr.apply(p, n, fn, dt);
  CHECK(fr.stuck());
}

TEST_CASE("friction: a closed path (out and back) takes energy, never gives it; a falling Fn slips, never pushes") {
  const st::rt::FrictionConfig c = friction_test_config();
  st::rt::Friction fr(c, 0.5, 1e-3);
  const Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d p(0, 0, 0), f = Eigen::Vector3d::Zero();
  double work = 0;  // the friction force's work on the tool, mJ (N·mm): zero-order hold
  for (int k = 0; k <= 4000; ++k) {
    const double t = k * 1e-3;
    const double x = 10 * std::sin(2 * M_PI * t / 2);          // two full strokes of ±10 mm
    const double fn = 1.1 + 0.5 * std::sin(2 * M_PI * 7 * t);  // a normal force that wobbles
    const Eigen::Vector3d next(x, 0.3 * std::sin(2 * M_PI * t), 0);
    work += f.dot(next - p);
    p = next;
    f = fr.apply(p, n, fn, 1e-3);
    CHECK(f.norm() <= c.static_mu * fn + 1e-12);
  }
  CHECK(work < 0);
  CHECK(fr.stats().breakaways >= 4);
  CHECK(fr.stats().sticks >= 4);
}

TEST_CASE(
    "friction: a new contact plane does not move the stick point; no normal force or bad input ends the contact") {
  st::rt::FrictionConfig c = friction_test_config();
  c.damping_margin = 0;  // the spring alone: the force is k·d exactly
  st::rt::Friction fr(c, 0.5, 1e-3);
  Eigen::Vector3d p(1, 2, 3);
  fr.apply(p, Eigen::Vector3d::UnitZ(), 1.0, 1e-3);
  const Eigen::Vector3d stick = fr.stick_point_mm();
  CHECK(stick == p);
  p.x() += 0.1;
  const Eigen::Vector3d tilted = Eigen::Vector3d(0.1, 0, 1).normalized();
  const Eigen::Vector3d f = fr.apply(p, tilted, 1.0, 1e-3);
  CHECK(fr.stuck());
  CHECK(fr.stick_point_mm() == stick);
  CHECK(std::abs(f.dot(tilted)) < 1e-12);  // in the new plane
  CHECK(f.norm() == doctest::Approx(0.1 * tilted.z()).epsilon(1e-3));
  CHECK(fr.apply(p, Eigen::Vector3d::UnitZ(), 0.0, 1e-3).isZero());
  CHECK_FALSE(fr.stuck());
  CHECK_FALSE(fr.sliding());
  CHECK(fr.apply(Eigen::Vector3d(NAN, 0, 0), Eigen::Vector3d::UnitZ(), 1.0, 1e-3).isZero());
  CHECK(fr.apply(p, Eigen::Vector3d::Zero(), 1.0, 1e-3).isZero());
  CHECK(fr.apply(p, Eigen::Vector3d::UnitZ(), INFINITY, 1e-3).isZero());
  // Contact again: stuck at the new point.
  fr.apply(Eigen::Vector3d(5, 5, 5), Eigen::Vector3d::UnitZ(), 1.0, 1e-3);
  CHECK(fr.stick_point_mm() == Eigen::Vector3d(5, 5, 5));
}
