// SPDX-License-Identifier: BSD-3-Clause
#include <spheretouch/rt/interpolator.hpp>

#include <algorithm>
#include <cmath>
#include <sstream>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/rt/constants.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

Result<InterpMode> parse_interp_mode(std::string_view name) {
  if (name == "hold") return InterpMode::hold;
  if (name == "paper") return InterpMode::paper;
  if (name == "plane") return InterpMode::plane;
  return fail("interpolation '", std::string(name), "': expected hold, paper or plane");
}

const char* to_string(InterpMode mode) {
  switch (mode) {
    case InterpMode::hold:
      return "hold";
    case InterpMode::paper:
      return "paper";
    case InterpMode::plane:
      return "plane";
  }
  return "?";
}

InterpolatorConfig DefaultInterpolatorConfig() { return InterpolatorConfig{}; }

std::string Interpolator::check(const InterpolatorConfig& c) {
  std::ostringstream os;
  if (c.stale_timeout_ns <= 0)
    os << "interpolation: stale_timeout_ns = " << c.stale_timeout_ns << ", expected > 0";
  else if (c.fade_ns < 0)
    os << "interpolation: fade_ns = " << c.fade_ns << ", expected >= 0";
  else if (c.crossfade_ns < 0)
    os << "interpolation: crossfade_ns = " << c.crossfade_ns << ", expected >= 0";
  else if (!(std::isfinite(c.paper_gain_N_per_mm) && c.paper_gain_N_per_mm >= 0))
    os << "interpolation: paper_gain_N_per_mm = " << c.paper_gain_N_per_mm << ", expected a finite value >= 0";
  else if (!(std::isfinite(c.paper_max_move_mm) && c.paper_max_move_mm >= 0))
    os << "interpolation: paper_max_move_mm = " << c.paper_max_move_mm << ", expected a finite value >= 0";
  else if (!(std::isfinite(c.damping_N_s_per_mm) && c.damping_N_s_per_mm >= 0))
    os << "interpolation: damping_N_s_per_mm = " << c.damping_N_s_per_mm << ", expected a finite value >= 0";
  return os.str();
}

Interpolator::Interpolator(const ForceLaw& law, const InterpolatorConfig& config) : law_(law), c_(config) {
  ST_ASSERT(check(config).empty(), "an Interpolator's config passes check() (interpolator.hpp)");
}

namespace {
bool model_ok(const geom::ContactModel& m) {
  if (!geom::finite(m.pose) || !std::isfinite(m.penetration_mm) || m.penetration_mm < 0) return false;
  if (!m.in_contact()) return true;
  if (!geom::finite(m.force_dir) || !geom::finite(m.probe_point) || !geom::finite(m.plane_point)) return false;
  const double n = geom::to_eigen(m.force_dir).norm();
  return std::abs(n - 1.0) <= 1e-6;
}
}  // namespace

double Interpolator::crossfade_span() const noexcept {
  const double span = static_cast<double>(c_.crossfade_ns);
  return interval_ns_ > 0 ? std::min(span, kCrossfadeRounds * interval_ns_) : span;
}

void Interpolator::on_model(const geom::ContactModel& model, std::int64_t now_ns) noexcept {
  const bool ok = model_ok(model), was_contact = contact_;
  const bool new_contact = ok && model.in_contact();
  // The model in use until now, for the cross-fade (evaluated at the pose of the next tick). A
  // release in progress keeps the model it releases while further no-contact models arrive.
  if (!pending_offset_ && !(releasing_ && !new_contact)) {
    prev_contact_ = contact_;
    prev_fd_ = fd_;
    prev_probe_point_ = probe_point_;
    prev_plane_point_ = plane_point_;
    prev_offset_ = offset_;
    prev_fade_ = state_.fade;
    const double faded = static_cast<double>(std::max<std::int64_t>(now_ns - received_ns_, 0));
    const double span = crossfade_span();
    prev_weight_ = (have_model_ && span > 0 && faded < span) ? 1.0 - faded / span : 0.0;
  }
  if (have_model_ && now_ns > received_ns_) {
    const double gap = static_cast<double>(now_ns - received_ns_);
    interval_ns_ = interval_ns_ > 0 ? 0.8 * interval_ns_ + 0.2 * gap : gap;
  }
  model_ = model;
  if (!ok) {
    ++rejected_;
    model_.flags &= ~geom::kInContact;  // garbage from the collision side renders as no contact
  }
  have_model_ = true;
  received_ns_ = now_ns;
  contact_ = model_.in_contact();
  pending_offset_ = true;
  if (contact_) {
    releasing_ = false;
  } else if (was_contact && c_.mode == InterpMode::plane) {
    releasing_ = true;
    release_ns_ = now_ns;
  }
  if (!contact_) {
    fd_.setZero();
    force_a_.setZero();
    return;
  }
  // The lever arm of the force about the tool point, carried with the probe (probe frame); the
  // one in use cross-fades to it like the force does.
  lever_ = geom::to_eigen(model_.pose).inverse() * geom::to_eigen(model_.pressure_point) - tcp_;
  if (!lever_.allFinite()) lever_.setZero();
  lever_from_ = have_lever_ ? last_lever_ : lever_;
  fd_ = geom::to_eigen(model_.force_dir).normalized();
  probe_point_ = geom::to_eigen(model_.probe_point);
  plane_point_ = geom::to_eigen(model_.plane_point);
  anchor_ = geom::to_eigen(model_.pose) * probe_point_;
  force_a_ = law_.magnitude_N(model_.penetration_mm) * fd_;
}

Eigen::Vector3d Interpolator::force(const Eigen::Isometry3d& pose, std::int64_t now_ns) noexcept {
  const double dt_s = last_ns_ ? static_cast<double>(now_ns - last_ns_) * 1e-9 : 0.0;
  last_ns_ = now_ns;
  state_ = InterpState{};
  torque_.setZero();
  lever_out_.setZero();
  if (!pose.matrix().allFinite()) {
    ++bad_poses_;
    last_out_.setZero();
    return Eigen::Vector3d::Zero();
  }
  if (!have_model_) return Eigen::Vector3d::Zero();

  // Staleness: measured from the local arrival of the newest model.
  const std::int64_t idle = now_ns - received_ns_;
  double fade = 1.0;
  if (idle > c_.stale_timeout_ns) {
    fade = c_.fade_ns > 0 ? 1.0 - static_cast<double>(idle - c_.stale_timeout_ns) / static_cast<double>(c_.fade_ns) : 0.0;
    fade = std::clamp(fade, 0.0, 1.0);
  }

  Eigen::Vector3d f = Eigen::Vector3d::Zero();
  double pd = 0;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  Eigen::Vector3d lever = lever_;  // the lever arm of this tick's force (probe frame)
  if (contact_) {
    p = pose * probe_point_;
    switch (c_.mode) {
      case InterpMode::hold:
        f = force_a_;
        pd = model_.penetration_mm;
        break;
      case InterpMode::paper: {
        Eigen::Vector3d d = p - anchor_;  // §3.7 D: movement of the probe since the model's pose
        const double dn = d.norm();
        if (dn > c_.paper_max_move_mm) d *= c_.paper_max_move_mm / dn;
        f = force_a_ - c_.paper_gain_N_per_mm * d;  // moving into the surface (against FD) pushes harder
        const double along = f.dot(fd_);
        if (along < 0) f -= along * fd_;  // never pull the probe into the object
        pd = model_.penetration_mm - d.dot(fd_);
        break;
      }
      case InterpMode::plane:
        pd = (plane_point_ - p).dot(fd_);
        f = law_.magnitude_N(pd) * fd_;
        break;
    }
  }
  if (c_.mode == InterpMode::plane && releasing_) {
    // The contact ended: the old model at this pose, fading out over kReleaseFadeNs, never rising.
    const double w = 1.0 - static_cast<double>(std::max<std::int64_t>(now_ns - release_ns_, 0)) / kReleaseFadeNs;
    lever = last_lever_;  // the released model's
    if (w > 0 && prev_contact_) {
      p = pose * prev_probe_point_;
      pd = (prev_plane_point_ - p).dot(prev_fd_);
      f = (w * prev_fade_ * law_.magnitude_N(pd)) * prev_fd_;
      const double cap = last_out_.norm(), fn = f.norm();
      if (fn > cap) f *= cap / fn;
    } else {
      releasing_ = false;
    }
    pending_offset_ = false;
    offset_.setZero();
  } else if (c_.mode == InterpMode::plane) {
    // Cross-fade: the jump a new model would cause decays linearly over crossfade_ns (or
    // kCrossfadeRounds model intervals, if shorter).
    if (pending_offset_) {
      // The old model at THIS pose (plus what was still left of its own cross-fade) minus the new
      // one at this pose: only the models' disagreement is faded, never the probe's motion.
      Eigen::Vector3d old = prev_weight_ * prev_offset_;
      if (prev_contact_) {
        const double old_pd = (prev_plane_point_ - pose * prev_probe_point_).dot(prev_fd_);
        old += law_.magnitude_N(old_pd) * prev_fd_;
      }
      old *= prev_fade_;  // a stale, fading old model hands over what it was rendering
      offset_ = c_.crossfade_ns > 0 && old.allFinite() ? Eigen::Vector3d(old - f) : Eigen::Vector3d::Zero();
      pending_offset_ = false;
    }
    // The fade counts the current tick too (idle + dt): a model arriving every tick must still
    // let the output move. Otherwise the offset is re-taken at full weight on each arrival and
    // the force freezes at its old value while updates stream in (found in `spheretouch run`).
    // With arrivals every tick this is exponential smoothing with time constant ~crossfade_ns.
    const double faded = static_cast<double>(std::max<std::int64_t>(idle, 0)) + dt_s * 1e9;
    const double span = crossfade_span();
    if (span > 0 && faded < span) {
      f += offset_ * (1.0 - faded / span);
      lever += (lever_from_ - lever_) * (1.0 - faded / span);
    }
  } else {
    pending_offset_ = false;
  }
  if (contact_ && c_.damping_N_s_per_mm > 0) {
    if (!have_last_point_) velocity_fd_ = 0;
    if (dt_s > 0 && dt_s < 0.1 && have_last_point_) {
      const double v = (p - last_point_).dot(fd_) / dt_s;  // mm/s, + = leaving the surface
      velocity_fd_ += 0.3 * (v - velocity_fd_);            // one-pole low-pass, ~57 Hz at 1 kHz
    }
    const double along = f.dot(fd_);
    if (along > 0) {
      double fd_damp = -c_.damping_N_s_per_mm * velocity_fd_;
      if (along + fd_damp < 0) fd_damp = -along;  // damping never pulls
      f += fd_damp * fd_;
    }
  }
  last_point_ = p;
  have_last_point_ = contact_;
  if (!f.allFinite()) f.setZero();
  if ((f * fade).norm() < kMinRenderedForceN) f.setZero();  // a released force reaches exactly 0
  last_out_ = f * fade;  // what was commanded: the next cross-fade starts from it (even after a stall)
  // The torque about the tool point: the force at the pressure point, mm -> m.
  lever_out_ = last_out_.squaredNorm() > 0 ? Eigen::Vector3d(pose.linear() * lever) : Eigen::Vector3d::Zero();
  if (!lever_out_.allFinite()) lever_out_.setZero();
  torque_ = 1e-3 * lever_out_.cross(last_out_);
  if (contact_) {
    last_lever_ = lever;
    have_lever_ = true;
  } else if (!releasing_) {
    have_lever_ = false;
  }
  state_.penetration_mm = std::isfinite(pd) ? pd : 0.0;
  state_.fade = fade;
  state_.raw_force_N = f.norm();
  state_.in_contact = contact_;
  return f * fade;
}

}  // namespace st::rt
