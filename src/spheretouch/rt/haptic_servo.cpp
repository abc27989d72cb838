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
  for (Channel& c : channels_) c.interp.set_tool_point(config.tcp_mm);
  const double dev = device_.max_torque_Nm();
  torque_ceiling_Nm_ = config.dof == 6 ? std::min(config.torque_limit_Nm, std::isfinite(dev) && dev > 0 ? dev : 0.0) : 0.0;
}

HapticServo::Channel HapticServo::make_channel(const ForceLaw& law, double damping_N_s_per_mm,
                                               const FrictionConfig& friction) const {
  InterpolatorConfig ic = interp_config_;
  ic.damping_N_s_per_mm = damping_N_s_per_mm;
  const double k = law.max_stiffness_N_per_mm();
  return Channel{Interpolator(law, ic), PassivityGuard(passivity_config_, k, period_s_),
                 Friction(friction, k, period_s_), k};
}

HapticServo::HapticServo(Device& device, TripleBuffer<PoseSample>& poses, TripleBuffer<geom::ContactSet>& models,
                         const ForceLaw& law, const InterpolatorConfig& interp, SaturationConfig saturation,
                         Telemetry* telemetry, const PassivityConfig& passivity, double period_s)
    : device_(device),
      poses_(poses),
      models_(models),
      interp_config_(interp),
      passivity_config_(passivity),
      sat_(capped(saturation, device)),
      telemetry_(telemetry),
      passivity_on_(passivity.enabled),
      margin_(passivity.colgate_margin),
      period_s_(period_s) {
  channels_.push_back(make_channel(law, interp.damping_N_s_per_mm, FrictionConfig{}));
  channels_[0].live = true;  // one object: ticked from the start, as it always was
}

void HapticServo::set_friction(const FrictionConfig& config) {
  ST_ASSERT(check(config).empty(), "the friction config passed check()");
  channels_[0].friction = Friction(config, channels_[0].k_N_per_mm, period_s_);
}

void HapticServo::set_objects(const std::vector<ObjectMaterial>& materials) {
  ST_ASSERT(!materials.empty(), "at least one object");
  std::vector<Channel> ch;
  ch.reserve(materials.size());
  for (const ObjectMaterial& m : materials) {
    ST_ASSERT(check(m.friction).empty(), "the friction config passed check()");
    ch.push_back(make_channel(m.law, m.damping_N_s_per_mm, m.friction));
  }
  // One object renders as it always did (ticked from the start); of several, each from its first model.
  if (ch.size() == 1) ch[0].live = true;
  channels_ = std::move(ch);
  for (Channel& c : channels_) c.interp.set_tool_point(wrench_.tcp_mm);
}

FrictionStats HapticServo::friction_stats() const {
  FrictionStats s;
  for (const Channel& c : channels_) {
    const FrictionStats& f = c.friction.stats();
    s.stuck_ticks += f.stuck_ticks;
    s.sliding_ticks += f.sliding_ticks;
    s.breakaways += f.breakaways;
    s.sticks += f.sticks;
  }
  return s;
}

std::uint64_t HapticServo::passivity_active_ticks() const {
  std::uint64_t n = 0;
  for (const Channel& c : channels_) n += c.guard.active_ticks();
  return n;
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
    const Channel& c = channels_[primary_];
    const double lever_m = 1e-3 * c.interp.lever_mm().norm();
    const double T = std::max(period_s_, c.interp.model_interval_ns() * 1e-9);
    const double k_rot = 1e3 * c.k_N_per_mm * lever_m * lever_m;  // N·m/rad (k in N/m)
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
    const geom::ContactSet& set = models_.output();
    const std::uint32_t n = std::min(set.count, geom::kMaxContactObjects);
    for (std::uint32_t i = 0; i < n; ++i) {
      if (set.object[i] >= channels_.size()) {
        ++stats_.bad_objects;
        continue;
      }
      Channel& c = channels_[set.object[i]];
      c.interp.on_model(set.models[i], now);
      c.live = true;
    }
    set_seq_ = set.seq;
    model_pose_ns_ = set.pose_sampled_ns;
    model_received_ns_ = now;
    model_contacts_ = set.contacts;
    ++stats_.models;
  }
  const double dt_s = last_ns_ ? static_cast<double>(now - last_ns_) * 1e-9 : 0.0;
  last_ns_ = now;
  // Each object's force: interpolated, guarded (the guard acts while that surface pushes: a
  // contact cycle = its force above zero), plus its friction at the tool point under its normal
  // force after the guard. The deepest touching object is the primary one (telemetry).
  Eigen::Vector3d total = Eigen::Vector3d::Zero();
  bool in_contact = false, stuck = false, sliding = false;
  std::size_t live = 0;
  double deepest = -1;
  std::size_t first_live = 0;
  for (std::size_t i = 0; i < channels_.size(); ++i) {
    Channel& c = channels_[i];
    if (!c.live) continue;
    if (live++ == 0) first_live = i;
    const Eigen::Vector3d raw = have_pose ? c.interp.force(pose, now) : Eigen::Vector3d::Zero();
    const Eigen::Vector3d n = raw.squaredNorm() > 0 ? c.interp.normal() : Eigen::Vector3d::Zero();
    c.guarded = have_pose ? c.guard.apply(raw, pose.translation(), n, dt_s) : raw;
    c.ft.setZero();
    const bool touching = c.interp.state().in_contact;
    if (c.friction.enabled()) {
      const double fn = have_pose && touching ? std::max(0.0, c.guarded.dot(n)) : 0.0;
      c.ft = c.friction.apply(have_pose ? Eigen::Vector3d(pose * wrench_.tcp_mm) : Eigen::Vector3d::Zero(), n, fn, dt_s);
    }
    total += c.guarded + c.ft;
    in_contact |= touching;
    stuck |= c.friction.stuck();
    sliding |= c.friction.sliding();
    if (touching && c.interp.state().penetration_mm > deepest) {
      deepest = c.interp.state().penetration_mm;
      primary_ = i;
    }
  }
  if (deepest < 0) primary_ = first_live;  // none touching: the first live object's (releasing) force
  const Channel& primary = channels_[primary_];
  const Eigen::Vector3d f = sat_.apply(total, dt_s);
  // Each guard observes its own surface's part of what was commanded (the saturator scales the sum).
  const double tn = total.norm();
  const double scale = tn > 0 ? f.norm() / tn : 0.0;
  for (Channel& c : channels_) {
    if (!c.live) continue;
    if (live == 1)
      c.guard.commanded(c.ft.isZero() ? f : Eigen::Vector3d(f - scale * c.ft));
    else
      c.guard.commanded(scale * c.guarded);
  }
  if (sat_.limited()) ++stats_.saturated;
  // The torque: the commanded force's moment about the tool point (each object's force at its
  // lever arm from its interpolator), within the torque ceiling; commanded to 6-DOF devices only.
  Eigen::Vector3d tau = Eigen::Vector3d::Zero();
  if (live == 1) {
    tau = 1e-3 * primary.interp.lever_mm().cross(f);
  } else {
    for (const Channel& c : channels_)
      if (c.live) tau += 1e-3 * c.interp.lever_mm().cross(Eigen::Vector3d(scale * (c.guarded + c.ft)));
  }
  if (!tau.allFinite()) tau.setZero();
  const double tau_norm = tau.norm();
  if (tau_norm > peak_torque_Nm_) peak_torque_Nm_ = tau_norm;
  if (wrench_.dof == 6) {
    tau = have_pose ? guard_torque(tau, pose.linear(), in_contact, dt_s) : Eigen::Vector3d::Zero();
    const double tq = tau.norm();
    if (tq > torque_ceiling_Nm_) tau *= torque_ceiling_Nm_ > 0 ? torque_ceiling_Nm_ / tq : 0.0;
    last_tau_ = tau;
    device_.command_wrench(now, f, tau);
  } else {
    device_.command_force(now, f);
  }
  ++stats_.ticks;
  const double f_norm = f.norm();
  if (f_norm > peak_force_N_) peak_force_N_ = f_norm;
  const std::uint32_t flags = (in_contact ? kTickInContact : 0u) | (sat_.limited() ? kTickSaturated : 0u) |
                              (have_pose ? 0u : kTickNoPose) | (stuck ? kTickStuck : 0u) | (sliding ? kTickSliding : 0u);
  const InterpState& ps = primary.interp.state();
  if (status_ && info.tick % kStatusEveryTicks == 0) {
    ServoStatus st;
    st.updated_ns = now;
    st.ticks = info.tick + 1;
    st.misses = info.deadline_index - info.tick;
    st.pose_seq = pose_seq_;
    st.pose_sampled_ns = pose_ns_;
    st.model_seq = set_seq_;
    st.model_received_ns = model_received_ns_;
    st.model_pose_ns = model_pose_ns_;
    st.models = stats_.models;
    for (int i = 0; i < 3; ++i) st.force_N[i] = f(i);
    st.peak_force_N = peak_force_N_;
    st.penetration_mm = ps.penetration_mm;
    st.fade = ps.fade;
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
    s.model_seq = set_seq_;
    s.model_age_ns = model_pose_ns_ ? now - model_pose_ns_ : -1;
    if (have_pose) {
      // The proxy: the probe moved out of the object by the depth along the contact normal.
      const double pd = ps.in_contact ? std::max(0.0, ps.penetration_mm) : 0.0;
      const Eigen::Vector3d proxy = pose.translation() + pd * primary.interp.normal();
      for (int i = 0; i < 3; ++i) {
        s.position_mm[i] = pose.translation()(i);
        s.proxy_mm[i] = proxy(i);
      }
    }
    for (int i = 0; i < 3; ++i) {
      s.force_N[i] = f(i);
      s.torque_Nm[i] = tau(i);
    }
    s.penetration_mm = ps.penetration_mm;
    s.fade = ps.fade;
    s.ceiling_N = sat_.ceiling_N();
    s.flags = flags;
    s.misses = static_cast<std::uint32_t>(info.deadline_index - info.tick);
    telemetry_->push(s);
  }
}

}  // namespace st::rt
