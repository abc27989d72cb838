// SPDX-License-Identifier: BSD-3-Clause
// Friction: see friction.hpp for the model and why it is passive.
#include <spheretouch/rt/friction.hpp>

#include <algorithm>
#include <cmath>

namespace st::inline SPHERETOUCH_ABI::rt {

std::string check(const FrictionConfig& c) {
  if (!(c.dynamic_mu >= 0) || !(c.dynamic_mu <= 10)) return "dynamic_friction: must be in [0, 10]";
  if (!(c.static_mu >= 0) || !(c.static_mu <= 10)) return "static_friction: must be in [0, 10]";
  if (c.dynamic_mu > c.static_mu)
    return "dynamic_friction: must not exceed static_friction (a contact that slides harder than it sticks never "
           "sticks)";
  if (!(c.stiffness_N_per_mm >= 0) || !std::isfinite(c.stiffness_N_per_mm))
    return "friction_stiffness_n_per_mm: must be a finite number >= 0 (0: the force law's steepest slope)";
  if (!(c.damping_margin >= 0) || !(c.damping_margin <= 100)) return "friction damping margin: must be in [0, 100]";
  return {};
}

Friction::Friction(const FrictionConfig& config, double law_stiffness_N_per_mm, double period_s)
    : config_(config),
      k_(config.stiffness_N_per_mm > 0 ? config.stiffness_N_per_mm : law_stiffness_N_per_mm),
      b_(config.damping_margin * k_ * period_s / 2),
      period_s_(period_s) {}

Eigen::Vector3d Friction::apply(const Eigen::Vector3d& p_mm, const Eigen::Vector3d& n, double fn_N, double dt_s) noexcept {
  if (!enabled() || !(fn_N > 0) || !std::isfinite(fn_N) || !p_mm.allFinite() || !n.allFinite() ||
      !(n.squaredNorm() > 0.25) || !(k_ > 0)) {
    in_contact_ = false;
    return Eigen::Vector3d::Zero();
  }
  const Eigen::Vector3d nn = n.normalized();
  const auto tangential = [&](const Eigen::Vector3d& v) -> Eigen::Vector3d { return v - v.dot(nn) * nn; };
  if (!in_contact_) {  // a contact begins: stuck where the tool point touched
    in_contact_ = true;
    stuck_ = true;
    stick_ = p_mm;
    last_p_ = p_mm;
    last_d_.setZero();
    v_.setZero();
  }
  const double dt = (dt_s > 0 && dt_s < 0.1) ? dt_s : period_s_;
  v_ += 0.3 * (tangential(p_mm - last_p_) / dt - v_);  // one-pole low-pass, as the passivity guard's
  last_p_ = p_mm;
  // The offset in this tick's plane: a new contact plane re-projects, it never moves the stick point.
  Eigen::Vector3d d = tangential(p_mm - stick_);
  const double len = d.norm();
  if (stuck_) {
    if (k_ * len > config_.static_mu * fn_N) {
      stuck_ = false;
      ++stats_.breakaways;
    }
  } else if (len > 0 && (d - last_d_).dot(d) <= 0) {  // no longer moving away from the stick point
    stuck_ = true;
    ++stats_.sticks;
  }
  Eigen::Vector3d f;
  if (stuck_) {
    f = -k_ * d - b_ * v_;
    // The damping never pushes the force past the cone (it would break away on its own say-so).
    const double cap = config_.static_mu * fn_N, fl = f.norm();
    if (fl > cap) f *= cap / fl;
    ++stats_.stuck_ticks;
  } else {
    const double reach = config_.dynamic_mu * fn_N / k_;  // the offset at which the spring gives μd·Fn
    if (len > reach && len > 0) {
      d *= reach / len;
      stick_ = p_mm - d;  // dragged behind the tool point (in the plane through it)
    }
    f = -k_ * d;
    ++stats_.sliding_ticks;
  }
  last_d_ = d;
  return f.allFinite() ? f : Eigen::Vector3d::Zero();
}

}  // namespace st::rt
