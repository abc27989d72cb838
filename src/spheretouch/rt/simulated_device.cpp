// SPDX-License-Identifier: BSD-3-Clause
#include <spheretouch/rt/simulated_device.hpp>
#include <spheretouch/geom/text_file.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <spheretouch/geom/pose_io.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

Eigen::Isometry3d Trajectory::at(double t_s) const {
  if (keys.empty()) return Eigen::Isometry3d::Identity();
  if (!(t_s > keys.front().t_s)) return keys.front().pose;  // also NaN
  if (t_s >= keys.back().t_s) return keys.back().pose;
  const auto it = std::upper_bound(keys.begin(), keys.end(), t_s, [](double t, const TimedPose& k) { return t < k.t_s; });
  const TimedPose& b = *it;
  const TimedPose& a = *(it - 1);
  const double s = (t_s - a.t_s) / (b.t_s - a.t_s);
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  const Eigen::Quaterniond qa(a.pose.linear()), qb(b.pose.linear());
  p.linear() = qa.slerp(s, qb).toRotationMatrix();
  p.translation() = (1 - s) * a.pose.translation() + s * b.pose.translation();
  return p;
}

Result<Trajectory> parse_trajectory(const std::string& text, const std::string& name) {
  Trajectory tr;
  std::istringstream in(text);
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    double v[17];
    int n = 0;
    std::string tok;
    while (ls >> tok) {
      if (n == 17) return fail(name, ":", lineno, ": more than 17 numbers (expected t_s and a row-major 4x4)");
      char* end = nullptr;
      v[n] = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0') return fail(name, ":", lineno, ": '", tok, "' is not a number");
      if (!std::isfinite(v[n])) return fail(name, ":", lineno, ": value ", n + 1, " is not finite");
      ++n;
    }
    if (n == 0) continue;
    if (n != 17) return fail(name, ":", lineno, ": ", n, " numbers, expected 17 (t_s and a row-major 4x4)");
    TimedPose k;
    k.t_s = v[0];
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) k.pose.matrix()(i, j) = v[1 + 4 * i + j];
    if (const std::string why = geom::check_rigid(k.pose.matrix()); !why.empty())
      return fail(name, ":", lineno, ": ", why);
    if (!tr.keys.empty() && !(k.t_s > tr.keys.back().t_s))
      return fail(name, ":", lineno, ": time ", k.t_s, " s is not after the previous ", tr.keys.back().t_s, " s");
    tr.keys.push_back(k);
  }
  if (tr.keys.empty()) return fail(name, ": no poses");
  return tr;
}

Result<Trajectory> load_trajectory(const std::string& path) {
  // A trajectory is a text file of at most kMaxTrajectoryBytes: /dev/zero or a FIFO must not be
  // read into memory without end.
  Result<std::string> text = geom::read_text_file(path, kMaxTrajectoryBytes, "trajectory file");
  if (!text) return Error{text.error()};
  return parse_trajectory(text.value(), path);
}

Trajectory builtin_press_slide(const Eigen::Vector3d& surface, const Eigen::Vector3d& normal, double depth_mm,
                               double slide_mm) {
  const Eigen::Vector3d n = normal.normalized();
  // A tangent: any unit vector perpendicular to n.
  const Eigen::Vector3d tangent =
      (std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY()).cross(n).cross(n).normalized() * -1.0;
  auto key = [&](double t, const Eigen::Vector3d& p) {
    TimedPose k;
    k.t_s = t;
    k.pose.translation() = p;
    return k;
  };
  const Eigen::Vector3d above = surface + 10.0 * n, pressed = surface - depth_mm * n;
  Trajectory tr;
  tr.keys = {key(0.0, above),
             key(1.0, surface),
             key(1.5, pressed),
             key(2.0, pressed),
             key(4.0, pressed + slide_mm * tangent),
             key(4.5, surface + slide_mm * tangent + 10.0 * n),
             key(5.0, surface + slide_mm * tangent + 10.0 * n)};
  return tr;
}

SimulatedDevice::SimulatedDevice(Trajectory script, VirtualUser user, std::size_t capacity, double max_force_N)
    : script_(std::move(script)), user_(user), max_force_(max_force_N), record_(capacity > 0) {
  records_.reserve(capacity);
  pose_ = script_.at(0);
  x_ = pose_.translation();
}

bool SimulatedDevice::read_pose(std::int64_t now_ns, Eigen::Isometry3d& pose) noexcept {
  if (start_ns_ < 0) start_ns_ = last_ns_ = now_ns;
  elapsed_s_ = static_cast<double>(now_ns - start_ns_) * 1e-9;
  const double d = script_.duration_s();
  const double t = (repeat_ && d > 0) ? std::fmod(elapsed_s_, d) : elapsed_s_;
  finished_ = !repeat_ && elapsed_s_ >= d;
  const Eigen::Isometry3d target = script_.at(t);
  if (!user_.enabled) {
    pose_ = target;
  } else {
    // Semi-implicit Euler in substeps of <= 0.5 ms; units: N = kg·m/s² = 1000 kg·mm/s².
    double dt = std::clamp(static_cast<double>(now_ns - last_ns_) * 1e-9, 0.0, 0.05);
    while (dt > 0) {
      const double h = std::min(dt, 5e-4);
      const Eigen::Vector3d f =
          user_.stiffness_N_per_mm * (target.translation() - x_) - user_.damping_N_s_per_mm * v_ + last_force_;
      v_ += h * (f / user_.mass_kg) * 1000.0;
      x_ += h * v_;
      dt -= h;
    }
    pose_.linear() = target.linear();
    pose_.translation() = x_;
  }
  last_ns_ = now_ns;
  pose = pose_;
  return true;
}

void SimulatedDevice::command_force(std::int64_t now_ns, const Eigen::Vector3d& force_N) noexcept {
  last_force_ = force_N.allFinite() ? force_N : Eigen::Vector3d::Zero();
  if (!record_) return;
  if (records_.size() < records_.capacity()) {
    ForceRecord r;
    r.t_ns = now_ns;
    r.position = pose_.translation();
    r.force_N = last_force_;
    records_.push_back(r);  // within the reserved capacity: no allocation
  } else {
    ++dropped_;
  }
}

}  // namespace st::rt
