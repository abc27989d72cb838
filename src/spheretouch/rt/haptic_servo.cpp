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
      friction_(FrictionConfig{}, law.max_stiffness_N_per_mm(), period_s),
      telemetry_(telemetry),
      passivity_on_(passivity.enabled),
      margin_(passivity.colgate_margin),
      period_s_(period_s),
      stiffness_N_per_mm_(law.max_stiffness_N_per_mm()) {}

void HapticServo::set_friction(const FrictionConfig& config) {
  ST_ASSERT(check(config).empty(), "the friction config passed check()");
  friction_ = Friction(config, stiffness_N_per_mm_, period_s_);
}

Eigen::Vector3d HapticServo::guard_torque(const Eigen::Vector3d& tau, const Eigen::Matrix3d& R, bool in_contact,
                                          double dt_s) noexcept {
  // The rotational counterpart of the translational guard (passivity.hpp), for the torque a
  // 6-DOF device renders. The contact's rotational stiffness is the law's k times the lever's
  // square (τ = ℓ × F, and F changes by k·(dθ × ℓ)); held between collision rounds (the
  // collision period T) it needs damping b >= K·T/2 to stay passive (Colgate's bound for a
  // sampled spring), applied with the translational guard's margin and never larger than the
  // torque itself. Then an energy observer over the commanded torque's work τ·dθ, reset at each
  // contact's start: while it is above zero (the contact has put energy into the hand's
  // rotation), the torque's component along the rotation is removed and, within the torque's own
  // size, turned into a brake that takes the excess back over the next tick (if it turns as this one).
  Eigen::Vector3d dtheta = Eigen::Vector3d::Zero();
  if (have_rot_) {
    const Eigen::AngleAxisd d(R * last_rot_.transpose());
    dtheta = d.angle() * d.axis();
    if (!dtheta.allFinite()) dtheta.setZero();
  }
  last_rot_ = R;
  have_rot_ = true;
  // Work of last tick's command over the rotation since (J -> mJ).
  if (in_contact)
    rot_energy_mJ_ += 1e3 * last_tau_.dot(dtheta);
  else
    rot_energy_mJ_ = 0;
  if (dt_s > 0 && dt_s < 0.1) omega_ += 0.3 * (dtheta / dt_s - omega_);  // one-pole low-pass, as the interpolator's
  Eigen::Vector3d out = tau;
  if (passivity_on_ && in_contact) {
    const double lever_m = 1e-3 * interp_.lever_mm().norm();
    const double T = std::max(period_s_, interp_.model_interval_ns() * 1e-9);
    const double k_rot = 1e3 * stiffness_N_per_mm_ * lever_m * lever_m;  // N·m/rad (k in N/m)
    Eigen::Vector3d damp = -(margin_ * k_rot * T / 2) * omega_;
    const double tn = tau.norm(), dn = damp.norm();
    if (dn > tn && dn > 0) damp *= tn / dn;
    out += damp;
    // The observer: the torque along this tick's rotation is what does work on the next one.
    const double w2 = dtheta.squaredNorm();
    if (rot_energy_mJ_ > 0 && w2 > 0) {
      const double along = out.dot(dtheta) / w2;  // N·m per rad of rotation
      const double need = 1e-3 * rot_energy_mJ_ / w2;
      const double take = std::min(std::max(along, 0.0) + need, std::max(along, 0.0) + out.norm() / std::sqrt(w2));
      out -= take * dtheta;
      ++rot_guard_ticks_;
    }
  }
  if (!out.allFinite()) out.setZero();
  return out;
}

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
  // Friction at the tool point, under the surface's normal force after the guard.
  Eigen::Vector3d ft = Eigen::Vector3d::Zero();
  if (friction_.enabled()) {
    const double fn = have_pose && interp_.state().in_contact ? std::max(0.0, guarded.dot(n)) : 0.0;
    ft = friction_.apply(have_pose ? Eigen::Vector3d(pose * wrench_.tcp_mm) : Eigen::Vector3d::Zero(), n, fn, dt_s);
  }
  const Eigen::Vector3d total = guarded + ft;
  const Eigen::Vector3d f = sat_.apply(total, dt_s);
  // The guard observes the surface's part of what was commanded (the saturator scales the sum).
  const double tn = total.norm();
  guard_.commanded(ft.isZero() ? f : Eigen::Vector3d(f - (tn > 0 ? f.norm() / tn : 0.0) * ft));
  if (sat_.limited()) ++stats_.saturated;
  // The torque: the commanded force's moment about the tool point (its lever arm from the
  // interpolator), within the torque ceiling; commanded to 6-DOF devices only.
  Eigen::Vector3d tau = 1e-3 * interp_.lever_mm().cross(f);
  if (!tau.allFinite()) tau.setZero();
  const double tau_norm = tau.norm();
  if (tau_norm > peak_torque_Nm_) peak_torque_Nm_ = tau_norm;
  if (wrench_.dof == 6) {
    tau = have_pose ? guard_torque(tau, pose.linear(), interp_.state().in_contact, dt_s) : Eigen::Vector3d::Zero();
    const double tn = tau.norm();
    if (tn > torque_ceiling_Nm_) tau *= torque_ceiling_Nm_ > 0 ? torque_ceiling_Nm_ / tn : 0.0;
    last_tau_ = tau;
    device_.command_wrench(now, f, tau);
  } else {
    device_.command_force(now, f);
  }
  ++stats_.ticks;
  const double f_norm = f.norm();
  if (f_norm > peak_force_N_) peak_force_N_ = f_norm;
  const std::uint32_t flags = (interp_.state().in_contact ? kTickInContact : 0u) |
                              (sat_.limited() ? kTickSaturated : 0u) | (have_pose ? 0u : kTickNoPose) |
                              (friction_.stuck() ? kTickStuck : 0u) | (friction_.sliding() ? kTickSliding : 0u);
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
    for (int i = 0; i < 3; ++i) st.torque_Nm[i] = tau(i);
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
