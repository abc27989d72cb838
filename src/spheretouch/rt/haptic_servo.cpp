// SPDX-License-Identifier: BSD-3-Clause
#include <spheretouch/rt/haptic_servo.hpp>

#include <algorithm>
#include <cmath>
#include <string>

#include <spheretouch/geom/check.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

namespace {
SaturationConfig capped(SaturationConfig s, const Device& d) {
  const double dev = d.max_force_N();
  if (std::isfinite(dev) && dev > 0 && !(s.peak_N <= dev)) s.peak_N = dev;
  if (s.continuous_N > s.peak_N) s.continuous_N = s.peak_N;
  return s;
}
}  // namespace

std::string check(const WrenchConfig& c) {
  if (c.dof != 3 && c.dof != 6) return "dof: must be 3 or 6, got " + std::to_string(c.dof);
  if (!std::isfinite(c.torque_limit_Nm) || c.torque_limit_Nm < 0) return "torque_limit_nm: must be finite and >= 0";
  if (c.dof == 6 && !(c.torque_limit_Nm > 0)) return "torque_limit_nm: a 6-DOF device needs a torque limit > 0";
  if (!c.tcp_mm.allFinite()) return "tcp_mm: must be finite";
  return {};
}

void HapticServo::set_wrench(const WrenchConfig& config) {
  ST_ASSERT(check(config).empty(), "the wrench config passed check()");
  wrench_ = config;
  interp_.set_tool_point(config.tcp_mm);
  const double dev = device_.max_torque_Nm();
  torque_ceiling_Nm_ = config.dof == 6 ? std::min(config.torque_limit_Nm, std::isfinite(dev) && dev > 0 ? dev : 0.0) : 0.0;
}

HapticServo::HapticServo(Device& device, TripleBuffer<PoseSample>& poses, TripleBuffer<geom::ContactModel>& models,
                         const ForceLaw& law, const InterpolatorConfig& interp, SaturationConfig saturation,
                         Telemetry* telemetry, const PassivityConfig& passivity, double period_s)
    : device_(device),
      poses_(poses),
      models_(models),
      interp_(law, interp),
      sat_(capped(saturation, device)),
      guard_(passivity, law.max_stiffness_N_per_mm(), period_s),
      telemetry_(telemetry) {}

void HapticServo::tick(const TickInfo& info) noexcept {
  const std::int64_t now = info.woke_ns;
  Eigen::Isometry3d pose;
  const bool have_pose = device_.read_pose(now, pose) && pose.matrix().allFinite();
  if (have_pose) {
    PoseSample& ps = poses_.input();
    ps.seq = ++pose_seq_;
    ps.sampled_ns = now;
    pose_ns_ = now;
    ps.pose = geom::to_pod(pose);
    poses_.publish();
  } else {
    ++stats_.pose_failures;
  }
  if (models_.update()) {
    const geom::ContactModel& m = models_.output();
    interp_.on_model(m, now);
    model_pose_ns_ = m.pose_sampled_ns;
    model_received_ns_ = now;
    model_contacts_ = m.contacts;
    ++stats_.models;
  }
  const Eigen::Vector3d raw = have_pose ? interp_.force(pose, now) : Eigen::Vector3d::Zero();
  const double dt_s = last_ns_ ? static_cast<double>(now - last_ns_) * 1e-9 : 0.0;
  last_ns_ = now;
  // The passivity guard acts while the surface pushes (a contact cycle = force above zero).
  const Eigen::Vector3d n = raw.squaredNorm() > 0 ? interp_.normal() : Eigen::Vector3d::Zero();
  const Eigen::Vector3d guarded = have_pose ? guard_.apply(raw, pose.translation(), n, dt_s) : raw;
  const Eigen::Vector3d f = sat_.apply(guarded, dt_s);
  guard_.commanded(f);
  if (sat_.limited()) ++stats_.saturated;
  // The torque: the commanded force's moment about the tool point (its lever arm from the
  // interpolator), within the torque ceiling; commanded to 6-DOF devices only.
  Eigen::Vector3d tau = 1e-3 * interp_.lever_mm().cross(f);
  if (!tau.allFinite()) tau.setZero();
  const double tau_norm = tau.norm();
  if (tau_norm > peak_torque_Nm_) peak_torque_Nm_ = tau_norm;
  if (wrench_.dof == 6) {
    if (tau_norm > torque_ceiling_Nm_) tau *= torque_ceiling_Nm_ > 0 ? torque_ceiling_Nm_ / tau_norm : 0.0;
    device_.command_wrench(now, f, tau);
  } else {
    device_.command_force(now, f);
  }
  ++stats_.ticks;
  const double f_norm = f.norm();
  if (f_norm > peak_force_N_) peak_force_N_ = f_norm;
  const std::uint32_t flags = (interp_.state().in_contact ? kTickInContact : 0u) |
                              (sat_.limited() ? kTickSaturated : 0u) | (have_pose ? 0u : kTickNoPose);
  if (status_ && info.tick % kStatusEveryTicks == 0) {
    ServoStatus st;
    st.updated_ns = now;
    st.ticks = info.tick + 1;
    st.misses = info.deadline_index - info.tick;
    st.pose_seq = pose_seq_;
    st.pose_sampled_ns = pose_ns_;
    st.model_seq = interp_.model_seq();
    st.model_received_ns = model_received_ns_;
    st.model_pose_ns = model_pose_ns_;
    st.models = stats_.models;
    for (int i = 0; i < 3; ++i) st.force_N[i] = f(i);
    st.peak_force_N = peak_force_N_;
    st.penetration_mm = interp_.state().penetration_mm;
    st.fade = interp_.state().fade;
    st.contacts = model_contacts_;
    st.flags = flags;
    status_->store(st);
  }
  if (telemetry_) {
    TelemetrySample s;
    s.tick = info.tick;
    s.t_ns = now;
    s.latency_ns = now - info.deadline_ns;
    s.pose_seq = have_pose ? pose_seq_ : 0;
    s.model_seq = interp_.model_seq();
    s.model_age_ns = model_pose_ns_ ? now - model_pose_ns_ : -1;
    if (have_pose) {
      // The proxy: the probe moved out of the object by the depth along the contact normal.
      const double pd = interp_.state().in_contact ? std::max(0.0, interp_.state().penetration_mm) : 0.0;
      const Eigen::Vector3d proxy = pose.translation() + pd * interp_.normal();
      for (int i = 0; i < 3; ++i) {
        s.position_mm[i] = pose.translation()(i);
        s.proxy_mm[i] = proxy(i);
      }
    }
    for (int i = 0; i < 3; ++i) {
      s.force_N[i] = f(i);
      s.torque_Nm[i] = tau(i);
    }
    s.penetration_mm = interp_.state().penetration_mm;
    s.fade = interp_.state().fade;
    s.ceiling_N = sat_.ceiling_N();
    s.flags = flags;
    s.misses = static_cast<std::uint32_t>(info.deadline_index - info.tick);
    telemetry_->push(s);
  }
}

}  // namespace st::rt
