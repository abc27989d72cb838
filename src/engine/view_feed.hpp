// ViewFeed: what the collision thread shows a live viewer (spheretouch run --view): the newest
// round's pose, its colliding probe and object faces and the contact model, at most `rate_hz`
// times a second. The collision thread fills a frame only when one is due (a few tens of
// microseconds each time, not every round) and publishes it through a triple buffer: it never
// waits for the viewer, and the viewer never sees a frame being written.
#pragma once
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <span>

#include "geom/contact.hpp"
#include "rt/clock.hpp"
#include "rt/triple_buffer.hpp"

namespace st::engine {

/// Colliding faces a frame carries per body; more are counted (ViewFrame::kTruncated).
inline constexpr std::uint32_t kViewMaxFaces = 16384;

struct ViewFrame {
  static constexpr std::uint32_t kInContact = 1, kTruncated = 2;
  std::uint64_t round = 0;                                 ///< collision round (0: no frame yet)
  std::uint64_t pose_seq = 0;                              ///< the pose it answered
  std::int64_t made_ns = 0;                                ///< when the frame was filled, CLOCK_MONOTONIC
  double pose[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};  ///< probe → object file coordinates, rows of [R | t]
  double force_dir[3] = {};                                ///< the contact model's FD
  double contact_point[3] = {};                            ///< its contact point, object file coordinates
  double penetration_mm = 0;                               ///< its PD
  double round_ms = 0;                                     ///< the round's time
  std::uint32_t contacts = 0;                              ///< paper §3.5 contacts
  std::uint32_t flags = 0;                                 ///< kInContact, kTruncated
  std::uint32_t n_probe = 0, n_object = 0;                 ///< colliding faces listed below (distinct, ascending)
  std::uint32_t probe_faces[kViewMaxFaces];
  std::uint32_t object_faces[kViewMaxFaces];
};
static_assert(std::is_trivially_copyable_v<ViewFrame>);

class ViewFeed {
 public:
  explicit ViewFeed(double rate_hz = 60) : period_ns_(std::int64_t(1e9 / std::max(1.0, rate_hz))) {}
  /// Collision thread, after each round: fills and publishes a frame when one is due.
  void offer(std::uint64_t round, std::uint64_t pose_seq, const geom::Pose& pose, std::span<const geom::FacePair> pairs,
             const geom::ContactModel& m, std::int64_t round_ns) noexcept {
    const std::int64_t now = rt::now_ns();
    if (now - last_ns_ < period_ns_) return;
    last_ns_ = now;
    ViewFrame& f = frames_.input();
    f.round = round;
    f.pose_seq = pose_seq;
    f.made_ns = now;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) f.pose[4 * r + c] = pose.matrix()(r, c);
    const double fd[3] = {m.force_dir.x, m.force_dir.y, m.force_dir.z};
    const double cp[3] = {m.contact_point.x, m.contact_point.y, m.contact_point.z};
    std::copy(fd, fd + 3, f.force_dir);
    std::copy(cp, cp + 3, f.contact_point);
    f.penetration_mm = m.penetration_mm;
    f.round_ms = double(round_ns) * 1e-6;
    f.contacts = m.contacts;
    f.flags = m.in_contact() ? ViewFrame::kInContact : 0;
    f.n_probe = f.n_object = 0;
    for (const geom::FacePair& p : pairs) {
      if (f.n_probe == kViewMaxFaces || f.n_object == kViewMaxFaces) {
        f.flags |= ViewFrame::kTruncated;
        break;
      }
      f.probe_faces[f.n_probe++] = p.probe;
      f.object_faces[f.n_object++] = p.object;
    }
    f.n_probe = distinct(f.probe_faces, f.n_probe);
    f.n_object = distinct(f.object_faces, f.n_object);
    frames_.publish();
  }
  /// Viewer thread: the newest frame, if one came since the last call.
  bool take(ViewFrame& out) noexcept {
    if (!frames_.update()) return false;
    out = frames_.output();
    return true;
  }

 private:
  static std::uint32_t distinct(std::uint32_t* a, std::uint32_t n) {
    std::sort(a, a + n);
    return std::uint32_t(std::unique(a, a + n) - a);
  }
  std::int64_t period_ns_;
  std::int64_t last_ns_ = 0;
  rt::TripleBuffer<ViewFrame> frames_;
};

}  // namespace st::engine
