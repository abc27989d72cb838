// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// ScatterGather: the client side of the distributed collision (paper §3.4), owned by the
/// collision thread. One DEALER per worker, so every request is addressed to the worker that
/// holds the blocks (never round-robin). Each round sends one Query per live worker and gathers
/// until all have replied or the round's deadline passes; replies of older rounds are dropped by
/// sequence number, and the merged pairs are sorted and deduplicated. The client knows the whole
/// partition: a worker that misses `miss_limit` deadlines is marked down and its blocks are dealt
/// block-cyclically to the live workers, each of which is sent its enlarged block set (LoadBlocks,
/// content-addressed: never re-sent to a worker that already holds that hash). A worker that
/// answers again is given back its own blocks (reloaded if its epoch changed). A round says whether
/// it is complete: whether the block sets of the replies it merged cover every block.
//
// Client assist (ScatterConfig::assist_blocks, off by default): a static deal leaves one worker
// with more of a contact's work than the others, a different one at each pose. Each round the
// client takes a few of the busiest workers' heaviest blocks (judged by the work each block cost
// the round before, which each Result reports: the probe moves little between rounds; the pairs
// a block gave say little, most of its work being tests that found none), those workers skip them (the Query's
// skip list), and the collision thread answers them itself while the Queries are out, from its
// own copy of the object (it holds it to encode the block sets). A block counts as covered when
// its answer is merged, whoever gave it.
//
// Replicated deal (ScatterConfig::replicas, off by default): each worker also holds standby
// copies of other workers' blocks, as a second block set; each round the blocks that worked the
// round before go to the lighter of their two holders (client::BlockDeal: the owner skips such a
// block, the other holder takes it, QueryMsg::take), and a down worker's blocks are taken from
// their copies until the reassignment below holds them again. The assist works on top of the deal.
//
// Never blocks without a timeout: sends are non-blocking (a full queue counts as a miss), and
// every wait is bounded by the round's deadline. Not thread-safe: one thread owns it.
//
// Each worker is in a link state, kept across rounds, and has a turn in the current round. Two
// machines, not one, because they are independent: a Loading worker is still queried with a set
// it already holds. Each changes in one place, which stops on a cell marked `-` (ST_ASSERT; a
// release build ignores the event); a reply that fits no transition of its worker's turn is
// counted (bad_messages, stale_dropped) and dropped before it gets there.
//
//   link \ event  Hello    BlankHello  LoadStart  LoadEnd  MarkDown
//   Unknown       Live     Unknown     -          -        Down      no Hello with an epoch yet
//   Live          Live     Unknown     Loading    -        Down      up: queried with the best set it holds
//   Loading       Loading  -           Loading    Live     Down      Live, and a block set is being sent to it
//   Down          Live     Unknown     -          -        -         heartbeated; its blocks dealt to the others
//
//   Hello       a Hello with an epoch (one that also ends a load is a LoadEnd first)
//   BlankHello  a Hello with epoch 0: says nothing about its memory, so it counts as never heard
//   LoadStart   its target set (not held, not refused within load_timeout) is queued for upload; a
//               newer target replaces a set still being sent
//   LoadEnd     the set being sent is acknowledged (its Hello lists it), refused (LoadFailed,
//               TooLarge), lost to a restart (new epoch), or dropped with its socket
//   MarkDown    miss_limit missed rounds in a row, or a load with no progress for load_timeout
// Entering or leaving Down resets the miss count and deals the blocks anew. Down and Pinged
// workers get a Heartbeat every heartbeat_period, an Unknown one each round too, a Queried one
// every held_refresh_period. Any worker asked (Query or Heartbeat) and then silent for
// reconnect_after gets a fresh socket: not a state, as only the silence is timed anew.
//
//   turn \ event  NewRound  QuerySent  QueryUnsent  Ping    Result    NotLoaded  Hello
//   Idle          Idle      Queried    Unsent       Pinged  -         -          Idle
//   Queried       Idle      -          -            -       Answered  Answered   Queried
//   Unsent        Idle      -          -            -       -         Answered   Unsent
//   Pinged        Idle      -          -            -       -         -          Greeted
//   Answered      Idle      -          -            -       -         Answered   Answered
//   Greeted       Idle      -          -            -       -         -          Greeted
//
//   Idle      not asked: Down, or Loading with no held set to query
//   Queried   its Query is queued; Unsent: its Query could not be queued
//   Pinged    not queried (Unknown, or holds no set): it must say Hello by the deadline
//   Answered  its Result, or a NotLoaded naming this round; Greeted: its Hello
// At the round's end Queried, Unsent and Pinged count a miss (not while it is Loading within
// load_timeout); Answered and Greeted reset the count.
#pragma once
#include <spheretouch/abi.hpp>
#include <chrono>
#include <cstdint>
#include <future>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>
#include <zmq.hpp>

#include <spheretouch/net/block_set.hpp>
#include <spheretouch/net/protocol.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

using Clock = std::chrono::steady_clock;  ///< the clock of deadlines and timeouts

/// How the client talks to its workers.
struct ScatterConfig {
  std::vector<std::string> endpoints;               ///< worker i is endpoints[i] (tcp://, ipc://, inproc://)
  std::uint32_t miss_limit = 3;                     ///< K: consecutive missed deadlines before a worker is down
  std::chrono::milliseconds heartbeat_period{100};  ///< Heartbeats to down workers
  /// Heartbeats to busy workers too, this often: their Hello says which block sets they still
  /// hold (they drop idle ones), so the client can drop its copies and memory stays flat.
  std::chrono::milliseconds held_refresh_period{5000};
  std::chrono::milliseconds load_timeout{10000};  ///< an upload not acknowledged in this long fails
  /// A worker asked but silent this long gets a fresh socket: libzmq gives up on a connection for
  /// good after a protocol error (such as an oversized or garbled frame) and never reconnects it.
  std::chrono::milliseconds reconnect_after{1000};
  std::uint32_t chunk_bytes = 256u << 10;  ///< LoadBlocks chunk size (≤ limits.max_chunk_bytes)
  std::uint32_t leaf_faces = geom::DefaultTreeConfig().leaf_faces;  ///< tree parameter sent with every block set
  geom::Mapping mapping = geom::Mapping::block_cyclic;              ///< how blocks are dealt to the workers
  std::uint64_t mapping_seed = 1;                                   ///< for geom::Mapping::random
  int sndhwm = 8;                   ///< per-worker send queue, messages (small: no stale backlog)
  int rcvhwm = 64;                  ///< per-worker receive queue, messages
  Limits limits = DefaultLimits();  ///< decode limits for replies
  /// Busy-poll for replies this long before blocking in poll(), us: trades CPU on the collision
  /// thread's core for the wake-up latency of an idle core (tens of us on a VM). 0 = never spin.
  std::uint32_t spin_us = 0;
  ///@{
  /// CURVE: the workers' public key (one fleet key) and this client's key pair, Z85; all empty
  /// for plain loopback / ipc.
  std::string curve_server_public, curve_public, curve_secret;
  ///@}
  /// This client's ZeroMQ routing id on every worker (1–255 bytes, first byte not 0). A worker
  /// shows a client only the block sets it sent, so without CURVE this id is the client's
  /// identity: keep it secret. Empty (the default): 16 random bytes per client, so a restarted
  /// client loads its sets again; under CURVE the client key is the identity instead.
  std::string routing_id;
  /// Client assist: each round the collision thread answers up to this many blocks itself while
  /// the Queries are out (their workers skip them, QueryMsg::skip): the heaviest blocks of the
  /// busiest workers by the work each block cost the round before (choose_assist()). The
  /// collision thread waits for the gather anyway; this is work it takes off the slowest worker.
  /// It answers them with a worker's own backend (tree_backend.hpp) holding a block set of every
  /// block: costs that set's trees (the probe's and the object's, one subtree per block, as a
  /// worker builds them), built once by create(), and 4 bytes per object face. 0 = off (the default).
  std::uint32_t assist_blocks = 0;
  /// Replicated deal: every block is also held by a second worker (its standby copy, on a worker
  /// drawn by a hash of the block, second_holder()), and each round the blocks that worked the
  /// round before go, the heaviest first, to the less loaded of their two holders (judged by the
  /// work the workers report); a down worker's blocks are answered from their copies at once.
  /// Costs each worker a second block set (as much memory again as its share, sent once) and a
  /// Query two lists (QueryMsg::skip, QueryMsg::take). Off (the default): one holder per block.
  bool replicas = false;
  /// With replicas: a block stays with the holder that answered it the round before unless the
  /// other is lighter by more than this fraction of the mean load (each change of a worker's
  /// blocks costs its coherent collider a plain round). 0: the fresh two-choice deal every round.
  double deal_stickiness = 0.05;
  /// Take each round's distinct faces (RoundResult::probe_faces, object_faces, contacts(): paper
  /// §3.5's merge), a pass over the merged pairs and a sort of their object faces after the last
  /// Result is in: about as long as the k-way merge itself (`spheretouch-bench scale`,
  /// client_distinct_us). Off: both lists stay empty, for a caller that needs the pairs alone
  /// (the run's collision thread, which counts contacts in its contact model).
  bool distinct_faces = true;
  /// The scene object this client answers for (a scene of several objects has one client per
  /// object over the same workers): its block sets carry it, its Queries name it, and a Result
  /// naming another is refused. < Limits::max_objects.
  std::uint32_t object = 0;
};

/// What the collision thread gets back from one round.
struct RoundResult {
  std::uint64_t seq = 0;        ///< the round's sequence number
  std::vector<FacePair> pairs;  ///< colliding pairs, sorted by (probe, object), unique
  /// distinct colliding probe faces, ascending (merged over workers; empty unless ScatterConfig::distinct_faces)
  std::vector<std::uint32_t> probe_faces;
  std::vector<std::uint32_t> object_faces;  ///< distinct colliding object faces, ascending (the same)
  bool complete = false;                    ///< the merged replies cover every block: pairs are exact
  std::uint32_t workers_asked = 0;          ///< Queries sent this round
  std::uint32_t workers_replied = 0;        ///< Results merged this round
  std::uint32_t blocks_covered = 0;         ///< blocks whose pairs are in `pairs`
  std::uint32_t blocks_total = 0;           ///< blocks in the partition
  std::uint32_t stale_dropped = 0;          ///< stale replies dropped (older rounds, a restarted worker's past life)
  std::uint32_t bad_messages = 0;           ///< undecodable or unexpected replies dropped
  QueryStats stats;                         ///< summed counters; compute_ns is the slowest worker's
  std::vector<QueryStats> worker_stats;     ///< per worker (endpoint order): its Result's counters, zero if none
  std::uint32_t blocks_assisted = 0;        ///< blocks the client answered itself (ScatterConfig::assist_blocks)
  QueryStats assist;               ///< the client's own work on them (tests also in `stats`; its time here only)
  std::uint32_t blocks_moved = 0;  ///< blocks answered by their standby holder to balance the load (replicas)
  /// "Contacts" (paper §3.5): distinct colliding probe faces + distinct colliding object faces (0
  /// without ScatterConfig::distinct_faces).
  std::size_t contacts() const { return probe_faces.size() + object_faces.size(); }
};

/// A worker as the client sees it.
struct WorkerStatus {
  std::string endpoint;                      ///< where it is
  bool up = true;                            ///< not marked down
  std::uint32_t worker_id = 0;               ///< from its last Hello
  std::uint64_t epoch = 0;                   ///< from its last Hello (0: never heard)
  std::uint32_t misses = 0;                  ///< consecutive missed deadlines
  std::vector<std::uint32_t> target_blocks;  ///< blocks it is meant to hold now
  bool holds_target = false;                 ///< it has acknowledged its target block set
  std::uint64_t bytes_sent = 0;              ///< LoadBlocks bytes sent to it so far
  std::uint32_t loads_sent = 0;              ///< block sets sent to it so far
  std::size_t sets_held = 0;                 ///< block sets it holds, from its last Hello
  /// Why the last message from it this client could not read was refused (empty: none), such as
  /// "header at byte 4: version: 1 not supported (this build speaks 2)": a daemon of another version.
  std::string unreadable;
  /// Why it last refused a block set this client sent (its LoadFailed or TooLarge text, such as a
  /// set over its max_blockset_bytes or "worker full") or a Query (a round's pairs over its
  /// max_pairs or the set's work budget: that round is incomplete); empty: none refused.
  std::string refused;
  std::vector<std::uint32_t> standby_blocks;  ///< its copies of other workers' blocks (ScatterConfig::replicas)
  bool holds_standby = false;                 ///< it has acknowledged its standby set (or has none)
};

/// The collision thread's client to the worker fleet.
class ScatterGather {
 public:
  /// Connects to every endpoint and prepares the block-cyclic partition of `blocks` (the object's
  /// layer-n blocks, global face ids) over them. Fails on bad endpoints or block ids.
  static Result<std::unique_ptr<ScatterGather>> create(zmq::context_t& ctx, ScatterConfig config, geom::Mesh probe,
                                                       geom::Mesh object, Blocks blocks);
  ~ScatterGather();

  /// One round: Query every live worker with `pose`, gather until all replied or `deadline`.
  /// `seq` must grow from round to round. Returns by the deadline (plus the time to merge).
  void round(std::uint64_t seq, const geom::Pose& pose, Clock::time_point deadline, RoundResult& out);
  /// Same, returning a new RoundResult.
  RoundResult round(std::uint64_t seq, const geom::Pose& pose, Clock::time_point deadline);
  /// Services Hellos, heartbeats and uploads until every live worker holds its target block set
  /// (true) or `deadline` passes (false). Call between rounds or before the first.
  bool wait_ready(Clock::time_point deadline);

  std::vector<WorkerStatus> workers() const;  ///< a snapshot of every worker
  std::size_t encoded_sets() const;           ///< block sets this client keeps encoded (memory)
  std::uint32_t blocks_total() const;         ///< blocks in the partition

 private:
  struct Impl;
  explicit ScatterGather(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// A block's work in the round before, as the client assist judges it (choose_assist()).
struct BlockWork {
  std::uint32_t block = 0;  ///< global block id
  std::uint32_t owner = 0;  ///< the worker asked for it this round (< workers)
  double work = 0;          ///< its work the round before (ResultMsg::worked; its pairs where none was reported), > 0
};
/// The blocks the client answers itself this round (ScatterConfig::assist_blocks), ascending: up
/// to `max_blocks` times, the busiest worker's heaviest block lighter than that worker's load
/// minus the client's, so each move shortens the longest of the two. `worked` lists the blocks
/// with work (the others weigh nothing), each once.
std::vector<std::uint32_t> choose_assist(std::span<const BlockWork> worked, std::uint32_t workers, std::uint32_t max_blocks);

}  // namespace st::net
