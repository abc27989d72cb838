// SPDX-License-Identifier: BSD-3-Clause
// ViewFeed: what the collision thread shows a live viewer: the newest round's pose, its colliding
// probe and object faces and the contact model, at most rt::kViewRateHz times a second, as an
// rt::ViewFrame stored into the run's shared-memory status area (ShmStatus::view, a SeqLock).
// Every run publishes frames, so the run's own view (`run --view`) and a monitor attached at any
// time (`monitor --view`) read the same ones. The collision thread fills a frame only when one is
// due (a few tens of microseconds each time, not every round) and stores only the part in use:
// it never waits for a viewer, and a viewer never sees a frame being written.
#pragma once
#include <spheretouch/abi.hpp>
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>

#include <spheretouch/geom/contact.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/seqlock.hpp>
#include <spheretouch/rt/view_frame.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

class ViewFeed {
 public:
  /// Frames go to `out` (the run's ShmStatus::view), at most `rate_hz` a second.
  explicit ViewFeed(rt::SeqLock<rt::ViewFrame>& out, double rate_hz = rt::kViewRateHz)
      : out_(out), period_ns_(std::int64_t(1e9 / std::max(1.0, rate_hz))), frame_(std::make_unique<rt::ViewFrame>()) {}
  /// True when offer() would publish a frame now (at most rate_hz a second).
  bool due() const noexcept { return rt::now_ns() - last_ns_ >= period_ns_; }
  /// Collision thread, after each round: fills and publishes a frame when one is due. No
  /// allocation, no lock; the store is one pass over the frame's used words.
  void offer(std::uint64_t round, std::uint64_t pose_seq, const geom::Pose& pose, std::span<const geom::FacePair> pairs,
             const geom::ContactModel& m, std::int64_t round_ns) noexcept {
    const std::int64_t now = rt::now_ns();
    if (now - last_ns_ < period_ns_) return;
    last_ns_ = now;
    rt::ViewFrame& f = *frame_;
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
    f.flags = m.in_contact() ? rt::ViewFrame::kInContact : 0;
    // Probe ids in the first half, object ids in the second; each made distinct, then the
    // object's moved down behind the probe's.
    std::uint32_t* probe = f.faces;
    std::uint32_t* object = f.faces + rt::kViewMaxFaces;
    std::uint32_t n = 0;
    for (const geom::FacePair& p : pairs) {
      if (n == rt::kViewMaxFaces) {
        f.flags |= rt::ViewFrame::kTruncated;
        break;
      }
      probe[n] = p.probe;
      object[n] = p.object;
      ++n;
    }
    f.n_probe = distinct(probe, n);
    f.n_object = distinct(object, n);
    std::memmove(f.faces + f.n_probe, object, 4 * std::size_t(f.n_object));
    out_.store(f, f.used_bytes());
  }

 private:
  static std::uint32_t distinct(std::uint32_t* a, std::uint32_t n) {
    std::sort(a, a + n);
    return std::uint32_t(std::unique(a, a + n) - a);
  }
  rt::SeqLock<rt::ViewFrame>& out_;
  std::int64_t period_ns_;
  std::int64_t last_ns_ = 0;
  std::unique_ptr<rt::ViewFrame> frame_;  // filled here, then stored (128 KiB: not on the stack)
};

}  // namespace st::engine
