// SPDX-License-Identifier: BSD-3-Clause
// The collision thread of `spheretouch run`: take the newest pose → one
// collision round (in this thread, or scatter-gather over workers) → contact model (paper §3.6)
// → publish. It runs as fast as it can, or at a capped rate.
//
// A scene of several objects: the round first tests the probe's bounding sphere against each
// object's (placed in the world), and collides only the objects it can reach; each touched object
// gets its own contact model (its own builder and history, built in the object's frame and
// placed in the world), and the round publishes them together as one geom::ContactSet. An object
// the probe left is sent a "no contact" model for kLingerNs after (the servo reads the newest set
// only, so one such model could be overwritten before it is read); an object far from the probe
// costs one sphere test a round.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstdio>
#include <functional>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include <spheretouch/collide.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/histogram.hpp>
#include <spheretouch/rt/pose_sample.hpp>
#include <spheretouch/rt/shm_status.hpp>
#include <spheretouch/rt/triple_buffer.hpp>
#include <spheretouch/engine/view_feed.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

/// An object the probe left is still sent (a "no contact" model) this long, ns: the servo takes
/// only the newest set, at least once a tick, so it sees the release.
inline constexpr std::int64_t kLingerNs = 50'000'000;

/// One object of the world as the collision thread sees it.
struct WorldObject {
  const geom::Mesh* mesh = nullptr;               ///< in its file coordinates; outlives the loop
  geom::Pose placement = geom::Pose::Identity();  ///< object file coordinates → world
  /// Its bounding sphere, object file coordinates (radius infinite: never culled).
  BoundingSphere bound{geom::Vec3::Zero(), std::numeric_limits<double>::infinity()};
};

/// Per object, over a run (the summary's per-object lines).
struct ObjectRoundStats {
  std::uint64_t reached = 0;       ///< rounds the probe's bounding sphere reached it (collided)
  std::uint64_t touching = 0;      ///< rounds its model was in contact
  std::uint32_t peak_pairs = 0;    ///< most face pairs in one round
  double peak_penetration_mm = 0;  ///< deepest PD
};

/// One finished collision round, for the trace and the summary.
struct RoundRecord {
  std::int64_t start_ns = 0, end_ns = 0;  ///< CLOCK_MONOTONIC
  std::uint64_t pose_seq = 0;             ///< pose it answered
  std::uint32_t pairs = 0, contacts = 0;  ///< face pairs, paper §3.5 contacts (summed over objects)
  double penetration_mm = 0;              ///< PD of the model built from it (the deepest object's)
  bool complete = true;                   ///< every worker answered (always true without workers)
};

/// What one round of collision detection returns to the loop.
struct RoundOutput {
  std::vector<geom::FacePair> pairs;  ///< colliding pairs (any order)
  bool complete = true;               ///< false when a worker missed the deadline
};

/// Computes the pairs of object `object` (index into the loop's objects) for `pose` (probe →
/// that object's file coordinates); set up by the caller (direct collide() or scatter-gather).
using CollideFn = std::function<void(std::uint64_t seq, std::uint32_t object, const geom::Pose& pose, RoundOutput& out)>;

/// The collision thread. Its memory does not grow with the run's length: rounds are kept in memory
/// only up to `max_rounds` (0 = none) and streamed to a CSV file if asked (write_rounds_csv);
/// latencies go into a fixed-size histogram.
class CollisionLoop {
 public:
  /// `rate_hz` 0 = uncapped. `max_rounds` bounds the records kept in memory (later rounds are
  /// counted, streamed to the rounds CSV and in the latency histogram, not stored).
  /// `contact` selects the contact model (the builder is prepared for the meshes here, not in
  /// the first round).
  /// `objects` is the world (one object: never culled, its model sent every round, as a
  /// single-object run always did); `probe_bound` bounds the probe (its file
  /// coordinates).
  CollisionLoop(const geom::Mesh& probe, const BoundingSphere& probe_bound, std::vector<WorldObject> objects,
                rt::TripleBuffer<rt::PoseSample>& poses, rt::TripleBuffer<geom::ContactSet>& models, CollideFn collide,
                double rate_hz, std::size_t max_rounds, const geom::ContactConfig& contact = geom::DefaultContactConfig());
  /// One object at the world's origin.
  CollisionLoop(const geom::Mesh& probe, const geom::Mesh& object, rt::TripleBuffer<rt::PoseSample>& poses,
                rt::TripleBuffer<geom::ContactSet>& models, CollideFn collide, double rate_hz, std::size_t max_rounds,
                const geom::ContactConfig& contact = geom::DefaultContactConfig())
      : CollisionLoop(probe, BoundingSphere{geom::Vec3::Zero(), std::numeric_limits<double>::infinity()},
                      {WorldObject{&object}}, poses, models, std::move(collide), rate_hz, max_rounds, contact) {}
  ~CollisionLoop();
  /// Offer every round to a live viewer's feed (null = off); before start().
  void show_to(ViewFeed* feed) { view_ = feed; }
  /// Publish a CollisionStatus after every round into `status` (null = off); before start().
  void publish_status_to(rt::SeqLock<rt::CollisionStatus>* status) { status_ = status; }
  /// Streams one line per round (RoundRecord's fields) to `path`; before start(). The file is
  /// flushed and closed by stop().
  Status write_rounds_csv(const std::string& path);
  void start();  ///< starts the thread
  void stop();   ///< stops and joins it (idempotent)
  /// After stop(): empty when every line of the rounds CSV and its close succeeded, else the first
  /// failure naming the file (a full disk); the loop stops writing the CSV after it.
  const std::string& rounds_csv_error() const { return rounds_error_; }

  std::uint64_t rounds() const { return rounds_.load(std::memory_order_relaxed); }          ///< rounds so far
  std::uint64_t incomplete() const { return incomplete_.load(std::memory_order_relaxed); }  ///< rounds missing a worker
  std::int64_t last_latency_ns() const {
    return last_latency_ns_.load(std::memory_order_relaxed);
  }  ///< newest round's time
  std::uint32_t last_contacts() const {
    return last_contacts_.load(std::memory_order_relaxed);
  }                                                                     ///< newest round's contacts
  const std::vector<RoundRecord>& records() const { return records_; }  ///< the first max_rounds, after stop()
  const rt::LatencyHistogram& latency() const { return latency_; }      ///< every round's latency, after stop()
  /// The latency of the rounds that found contact (pairs), after stop(): what the force waits
  /// for, which the rounds without contact (most of a run, a sphere test or a few) hide in latency().
  const rt::LatencyHistogram& contact_latency() const { return contact_latency_; }
  /// The round with the deepest penetration (the peak of the force law): its pose (probe → that
  /// object) and pairs, and which object.
  const geom::Pose& peak_pose() const { return peak_pose_; }
  const std::vector<geom::FacePair>& peak_pairs() const { return peak_pairs_; }  ///< after stop()
  std::uint32_t peak_object() const { return peak_object_; }                     ///< after stop()
  /// Per object (the constructor's order), after stop().
  const std::vector<ObjectRoundStats>& object_stats() const { return object_stats_; }
  /// Rounds in which the probe touched two or more objects at once (their forces add), after stop().
  std::uint64_t multi_touch_rounds() const { return multi_touch_rounds_; }
  /// Rounds that touched more objects than a ContactSet carries (the deepest were rendered).
  std::uint64_t overflow_rounds() const { return overflow_rounds_; }
  double peak_penetration_mm() const { return peak_pd_; }  ///< after stop()

 private:
  void run();
  const geom::Mesh& probe_;
  BoundingSphere probe_bound_;
  std::vector<WorldObject> objects_;
  rt::TripleBuffer<rt::PoseSample>& poses_;
  rt::TripleBuffer<geom::ContactSet>& models_;
  CollideFn collide_;
  std::vector<geom::ContactBuilder> builders_;  ///< one per object (its history)
  std::vector<ObjectRoundStats> object_stats_;
  std::uint64_t overflow_rounds_ = 0, multi_touch_rounds_ = 0;
  std::uint32_t peak_object_ = 0;
  std::vector<geom::FacePair> view_pairs_;  ///< a frame's pairs over every object (offset face ids)
  rt::SeqLock<rt::CollisionStatus>* status_ = nullptr;
  ViewFeed* view_ = nullptr;
  double rate_hz_;
  std::size_t max_rounds_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> rounds_{0}, incomplete_{0};
  std::atomic<std::int64_t> last_latency_ns_{0};
  std::atomic<std::uint32_t> last_contacts_{0};
  std::vector<RoundRecord> records_;
  rt::LatencyHistogram latency_, contact_latency_;
  std::FILE* rounds_csv_ = nullptr;
  std::string rounds_path_, rounds_error_;
  geom::Pose peak_pose_ = geom::Pose::Identity();
  std::vector<geom::FacePair> peak_pairs_;
  double peak_pd_ = -1;
  std::thread thread_;
};

}  // namespace st::engine
