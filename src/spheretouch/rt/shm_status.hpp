// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// ShmStatus: the live status area of the shared-memory segment (after the two triple buffers).
/// The haptic servo and the collision thread each publish a small struct through a SeqLock, the
/// collision thread also a view frame (ViewFrame), and the run says once which scene and meshes
/// it loaded (SceneRef), so any number of read-only attachers (`spheretouch monitor`, its
/// `--view`, the run's own status line and view) can watch a session without consuming the
/// triple buffers' single reader's updates.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include <spheretouch/rt/seqlock.hpp>
#include <spheretouch/rt/view_frame.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// What the servo publishes every kStatusEveryTicks ticks (from the tick path: plain stores).
struct ServoStatus {
  std::int64_t updated_ns = 0;         ///< tick time of this snapshot, CLOCK_MONOTONIC ns
  std::uint64_t ticks = 0;             ///< ticks run
  std::uint64_t misses = 0;            ///< deadlines skipped
  std::uint64_t pose_seq = 0;          ///< newest pose published
  std::int64_t pose_sampled_ns = 0;    ///< when it was read from the device
  std::uint64_t model_seq = 0;         ///< newest contact model taken (0 = none yet)
  std::int64_t model_received_ns = 0;  ///< when the servo took it
  std::int64_t model_pose_ns = 0;      ///< the pose sampling time that model answered
  std::uint64_t models = 0;            ///< contact models taken so far
  double force_N[3] = {};              ///< commanded force, object frame
  double peak_force_N = 0;             ///< largest |force| commanded so far
  double penetration_mm = 0;           ///< PD used this tick
  double fade = 0;                     ///< stale-fade factor in [0, 1]
  std::uint32_t contacts = 0;          ///< newest model's contacts (paper §3.5)
  std::uint32_t flags = 0;             ///< kTick* flags (telemetry.hpp)
  double torque_Nm[3] = {};            ///< torque about the tool centre point, object frame (commanded if 6-DOF)
};
static_assert(std::is_trivially_copyable_v<ServoStatus> && sizeof(ServoStatus) == 152);

/// What the collision thread publishes after every round.
struct CollisionStatus {
  std::int64_t updated_ns = 0;   ///< end of the round, CLOCK_MONOTONIC ns
  std::uint64_t rounds = 0;      ///< rounds so far
  std::uint64_t model_seq = 0;   ///< model published by the round
  std::uint64_t pose_seq = 0;    ///< pose it answered
  std::int64_t latency_ns = 0;   ///< round time
  double penetration_mm = 0;     ///< PD of the model
  std::uint32_t contacts = 0;    ///< contacts of the model
  std::uint32_t incomplete = 0;  ///< rounds so far that missed a worker (low 32 bits)
};
static_assert(std::is_trivially_copyable_v<CollisionStatus> && sizeof(CollisionStatus) == 56);

/// Which scene file and meshes the run loaded, written once before it starts: a monitor serving
/// the live view (`spheretouch monitor --view`) loads the same meshes from the file and checks
/// them against the counts and hashes (the file may have changed since). No command-line flag of
/// `run` changes the meshes, so the file is all it needs.
struct SceneRef {
  static constexpr std::size_t kMaxPath = 4096;  ///< PATH_MAX on Linux, with the NUL
  char scene_path[kMaxPath] = {};                ///< absolute, NUL-terminated; "" = none (not from a file, or too long)
  ///@{
  std::uint64_t probe_hash = 0, object_hash = 0;        ///< geom::mesh_hash of each body as loaded
  std::uint32_t probe_vertices = 0, probe_faces = 0;    ///< the probe's counts
  std::uint32_t object_vertices = 0, object_faces = 0;  ///< the object's counts
  ///@}
};
static_assert(std::is_trivially_copyable_v<SceneRef> && sizeof(SceneRef) == 4128);

/// Servo process states, in ShmStatus::servo_state.
enum class ServoState : std::uint32_t { none = 0, starting = 1, running = 2, finished = 3 };

/// The status area. Process-level words are plain atomics written outside the tick path.
struct alignas(kCacheLine) ShmStatus {
  std::atomic<std::int32_t> servo_pid{0};           ///< process running the haptic servo (0 = not yet)
  std::atomic<std::uint32_t> servo_state{0};        ///< ServoState
  std::atomic<std::uint64_t> servo_start_ticks{0};  ///< its start time (process_alive())
  std::atomic<std::uint32_t> split{0};              ///< 1: the servo is its own process
  std::atomic<std::uint32_t> collision_lost{0};     ///< servo's verdict: 1 collision side silent, 2 dead
  SeqLock<ServoStatus> servo;                       ///< written by the servo tick
  SeqLock<CollisionStatus> collision;               ///< written by the collision thread
  SeqLock<SceneRef> scene;                          ///< written once, before the run starts
  SeqLock<ViewFrame> view;                          ///< written by the collision thread, at most kViewRateHz
};

/// The servo publishes its status every this many ticks: 100 Hz at 1 kHz, plenty for a display,
/// and keeps the tick's extra stores to ~17 words one tick in ten.
inline constexpr std::uint64_t kStatusEveryTicks = 10;

}  // namespace st::rt
