// SPDX-License-Identifier: BSD-3-Clause
// The collision thread of `spheretouch run`: take the newest pose → one
// collision round (in this thread, or scatter-gather over workers) → contact model (paper §3.6)
// → publish. It runs as fast as it can, or at a capped rate.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstdio>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/histogram.hpp>
#include <spheretouch/rt/pose_sample.hpp>
#include <spheretouch/rt/shm_status.hpp>
#include <spheretouch/rt/triple_buffer.hpp>
#include <spheretouch/engine/view_feed.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

/// One finished collision round, for the trace and the summary.
struct RoundRecord {
  std::int64_t start_ns = 0, end_ns = 0;  ///< CLOCK_MONOTONIC
  std::uint64_t pose_seq = 0;             ///< pose it answered
  std::uint32_t pairs = 0, contacts = 0;  ///< face pairs, paper §3.5 contacts
  double penetration_mm = 0;              ///< PD of the model built from it
  bool complete = true;                   ///< every worker answered (always true without workers)
};

/// What one round of collision detection returns to the loop.
struct RoundOutput {
  std::vector<geom::FacePair> pairs;  ///< colliding pairs (any order)
  bool complete = true;               ///< false when a worker missed the deadline
};

/// Computes the pairs for a pose; set up by the caller (direct collide() or scatter-gather).
using CollideFn = std::function<void(std::uint64_t seq, const geom::Pose& pose, RoundOutput& out)>;

/// The collision thread. Its memory does not grow with the run's length: rounds are kept in memory
/// only up to `max_rounds` (0 = none) and streamed to a CSV file if asked (write_rounds_csv);
/// latencies go into a fixed-size histogram.
class CollisionLoop {
 public:
  /// `rate_hz` 0 = uncapped. `max_rounds` bounds the records kept in memory (later rounds are
  /// counted, streamed to the rounds CSV and in the latency histogram, not stored).
  /// `contact` selects the contact model (the builder is prepared for the meshes here, not in
  /// the first round).
  CollisionLoop(const geom::Mesh& probe, const geom::Mesh& object, rt::TripleBuffer<rt::PoseSample>& poses,
                rt::TripleBuffer<geom::ContactModel>& models, CollideFn collide, double rate_hz, std::size_t max_rounds,
                const geom::ContactConfig& contact = geom::DefaultContactConfig());
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
  /// The round with the deepest penetration (the peak of the force law): its pose and pairs.
  const geom::Pose& peak_pose() const { return peak_pose_; }
  const std::vector<geom::FacePair>& peak_pairs() const { return peak_pairs_; }  ///< after stop()
  double peak_penetration_mm() const { return peak_pd_; }                        ///< after stop()

 private:
  void run();
  const geom::Mesh& probe_;
  const geom::Mesh& object_;
  rt::TripleBuffer<rt::PoseSample>& poses_;
  rt::TripleBuffer<geom::ContactModel>& models_;
  CollideFn collide_;
  geom::ContactBuilder builder_;
  rt::SeqLock<rt::CollisionStatus>* status_ = nullptr;
  ViewFeed* view_ = nullptr;
  double rate_hz_;
  std::size_t max_rounds_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> rounds_{0}, incomplete_{0};
  std::atomic<std::int64_t> last_latency_ns_{0};
  std::atomic<std::uint32_t> last_contacts_{0};
  std::vector<RoundRecord> records_;
  rt::LatencyHistogram latency_;
  std::FILE* rounds_csv_ = nullptr;
  std::string rounds_path_, rounds_error_;
  geom::Pose peak_pose_ = geom::Pose::Identity();
  std::vector<geom::FacePair> peak_pairs_;
  double peak_pd_ = -1;
  std::thread thread_;
};

}  // namespace st::engine
