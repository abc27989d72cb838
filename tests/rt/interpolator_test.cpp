// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/interpolator.* and src/spheretouch/rt/saturation.*: each interpolation method on synthetic
// contact sequences against a flat wall (z < 0 is inside, FD = +z), updates stopping, bad input,
// and a randomized property: every output finite and within the saturation ceiling.
#include <spheretouch/rt/interpolator.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <random>

#include <spheretouch/collide.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/rt/constants.hpp>
#include <spheretouch/rt/saturation.hpp>
#include "rt_test_util.hpp"

using namespace st::rt;
using st::geom::ContactModel;

namespace {
constexpr std::int64_t kMs = 1'000'000;

Eigen::Isometry3d at_z(double z, double x = 0) {
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  p.translation() = Eigen::Vector3d(x, 0, z);
  return p;
}
// Model of a probe point at the probe origin, probe at height z above the wall z = 0.
ContactModel wall_model(std::uint64_t seq, double z, double x = 0) {
  ContactModel m;
  m.seq = seq;
  m.pose = st::geom::to_pod(at_z(z, x));
  if (z > 0) return m;
  m.flags = st::geom::kInContact;
  m.force_dir = {0, 0, 1};
  m.probe_point = {0, 0, 0};
  m.penetration_mm = -z;
  m.plane_point = {x, 0, 0};
  m.contact_point = {x, 0, 0};
  return m;
}
InterpolatorConfig cfg(InterpMode mode) {
  InterpolatorConfig c = DefaultInterpolatorConfig();
  c.mode = mode;
  return c;
}
}  // namespace

TEST_CASE("interpolator: no model yet means no force") {
  Interpolator in(ForceLaw{}, cfg(InterpMode::plane));
  CHECK(in.force(at_z(-5), 0).norm() == 0.0);
}

TEST_CASE("interpolator: hold keeps the model's force whatever the probe does") {
  const ForceLaw law;
  Interpolator in(law, cfg(InterpMode::hold));
  in.on_model(wall_model(1, -2.0), 0);
  for (double z : {-2.0, -5.0, 3.0}) {
    const Eigen::Vector3d f = in.force(at_z(z), kMs);
    CHECK(f.z() == doctest::Approx(law.magnitude_N(2.0)));
    CHECK(f.x() == 0.0);
  }
  in.on_model(wall_model(2, 1.0), 2 * kMs);  // contact ended
  CHECK(in.force(at_z(-2.0), 3 * kMs).norm() == 0.0);
}

TEST_CASE("interpolator: paper B = A + D, bounded, never pulling") {
  const ForceLaw law;
  InterpolatorConfig c = cfg(InterpMode::paper);
  Interpolator in(law, c);
  in.on_model(wall_model(1, -2.0), 0);
  const double a = law.magnitude_N(2.0);
  // 0.4 mm deeper: force grows by gain * 0.4.
  CHECK(in.force(at_z(-2.4), kMs).z() == doctest::Approx(a + c.paper_gain_N_per_mm * 0.4));
  // 50 mm deeper: D capped at paper_max_move_mm.
  CHECK(in.force(at_z(-52), 2 * kMs).z() == doctest::Approx(a + c.paper_gain_N_per_mm * c.paper_max_move_mm));
  // Sliding 1 mm along +x: tangential component -gain * 1 (the paper adds D as a vector).
  const Eigen::Vector3d s = in.force(at_z(-2.0, 1.0), 3 * kMs);
  CHECK(s.x() == doctest::Approx(-c.paper_gain_N_per_mm));
  CHECK(s.z() == doctest::Approx(a));
  // Pulled far out: the normal component never goes below zero.
  const Eigen::Vector3d out = in.force(at_z(40), 4 * kMs);
  CHECK(out.z() >= 0.0);
  // Extrapolation cannot grow while updates stop: bounded by A + gain * max_move for any pose.
  for (double z = -100; z < 100; z += 0.5)
    CHECK(in.force(at_z(z), 5 * kMs).norm() <= a + c.paper_gain_N_per_mm * c.paper_max_move_mm + 1e-12);
}

TEST_CASE("interpolator: plane recomputes PD every tick against the newest plane") {
  const ForceLaw law;
  InterpolatorConfig c = cfg(InterpMode::plane);
  c.crossfade_ns = 0;
  Interpolator in(law, c);
  in.on_model(wall_model(1, -1.0), 0);
  for (double z = -3; z <= 1; z += 0.25) {
    const Eigen::Vector3d f = in.force(at_z(z, 7.0), kMs);  // sliding along the plane changes nothing
    CHECK(f.z() == doctest::Approx(law.magnitude_N(-z)));
    CHECK(in.state().penetration_mm == doctest::Approx(-z));
  }
}

TEST_CASE("interpolator: plane cross-fades a new plane without a jump") {
  const ForceLaw law;
  InterpolatorConfig c = cfg(InterpMode::plane);
  c.crossfade_ns = 10 * kMs;
  Interpolator in(law, c);
  in.on_model(wall_model(1, -2.0), 0);
  // The first model fades in from zero force too (contact onset without a jolt).
  CHECK(in.force(at_z(-2.0), kMs).z() == doctest::Approx(0.1 * law.magnitude_N(2.0)));
  const double before = in.force(at_z(-2.0), 11 * kMs).z();
  CHECK(before == doctest::Approx(law.magnitude_N(2.0)));
  // New model: the wall is now 1 mm lower (plane at z = -1), probe unchanged: target PD = 1.
  ContactModel m = wall_model(2, -2.0);
  m.plane_point = {0, 0, -1};
  m.penetration_mm = 1.0;
  in.on_model(m, 12 * kMs);
  const double at_arrival = in.force(at_z(-2.0), 12 * kMs).z();
  // Continuous: the arrival tick moves one tick (1 ms of the 10 ms fade) toward the new force.
  CHECK(at_arrival == doctest::Approx(law.magnitude_N(1.0) + 0.9 * (before - law.magnitude_N(1.0))));
  const double mid = in.force(at_z(-2.0), 16 * kMs).z();  // 4 ms idle + this 4 ms step: 80 % faded
  CHECK(mid < before);
  CHECK(mid > law.magnitude_N(1.0));
  const double after = in.force(at_z(-2.0), 23 * kMs).z();
  CHECK(after == doctest::Approx(law.magnitude_N(1.0)));
}

TEST_CASE("interpolator: when updates stop, every method fades to zero") {
  for (InterpMode mode : {InterpMode::hold, InterpMode::paper, InterpMode::plane}) {
    CAPTURE(to_string(mode));
    const InterpolatorConfig c = cfg(mode);
    Interpolator in(ForceLaw{}, c);
    in.on_model(wall_model(1, -2.0), 0);
    const double full = in.force(at_z(-2.0), c.stale_timeout_ns).norm();
    CHECK(full > 0.5);
    const double half = in.force(at_z(-2.0), c.stale_timeout_ns + c.fade_ns / 2).norm();
    CHECK(half == doctest::Approx(full / 2).epsilon(1e-6));
    CHECK(in.state().fade == doctest::Approx(0.5));
    double prev = half;
    for (std::int64_t t = c.stale_timeout_ns + c.fade_ns / 2; t < c.stale_timeout_ns + 2 * c.fade_ns; t += kMs) {
      const double f = in.force(at_z(-2.0), t).norm();
      CHECK(f <= prev + 1e-12);
      prev = f;
    }
    CHECK(in.force(at_z(-2.0), c.stale_timeout_ns + c.fade_ns).norm() == 0.0);
    CHECK(in.force(at_z(-30.0), 10'000 * kMs).norm() == 0.0);
    // A new update brings the force back.
    in.on_model(wall_model(2, -2.0), 10'001 * kMs);
    CHECK(in.force(at_z(-2.0), 10'001 * kMs + c.crossfade_ns).norm() > 0.5);  // plane ramps in
  }
}

TEST_CASE("interpolator: plane resumes smoothly after a stall faded the force out") {
  const ForceLaw law;
  const InterpolatorConfig c = cfg(InterpMode::plane);
  Interpolator in(law, c);
  in.on_model(wall_model(1, -2.0), 0);
  CHECK(in.force(at_z(-2.0), 50 * kMs).norm() > 1.0);
  const std::int64_t silent = c.stale_timeout_ns + c.fade_ns + 10 * kMs;
  CHECK(in.force(at_z(-2.0), silent).norm() == 0.0);
  in.on_model(wall_model(2, -2.0), silent + kMs);
  // No jump back up: the first tick after the stall gets one tick's share (1/10) of the step.
  CHECK(in.force(at_z(-2.0), silent + kMs).norm() == doctest::Approx(0.1 * law.magnitude_N(2.0)));
  CHECK(in.force(at_z(-2.0), silent + kMs + c.crossfade_ns).norm() == doctest::Approx(law.magnitude_N(2.0)));
}

TEST_CASE("interpolator: bad models and poses give zero force, counted") {
  Interpolator in(ForceLaw{}, cfg(InterpMode::plane));
  ContactModel m = wall_model(1, -2.0);
  m.penetration_mm = std::numeric_limits<double>::quiet_NaN();
  in.on_model(m, 0);
  CHECK(in.rejected_models() == 1);
  CHECK(in.force(at_z(-2.0), 20 * kMs).norm() == 0.0);
  m = wall_model(2, -2.0);
  m.force_dir = {0, 0, 2};  // not unit
  in.on_model(m, 21 * kMs);
  CHECK(in.rejected_models() == 2);
  in.on_model(wall_model(3, -2.0), 22 * kMs);
  Eigen::Isometry3d bad = at_z(-2.0);
  bad.translation().x() = std::numeric_limits<double>::infinity();
  CHECK(in.force(bad, 40 * kMs).norm() == 0.0);
  CHECK(in.bad_poses() == 1);
  CHECK(in.force(at_z(-2.0), 41 * kMs).norm() > 0.0);
}

TEST_CASE("interpolator: damping opposes motion along FD and never pulls") {
  InterpolatorConfig c = cfg(InterpMode::plane);
  c.crossfade_ns = 0;
  c.damping_N_s_per_mm = 0.002;
  const ForceLaw law;
  Interpolator in(law, c);
  in.on_model(wall_model(1, -2.0), 0);
  double z = -2.0;
  Eigen::Vector3d f;
  for (int i = 1; i <= 50; ++i) {  // pressing in at 100 mm/s
    z -= 0.1;
    f = in.force(at_z(z), i * kMs);
  }
  CHECK(f.z() > law.magnitude_N(-z));  // damping adds while moving in
  for (int i = 51; i <= 200; ++i) {    // leaving fast: 1000 mm/s
    z += 1.0;
    f = in.force(at_z(z), i * kMs);
    CHECK(f.z() >= 0.0);
  }
}

TEST_CASE("interpolator + saturation: random sequences stay finite and within the ceiling") {
  std::mt19937_64 rng(12345);
  std::uniform_real_distribution<double> u(-1, 1);
  const double nasty[] = {0.0,
                          -0.0,
                          1e-300,
                          -1e-300,
                          1e300,
                          -1e300,
                          std::numeric_limits<double>::quiet_NaN(),
                          std::numeric_limits<double>::infinity(),
                          -std::numeric_limits<double>::infinity(),
                          std::numeric_limits<double>::denorm_min()};
  auto pick = [&](double scale) {
    const auto r = rng() % 20;
    return r < 10 ? nasty[r] : u(rng) * scale;
  };
  for (InterpMode mode : {InterpMode::hold, InterpMode::paper, InterpMode::plane}) {
    InterpolatorConfig c = cfg(mode);
    c.damping_N_s_per_mm = 0.001;
    Interpolator in(ForceLaw{}, c);
    Saturator sat(DefaultSaturationConfig());
    std::int64_t t = 0;
    for (int i = 0; i < 20000; ++i) {
      t += kMs;
      if (i % 7 == 0) {
        ContactModel m = wall_model(static_cast<std::uint64_t>(i), -std::abs(u(rng)) * 20);
        if (i % 21 == 0) m.penetration_mm = pick(1e3);
        if (i % 35 == 0) m.plane_point.z = pick(10);
        if (i % 49 == 0) m.force_dir.z = pick(2);
        in.on_model(m, t);
      }
      Eigen::Isometry3d p = at_z(u(rng) * 30, u(rng) * 10);
      if (i % 13 == 0) p.translation().z() = pick(1e6);
      const Eigen::Vector3d raw = in.force(p, t);
      REQUIRE(raw.allFinite());
      const Eigen::Vector3d out = sat.apply(raw, (i % 101 == 0) ? pick(1.0) : 1e-3);
      REQUIRE(out.allFinite());
      REQUIRE(out.norm() <= kOmniPeakForceN * (1 + 1e-12));
    }
  }
}

TEST_CASE("saturation: peak cap, sustained limit settles at the continuous force") {
  SaturationConfig c = DefaultSaturationConfig();
  Saturator sat(c);
  const Eigen::Vector3d big(0, 0, 10);
  CHECK(sat.apply(big, 1e-3).norm() == doctest::Approx(c.peak_N));
  CHECK(sat.limited());
  CHECK(sat.apply(Eigen::Vector3d(0, 0, std::nan("")), 1e-3).norm() == 0.0);
  CHECK(sat.nonfinite_inputs() == 1);
  // Push at 2 N for 60 s of 1 ms ticks: RMS and output settle at the continuous 0.88 N.
  Eigen::Vector3d out;
  for (int i = 0; i < 60000; ++i) out = sat.apply(Eigen::Vector3d(2, 0, 0), 1e-3);
  CHECK(out.norm() == doctest::Approx(c.continuous_N).epsilon(0.02));
  CHECK(sat.rms_N() <= c.continuous_N * 1.001);
  // A light touch stays below the onset and is untouched.
  Saturator s2(c);
  for (int i = 0; i < 60000; ++i) out = s2.apply(Eigen::Vector3d(0.5, 0, 0), 1e-3);
  CHECK(out.x() == 0.5);
  // Without the sustained limit only the peak applies.
  c.sustained = false;
  Saturator s3(c);
  for (int i = 0; i < 60000; ++i) out = s3.apply(Eigen::Vector3d(2, 0, 0), 1e-3);
  CHECK(out.x() == 2.0);
  c.continuous_N = 5;
  c.sustained = true;
  CHECK(Saturator::check(c).find("continuous_N") != std::string::npos);
}

TEST_CASE("interpolator: plane follows models that arrive every tick (no freeze), and releases to zero") {
  // Regression: the cross-fade restarted at full weight on every arrival, so with one model per
  // tick the output never left its old value (zero on contact, stuck on after release).
  const ForceLaw law;
  InterpolatorConfig c = cfg(InterpMode::plane);
  c.crossfade_ns = 10 * kMs;
  Interpolator in(law, c);
  std::int64_t t = 0;
  for (int k = 1; k <= 60; ++k, t += kMs) {  // 60 ms in contact at 2 mm, a model every tick
    in.on_model(wall_model(std::uint64_t(k), -2.0), t);
    in.force(at_z(-2.0), t);
  }
  CHECK(in.force(at_z(-2.0), t).z() == doctest::Approx(law.magnitude_N(2.0)).epsilon(0.01));
  for (int k = 61; k <= 120; ++k, t += kMs) {  // released: models without contact every tick
    ContactModel none{};
    none.seq = std::uint64_t(k);
    in.on_model(none, t);
    in.force(at_z(5.0), t);
  }
  CHECK(in.force(at_z(5.0), t).norm() < 0.01 * law.magnitude_N(2.0));
}

TEST_CASE("interpolator: a no-contact model ends the contact: the old plane followed out, fading, never rising") {
  const ForceLaw law;
  Interpolator in(law, cfg(InterpMode::plane));
  for (int t = 0; t <= 100; ++t) {  // the onset's fade-in has died out by 100 ms
    if (t % 2 == 0) in.on_model(wall_model(std::uint64_t(t + 1), -2.0), t * kMs);
    (void)in.force(at_z(-2.0), t * kMs);
  }
  const double held = in.force(at_z(-1.0), 101 * kMs).z();
  CHECK(held == doctest::Approx(law.magnitude_N(1.0)).epsilon(1e-4));
  // The collision side says "no contact" (its pose was clear); the probe is still 1 mm under the
  // old plane: the force falls to zero over kReleaseFadeNs, every tick below the one before,
  // also when a second no-contact model arrives on the way.
  ContactModel clear = wall_model(100, 0.5);
  in.on_model(clear, 102 * kMs);
  double last = held;
  for (int t = 102; t <= 102 + int(kReleaseFadeNs / kMs); ++t) {
    if (t == 104) in.on_model(wall_model(101, 0.5), t * kMs);
    const double f = in.force(at_z(-1.0), t * kMs).z();
    CAPTURE(t);
    CHECK(f <= last);
    CHECK(f >= 0.0);
    if (t < 102 + int(kReleaseFadeNs / kMs)) CHECK(f > 0.0);
    last = f;
  }
  CHECK(last == 0.0);
  CHECK(in.force(at_z(-1.0), 120 * kMs).z() == 0.0);
  // Following the probe out: once it is above the old plane the force is zero at once.
  Interpolator out(law, cfg(InterpMode::plane));
  for (int t = 0; t <= 20; ++t) {
    if (t % 2 == 0) out.on_model(wall_model(std::uint64_t(t + 1), -2.0), t * kMs);
    (void)out.force(at_z(-2.0), t * kMs);
  }
  (void)out.force(at_z(-0.2), 21 * kMs);
  out.on_model(wall_model(50, 0.5), 22 * kMs);
  CHECK(out.force(at_z(0.1), 22 * kMs).z() == 0.0);
}

TEST_CASE("interpolator: the cross-fade lasts kCrossfadeRounds model intervals when models come faster") {
  const ForceLaw law;
  Interpolator in(law, cfg(InterpMode::plane));  // crossfade_ns 10 ms
  for (int t = 0; t <= 100; ++t) {
    if (t % 2 == 0) in.on_model(wall_model(std::uint64_t(t + 1), -2.0), t * kMs);
    (void)in.force(at_z(-2.0), t * kMs);
  }
  CHECK(in.force(at_z(-2.0), 101 * kMs).z() == doctest::Approx(law.magnitude_N(2.0)).epsilon(1e-4));
  ContactModel m = wall_model(99, -2.0);  // the wall 1 mm lower: PD 1 at the same pose
  m.plane_point = {0, 0, -1};
  m.penetration_mm = 1.0;
  in.on_model(m, 102 * kMs);
  const int span_ms = int(kCrossfadeRounds * 2);  // models every 2 ms
  double mid = 0, done = 0;
  for (int t = 102; t <= 102 + span_ms; ++t) {
    const double f = in.force(at_z(-2.0), t * kMs).z();
    if (t == 102 + span_ms - 2) mid = f;
    done = f;
  }
  CHECK(mid > law.magnitude_N(1.0) + 1e-3);                            // still fading
  CHECK(done == doctest::Approx(law.magnitude_N(1.0)).epsilon(1e-4));  // done within the span, not 10 ms
}

TEST_CASE("Interpolator: the torque is the force's moment about the tool point, carried with the probe") {
  using st::geom::to_pod;
  InterpolatorConfig c = DefaultInterpolatorConfig();
  ForceLaw law;
  Interpolator in(law, c);
  const Eigen::Vector3d tcp(0, 0, 10);  // the tool point, probe frame: 10 mm above the probe's origin
  in.set_tool_point(tcp);
  // A flat press: FD = +z, the plane at z = 0, the probe's origin 1 mm below it; the patch's
  // centre 6 mm off the tool point along x (a box pressed off-centre).
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(0, 0, -1);
  st::geom::ContactModel m = wall_contact(pose, 1, Eigen::Vector3d(6, 0, 0));
  in.on_model(m, 1'000'000);
  const Eigen::Vector3d f = in.force(pose, 1'000'000 + kDefaultCrossfadeNs * 10);
  REQUIRE(f.z() > 0.1);
  // Analytic: (pressure point − tool point) × F = (6, 0, −11) mm × (0, 0, Fz) = (0, −6 Fz, 0) N·mm.
  const Eigen::Vector3d expect = 1e-3 * Eigen::Vector3d(6, 0, -11).cross(f);
  CHECK((in.torque_Nm() - expect).norm() <= 1e-12 * expect.norm());
  CHECK(in.torque_Nm().y() == doctest::Approx(-6e-3 * f.z()));
  // The probe turned 30° about z at the same depth: the lever arm turns with it (carried with
  // the probe between models).
  Eigen::Isometry3d turned = pose;
  turned.linear() = Eigen::AngleAxisd(M_PI / 6, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d f2 = in.force(turned, 1'000'000 + kDefaultCrossfadeNs * 11);
  const Eigen::Vector3d lever = turned.linear() * Eigen::Vector3d(6, 0, -11);
  CHECK((in.torque_Nm() - 1e-3 * lever.cross(f2)).norm() <= 1e-12 * in.torque_Nm().norm());
  // A pressure point on the tool point's line along the force: no torque.
  m.seq = 2;
  m.pressure_point = to_pod(Eigen::Vector3d(0, 0, -0.5));
  in.on_model(m, 200'000'000);
  in.force(pose, 200'000'000 + kDefaultCrossfadeNs * 10);
  CHECK(in.torque_Nm().norm() < 1e-15);
}

TEST_CASE("Interpolator: a new model's lever arm is cross-faded in: the torque moves in small steps") {
  using st::geom::to_pod;
  Interpolator in(ForceLaw{}, DefaultInterpolatorConfig());
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(0, 0, -1);
  st::geom::ContactModel m = wall_contact(pose, 1, Eigen::Vector3d::Zero());
  std::int64_t t = 1'000'000;
  Eigen::Vector3d last = Eigen::Vector3d::Zero();
  double worst = 0, peak = 0;
  for (int round = 0; round < 40; ++round) {
    m.seq = std::uint64_t(round + 1);
    m.pressure_point = to_pod(Eigen::Vector3d(round % 2 ? 8.0 : -8.0, 0, 0));  // the centre jumps 16 mm a round
    in.on_model(m, t);
    for (int k = 0; k < 2; ++k, t += 1'000'000) {  // a round every 2 ticks
      in.force(pose, t);
      if (round > 2) worst = std::max(worst, (in.torque_Nm() - last).norm());
      peak = std::max(peak, in.torque_Nm().norm());
      last = in.torque_Nm();
    }
  }
  REQUIRE(peak > 0);
  // A switch at once would step by the whole 16 mm lever (2 x peak); the cross-fade spreads it.
  CHECK(worst < 0.6 * peak);
}

namespace {
// The model the patch builder makes for `probe` at `pose` against `object` (every colliding pair).
st::geom::ContactModel built_model(const st::geom::Mesh& probe, const st::geom::Mesh& object, const Eigen::Isometry3d& pose) {
  st::Result<st::Body> p = st::Body::make(probe), o = st::Body::make(object);
  REQUIRE(p.ok());
  REQUIRE(o.ok());
  st::CollisionResult r;
  st::ComputeCollision(p.value(), o.value()).at_relative(pose, st::CollisionRequest::all_pairs(), r);
  st::geom::ContactBuilder builder;
  st::geom::ContactModel m = builder.build(probe, object, pose, r.pairs);
  m.seq = 1;
  m.pose = st::geom::to_pod(pose);
  return m;
}
}  // namespace

TEST_CASE("Interpolator: wrench of real contacts: a box pressed off its tool point, a sphere end about its centre") {
  const st::geom::Mesh plate = st::geom::make_box({200, 200, 200});  // top face at z = 100
  // The force and torque about `tcp` an interpolator renders for the builder's model at `pose`.
  auto wrench_at = [&](const st::geom::Mesh& probe, const Eigen::Isometry3d& pose, const Eigen::Vector3d& tcp,
                       Eigen::Vector3d& torque) {
    Interpolator in(ForceLaw{}, DefaultInterpolatorConfig());
    in.set_tool_point(tcp);
    const st::geom::ContactModel m = built_model(probe, plate, pose);
    REQUIRE(m.in_contact());
    in.on_model(m, 1'000'000);
    const Eigen::Vector3d f = in.force(pose, 2'000'000);
    torque = in.torque_Nm();
    return f;
  };
  {
    // A 20 mm box pressed 1 mm flat; the tool point 6 mm off its axis on its top face. The force
    // acts at the middle of the pressed square: τ = (c − r) × F = (−6, 0, −20) mm × (0, 0, F).
    const st::geom::Mesh cube = st::geom::make_box({20, 20, 20});
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Eigen::Vector3d(13.0, -7.0, 100 + 10 - 1.0);
    Eigen::Vector3d torque;
    const Eigen::Vector3d f = wrench_at(cube, pose, Eigen::Vector3d(6, 0, 10), torque);
    REQUIRE(f.z() > 0.01);
    const Eigen::Vector3d analytic = 1e-3 * Eigen::Vector3d(-6, 0, -20).cross(Eigen::Vector3d(0, 0, f.z()));
    CHECK((torque - analytic).norm() <= 0.02 * analytic.norm());
    MESSAGE("box off-centre: torque " << torque.transpose() << " N·m, analytic " << analytic.transpose());
  }
  {
    // A capsule's spherical end pressed end-on: about the end's centre no torque (the force's line
    // of action passes through it).
    const st::geom::Mesh capsule = st::geom::make_capsule(8, 30, 32);  // end centres at z = ±15
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();  // tip down
    pose.translation() = Eigen::Vector3d(4.0, 2.0, 100 + 23 - 0.8);
    Eigen::Vector3d torque;
    const Eigen::Vector3d f = wrench_at(capsule, pose, Eigen::Vector3d(0, 0, 15), torque);
    REQUIRE(f.norm() > 0.01);
    CHECK(torque.norm() <= 1e-6);
    MESSAGE("sphere end on a plane: |torque| about its centre " << torque.norm() << " N·m at |F| " << f.norm() << " N");
  }
}
