// SPDX-License-Identifier: BSD-3-Clause
// PoseFeedDevice (the browser device): poses pushed at a page's rate come out at the servo's rate
// without steps, one source period behind; bad poses are refused before the servo sees them.
#include <cmath>

#include "doctest/doctest.h"
#include <spheretouch/rt/pose_feed_device.hpp>

TEST_CASE("pose feed device: home before the first pose, then upsampled without steps; bad poses refused") {
  Eigen::Isometry3d grip = Eigen::Isometry3d::Identity();
  grip.translate(Eigen::Vector3d(0, 0, -2));  // the tip 2 mm above the probe's origin
  st::rt::PoseFeedDevice dev(grip, Eigen::Vector3d(1, 2, 3), 4.0);
  CHECK(dev.max_force_N() == 4.0);
  Eigen::Isometry3d pose;
  REQUIRE(dev.read_pose(0, pose));
  CHECK((pose * Eigen::Vector3d(0, 0, 2) - Eigen::Vector3d(1, 2, 3)).norm() < 1e-12);  // the tip at home

  // A page at 50 Hz moving the tip 1 mm per frame along x; the servo at 1 kHz.
  const std::int64_t ms = 1'000'000;
  const Eigen::Quaterniond id = Eigen::Quaterniond::Identity();
  double prev_x = NAN, max_step = 0;
  for (int t = 0; t <= 200; ++t) {
    if (t % 20 == 0) REQUIRE(dev.offer(Eigen::Vector3d(t / 20, 0, 0), id, t * ms));
    REQUIRE(dev.read_pose(t * ms, pose));
    const double x = (pose * Eigen::Vector3d(0, 0, 2)).x();
    if (!std::isnan(prev_x)) max_step = std::max(max_step, std::abs(x - prev_x));
    prev_x = x;
  }
  CHECK(max_step <= 1.0 / 20 + 1e-12);    // 1 mm per 20 ms spread over 20 ticks: never a jump
  CHECK(prev_x == doctest::Approx(9.0));  // one page period behind the newest (10)
  REQUIRE(dev.read_pose(230 * ms, pose));
  CHECK((pose * Eigen::Vector3d(0, 0, 2)).x() == doctest::Approx(10.0));  // and there once the period has passed
  CHECK(dev.offers() == 11);

  // Rotation by slerp: half-way between identity and 90° about z.
  const Eigen::Quaterniond quarter(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()));
  REQUIRE(dev.offer(Eigen::Vector3d(10, 0, 0), quarter, 300 * ms));
  REQUIRE(dev.read_pose(350 * ms, pose));  // the span is 200 -> 300 ms, replayed from 300 ms: half-way at 350
  CHECK(Eigen::AngleAxisd(pose.linear()).angle() == doctest::Approx(M_PI / 4).epsilon(1e-9));

  // Refused: NaN, infinite, out of range, not unit; the last good pose stays.
  CHECK_FALSE(dev.offer(Eigen::Vector3d(NAN, 0, 0), id, 400 * ms));
  CHECK_FALSE(dev.offer(Eigen::Vector3d(0, INFINITY, 0), id, 400 * ms));
  CHECK_FALSE(dev.offer(Eigen::Vector3d(2e6, 0, 0), id, 400 * ms));
  CHECK_FALSE(dev.offer(Eigen::Vector3d(0, 0, 0), Eigen::Quaterniond(2, 0, 0, 0), 400 * ms));
  CHECK_FALSE(dev.offer(Eigen::Vector3d(0, 0, 0), Eigen::Quaterniond(NAN, 0, 0, 0), 400 * ms));
  CHECK(dev.refused() == 5);
  REQUIRE(dev.read_pose(500 * ms, pose));
  CHECK(((pose * Eigen::Vector3d(0, 0, 2)) - Eigen::Vector3d(10, 0, 0)).norm() < 1e-9);
  CHECK(pose.matrix().allFinite());
}
