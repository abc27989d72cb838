// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// ShmSegment: a named POSIX shared-memory segment holding the pose and contact-model triple
/// buffers, so the haptic servo can run as its own process.
/// A versioned header (magic, layout version, sizes, creator pid and start time) guards it:
/// attach() refuses anything that does not match this build or whose creator is dead;
/// create() replaces a segment left by a dead process and refuses one whose creator lives.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/pose_sample.hpp>
#include <spheretouch/rt/shm_status.hpp>
#include <spheretouch/rt/triple_buffer.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// First bytes of the segment. Plain data except the state word. The fields up to
/// creator_start_ticks keep their offsets in every layout version, so a newer build can still
/// tell whether an old segment's creator is alive.
struct alignas(kCacheLine) ShmHeader {
  std::uint64_t magic;                ///< kShmMagic
  std::uint32_t layout_version;       ///< kShmLayoutVersion
  std::uint32_t header_size;          ///< sizeof(ShmHeader)
  std::uint64_t total_size;           ///< sizeof(ShmLayout), bytes
  std::uint32_t pose_size;            ///< sizeof(PoseSample)
  std::uint32_t model_size;           ///< sizeof(geom::ContactSet)
  std::int32_t creator_pid;           ///< process that created the segment
  std::uint32_t reserved;             ///< zero
  std::uint64_t creator_start_ticks;  ///< its start time, clock ticks after boot (/proc/pid/stat 22)
  std::int64_t created_ns;            ///< CLOCK_MONOTONIC at creation
  std::atomic<std::uint32_t> state;   ///< 0 = being initialised, 1 = ready
};

/// "STSHMRT1" little-endian: identifies a spheretouch real-time segment.
inline constexpr std::uint64_t kShmMagic = 0x3154524D48535453ull;
/// Bump on any change of ShmHeader, ShmLayout, PoseSample, ContactModel, ContactSet or ShmStatus.
/// 2: the status area (ShmStatus) after the triple buffers. 3: ContactModel 288 B (contact model
/// kind, inside vertex counts). 4: ShmStatus ends with the scene reference and the view frame
/// (SceneRef, ViewFrame: the live view reads the segment). 5: ContactModel 312 B (pressure_point,
/// the wrench's point of application), ServoStatus 152 B (torque_Nm). 6: the collision side sends
/// a ContactSet (the models of every touched object of a scene of several).
inline constexpr std::uint32_t kShmLayoutVersion = 6;

/// The whole segment.
struct ShmLayout {
  ShmHeader header;                       ///< guard
  TripleBuffer<PoseSample> poses;         ///< haptic → collision
  TripleBuffer<geom::ContactSet> models;  ///< collision → haptic
  ShmStatus status;                       ///< live status, any number of readers
};

/// A mapping of the segment. The creator unlinks the name when destroyed.
class ShmSegment {
 public:
  /// Creates `name` ("/spheretouch-x"; a missing leading '/' is added). An existing segment
  /// with our magic is replaced if its creator is dead and refused if it is alive; one without
  /// our magic is refused (not ours to delete), except an empty one older than 2 s (a creator
  /// that died between shm_open and ftruncate).
  static Result<std::unique_ptr<ShmSegment>> create(const std::string& name);
  /// Attaches to an existing, ready segment of this layout whose creator is alive.
  static Result<std::unique_ptr<ShmSegment>> attach(const std::string& name);
  /// Maps an existing segment of this layout read-only (PROT_READ), for watchers: any number
  /// may attach, and the creator may be dead (a split servo outliving its collision side).
  /// Only header() and status() may be used on it.
  static Result<std::unique_ptr<const ShmSegment>> attach_read_only(const std::string& name);
  /// Removes the name (no error if absent).
  static Status remove(const std::string& name);
  ~ShmSegment();
  ShmSegment(const ShmSegment&) = delete;
  ShmSegment& operator=(const ShmSegment&) = delete;

  TripleBuffer<PoseSample>& poses() { return layout_->poses; }          ///< haptic → collision
  TripleBuffer<geom::ContactSet>& models() { return layout_->models; }  ///< collision → haptic
  ShmStatus& status() { return layout_->status; }                       ///< live status (writers)
  const ShmStatus& status() const { return layout_->status; }           ///< live status (readers)
  const ShmHeader& header() const { return layout_->header; }           ///< the guard
  /// True when the creator recorded in the header is alive.
  bool creator_alive() const;
  /// Unlinks the name if it still refers to this segment and its creator is dead (an attacher
  /// that outlived the creator tidies up); true when it did.
  bool unlink_if_orphaned() const;
  const std::string& name() const { return name_; }  ///< normalised name
  bool creator() const { return creator_; }          ///< this mapping created it
  /// Survives another process truncating the segment (ftruncate on /dev/shm/NAME): a SIGBUS on
  /// this mapping replaces it with private zero pages, so the process goes on (its triple buffers
  /// then hold zeros: no contact, zero force) and truncated() turns true, instead of the process
  /// dying. Installs a process-wide SIGBUS handler (other SIGBUS keep their default action); call
  /// before the real-time threads start. At most four guarded mappings per process.
  void guard_truncation();
  /// True once a guarded mapping was found truncated (the process should stop, saying so).
  static bool truncated() noexcept;

 private:
  ShmSegment(std::string name, ShmLayout* layout, bool creator)
      : name_(std::move(name)), layout_(layout), creator_(creator) {}
  bool names_this() const;  ///< the name still refers to this segment (same creator and time)
  std::string name_;
  ShmLayout* layout_;
  bool creator_;
};

/// Start time of a process in clock ticks after boot (/proc/pid/stat field 22); 0 if unknown.
std::uint64_t process_start_ticks(int pid);
/// True when pid names a live process started at start_ticks (guards against pid reuse).
bool process_alive(int pid, std::uint64_t start_ticks);
/// Resident set size of a process in bytes (/proc/pid/statm; pid 0 = this process); 0 if unknown.
std::uint64_t resident_bytes(int pid = 0);

}  // namespace st::rt
