// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// One worker as ScatterGather sees it (not installed): its socket, its two state machines (the
/// tables in scatter_gather.hpp) and what the client knows of its memory.
#pragma once
#include <spheretouch/abi.hpp>
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>
#include <zmq.hpp>

#include <spheretouch/net/block_set_cache.hpp>
#include <spheretouch/net/scatter_gather.hpp>

namespace st::inline SPHERETOUCH_ABI::net::client {

using Clock = std::chrono::steady_clock;

// A worker's two state machines. link_after() and turn_after() are the tables in
// scatter_gather.hpp, which also says what each state and event means; kNoLink / kNoTurn marks a
// cell that is not a transition.
enum class Link : std::uint8_t { Unknown, Live, Loading, Down };
enum class LinkEvent : std::uint8_t { Hello, BlankHello, LoadStart, LoadEnd, MarkDown };
enum class Turn : std::uint8_t { Idle, Queried, Unsent, Pinged, Answered, Greeted };
enum class TurnEvent : std::uint8_t { NewRound, QuerySent, QueryUnsent, Ping, Result, NotLoaded, Hello };

inline constexpr Link kNoLink = static_cast<Link>(0xff);
inline constexpr Turn kNoTurn = static_cast<Turn>(0xff);

constexpr Link link_after(Link from, LinkEvent e) {
  using enum Link;
  constexpr Link x = kNoLink;
  // clang-format off
  constexpr Link table[4][5] = {
      // Hello    BlankHello  LoadStart  LoadEnd  MarkDown
      {Live,      Unknown,    x,         x,       Down},  // Unknown
      {Live,      Unknown,    Loading,   x,       Down},  // Live
      {Loading,   x,          Loading,   Live,    Down},  // Loading
      {Live,      Unknown,    x,         x,       x   },  // Down
  };
  // clang-format on
  return table[static_cast<int>(from)][static_cast<int>(e)];
}

constexpr Turn turn_after(Turn from, TurnEvent e) {
  using enum Turn;
  constexpr Turn x = kNoTurn;
  // clang-format off
  constexpr Turn table[6][7] = {
      // NewRound  QuerySent  QueryUnsent  Ping    Result    NotLoaded  Hello
      {Idle,       Queried,   Unsent,      Pinged, x,        x,         Idle    },  // Idle
      {Idle,       x,         x,           x,      Answered, Answered,  Queried },  // Queried
      {Idle,       x,         x,           x,      x,        Answered,  Unsent  },  // Unsent
      {Idle,       x,         x,           x,      x,        x,         Greeted },  // Pinged
      {Idle,       x,         x,           x,      x,        Answered,  Answered},  // Answered
      {Idle,       x,         x,           x,      x,        x,         Greeted },  // Greeted
  };
  // clang-format on
  return table[static_cast<int>(from)][static_cast<int>(e)];
}

/// Up and heard from: it may be queried and sent block sets.
constexpr bool heard(Link l) { return l == Link::Live || l == Link::Loading; }
/// At the round's end: asked and not answered, a miss.
constexpr bool missed(Turn t) { return t == Turn::Queried || t == Turn::Unsent || t == Turn::Pinged; }
/// In a round: a reply is still awaited (a Result, or the Hello a ping asks for).
constexpr bool awaited(Turn t) { return t == Turn::Queried || t == Turn::Pinged; }

struct Peer {
  std::string endpoint;
  zmq::socket_t sock;
  Link link = Link::Unknown;
  Turn turn = Turn::Idle;
  std::uint32_t worker_id = 0;
  std::uint64_t epoch = 0;               // from its last Hello (0: none with an epoch yet)
  std::uint64_t retired_epoch = 0;       // the epoch its last restart replaced (a Hello of it is stale)
  std::uint32_t misses = 0;              // rounds missed in a row (0 while Down)
  std::vector<std::uint64_t> held;       // hashes from its last Hello, MRU first
  std::vector<std::uint32_t> original;   // its own blocks (ScatterConfig::mapping)
  std::vector<std::uint32_t> target;     // blocks it should hold now
  std::uint64_t target_hash = 0;         // 0 while the target is being encoded
  std::vector<std::uint32_t> standby;    // its copies of other workers' blocks (ScatterConfig::replicas)
  std::uint64_t standby_hash = 0;        // their set's hash (0: none)
  SetPtr upload;                         // the block set being sent: non-null exactly while Loading
  std::size_t upload_off = 0;            // bytes of `upload` handed to ZeroMQ
  Clock::time_point load_progress_at{};  // upload started or last chunk queued: load_timeout runs from here
  std::uint64_t refused_hash = 0;        // a set it refused to load: not sent again for load_timeout
  Clock::time_point refused_at{};        // when it refused `refused_hash`
  Clock::time_point heartbeat_due{};     // next Heartbeat while it is not queried (heartbeat_period)
  Clock::time_point held_refresh_due{};  // next Heartbeat to a queried worker (held_refresh_period)
  // revive_silent(): asked after silent_since and nothing heard for reconnect_after.
  Clock::time_point silent_since{};  // last message received from it, or its socket opened if later
  Clock::time_point asked_at{};      // last Query or Heartbeat that wants an answer
  std::uint64_t nonce = 0;
  std::string unreadable;           // why its last undecodable message was refused
  std::string refused;              // why it last refused a set we sent (its Error text)
  SetPtr asked;                     // the block set this round's Query named; null if no Query was queued
  SetPtr standby_asked;             // its standby set, named by this round's Query (null: none)
  std::vector<std::uint32_t> skip;  // blocks of `asked` someone else answers this round (BlockDeal)
  std::vector<std::uint32_t> take;  // blocks of `standby_asked` it answers this round (BlockDeal)
  std::uint64_t compute_ns = 0;     // the compute its last Result reported (send_order())
  // Totals.
  std::uint64_t bytes_sent = 0;
  std::uint32_t loads_sent = 0;

  bool holds(std::uint64_t h) const { return h && std::find(held.begin(), held.end(), h) != held.end(); }
  /// A fresh socket to `endpoint` (whatever was queued for the old one is dropped; libzmq
  /// reconnects tcp:// and ipc:// by itself, but not inproc:// once its binder is gone).
  Status open(zmq::context_t& ctx, const ScatterConfig& cfg, const std::string& routing_id);
  /// Queues `m` without blocking (encoded into `buf`); false when it could not be queued.
  bool send(const Message& m, std::vector<std::uint8_t>& buf);
  /// The one place its link state changes; true when it entered or left Down (its blocks must
  /// be dealt anew).
  bool step(LinkEvent e);
  /// The one place its turn in the round changes. Replies that fit no transition are counted and
  /// dropped by the caller before they get here.
  void step(TurnEvent e);

  /// A Heartbeat now; the next one due heartbeat_period later (kFirstContactRetry later when it
  /// could not be queued to a worker never heard from: its connection is not up yet).
  void heartbeat(const ScatterConfig& cfg, Clock::time_point now, std::vector<std::uint8_t>& buf);
  static constexpr std::chrono::milliseconds kFirstContactRetry{5};
  /// The set it should be sent next: its target, then its standby set; 0 when it holds both
  /// (or the target is still being encoded).
  std::uint64_t wanted() const {
    if (!target.empty() && !target_hash) return 0;
    if (target_hash && !holds(target_hash)) return target_hash;
    return standby_hash && !holds(standby_hash) ? standby_hash : 0;
  }
  /// Its standby set was refused (or cost it its share) within load_timeout: not sent again,
  /// and not waited for, until then.
  bool standby_refused(const ScatterConfig& cfg, Clock::time_point now) const {
    return standby_hash && refused_hash == standby_hash && now - refused_at < cfg.load_timeout;
  }
  /// Starts sending wanted() if it is heard from, is not being sent it and did not refuse it
  /// within load_timeout (a newer target replaces a set still being sent).
  void maybe_start_upload(const ScatterConfig& cfg, const BlockSetCache& sets, Clock::time_point now);
  /// Queues the chunks of the set being sent until ZeroMQ's queue is full.
  void pump_upload(const ScatterConfig& cfg, Clock::time_point now, std::vector<std::uint8_t>& buf);
  /// Loading with bytes not yet handed to ZeroMQ: it waits for send room (pump_upload).
  bool upload_has_room() const { return link == Link::Loading && upload_off < upload->bytes.size(); }
  /// Loading, and nothing sent or acknowledged for load_timeout.
  bool load_stuck(const ScatterConfig& cfg, Clock::time_point now) const {
    return link == Link::Loading && now - load_progress_at > cfg.load_timeout;
  }

  /// What receive() found.
  enum class Received : std::uint8_t { none, message, bad };
  /// The next message waiting on its socket, decoded into `m` (none: nothing waiting; bad: a
  /// misframed or undecodable one, `unreadable` says why, `m` unspecified). A Result reuses the
  /// room of the ResultMsg `m` holds (decode()).
  Received receive(const Limits& limits, Clock::time_point now, Message& m);
};

/// Which blocks a round's Results cover. When the asked sets are a partition of the blocks (each
/// in exactly one: every worker heard and holding its target, the steady state) a Result covers
/// its asked set but what it skips (a subset: BlockDeal), and what it takes from its standby set:
/// counted, in O(1). Otherwise marked block by block, O(blocks) a round (34,667 blocks on
/// armadillo_L2 at W >= 2: ~150 µs of the client's CPU a round when every round marked them).
struct Coverage {
  std::vector<std::uint8_t> marks;  ///< per block: covered this round (when not counting; choose_sets' scratch)
  std::vector<SetPtr> partition;    ///< the asked sets (per peer) choose_sets() last found a partition
  bool counting = false;            ///< this round's asked sets are that partition
  std::size_t count = 0;            ///< blocks covered so far this round (counting)

  /// A round starts: nothing covered yet.
  void begin_round() {
    count = 0;
    if (!counting) std::fill(marks.begin(), marks.end(), 0);
  }
  /// p's Result came in.
  void note(const Peer& p) {
    if (counting) {
      count += p.asked->blocks.size() - p.skip.size() + p.take.size();
      return;
    }
    for (std::uint32_t b : p.asked->blocks)
      if (!std::binary_search(p.skip.begin(), p.skip.end(), b)) marks[b] = 1;
    for (std::uint32_t b : p.take) marks[b] = 1;  // blocks of its standby set
  }
  /// Blocks covered, with the client assist's `assisted` (marked in `marks` when not counting).
  std::size_t covered(std::uint32_t assisted) const {
    return counting ? count + assisted : std::size_t(std::count(marks.begin(), marks.end(), 1));
  }
};

/// Picks the block set each live worker is queried with (Peer::asked): its target if it holds it,
/// otherwise the largest set it holds but its standby set; then, while blocks are uncovered, a
/// held superset that covers them (a survivor keeps answering for a returning worker's blocks
/// until that one is loaded). Each queried worker that holds its standby set names it too
/// (Peer::standby_asked). Sets `cover.counting`: the asked sets are a partition of the blocks
/// (the same sets as the last partition found are one too: no pass over the blocks).
void choose_sets(std::vector<Peer>& peers, const BlockSetCache& sets, Coverage& cover);
/// Each live worker's target hash, once its target set is encoded (BlockSetCache::get starts
/// the encoding).
void refresh_targets(std::vector<Peer>& peers, BlockSetCache& sets);
/// Deals the blocks of down workers block-cyclically over the live ones (paper §3.4): each
/// worker's target is its own blocks plus its deal; then prune_sets().
void reassign(std::vector<Peer>& peers, BlockSetCache& sets);
/// Drops encoded sets no worker is meant to hold, holds, is being sent or owns originally.
void prune_sets(const std::vector<Peer>& peers, BlockSetCache& sets);
/// The order a round's Queries go out in (`order`: every peer's index): the slowest worker of the
/// round before first (by the compute its Result reported). A worker starts when its Query is out,
/// and the client's sends take about a microsecond each on a real network (half a message pair of
/// its work, spheretouch-bench scale): the one that needs longest should not also start last.
void send_order(const std::vector<Peer>& peers, std::vector<std::uint32_t>& order);

}  // namespace st::net::client
