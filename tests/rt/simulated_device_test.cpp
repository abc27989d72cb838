// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/simulated_device.*: trajectory interpolation and file validation, the built-in
// script, the virtual user reacting to force, and force recording with counted overflow.
#include <spheretouch/rt/simulated_device.hpp>

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>

#include "rt_test_util.hpp"

using namespace st::rt;

namespace {
constexpr std::int64_t kOneMs = 1'000'000;
}

TEST_CASE("trajectory: file format parsed and validated with line numbers") {
  const std::string good =
      "# t  R|t rows\n"
      "0   1 0 0 0  0 1 0 0  0 0 1 10  0 0 0 1\n"
      "1.0 1 0 0 4  0 1 0 0  0 0 1 0   0 0 0 1  # pressed\n";
  auto t = parse_trajectory(good, "good.traj");
  REQUIRE_MESSAGE(t.ok(), err_of(t));
  CHECK(t.value().keys.size() == 2);
  const Eigen::Isometry3d mid = t.value().at(0.5);
  CHECK(mid.translation().x() == doctest::Approx(2.0));
  CHECK(mid.translation().z() == doctest::Approx(5.0));
  CHECK(t.value().at(-1).translation().z() == 10.0);
  CHECK(t.value().at(99).translation().x() == 4.0);

  auto bad = [](const std::string& text, const char* what) {
    auto r = parse_trajectory(text, "bad.traj");
    REQUIRE_FALSE(r.ok());
    CHECK_MESSAGE(r.error().find(what) != std::string::npos, r.error());
  };
  bad("0 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n0 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n", "bad.traj:2: time");
  bad("0 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0\n", "16 numbers");
  bad("0 2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n", "orthonormal");
  bad("0 1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 1\n", "last row");
  bad("0 1 0 0 nan 0 1 0 0 0 0 1 0 0 0 0 1\n", "not finite");
  bad("0 1 0 0 x 0 1 0 0 0 0 1 0 0 0 0 1\n", "not a number");
  bad("# nothing\n", "no poses");
  CHECK_FALSE(load_trajectory("/nonexistent/x.traj").ok());
}

TEST_CASE("simulated device: built-in script approaches, presses, slides, releases") {
  const Trajectory tr = builtin_press_slide({0, 0, 0}, {0, 0, 1}, 3.0, 20.0);
  SimulatedDevice dev(tr, VirtualUser{}, 16);
  Eigen::Isometry3d p;
  REQUIRE(dev.read_pose(0, p));
  CHECK(p.translation().z() == doctest::Approx(10.0));
  REQUIRE(dev.read_pose(2000 * kOneMs, p));
  CHECK(p.translation().z() == doctest::Approx(-3.0));
  REQUIRE(dev.read_pose(4000 * kOneMs, p));
  CHECK(p.translation().head<2>().norm() == doctest::Approx(20.0));
  CHECK(p.translation().z() == doctest::Approx(-3.0));
  REQUIRE(dev.read_pose(6000 * kOneMs, p));
  CHECK(p.translation().z() == doctest::Approx(10.0));
  CHECK(dev.finished());
}

TEST_CASE("simulated device: the virtual user yields to the commanded force; records counted") {
  TimedPose k;
  k.pose.translation() = Eigen::Vector3d(0, 0, -3);  // the hand wants to be 3 mm inside
  Trajectory tr;
  tr.keys = {k};
  VirtualUser user;
  user.enabled = true;
  SimulatedDevice dev(tr, user, 100);
  Eigen::Isometry3d p;
  // A wall at z = 0 rendered as a 0.5 N/mm spring, 2 s at 1 kHz.
  for (int i = 0; i < 2000; ++i) {
    REQUIRE(dev.read_pose(i * kOneMs, p));
    const double z = p.translation().z();
    dev.command_force(i * kOneMs, Eigen::Vector3d(0, 0, z < 0 ? -0.5 * z : 0.0));
  }
  // Equilibrium: 0.3 (target - z) = -0.5 z  ->  z = -0.9 / 0.8 = -1.125 mm.
  CHECK(p.translation().z() == doctest::Approx(-1.125).epsilon(0.01));
  CHECK(dev.records().size() == 100);
  CHECK(dev.dropped_records() == 1900);
  CHECK(dev.records()[5].t_ns == 5 * kOneMs);
}

TEST_CASE("load_trajectory: /dev/zero, a directory and an oversized file are refused before reading") {
  auto z = st::rt::load_trajectory("/dev/zero");
  REQUIRE_FALSE(z.ok());
  CHECK(z.error().find("not a regular file") != std::string::npos);
  auto d = st::rt::load_trajectory("/tmp");
  REQUIRE_FALSE(d.ok());
  CHECK(d.error().find("is a directory, not a trajectory file") != std::string::npos);
  const std::string big = (std::filesystem::temp_directory_path() / "st_big_trajectory.txt").string();
  {
    std::ofstream o(big);
    REQUIRE(o.good());
  }
  std::filesystem::resize_file(big, st::rt::kMaxTrajectoryBytes + 1);  // sparse: costs no disk
  auto b = st::rt::load_trajectory(big);
  std::filesystem::remove(big);
  REQUIRE_FALSE(b.ok());
  CHECK(b.error().find("limit for a trajectory file") != std::string::npos);
}
