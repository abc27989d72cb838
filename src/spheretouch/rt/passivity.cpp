// SPDX-License-Identifier: BSD-3-Clause
#include <spheretouch/rt/passivity.hpp>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace st::inline SPHERETOUCH_ABI::rt {

namespace {
/// Energy over which the passivity controller fades in before the predicted end-of-cycle energy
/// reaches zero, mJ: a few percent of a light press's stored energy (a 1 mm press on the default
/// law holds ~0.3 mJ), so the controller is fully on by the time it is needed.
constexpr double kRampMJ = 0.02;
/// The controller spreads an excess over this many ticks (it asks for excess / kSpreadTicks a
/// tick): taking it all in one tick drops the force, the observer then sees no excess, the force
/// comes back, and a fast release chatters (1.30, 0.31, 1.00, 0.54 N on successive ticks).
constexpr double kSpreadTicks = 4;
/// Per tick, the damper keeps at least this share of last tick's value while it is needed: it
/// lets go over ~10 ticks instead of switching off, so the force it takes away comes back
/// without a step (and never with a sign reversal of the force's change).
constexpr double kDamperHold = 0.8;
}  // namespace

PassivityConfig DefaultPassivityConfig() { return PassivityConfig{}; }

std::string PassivityGuard::check(const PassivityConfig& c) {
  std::ostringstream os;
  if (!(std::isfinite(c.colgate_margin) && c.colgate_margin >= 0 && c.colgate_margin <= 100))
    os << "passivity: colgate_margin = " << c.colgate_margin << ", expected a value in [0, 100]";
  else if (!(std::isfinite(c.max_damping_N_s_per_mm) && c.max_damping_N_s_per_mm >= 0 && c.max_damping_N_s_per_mm <= 10))
    os << "passivity: max_damping_n_s_per_mm = " << c.max_damping_N_s_per_mm << ", expected a value in [0, 10]";
  return os.str();
}

PassivityGuard::PassivityGuard(const PassivityConfig& config, double stiffness_N_per_mm, double period_s)
    : c_(config),
      b_min_(config.colgate_margin * std::max(stiffness_N_per_mm, 0.0) * std::max(period_s, 0.0) / 2),
      k_(std::isfinite(stiffness_N_per_mm) ? std::max(stiffness_N_per_mm, 0.0) : 0.0),
      period_s_(period_s > 0 ? period_s : 1e-3) {}

void PassivityGuard::reset() noexcept {
  last_x_.setZero();
  last_f_.setZero();
  vn_ = 0;
  alpha_ = 0;
  energy_ = 0;
  have_x_ = false;
  contact_ = false;
  state_ = PassivityState{};
}

Eigen::Vector3d PassivityGuard::apply(const Eigen::Vector3d& f, const Eigen::Vector3d& x_mm, const Eigen::Vector3d& n,
                                      double dt_s) noexcept {
  state_ = PassivityState{};
  if (!c_.enabled) return f;
  if (!x_mm.allFinite() || !f.allFinite()) {
    have_x_ = false;
    return f;
  }
  const double dt = (dt_s > 0 && dt_s < 0.1) ? dt_s : period_s_;
  const bool contact = n.allFinite() && n.squaredNorm() > 0.25;
  // Observer: what the force commanded last tick did over the motion since (zero-order hold).
  Eigen::Vector3d dx = Eigen::Vector3d::Zero();
  if (have_x_) {
    dx = x_mm - last_x_;
    energy_ += last_f_.dot(dx);
  }
  last_x_ = x_mm;
  have_x_ = true;
  if (contact != contact_) {
    // A cycle ends or begins: the surface keeps no credit for what it absorbed, only a debt.
    energy_ = std::max(energy_, 0.0);
    vn_ = 0;
    alpha_ = 0;
    contact_ = contact;
  }
  state_.energy_mJ = energy_;
  if (!contact) return f;

  // Normal velocity, + = leaving the surface; a one-pole low-pass (~57 Hz at 1 kHz) so encoder
  // quantisation on a real device does not turn into buzz.
  const double vn_raw = dx.dot(n) / dt;
  vn_ += 0.3 * (vn_raw - vn_);

  double add = -b_min_ * vn_;  // stage 1: Colgate's minimum damping
  // Stage 2 acts on the energy the cycle would end with if the surface gave back what it holds
  // now: E + U, U = F_n²/(2k) (exact on the law's linear part, where every release ends; below the
  // stored energy on the log part). Acting on E alone would notice the excess only in the last
  // ticks of a release, when the force left is too small to take it back without pulling. The
  // damper fades in over the last kRampMJ before that energy reaches zero, and never takes more
  // than the excess over one tick, so it switches on and off without a force step (an on/off
  // passivity controller buzzes).
  const double fn = std::max(f.dot(n), 0.0);
  const double predicted = energy_ + (k_ > 0 ? fn * fn / (2 * k_) : 0.0);
  const double excess = predicted + kRampMJ;
  // Only while leaving the surface: a zero-order hold gives energy back on the way out. On the
  // way in the prediction runs a tick ahead of the observer (it already counts the new force's
  // stored energy), and damping there would only stiffen a fast press.
  // The damper asks for the excess over kSpreadTicks ticks and lets go gradually (kDamperHold):
  // it may dissipate a little more than the excess (passive), never switches off in one tick.
  double alpha = 0;
  if (vn_ > 1e-9) {
    if (excess > 0) {
      const double ramp = std::min(excess / kRampMJ, 1.0);
      alpha = std::min(c_.max_damping_N_s_per_mm * ramp, excess / (kSpreadTicks * dt * vn_ * vn_));
    }
    alpha = std::min(std::max(alpha, kDamperHold * alpha_), c_.max_damping_N_s_per_mm);
  }
  alpha_ = alpha;
  if (alpha > 0) {
    add -= alpha * vn_;
    state_.active = true;
    ++active_ticks_;
  }
  Eigen::Vector3d out = f + add * n;
  const double along = out.dot(n);
  if (along < 0) out -= along * n;  // the guard never makes the surface pull
  state_.damping_N = (out - f).dot(n);
  return out;
}

}  // namespace st::rt
