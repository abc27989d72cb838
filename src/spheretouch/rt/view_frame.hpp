// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// ViewFrame: what a live viewer shows of one collision round (the pose, the colliding probe and
/// object faces, the contact model). The collision thread publishes one at most kViewRateHz times
/// a second into the shared-memory status area (ShmStatus::view, a SeqLock), so the run's own
/// view and a monitor attached later (`spheretouch monitor --view`) read the same frames.
/// A frame read from a segment may have been written by anyone who can write the segment:
/// sanitize_view_frame() bounds it before a viewer uses it.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Colliding faces a frame carries per body; more are counted (ViewFrame::kTruncated). 16384 ids
/// cover a hand pressed flat into a million-face object; a frame is then 128 KiB.
inline constexpr std::uint32_t kViewMaxFaces = 16384;
/// Frames per second the collision thread publishes at most: a display's refresh rate (a page
/// draws no faster), and one frame fill (~tens of µs) per 16.7 ms keeps it off the round's cost.
inline constexpr double kViewRateHz = 60;

/// One collision round as a viewer shows it; plain data, published through a SeqLock.
struct ViewFrame {
  ///@{
  /// `flags` bits: in contact, face lists cut at kViewMaxFaces; kKnownFlags = every bit defined.
  static constexpr std::uint32_t kInContact = 1, kTruncated = 2, kKnownFlags = 3;
  ///@}
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
  ///@{
  std::uint32_t n_probe = 0, n_object = 0;  ///< colliding faces listed below
  ///@}
  /// Probe faces in [0, n_probe), then object faces in [n_probe, n_probe + n_object); each list
  /// distinct and ascending. One array, so the part in use is one prefix of the frame.
  std::uint32_t faces[2 * kViewMaxFaces];

  /// Bytes from the frame's start to the end of its face lists (counts clamped): what a writer
  /// must publish (SeqLock::store(v, bytes)).
  std::size_t used_bytes() const noexcept {
    const std::size_t n = std::size_t(n_probe < kViewMaxFaces ? n_probe : kViewMaxFaces) +
                          std::size_t(n_object < kViewMaxFaces ? n_object : kViewMaxFaces);
    return offsetof(ViewFrame, faces) + 4 * n;
  }
};
static_assert(std::is_trivially_copyable_v<ViewFrame> && std::is_standard_layout_v<ViewFrame>);
static_assert(offsetof(ViewFrame, faces) == 200 && sizeof(ViewFrame) == 200 + 8 * kViewMaxFaces);

/// Makes a frame that came through shared memory safe to send to a page that draws meshes of
/// `probe_faces` and `object_faces` faces: non-finite numbers become 0 and unknown flag bits are
/// cleared. False (refuse the frame) when a face count exceeds kViewMaxFaces or a face id is not
/// below its body's face count; `why` (may be null) then says which.
bool sanitize_view_frame(ViewFrame& f, std::uint32_t probe_faces, std::uint32_t object_faces,
                         const char** why = nullptr) noexcept;

}  // namespace st::rt
