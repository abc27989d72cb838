// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/passivity.*: a sampled spring pressed and released injects energy (Colgate), the
// guard takes it back; the guard never pulls and passes forces through when disabled; and in
// closed loop (the virtual user's hand, the servo, the patch contact model on a box, a slow
// collision side), every contact cycle returns no more energy than it took.
#include <spheretouch/rt/passivity.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/rt/haptic_servo.hpp>
#include <spheretouch/rt/simulated_device.hpp>

using namespace st::rt;
using Eigen::Vector3d;

namespace {
constexpr double kPi = 3.14159265358979323846;

// A prescribed press and release against a spring of stiffness k along +z, 1 ms ticks, force
// held over each tick (zero-order hold). Returns Σ F_k·(x_{k+1} − x_k), mJ.
double spring_cycle_energy(bool guarded, double k_N_per_mm, double depth_mm, int ticks) {
  PassivityConfig c = DefaultPassivityConfig();
  c.enabled = guarded;
  PassivityGuard g(c, k_N_per_mm, 1e-3);
  const Vector3d n = Vector3d::UnitZ();
  double energy = 0;
  Vector3d f_prev = Vector3d::Zero(), x_prev = Vector3d::Zero();
  for (int i = 0; i <= ticks; ++i) {
    const double s = std::sin(kPi * i / ticks);
    const double d = depth_mm * s * s;  // 0 → depth → 0
    const Vector3d x(0, 0, -d);
    if (i > 0) energy += f_prev.dot(x - x_prev);
    const Vector3d raw = k_N_per_mm * d * n;
    const Vector3d f = g.apply(raw, x, d > 0 ? n : Vector3d::Zero(), 1e-3);
    CHECK(f.dot(n) >= 0.0);  // never pulls
    g.commanded(f);
    f_prev = f;
    x_prev = x;
  }
  return energy;
}
}  // namespace

TEST_CASE("passivity: a sampled spring injects energy, the guard takes it back") {
  for (int ticks : {40, 200, 1000}) {
    CAPTURE(ticks);
    const double raw = spring_cycle_energy(false, 0.59, 5.0, ticks);
    const double guarded = spring_cycle_energy(true, 0.59, 5.0, ticks);
    CHECK(raw > 0.0);        // the zero-order hold gives back more than it took
    CHECK(guarded <= 1e-9);  // the guard: no net energy out
  }
}

TEST_CASE("passivity: disabled passes forces through; config is checked; non-finite input is safe") {
  PassivityConfig off = DefaultPassivityConfig();
  off.enabled = false;
  PassivityGuard g(off, 0.59, 1e-3);
  const Vector3d f(0.1, 0.2, 0.3);
  CHECK(g.apply(f, Vector3d(0, 0, -1), Vector3d::UnitZ(), 1e-3) == f);
  PassivityConfig bad = DefaultPassivityConfig();
  bad.colgate_margin = -1;
  CHECK(PassivityGuard::check(bad).find("colgate_margin") != std::string::npos);
  bad = DefaultPassivityConfig();
  bad.max_damping_N_s_per_mm = std::nan("");
  CHECK(PassivityGuard::check(bad).find("max_damping_n_s_per_mm") != std::string::npos);
  CHECK(PassivityGuard::check(DefaultPassivityConfig()).empty());
  PassivityGuard on(DefaultPassivityConfig(), 0.59, 1e-3);
  const Vector3d out = on.apply(f, Vector3d(0, 0, std::nan("")), Vector3d::UnitZ(), 1e-3);
  CHECK(out.allFinite());
  CHECK(on.min_damping_N_s_per_mm() == doctest::Approx(2.0 * 0.59 * 1e-3 / 2));
}

TEST_CASE("passivity: closed loop with the hand, the servo and the patch model: no contact cycle injects energy") {
  using namespace st::geom;
  const Mesh box = make_box({40, 40, 40});  // top face at z = +20
  const Mesh ball = make_icosphere(10, 12);
  const SphereTree box_tree = SphereTree::build(box).value(), ball_tree = SphereTree::build(ball).value();
  // The user's hand pushes the ball 4 mm into the top face and lets go, three times.
  Trajectory script;
  for (int c = 0; c < 3; ++c) {
    const double t0 = 0.8 * c;
    TimedPose up, down, hold;
    up.t_s = t0 + 1e-3;
    up.pose.translation() = Vector3d(0.5 * c, 0, 35);
    down.t_s = t0 + 0.3;
    down.pose.translation() = Vector3d(0.5 * c, 0, 26);
    hold.t_s = t0 + 0.45;
    hold.pose.translation() = Vector3d(0.5 * c, 0, 26);
    script.keys.push_back(up);
    script.keys.push_back(down);
    script.keys.push_back(hold);
  }
  TimedPose end;
  end.t_s = 2.6;
  end.pose.translation() = Vector3d(1, 0, 35);
  script.keys.push_back(end);
  VirtualUser user;
  user.enabled = true;
  const int ticks = 2700;
  SimulatedDevice device(script, user, ticks + 10);
  TripleBuffer<PoseSample> poses;
  TripleBuffer<ContactSet> models;
  HapticServo servo(device, poses, models, ForceLaw{}, DefaultInterpolatorConfig(), DefaultSaturationConfig(), nullptr,
                    DefaultPassivityConfig(), 1e-3);
  ContactBuilder builder;
  builder.prepare(ball, box);
  CollideScratch scratch;
  CollideResult result;
  constexpr int kRoundTicks = 3;  // a collision round every 3 ms, delivered 3 ms after its pose
  ContactModel pending{};
  bool have_pending = false;
  std::uint64_t seq = 0;
  for (int k = 0; k < ticks; ++k) {
    const std::int64_t t = 1'000'000'000 + std::int64_t(k) * 1'000'000;
    if (have_pending && k % kRoundTicks == 0) {
      models.write(ContactSet::of(pending));
      have_pending = false;
    }
    TickInfo info;
    info.tick = info.deadline_index = std::uint64_t(k);
    info.deadline_ns = info.woke_ns = t;
    info.period_ns = 1'000'000;
    servo.tick(info);
    if (k % kRoundTicks == 0) {
      poses.update();
      const PoseSample ps = poses.output();
      const Pose pose = to_eigen(ps.pose);
      collide(ball, ball_tree, box, box_tree, pose, {}, scratch, result);
      pending = builder.build(ball, box, pose, result.pairs);
      pending.seq = ++seq;
      pending.pose_seq = ps.seq;
      pending.pose_sampled_ns = ps.sampled_ns;
      have_pending = true;
    }
  }
  // Energy the commanded force put into the hand, per contact cycle (force on to force off).
  const std::vector<ForceRecord>& r = device.records();
  REQUIRE(r.size() == std::size_t(ticks));
  std::vector<double> cycles;
  double e = 0;
  bool on = false;
  for (std::size_t i = 0; i + 1 < r.size(); ++i) {
    const bool f_on = r[i].force_N.norm() > 0;
    if (f_on && !on) e = 0;
    if (f_on) e += r[i].force_N.dot(r[i + 1].position - r[i].position);
    if (!f_on && on) cycles.push_back(e);
    on = f_on;
  }
  REQUIRE(cycles.size() >= 3);
  for (double c : cycles) {
    CAPTURE(c);
    CHECK(c <= 1e-6);
  }
  CHECK(servo.peak_force_N() > 0.5);  // it did press (the hand settles ~2.4 mm deep): not a contact-free run
  MESSAGE("contact cycles: " << cycles.size() << ", energy per cycle (mJ): " << cycles[0] << " " << cycles[1] << " "
                             << cycles[2] << "; guard acted on " << servo.passivity().active_ticks() << " ticks");
}

TEST_CASE("passivity: a fast release with an energy excess: the force falls without chattering") {
  // A spring pressed 3 mm, then released at 300 mm/s while the rendered force lags the motion by
  // one tick (a contact model one round old): the zero-order hold gives back more than it took,
  // the controller takes it back, spread over ticks: the force never rises while it falls.
  const double k = 0.59;
  PassivityGuard g(DefaultPassivityConfig(), k, 1e-3);
  const Vector3d n = Vector3d::UnitZ();
  std::vector<double> depth;
  for (int i = 0; i <= 300; ++i) depth.push_back(3.0 * i / 300.0);  // slow press, 300 ms
  for (int i = 0; i < 100; ++i) depth.push_back(3.0);               // hold
  for (double d = 3.0; d > 0; d -= 0.3) depth.push_back(d);         // 300 mm/s out
  depth.push_back(0);
  double energy = 0, f_prev_n = 0, step_prev = 0;
  Vector3d f_prev = Vector3d::Zero();
  int reversals = 0;
  for (std::size_t i = 0; i < depth.size(); ++i) {
    const Vector3d x(0, 0, -depth[i]);
    if (i > 0) energy += f_prev.dot(x - Vector3d(0, 0, -depth[i - 1]));
    const double lagged = i > 0 ? depth[i - 1] : 0.0;  // the model's depth, a tick late
    const Vector3d f = g.apply(k * lagged * n, x, depth[i] > 0 ? n : Vector3d::Zero(), 1e-3);
    g.commanded(f);
    if (i > 400) {  // releasing: the steps of the force along n never change sign
      const double step = f.dot(n) - f_prev_n;
      if (step * step_prev < -1e-12) ++reversals;
      if (std::abs(step) > 1e-12) step_prev = step;
    }
    f_prev_n = f.dot(n);
    f_prev = f;
  }
  CHECK(reversals == 0);
  CHECK(energy <= 1e-9);
}
