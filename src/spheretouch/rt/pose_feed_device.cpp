// SPDX-License-Identifier: BSD-3-Clause
// PoseFeedDevice: see pose_feed_device.hpp.
#include <spheretouch/rt/pose_feed_device.hpp>

#include <algorithm>
#include <cmath>

namespace st::inline SPHERETOUCH_ABI::rt {

PoseFeedDevice::PoseFeedDevice(const Eigen::Isometry3d& grip, const Eigen::Vector3d& home, double max_force_N,
                               double max_abs_mm)
    : grip_(grip), home_(home), max_force_N_(max_force_N), max_abs_mm_(max_abs_mm) {}

bool PoseFeedDevice::offer(const Eigen::Vector3d& tip, const Eigen::Quaterniond& q, std::int64_t now_ns) noexcept {
  const double qn = q.norm();
  if (!tip.allFinite() || !q.coeffs().allFinite() || !(tip.cwiseAbs().maxCoeff() <= max_abs_mm_) ||
      !(std::abs(qn - 1) <= 1e-3)) {
    refused_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  const Eigen::Quaterniond u(Eigen::Vector4d(q.coeffs() / qn));
  Span s;
  const double b[7] = {tip.x(), tip.y(), tip.z(), u.w(), u.x(), u.y(), u.z()};
  std::copy(b, b + 7, s.b);
  if (last_.any) {
    std::copy(last_.b, last_.b + 7, s.a);
    s.ta = last_.tb;
  } else {
    std::copy(b, b + 7, s.a);
    s.ta = now_ns;
  }
  s.tb = std::max(now_ns, s.ta);
  s.any = true;
  last_ = s;
  spans_.write(s);
  offers_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

bool PoseFeedDevice::read_pose(std::int64_t now_ns, Eigen::Isometry3d& pose) noexcept {
  spans_.update();
  const Span& s = spans_.output();
  Eigen::Vector3d tip = home_;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  if (s.any) {
    // From a to b over the interval they arrived in, starting when b arrived: no step at an arrival.
    const double span = double(s.tb - s.ta);
    const double u = span > 0 ? std::clamp(double(now_ns - s.tb) / span, 0.0, 1.0) : 1.0;
    const Eigen::Vector3d pa(s.a[0], s.a[1], s.a[2]), pb(s.b[0], s.b[1], s.b[2]);
    const Eigen::Quaterniond qa(s.a[3], s.a[4], s.a[5], s.a[6]), qb(s.b[3], s.b[4], s.b[5], s.b[6]);
    tip = pa + u * (pb - pa);
    q = qa.slerp(u, qb);
  }
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translate(tip);
  t.rotate(q);
  pose = t * grip_;
  return true;
}

void PoseFeedDevice::command_force(std::int64_t, const Eigen::Vector3d&) noexcept {}

}  // namespace st::rt
