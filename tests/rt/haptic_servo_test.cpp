// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/haptic_servo.*: the whole haptic side at 1 kHz against a simulated device and a
// stand-in collision thread (probe tip vs a wall, via geom::ContactBuilder at ~100 Hz): the
// force is rendered, always finite and saturated, telemetry accounts for every tick, the tick
// path allocates nothing, and a collision side that stops makes the force fade to zero.
#include <spheretouch/rt/haptic_servo.hpp>

#include <doctest/doctest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>

#include "alloc_counter.hpp"
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/simulated_device.hpp>
#include "rt_test_util.hpp"
#include "test_util.hpp"

using namespace st::rt;
using namespace st::geom;

namespace {
Mesh wall() {
  Mesh m;
  m.local = {{-50, -50, 0}, {50, -50, 0}, {50, 50, 0}, {-50, 50, 0}};
  m.faces = {{0, 1, 2}, {0, 2, 3}};
  return m;
}
Mesh tip() {
  Mesh m;
  m.local = {{0, 0, 0}, {1, 0, 2}, {-0.5, 0.866, 2}, {-0.5, -0.866, 2}};
  m.faces = {{0, 2, 1}, {0, 3, 2}, {0, 1, 3}, {1, 2, 3}};
  return m;
}
// Stand-in collision thread: a probe face collides with both wall faces when one of its vertices
// is at or below z = 0 (the wall is far larger than the probe).
struct FakeCollision {
  TripleBuffer<PoseSample>& poses;
  TripleBuffer<ContactSet>& models;
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> published{0};
  void run() {
    const Mesh w = wall(), t = tip();
    ContactBuilder builder;
    std::vector<ContactPair> pairs;
    while (!stop.load(std::memory_order_relaxed)) {
      poses.update();
      const PoseSample ps = poses.output();
      if (ps.seq == 0) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        continue;
      }
      const Pose pose = to_eigen(ps.pose);
      pairs.clear();
      for (std::uint32_t f = 0; f < t.faces.size(); ++f) {
        bool below = false;
        for (std::uint32_t v : t.faces[f]) below |= (pose * t.local[v]).z() <= 0;
        if (below) {
          pairs.push_back({f, 0});
          pairs.push_back({f, 1});
        }
      }
      ContactModel m = builder.build(t, w, pose, pairs);
      m.seq = ++published;
      m.pose_seq = ps.seq;
      m.pose_sampled_ns = ps.sampled_ns;
      m.published_ns = now_ns();
      models.write(ContactSet::of(m));
      std::this_thread::sleep_for(std::chrono::milliseconds(10));  // a slow collision side
    }
  }
};
Trajectory press() {
  Trajectory tr;
  TimedPose a, b;
  a.pose.translation() = Eigen::Vector3d(0, 0, 5);
  b.t_s = 0.6;
  b.pose.translation() = Eigen::Vector3d(0, 0, -4);
  tr.keys = {a, b};
  return tr;
}
}  // namespace

TEST_CASE("HapticServo: renders contact from a slow collision side, finite, saturated, no allocation") {
  auto poses = std::make_unique<TripleBuffer<PoseSample>>();
  auto models = std::make_unique<TripleBuffer<ContactSet>>();
  SimulatedDevice dev(press(), VirtualUser{}, 4000);
  Telemetry tele(4000);
  HapticServo servo(dev, *poses, *models, ForceLaw{}, DefaultInterpolatorConfig(), DefaultSaturationConfig(), &tele);
  FakeCollision coll{*poses, *models};
  std::thread collision([&] {
    st::test::exclude_this_thread();  // it allocates (builder scratch); the tick path must not
    coll.run();
  });

  HapticLoopConfig lc = DefaultHapticLoopConfig();
  lc.max_periods = 1500;
  auto loop = std::make_unique<HapticLoop>(lc);
  REQUIRE(loop->start(servo).ok());
  while (loop->ticks() < 100) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  // Count allocations of the tick path (loop thread; this thread only sleeps and polls).
  while (coll.published < 5) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  st::test::arm_alloc_counter();
  const std::uint64_t t0 = loop->ticks();
  while (loop->running() && loop->ticks() < t0 + 500) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  const std::uint64_t allocs = st::test::disarm_alloc_counter();
  while (loop->running()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  loop->stop();
  coll.stop = true;
  collision.join();

  CHECK(allocs == 0);
  const LoopStats& ls = loop->stats();
  CHECK(ls.ticks + ls.misses == 1500);
  CHECK(servo.stats().ticks == ls.ticks);
  CHECK(servo.stats().models >= 1);
  const TelemetryStats ts = tele.stats();
  CHECK(ts.pushed + ts.dropped == ls.ticks);
  double fmax = 0;
  for (const ForceRecord& r : dev.records()) {
    REQUIRE(r.force_N.allFinite());
    REQUIRE(r.force_N.norm() <= 3.3 + 1e-12);
    CHECK(r.force_N.z() >= 0.0);
    fmax = std::max(fmax, r.force_N.norm());
  }
  CHECK(fmax > 1.0);  // 4 mm deep: law gives ~1.4 N
  // The ticks' flags, by name: contact while pressed, a pose every tick (the simulated device
  // always gives one), no bit but the named ones.
  std::vector<TelemetrySample> samples(4000);
  samples.resize(tele.drain_to(samples.data(), samples.size()));
  REQUIRE(!samples.empty());
  std::size_t in_contact = 0;
  double proxy_off = 0;  // largest distance of the proxy from the wall's plane while pressed
  for (const TelemetrySample& s : samples) {
    in_contact += (s.flags & kTickInContact) != 0;
    CHECK((s.flags & kTickNoPose) == 0);
    CHECK((s.flags & ~(kTickInContact | kTickSaturated | kTickNoPose)) == 0);
    // The proxy: the tip moved out along the wall's normal (+z) by the depth: on the wall's
    // plane while pressed (the tip's lowest point is its origin), the tip itself otherwise.
    CHECK(std::abs(s.proxy_mm[0] - s.position_mm[0]) < 1e-12);  // the normal is +z to rounding
    CHECK(std::abs(s.proxy_mm[1] - s.position_mm[1]) < 1e-12);
    if ((s.flags & kTickInContact) && s.penetration_mm > 0) {
      CHECK(s.proxy_mm[2] == doctest::Approx(s.position_mm[2] + s.penetration_mm).epsilon(1e-12));
      proxy_off = std::max(proxy_off, std::abs(s.proxy_mm[2]));
    } else if (!(s.flags & kTickInContact)) {
      CHECK(s.proxy_mm[2] == s.position_mm[2]);
    }
  }
  CHECK(in_contact > samples.size() / 4);
  CHECK(proxy_off < 1e-6);  // the plane's depth is exact for a flat wall
  MESSAGE("ticks " << ls.ticks << ", misses " << ls.misses << ", models " << servo.stats().models << ", max force "
                   << fmax << " N, allocations while armed " << allocs);
}

TEST_CASE("HapticServo: when the collision side stops, the force fades to zero") {
  auto poses = std::make_unique<TripleBuffer<PoseSample>>();
  auto models = std::make_unique<TripleBuffer<ContactSet>>();
  TimedPose k;
  k.pose.translation() = Eigen::Vector3d(0, 0, -3);
  Trajectory tr;
  tr.keys = {k};
  SimulatedDevice dev(tr, VirtualUser{}, 2000);
  InterpolatorConfig ic = DefaultInterpolatorConfig();
  ic.stale_timeout_ns = 100'000'000;
  ic.fade_ns = 100'000'000;
  HapticServo servo(dev, *poses, *models, ForceLaw{}, ic, DefaultSaturationConfig(), nullptr);
  // One model, then silence. Drive ticks by hand with synthetic times (no real loop needed).
  ContactBuilder b;
  const Mesh w = wall(), t = tip();
  const std::vector<ContactPair> pairs = {{0, 0}, {1, 0}, {2, 0}};
  // The tip comes down onto the wall from above (the wall is one open surface: a contact takes
  // the side the probe comes from) and is pressed 3 mm in.
  Pose pose = Pose::Identity();
  ContactModel m;
  for (double z = 0.5; z >= -3.0; z -= 0.5) {
    pose.translation() = Eigen::Vector3d(0, 0, z);
    m = b.build(t, w, pose, pairs);
  }
  REQUIRE(m.in_contact());
  CHECK(m.force_dir.z == 1.0);
  m.seq = 1;
  models->write(ContactSet::of(m));
  TickInfo info;
  info.period_ns = 1'000'000;
  for (std::uint64_t i = 0; i < 400; ++i) {
    info.tick = info.deadline_index = i;
    info.deadline_ns = info.woke_ns = 1'000'000'000 + static_cast<std::int64_t>(i) * 1'000'000;
    servo.tick(info);
  }
  const auto& r = dev.records();
  REQUIRE(r.size() == 400);
  CHECK(r[50].force_N.norm() > 1.0);
  CHECK(r[150].force_N.norm() < r[50].force_N.norm());
  CHECK(r[150].force_N.norm() > 0.0);
  CHECK(r[250].force_N.norm() == 0.0);
  CHECK(r[399].force_N.norm() == 0.0);
}

namespace {
/// A 6-DOF device that holds a fixed pose and records the last wrench or force it was given.
struct WrenchDevice final : Device {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  Eigen::Vector3d force = Eigen::Vector3d::Zero(), torque = Eigen::Vector3d::Zero();
  int wrenches = 0, forces = 0;
  double torque_max = 0.5;
  bool read_pose(std::int64_t, Eigen::Isometry3d& p) noexcept override {
    p = pose;
    return true;
  }
  void command_force(std::int64_t, const Eigen::Vector3d& f) noexcept override {
    force = f;
    ++forces;
  }
  void command_wrench(std::int64_t, const Eigen::Vector3d& f, const Eigen::Vector3d& t) noexcept override {
    force = f;
    torque = t;
    ++wrenches;
  }
  double max_force_N() const noexcept override { return 3.3; }
  double max_torque_Nm() const noexcept override { return torque_max; }
};
}  // namespace

TEST_CASE(
    "HapticServo: the wrench: torque about the tool point to 6-DOF devices, saturated; force only to 3-DOF ones") {
  CHECK(check(WrenchConfig{}).empty());
  CHECK(st::test::contains(check(WrenchConfig{.dof = 4}), "dof"));
  CHECK(st::test::contains(check(WrenchConfig{.dof = 6}), "torque_limit_nm"));
  for (const int dof : {3, 6}) {
    CAPTURE(dof);
    auto poses = std::make_unique<TripleBuffer<PoseSample>>();
    auto models = std::make_unique<TripleBuffer<ContactSet>>();
    WrenchDevice dev;
    dev.pose.translation() = Eigen::Vector3d(0, 0, -2);  // 2 mm into the wall z < 0
    HapticServo servo(dev, *poses, *models, ForceLaw{}, DefaultInterpolatorConfig(), DefaultSaturationConfig(), nullptr);
    // The tool point 40 mm above the probe's origin: a lever of 40 mm over a 10 mm offset.
    servo.set_wrench({.dof = dof, .torque_limit_Nm = 0.02, .tcp_mm = Eigen::Vector3d(0, 0, 40)});
    // The patch's centre 10 mm off the tool's axis.
    models->write(ContactSet::of(wall_contact(dev.pose, 2, Eigen::Vector3d(10, 0, 0))));
    TickInfo info;
    info.period_ns = 1'000'000;
    for (int k = 0; k < 20; ++k) {
      info.tick = std::uint64_t(k);
      info.deadline_index = info.tick;
      info.woke_ns = info.deadline_ns = 1'000'000'000 + k * 1'000'000;
      servo.tick(info);
    }
    REQUIRE(dev.force.z() > 0.1);
    // τ = (c − r) × F = (10, 0, −42) mm × (0, 0, F): (0, −10 F, 0) N·mm, above the 0.02 N·m limit
    // once F > 2 N, within it below.
    const double want = 1e-2 * dev.force.z();
    if (dof == 6) {
      CHECK(dev.forces == 0);
      CHECK(dev.wrenches == 20);
      CHECK(dev.torque.y() == doctest::Approx(-std::min(want, 0.02)));
      CHECK(std::abs(dev.torque.x()) < 1e-15);
      CHECK(std::abs(dev.torque.z()) < 1e-15);
      CHECK(servo.peak_torque_Nm() == doctest::Approx(want));
      // A device rendering less torque than the scene allows lowers the ceiling.
      dev.torque_max = 0.001;
      servo.set_wrench({.dof = 6, .torque_limit_Nm = 0.02, .tcp_mm = Eigen::Vector3d(0, 0, 40)});
      info.tick = info.deadline_index = 20;
      info.woke_ns = info.deadline_ns = 1'000'000'000 + 20 * 1'000'000;
      servo.tick(info);
      CHECK(dev.torque.norm() == doctest::Approx(0.001));
    } else {
      CHECK(dev.wrenches == 0);
      CHECK(dev.forces == 20);
      CHECK(servo.peak_torque_Nm() == doctest::Approx(want));  // computed and reported, not commanded
    }
  }
}

TEST_CASE("HapticServo: the rotational guard keeps the torque's work on a turning hand at or below zero") {
  // The hand turns at 1 rad/s about −y while the contact's torque points along −y (the patch's
  // centre 10 mm off the tool's axis): without the guard the torque feeds the rotation (energy
  // into the hand); with it the observer takes the torque along the rotation away.
  double work_mJ[2] = {0, 0};
  for (const bool guarded : {false, true}) {
    CAPTURE(guarded);
    auto poses = std::make_unique<TripleBuffer<PoseSample>>();
    auto models = std::make_unique<TripleBuffer<ContactSet>>();
    WrenchDevice dev;
    dev.torque_max = 1.0;
    dev.pose.translation() = Eigen::Vector3d(0, 0, -2);
    PassivityConfig pc = DefaultPassivityConfig();
    pc.enabled = guarded;
    HapticServo servo(dev, *poses, *models, ForceLaw{}, DefaultInterpolatorConfig(), DefaultSaturationConfig(), nullptr, pc);
    servo.set_wrench({.dof = 6, .torque_limit_Nm = 1.0, .tcp_mm = Eigen::Vector3d(0, 0, 40)});
    models->write(ContactSet::of(wall_contact(dev.pose, 2, Eigen::Vector3d(10, 0, -2))));
    TickInfo info;
    info.period_ns = 1'000'000;
    Eigen::Vector3d last_tau = Eigen::Vector3d::Zero();
    double peak = 0;
    for (int k = 0; k < 400; ++k) {
      const Eigen::Matrix3d before = dev.pose.linear();
      dev.pose.linear() = Eigen::AngleAxisd(-1e-3 * k, Eigen::Vector3d::UnitY()).toRotationMatrix();
      const Eigen::AngleAxisd d(dev.pose.linear() * before.transpose());
      work_mJ[guarded] += 1e3 * last_tau.dot(d.angle() * d.axis());  // last command over this rotation
      info.tick = info.deadline_index = std::uint64_t(k);
      info.woke_ns = info.deadline_ns = 1'000'000'000 + k * 1'000'000;
      servo.tick(info);
      last_tau = dev.torque;
      peak = std::max(peak, dev.torque.norm());
      REQUIRE(dev.torque.allFinite());
    }
    CHECK(peak > 0);  // a torque was rendered
    if (guarded) {
      CHECK(servo.rotational_guard_ticks() > 0);
      CHECK(servo.rotational_energy_mJ() == doctest::Approx(work_mJ[1]).epsilon(1e-6));
    }
  }
  MESSAGE("torque's work on the turning hand: unguarded " << work_mJ[0] << " mJ, guarded " << work_mJ[1] << " mJ");
  CHECK(work_mJ[0] > 0.05);   // the contact feeds the rotation
  CHECK(work_mJ[1] <= 1e-3);  // the guard keeps it at zero, within one tick's work
}

TEST_CASE("HapticServo: several objects: each rendered with its own material, the forces add, a release fades") {
  // A corner: object 0 is the wall z <= 0 (FD +z), object 1 the same wall in its own frame placed
  // turned 90 degrees about y (so it fills x <= 0 in the world, FD +x). The probe sits 2 mm into
  // the first and 1 mm into the second.
  const Eigen::Isometry3d pose(Eigen::Translation3d(-1, 0, -2));
  Eigen::Isometry3d placement = Eigen::Isometry3d::Identity();
  placement.rotate(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
  const ContactModel a = wall_contact(pose, 2, Eigen::Vector3d(-1, 0, 0));
  const ContactModel b = place(wall_contact(placement.inverse() * pose, 1, Eigen::Vector3d(0, 0, -1)), placement);
  CHECK((to_eigen(b.force_dir) - Eigen::Vector3d(1, 0, 0)).norm() < 1e-12);
  CHECK((to_eigen(b.pressure_point) - Eigen::Vector3d(-1, 0, 0)).norm() < 1e-12);
  CHECK((to_eigen(b.pose).matrix() - pose.matrix()).norm() < 1e-12);  // placed: the probe's world pose again

  auto linear = [](double k) {
    ForceLawConfig c = DefaultForceLawConfig();
    c.kind = LawKind::linear;
    c.spring_N_per_mm = k;
    return ForceLaw::make(c).value();
  };
  // A servo over `materials` with the probe held still at `pose`, ticked one period at a time.
  struct Rig {
    std::unique_ptr<TripleBuffer<PoseSample>> poses = std::make_unique<TripleBuffer<PoseSample>>();
    std::unique_ptr<TripleBuffer<ContactSet>> models = std::make_unique<TripleBuffer<ContactSet>>();
    WrenchDevice dev;
    HapticServo servo;
    TickInfo info;
    Rig(const Eigen::Isometry3d& at, const std::vector<ObjectMaterial>& materials)
        : servo(dev, *poses, *models, ForceLaw{}, DefaultInterpolatorConfig(), DefaultSaturationConfig(), nullptr) {
      dev.pose = at;
      servo.set_objects(materials);
      info.period_ns = 1'000'000;
    }
    void tick(int n) {
      for (int k = 0; k < n; ++k) {
        info.woke_ns = info.deadline_ns = 1'000'000'000 + std::int64_t(info.tick) * 1'000'000;
        servo.tick(info);
        ++info.tick;
        ++info.deadline_index;
      }
    }
  };
  struct Run {
    Eigen::Vector3d force;
    std::uint64_t bad;
  };
  // The force commanded after `n` ticks with `set` written first.
  auto run = [&](const std::vector<ObjectMaterial>& materials, const ContactSet& set, int n) {
    Rig r(pose, materials);
    r.models->write(set);
    r.tick(n);
    return Run{r.dev.force, r.servo.stats().bad_objects};
  };
  const std::vector<ObjectMaterial> two = {{linear(0.2), 0, {}}, {linear(0.3), 0, {}}};
  ContactSet both;
  both.seq = 1;
  both.count = 2;
  both.object[0] = 0;
  both.models[0] = a;
  both.object[1] = 1;
  both.models[1] = b;
  const Run sum = run(two, both, 20);
  CHECK(sum.force.x() == doctest::Approx(0.3 * 1).epsilon(1e-9));
  CHECK(sum.force.y() == doctest::Approx(0).epsilon(1e-12));
  CHECK(sum.force.z() == doctest::Approx(0.2 * 2).epsilon(1e-9));
  // Each alone gives its own part: the sum is exactly their sum.
  ContactSet only_a = both, only_b = both;
  only_a.count = 1;
  only_b.count = 1;
  only_b.object[0] = 1;
  only_b.models[0] = b;
  const Run ra = run(two, only_a, 20), rb = run(two, only_b, 20);
  CHECK((ra.force + rb.force - sum.force).norm() < 1e-12);
  CHECK(ra.force.x() == doctest::Approx(0).epsilon(1e-12));
  CHECK(rb.force.z() == doctest::Approx(0).epsilon(1e-12));
  // The saturator acts on the sum: stiff materials give a sum capped at the device's 3.3 N.
  const Run capped = run({{linear(5), 0, {}}, {linear(5), 0, {}}}, both, 20);
  CHECK(capped.force.norm() == doctest::Approx(3.3).epsilon(1e-6));
  // A model naming an object the servo has no material for is ignored and counted.
  ContactSet stray = only_a;
  stray.object[0] = 7;
  const Run rs = run(two, stray, 5);
  CHECK(rs.bad == 1);
  CHECK(rs.force.norm() == 0);

  // A release: object 1 says "no contact" while object 0 holds; object 1's share fades out (never
  // rising) and object 0's stays.
  Rig r(pose, two);
  r.models->write(both);
  r.tick(20);
  ContactSet release = both;
  release.seq = 2;
  release.models[1].flags = 0;  // object 1: no contact
  release.models[1].penetration_mm = 0;
  r.models->write(release);
  double last_x = r.dev.force.x();
  for (int k = 0; k < 200; ++k) {
    r.tick(1);
    CHECK(r.dev.force.x() <= last_x + 1e-12);
    last_x = r.dev.force.x();
    CHECK(r.dev.force.z() == doctest::Approx(0.4).epsilon(1e-9));
  }
  CHECK(r.dev.force.x() == doctest::Approx(0).epsilon(1e-12));
}
