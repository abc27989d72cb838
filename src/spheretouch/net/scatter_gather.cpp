// SPDX-License-Identifier: BSD-3-Clause
// ScatterGather (scatter_gather.hpp).
#include <spheretouch/net/scatter_gather.hpp>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/collide.hpp>
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/net/worker_config.hpp>

#include <malloc.h>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <random>
#include <thread>
#include <unordered_map>
#include <utility>

#include <spheretouch/net/socket_options.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

namespace {

/// An encoded block set the client may send: its blocks, content hash and bytes.
struct EncodedSet {
  std::vector<std::uint32_t> blocks;  // sorted
  std::uint64_t hash = 0;
  std::vector<std::uint8_t> bytes;
};
using SetPtr = std::shared_ptr<const EncodedSet>;

struct SceneData {
  geom::Mesh probe, object;
  Blocks blocks;
  std::uint32_t leaf_faces;
  std::uint32_t object_id = 0;  // ScatterConfig::object
};

Result<SetPtr> encode_set(const SceneData& s, std::vector<std::uint32_t> blocks) {
  auto bs = make_block_set(s.probe, s.object, s.blocks, blocks, s.leaf_faces, s.object_id);
  if (!bs) return Error{bs.error()};
  auto e = std::make_shared<EncodedSet>();
  e->blocks = std::move(blocks);
  e->bytes = encode_block_set(bs.value());
  e->hash = block_set_hash(e->bytes);
  return SetPtr(std::move(e));
}

bool is_superset(const std::vector<std::uint32_t>& big, const std::vector<std::uint32_t>& small) {
  return std::includes(big.begin(), big.end(), small.begin(), small.end());
}

// A worker's two state machines. link_after() and turn_after() are the tables in
// scatter_gather.hpp, which also says what each state and event means; kNoLink / kNoTurn marks a
// cell that is not a transition.
enum class Link : std::uint8_t { Unknown, Live, Loading, Down };
enum class LinkEvent : std::uint8_t { Hello, BlankHello, LoadStart, LoadEnd, MarkDown };
enum class Turn : std::uint8_t { Idle, Queried, Unsent, Pinged, Answered, Greeted };
enum class TurnEvent : std::uint8_t { NewRound, QuerySent, QueryUnsent, Ping, Result, NotLoaded, Hello };

constexpr Link kNoLink = static_cast<Link>(0xff);
constexpr Turn kNoTurn = static_cast<Turn>(0xff);

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

/// One long-lived thread that encodes block sets off the collision thread, jobs in order.
/// A thread per job (std::async) maps a fresh stack for every fault, and a process that asked
/// for mlockall(MCL_FUTURE) (`lock_memory`) keeps each one resident: +8 MB per encoding.
class Encoder {
 public:
  Encoder() : thread_([this] { loop(); }) {}
  Encoder(const Encoder&) = delete;
  Encoder& operator=(const Encoder&) = delete;
  ~Encoder() {
    {
      std::lock_guard<std::mutex> g(m_);
      stop_ = true;  // pending jobs are dropped: their futures report a broken promise
    }
    cv_.notify_one();
    thread_.join();
  }

  template <class Job>
  std::future<Result<SetPtr>> submit(Job&& job) {
    std::packaged_task<Result<SetPtr>()> task(std::forward<Job>(job));
    auto done = task.get_future();
    {
      std::lock_guard<std::mutex> g(m_);
      jobs_.push_back(std::move(task));
    }
    cv_.notify_one();
    return done;
  }

 private:
  void loop() {
    for (;;) {
      std::packaged_task<Result<SetPtr>()> task;
      {
        std::unique_lock<std::mutex> l(m_);
        cv_.wait(l, [this] { return stop_ || !jobs_.empty(); });
        if (stop_) return;
        task = std::move(jobs_.front());
        jobs_.pop_front();
      }
      task();
    }
  }

  std::mutex m_;
  std::condition_variable cv_;
  std::deque<std::packaged_task<Result<SetPtr>()>> jobs_;
  bool stop_ = false;
  std::thread thread_;  // last: starts once the members above exist
};

}  // namespace

struct ScatterGather::Impl {
  struct Peer {
    std::string endpoint;
    zmq::socket_t sock;
    Link link = Link::Unknown;
    Turn turn = Turn::Idle;
    std::uint32_t worker_id = 0;
    std::uint64_t epoch = 0;               // from its last Hello (0: none with an epoch yet)
    std::uint32_t misses = 0;              // rounds missed in a row (0 while Down)
    std::vector<std::uint64_t> held;       // hashes from its last Hello, MRU first
    std::vector<std::uint32_t> original;   // its own blocks (ScatterConfig::mapping)
    std::vector<std::uint32_t> target;     // blocks it should hold now
    std::uint64_t target_hash = 0;         // 0 while the target is being encoded
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
    SetPtr asked;                     // the block set this round's Query named; null if no Query was queued
    std::vector<std::uint32_t> skip;  // blocks of `asked` the client answers this round (assist)
    // Totals.
    std::uint64_t bytes_sent = 0;
    std::uint32_t loads_sent = 0;

    bool holds(std::uint64_t h) const { return h && std::find(held.begin(), held.end(), h) != held.end(); }
  };

  zmq::context_t* ctx = nullptr;
  // This client's ZeroMQ routing id on every worker socket (reconnects keep it); see
  // ScatterConfig::routing_id.
  std::string routing_id;
  ScatterConfig cfg;
  std::shared_ptr<const SceneData> scene;
  std::uint32_t probe_faces = 0, object_faces = 0;
  std::vector<Peer> peers;
  std::map<std::vector<std::uint32_t>, SetPtr> by_blocks;
  std::unordered_map<std::uint64_t, SetPtr> by_hash;
  std::map<std::vector<std::uint32_t>, std::future<Result<SetPtr>>> encoding;
  Encoder encoder;                // started with the client
  bool reassign_pending = false;  // a worker went down or came back: reassign()
  bool prune_pending = false;     // a worker dropped a set: prune_sets()
  std::uint64_t cur_seq = 0;
  bool in_round = false;
  std::vector<std::uint8_t> covered;  // per block, this round
  std::vector<std::uint8_t> buf;      // encode buffer
  // Client assist (cfg.assist_blocks): what the client needs to answer blocks itself.
  struct LocalBlock {
    // The block's faces and the vertices they use (object origin, local coords), with the tree a
    // worker builds for a block's subtree.
    std::optional<Body> body;
    std::vector<std::uint32_t> ids;  // global face id of each face
    std::uint64_t used = 0;          // last round it was answered in
  };
  std::optional<Body> probe_body;                       // the probe and its tree (built when assist is on)
  std::vector<std::uint32_t> face_block;                // object face -> its block
  std::vector<double> block_work;                       // per block: pairs it gave last round (0 where none)
  std::vector<std::uint32_t> worked;                    // blocks with block_work > 0
  std::vector<std::uint32_t> taken;                     // blocks the client answers this round, ascending
  std::vector<BlockWork> candidates;                    // scratch for choose_assist
  std::unordered_map<std::uint32_t, LocalBlock> local;  // blocks answered so far (bounded, LRU)
  std::optional<ComputeCollision> assist;               // the probe against one local block at a time
  CollisionResult assist_result;
  std::vector<zmq::pollitem_t> items;
  RoundResult* out = nullptr;

  // ---- worker state ------------------------------------------------------------------------

  /// The one place a worker's link state changes (the table in scatter_gather.hpp), with what
  /// entering or leaving a state implies.
  void step(Peer& p, LinkEvent e) {
    const Link next = link_after(p.link, e);
    ST_ASSERT(next != kNoLink, "a worker's link state changes only as the table says");
    if (next == kNoLink) return;
    if (p.link == Link::Loading && next != Link::Loading) p.upload = nullptr;
    if ((p.link == Link::Down) != (next == Link::Down)) {
      p.misses = 0;
      reassign_pending = true;  // its blocks are dealt anew
    }
    p.link = next;
    ST_ASSERT((p.link == Link::Loading) == (p.upload != nullptr), "a set is being sent exactly while Loading");
  }

  /// The one place a worker's turn in the round changes (the table in scatter_gather.hpp).
  /// Replies that fit no transition are counted and dropped by the caller before they get here.
  void step(Peer& p, TurnEvent e) {
    const Turn next = turn_after(p.turn, e);
    ST_ASSERT(next != kNoTurn, "a worker's turn changes only as the table says");
    if (next != kNoTurn) p.turn = next;
    ST_ASSERT(p.turn != Turn::Queried || p.asked, "a Query is out only with the set it named");
  }

  // ---- block sets --------------------------------------------------------------------------

  void remember(const SetPtr& s) {
    by_blocks[s->blocks] = s;
    by_hash[s->hash] = s;
  }

  /// The encoded set of `blocks`, or null while it is being encoded in the background.
  SetPtr get_set(const std::vector<std::uint32_t>& blocks) {
    if (auto it = by_blocks.find(blocks); it != by_blocks.end()) return it->second;
    auto f = encoding.find(blocks);
    if (f == encoding.end()) {
      // Encoding a multi-megabyte share takes milliseconds: never inside a round's deadline.
      encoding.emplace(blocks, encoder.submit([s = scene, blocks] { return encode_set(*s, blocks); }));
      return nullptr;
    }
    if (f->second.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return nullptr;
    Result<SetPtr> r = f->second.get();
    encoding.erase(f);
    ST_ASSERT(r.ok(), "blocks come from our own partition, so they encode");
    if (!r) return nullptr;
    remember(r.value());
    return r.value();
  }

  /// Drops encoded sets no worker is meant to hold, holds, or owns originally (memory stays
  /// bounded however often workers come and go), and collects finished background encodings.
  void prune_sets() {
    for (auto it = encoding.begin(); it != encoding.end();) {
      if (it->second.wait_for(std::chrono::seconds(0)) != std::future_status::ready) {
        ++it;
        continue;
      }
      if (Result<SetPtr> r = it->second.get(); r) remember(r.value());
      it = encoding.erase(it);
    }
    std::unordered_map<std::uint64_t, bool> keep;
    for (const Peer& p : peers) {
      for (std::uint64_t h : p.held) keep[h] = true;
      if (p.target_hash) keep[p.target_hash] = true;
      if (p.link == Link::Loading) keep[p.upload->hash] = true;
    }
    prune_pending = false;
    std::size_t dropped = 0;
    for (auto it = by_blocks.begin(); it != by_blocks.end();) {
      const bool original =
          std::any_of(peers.begin(), peers.end(), [&](const Peer& p) { return p.original == it->first; });
      const bool targeted = std::any_of(peers.begin(), peers.end(), [&](const Peer& p) { return p.target == it->first; });
      if (original || targeted || keep.count(it->second->hash)) {
        ++it;
        continue;
      }
      by_hash.erase(it->second->hash);
      it = by_blocks.erase(it);
      ++dropped;
    }
    if (dropped) ::malloc_trim(0);  // encoded sets are megabytes: give them back to the system
  }

  void refresh_targets() {
    for (Peer& p : peers)
      if (p.link != Link::Down && !p.target_hash && !p.target.empty())
        if (SetPtr s = get_set(p.target)) p.target_hash = s->hash;
  }

  /// Deals the blocks of down workers block-cyclically over the live ones (paper §3.4).
  void reassign() {
    reassign_pending = false;
    std::vector<std::size_t> alive;
    std::vector<std::uint32_t> orphans;
    for (std::size_t i = 0; i < peers.size(); ++i) {
      if (peers[i].link != Link::Down)
        alive.push_back(i);
      else
        orphans.insert(orphans.end(), peers[i].original.begin(), peers[i].original.end());
    }
    std::sort(orphans.begin(), orphans.end());
    for (Peer& p : peers) p.target = p.link != Link::Down ? p.original : std::vector<std::uint32_t>{};
    if (!alive.empty())
      for (std::size_t j = 0; j < orphans.size(); ++j) peers[alive[j % alive.size()]].target.push_back(orphans[j]);
    for (Peer& p : peers) {
      std::sort(p.target.begin(), p.target.end());
      SetPtr s = p.target.empty() ? nullptr : get_set(p.target);
      p.target_hash = s ? s->hash : 0;
    }
    prune_sets();
  }

  Status open_socket(Peer& p) {
    p.silent_since = std::max(p.silent_since, Clock::now());
    p.sock = zmq::socket_t(*ctx, zmq::socket_type::dealer);
    set_common_options(p.sock, cfg.sndhwm, cfg.rcvhwm, cfg.limits.max_message_bytes);
    p.sock.set(zmq::sockopt::routing_id, zmq::buffer(routing_id));
    p.sock.set(zmq::sockopt::immediate, 1);        // no queueing to a worker that is not connected
    p.sock.set(zmq::sockopt::reconnect_ivl, 100);  // a restarted worker is found within 0.1 s
    p.sock.set(zmq::sockopt::reconnect_ivl_max, 1000);
    p.sock.set(zmq::sockopt::heartbeat_ivl, 500);  // ZMTP heartbeats drop half-open connections
    p.sock.set(zmq::sockopt::heartbeat_timeout, 1500);
    if (!cfg.curve_server_public.empty()) {
      p.sock.set(zmq::sockopt::curve_serverkey, cfg.curve_server_public);
      p.sock.set(zmq::sockopt::curve_publickey, cfg.curve_public);
      p.sock.set(zmq::sockopt::curve_secretkey, cfg.curve_secret);
    }
    try {
      if (needs_ipv6(p.endpoint)) p.sock.set(zmq::sockopt::ipv6, 1);
      p.sock.connect(zmq_endpoint(p.endpoint));
    } catch (const zmq::error_t& e) { return fail("scatter-gather: connect ", p.endpoint, ": ", e.what()); }
    return Ok{};
  }

  // ---- sending -----------------------------------------------------------------------------

  bool send(Peer& p, const Message& m) {
    encode(m, buf);
    try {
      return p.sock.send(zmq::buffer(buf), zmq::send_flags::dontwait).has_value();
    } catch (const zmq::error_t&) { return false; }
  }

  void heartbeat(Peer& p, Clock::time_point now) {
    p.heartbeat_due = now + cfg.heartbeat_period;
    p.asked_at = now;
    send(p, HeartbeatMsg{++p.nonce});
  }

  void maybe_start_upload(Peer& p, Clock::time_point now) {
    if (!heard(p.link) || !p.target_hash || p.holds(p.target_hash)) return;
    if (p.link == Link::Loading && p.upload->hash == p.target_hash) return;
    if (p.refused_hash == p.target_hash && now - p.refused_at < cfg.load_timeout) return;
    p.upload = by_hash.at(p.target_hash);  // replaces a set still being sent for an older target
    p.upload_off = 0;
    p.load_progress_at = now;
    ++p.loads_sent;
    step(p, LinkEvent::LoadStart);
  }

  void pump_upload(Peer& p, Clock::time_point now) {
    if (p.link != Link::Loading || p.upload_off >= p.upload->bytes.size()) return;
    const auto& bytes = p.upload->bytes;
    const std::size_t chunk = std::max<std::size_t>(1, std::min(cfg.chunk_bytes, cfg.limits.max_chunk_bytes));
    LoadBlocksMsg m{p.upload->hash, bytes.size(), 0, {}};
    while (p.upload_off < bytes.size()) {
      const std::size_t n = std::min(chunk, bytes.size() - p.upload_off);
      m.offset = p.upload_off;
      m.data.assign(bytes.begin() + static_cast<std::ptrdiff_t>(p.upload_off),
                    bytes.begin() + static_cast<std::ptrdiff_t>(p.upload_off + n));
      if (!send(p, m)) break;  // queue full or not connected: resume on POLLOUT / next round
      p.upload_off += n;
      p.bytes_sent += n;
      p.load_progress_at = now;
    }
  }

  /// Loading, and nothing sent or acknowledged for load_timeout.
  bool load_stuck(const Peer& p, Clock::time_point now) const {
    return p.link == Link::Loading && now - p.load_progress_at > cfg.load_timeout;
  }

  // ---- receiving ---------------------------------------------------------------------------

  void on_hello(Peer& p, const HelloMsg& h, Clock::time_point now) {
    if (p.link == Link::Loading && h.epoch != p.epoch)
      step(p, LinkEvent::LoadEnd);  // restarted: whatever was sent is gone
    p.epoch = h.epoch;
    p.worker_id = h.worker_id;
    const std::size_t had = p.held.size();
    p.held.clear();
    for (const Held& x : h.held) p.held.push_back(x.hash);
    if (p.held.size() < had) prune_pending = true;  // it dropped a set: maybe ours can go too
    if (p.link == Link::Loading && p.holds(p.upload->hash)) step(p, LinkEvent::LoadEnd);  // load acknowledged
    step(p, h.epoch ? LinkEvent::Hello : LinkEvent::BlankHello);
    step(p, TurnEvent::Hello);
    maybe_start_upload(p, now);
  }

  void on_result(Peer& p, ResultMsg& r) {
    if (!in_round || r.seq != cur_seq) {
      ++out->stale_dropped;
      return;
    }
    if (p.turn != Turn::Queried || r.hash != p.asked->hash || r.object != cfg.object) {
      ++out->bad_messages;
      return;
    }
    for (const FacePair& fp : r.pairs)
      if (fp.probe >= probe_faces || fp.object >= object_faces) {
        ++out->bad_messages;
        return;
      }
    step(p, TurnEvent::Result);
    p.misses = 0;
    ++out->workers_replied;
    out->pairs.insert(out->pairs.end(), r.pairs.begin(), r.pairs.end());
    for (std::uint32_t b : p.asked->blocks)
      if (!std::binary_search(p.skip.begin(), p.skip.end(), b)) covered[b] = 1;
    out->worker_stats[std::size_t(&p - peers.data())] = r.stats;
    out->stats.sphere_tests += r.stats.sphere_tests;
    out->stats.tri_tests += r.stats.tri_tests;
    out->stats.compute_ns = std::max(out->stats.compute_ns, r.stats.compute_ns);
  }

  void on_error(Peer& p, const ErrorMsg& e, Clock::time_point now) {
    const bool query_turn = p.turn == Turn::Queried || p.turn == Turn::Unsent || p.turn == Turn::Answered;
    if (e.code == ErrorCode::NotLoaded && in_round && e.ref == cur_seq && query_turn) {
      step(p, TurnEvent::NotLoaded);  // alive, just not holding what we asked for; its Hello follows
      p.held.erase(std::remove(p.held.begin(), p.held.end(), p.asked ? p.asked->hash : 0), p.held.end());
    } else if (e.code == ErrorCode::LoadFailed || e.code == ErrorCode::TooLarge) {
      if (p.link == Link::Loading && (e.ref == p.upload->hash || e.ref == 0)) {
        p.refused_hash = p.upload->hash;
        p.refused_at = now;
        step(p, LinkEvent::LoadEnd);
      }
    } else if (out) {
      ++out->bad_messages;
    }
  }

  void drain(Peer& p, Clock::time_point now) {
    for (int budget = 0; budget < 256; ++budget) {
      zmq::message_t msg;
      try {
        if (!p.sock.recv(msg, zmq::recv_flags::dontwait)) return;
      } catch (const zmq::error_t&) { return; }
      if (msg.more()) {  // a worker sends one frame per message; drop the rest
        for (bool more = true; more;) {
          zmq::message_t junk;
          try {
            (void)p.sock.recv(junk, zmq::recv_flags::dontwait);
          } catch (const zmq::error_t&) { return; }
          more = junk.more();
        }
        if (out) ++out->bad_messages;
        continue;
      }
      Result<Message> m = decode({static_cast<const std::uint8_t*>(msg.data()), msg.size()}, cfg.limits);
      if (!m) {
        if (out) ++out->bad_messages;
        p.unreadable = m.error();
        continue;
      }
      p.silent_since = std::max(p.silent_since, now);
      if (auto* h = std::get_if<HelloMsg>(&m.value()))
        on_hello(p, *h, now);
      else if (auto* r = std::get_if<ResultMsg>(&m.value())) {
        if (out) on_result(p, *r);
      } else if (auto* e = std::get_if<ErrorMsg>(&m.value()))
        on_error(p, *e, now);
      else if (out)
        ++out->bad_messages;
    }
  }

  /// Waits until `until` (bounded) for replies or send room, then handles everything waiting.
  void wait_and_service(Clock::time_point until) {
    items.clear();
    for (Peer& p : peers) {
      short ev = ZMQ_POLLIN;
      if (p.link == Link::Loading && p.upload_off < p.upload->bytes.size()) ev |= ZMQ_POLLOUT;
      items.push_back({p.sock.handle(), 0, ev, 0});
    }
    const auto now = Clock::now();
    const auto left_us = std::chrono::duration_cast<std::chrono::microseconds>(until - now).count();
    // zmq_poll counts in ms: wait whole ms, and poll without waiting through the last fraction
    // so the round never overshoots its deadline by a millisecond.
    const long timeout_ms = left_us > 0 ? left_us / 1000 : 0;
    try {
      zmq::poll(items.data(), items.size(), std::chrono::milliseconds(timeout_ms));
    } catch (const zmq::error_t&) {}
    if (timeout_ms == 0 && left_us > 0) std::this_thread::yield();
    const auto t = Clock::now();
    for (std::size_t i = 0; i < peers.size(); ++i) {
      if (items[i].revents & ZMQ_POLLIN) drain(peers[i], t);
      if (items[i].revents & ZMQ_POLLOUT) pump_upload(peers[i], t);
    }
  }

  void service_now() {
    const auto now = Clock::now();
    for (Peer& p : peers) drain(p, now);
  }

  // ---- choosing what to ask -----------------------------------------------------------------

  /// Picks the block set each live worker is queried with: its target if it holds it, otherwise
  /// the largest set it holds; then, while blocks are uncovered, a held superset that covers
  /// them (a survivor keeps answering for a returning worker's blocks until that one is loaded).
  void choose_sets() {
    std::fill(covered.begin(), covered.end(), 0);
    for (Peer& p : peers) {
      p.asked = nullptr;
      if (!heard(p.link)) continue;
      if (p.holds(p.target_hash))
        p.asked = by_hash.at(p.target_hash);
      else
        for (std::uint64_t h : p.held)
          if (auto it = by_hash.find(h);
              it != by_hash.end() && (!p.asked || it->second->blocks.size() > p.asked->blocks.size()))
            p.asked = it->second;
      if (p.asked)
        for (std::uint32_t b : p.asked->blocks) covered[b] = 1;
    }
    if (std::all_of(covered.begin(), covered.end(), [](std::uint8_t c) { return c; })) return;
    for (Peer& p : peers) {
      if (!heard(p.link)) continue;
      SetPtr best;
      std::size_t best_gain = 0;
      for (std::uint64_t h : p.held) {
        auto it = by_hash.find(h);
        if (it == by_hash.end() || (p.asked && !is_superset(it->second->blocks, p.asked->blocks))) continue;
        std::size_t gain = 0;
        for (std::uint32_t b : it->second->blocks) gain += !covered[b];
        if (gain > best_gain) {
          best_gain = gain;
          best = it->second;
        }
      }
      if (best) {
        p.asked = best;
        for (std::uint32_t b : best->blocks) covered[b] = 1;
      }
    }
  }

  /// Gives a fresh socket to every worker that was asked but has been silent for
  /// reconnect_after (unless it is busy loading what we sent).
  void revive_silent(Clock::time_point now) {
    for (Peer& p : peers) {
      if (p.asked_at <= p.silent_since || now - p.silent_since < cfg.reconnect_after) continue;
      if (p.link == Link::Loading && !load_stuck(p, now)) continue;
      if (p.link == Link::Loading) step(p, LinkEvent::LoadEnd);  // dropped with the old socket
      (void)open_socket(p);
    }
  }

  void begin_round_sends(const geom::Pose& pose, Clock::time_point now) {
    revive_silent(now);
    if (reassign_pending)
      reassign();
    else if (prune_pending)
      prune_sets();
    refresh_targets();
    for (Peer& p : peers) maybe_start_upload(p, now);
    choose_sets();
    choose_assisted();
    std::fill(covered.begin(), covered.end(), 0);
    for (Peer& p : peers) {
      step(p, TurnEvent::NewRound);
      if (p.link == Link::Down) {
        if (now >= p.heartbeat_due) heartbeat(p, now);
        continue;
      }
      if (p.asked) {
        ++out->workers_asked;
        p.asked_at = now;
        if (send(p, QueryMsg{cur_seq, p.asked->hash, pose, p.skip, cfg.object})) {
          step(p, TurnEvent::QuerySent);
        } else {
          p.asked = nullptr;
          step(p, TurnEvent::QueryUnsent);  // counts as a miss
        }
        if (now >= p.held_refresh_due) {  // the Hello it answers with may arrive in any later round
          p.held_refresh_due = now + cfg.held_refresh_period;
          send(p, HeartbeatMsg{++p.nonce});
        }
      } else if (p.link != Link::Loading) {
        step(p, TurnEvent::Ping);  // unknown or empty: it must at least say hello by the deadline
        if (now >= p.heartbeat_due || p.link == Link::Unknown) heartbeat(p, now);
      }
      pump_upload(p, now);
    }
  }

  // ---- client assist ----------------------------------------------------------------------

  /// The blocks the client answers this round (choose_assist() over last round's pairs per
  /// block) and each asked worker's share of them (its Query's skip list).
  void choose_assisted() {
    taken.clear();
    for (Peer& p : peers) p.skip.clear();
    if (cfg.assist_blocks == 0 || worked.empty()) return;
    candidates.clear();
    for (std::uint32_t b : worked)
      for (std::uint32_t i = 0; i < peers.size(); ++i)
        if (const Peer& p = peers[i]; p.asked && std::binary_search(p.asked->blocks.begin(), p.asked->blocks.end(), b)) {
          candidates.push_back({b, i, block_work[b]});
          break;
        }
    taken = choose_assist(candidates, static_cast<std::uint32_t>(peers.size()), cfg.assist_blocks);
    for (Peer& p : peers)
      if (p.asked)
        for (std::uint32_t b : taken)
          if (std::binary_search(p.asked->blocks.begin(), p.asked->blocks.end(), b)) p.skip.push_back(b);
  }

  /// The client's own block: its faces, the vertices they use and its tree, made once and kept
  /// (the least recently used go beyond 8 × assist_blocks + 64).
  LocalBlock* local_block(std::uint32_t b) {
    auto it = local.find(b);
    if (it == local.end()) {
      const std::size_t cap = 8 * std::size_t(cfg.assist_blocks) + 64;
      if (local.size() >= cap) {
        auto oldest = local.begin();
        for (auto j = local.begin(); j != local.end(); ++j)
          if (j->second.used < oldest->second.used) oldest = j;
        local.erase(oldest);
      }
      const geom::Mesh& object = scene->object;
      LocalBlock lb;
      lb.ids = scene->blocks[b];
      std::sort(lb.ids.begin(), lb.ids.end());
      std::vector<std::uint32_t> verts;
      for (std::uint32_t f : lb.ids) verts.insert(verts.end(), object.faces[f].begin(), object.faces[f].end());
      std::sort(verts.begin(), verts.end());
      verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
      geom::Mesh mesh;
      mesh.name = object.name + " (block)";
      mesh.origin = object.origin;
      for (std::uint32_t v : verts) mesh.local.push_back(object.local[v]);
      auto at = [&](std::uint32_t v) {
        return static_cast<std::uint32_t>(std::lower_bound(verts.begin(), verts.end(), v) - verts.begin());
      };
      for (std::uint32_t f : lb.ids)
        mesh.faces.push_back({at(object.faces[f][0]), at(object.faces[f][1]), at(object.faces[f][2])});
      geom::TreeConfig params = geom::DefaultTreeConfig();
      params.leaf_faces = std::clamp<std::uint32_t>(scene->leaf_faces, 1, geom::kMaxLeafFaces);
      Result<Body> body = Body::make(std::move(mesh), params);
      ST_ASSERT(body.ok(), "a block of our own object builds a tree");
      if (!body) return nullptr;
      lb.body.emplace(std::move(body).value());
      it = local.emplace(b, std::move(lb)).first;
    }
    it->second.used = cur_seq;
    return &it->second;
  }

  /// Answers the taken blocks while the Queries are out: the same collide() a worker runs on its
  /// block's subtree, so the pairs are the ones the worker would have found.
  void answer_taken(const geom::Pose& pose) {
    if (taken.empty()) return;
    const auto t0 = Clock::now();
    for (std::uint32_t b : taken) {
      LocalBlock* lb = local_block(b);
      if (!lb) continue;  // not covered: the round says it is incomplete
      // One collider for every block: the probe's caches stay, the block's are derived per query.
      if (!assist)
        assist.emplace(*probe_body, *lb->body);
      else
        assist->set_object(*lb->body);
      CollisionRequest request = CollisionRequest::past_limit(cfg.limits.max_pairs);
      request.sort_pairs = false;  // the round's merge sorts
      assist->at_relative(pose, request, assist_result);
      if (!assist_result.complete) continue;  // more than max_pairs: left to the workers' refusal
      for (const geom::FacePair& fp : assist_result.pairs) out->pairs.push_back({fp.probe, lb->ids[fp.object]});
      out->assist.sphere_tests += assist_result.stats.node_pairs;
      out->assist.tri_tests += assist_result.stats.tri_pairs;
      ++out->blocks_assisted;
      covered[b] = 1;
    }
    out->stats.sphere_tests += out->assist.sphere_tests;
    out->stats.tri_tests += out->assist.tri_tests;
    out->assist.compute_ns =
        std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count());
  }

  /// Each block's pairs in this round's result: what choose_assisted() weighs next round.
  void note_block_work(const std::vector<FacePair>& pairs) {
    if (cfg.assist_blocks == 0) return;
    for (std::uint32_t b : worked) block_work[b] = 0;
    worked.clear();
    for (const FacePair& fp : pairs) {
      const std::uint32_t b = face_block[fp.object];
      if (b == UINT32_MAX) continue;
      if (block_work[b] == 0) worked.push_back(b);
      block_work[b] += 1;
    }
  }

  bool all_replied() const {
    bool any = false;
    for (const Peer& p : peers) {
      if (p.asked) any = true;  // a Query is out (answered or not)
      if (p.turn == Turn::Queried || p.turn == Turn::Pinged) return false;
    }
    return any;  // nobody to wait for: wait out the deadline instead of spinning the caller
  }

  void end_round(Clock::time_point now) {
    for (Peer& p : peers) {
      if (p.link == Link::Down) continue;
      if (!missed(p.turn)) {
        if (p.turn != Turn::Idle) p.misses = 0;  // Answered or Greeted
        if (load_stuck(p, now)) mark_down(p);
        continue;
      }
      if (p.link == Link::Loading && !load_stuck(p, now)) continue;  // busy loading: exempt
      if (++p.misses >= cfg.miss_limit) mark_down(p);
    }
  }

  void mark_down(Peer& p) {
    // A fresh socket drops whatever is queued for the dead worker, and re-arms the connection:
    // libzmq reconnects tcp:// and ipc:// by itself, but not inproc:// once its binder is gone.
    (void)open_socket(p);
    step(p, LinkEvent::MarkDown);
    p.heartbeat_due = Clock::now();
  }
};

Result<std::unique_ptr<ScatterGather>> ScatterGather::create(zmq::context_t& ctx, ScatterConfig config,
                                                             geom::Mesh probe, geom::Mesh object, Blocks blocks) {
  if (config.object >= config.limits.max_objects)
    return fail("scatter-gather: object ", config.object, " is not below max_objects = ", config.limits.max_objects);
  if (config.endpoints.empty()) return fail("scatter-gather: no worker endpoints");
  if (config.miss_limit == 0) return fail("scatter-gather: miss_limit must be at least 1");
  if (!config.curve_server_public.empty() || !config.curve_public.empty() || !config.curve_secret.empty()) {
    if (Status s = check_z85_key(config.curve_server_public, "curve_server_public"); !s) return Error{s.error()};
    if (Status s = check_z85_key(config.curve_public, "curve_public"); !s) return Error{s.error()};
    if (Status s = check_z85_key(config.curve_secret, "curve_secret"); !s) return Error{s.error()};
  }
  auto impl = std::make_unique<Impl>();
  impl->ctx = &ctx;
  if (!config.routing_id.empty()) {
    if (config.routing_id.size() > 255 || config.routing_id[0] == 0)
      return fail("scatter-gather: routing_id must be 1-255 bytes and must not start with a zero byte");
    impl->routing_id = config.routing_id;
  } else {
    std::random_device rd;  // getrandom(2) on Linux
    impl->routing_id.resize(16);
    for (char& c : impl->routing_id) c = static_cast<char>(rd() & 0xFF);
    if (impl->routing_id[0] == 0) impl->routing_id[0] = 1;
  }
  impl->probe_faces = static_cast<std::uint32_t>(probe.faces.size());
  impl->object_faces = static_cast<std::uint32_t>(object.faces.size());
  const auto nblocks = static_cast<std::uint32_t>(blocks.size());
  impl->scene = std::make_shared<const SceneData>(
      SceneData{std::move(probe), std::move(object), std::move(blocks), config.leaf_faces, config.object});
  if (config.assist_blocks > config.limits.max_skip)
    return fail("scatter-gather: assist_blocks = ", config.assist_blocks, " exceeds the skip list limit ",
                config.limits.max_skip);
  impl->covered.assign(nblocks, 0);
  impl->cfg = std::move(config);
  if (impl->cfg.assist_blocks > 0) {
    const SceneData& sc = *impl->scene;
    geom::TreeConfig params = geom::DefaultTreeConfig();
    params.leaf_faces = std::clamp<std::uint32_t>(sc.leaf_faces, 1, geom::kMaxLeafFaces);
    Result<geom::SphereTree> pt = geom::SphereTree::build(sc.probe, params);
    if (!pt) return fail("scatter-gather: client assist: probe tree: ", pt.error());
    // The body shares the scene's probe (an aliasing pointer: the scene data owns the mesh).
    Result<Body> pb = Body::make(std::shared_ptr<const geom::Mesh>(impl->scene, &sc.probe),
                                 std::make_shared<const geom::SphereTree>(std::move(pt).value()));
    if (!pb) return fail("scatter-gather: client assist: probe: ", pb.error());
    impl->probe_body.emplace(std::move(pb).value());
    impl->face_block.assign(sc.object.faces.size(), UINT32_MAX);
    for (std::uint32_t b = 0; b < nblocks; ++b)
      for (std::uint32_t f : sc.blocks[b])
        if (f < impl->face_block.size() && impl->face_block[f] == UINT32_MAX) impl->face_block[f] = b;
    impl->block_work.assign(nblocks, 0);
  }
  const auto share = deal_blocks(nblocks, static_cast<std::uint32_t>(impl->cfg.endpoints.size()), impl->cfg.mapping,
                                 impl->cfg.mapping_seed);
  for (std::size_t i = 0; i < impl->cfg.endpoints.size(); ++i) {
    Impl::Peer p;
    p.endpoint = impl->cfg.endpoints[i];
    if (Status st = impl->open_socket(p); !st) return Error{st.error()};
    p.original = share[i];
    p.target = p.original;
    impl->peers.push_back(std::move(p));
  }
  // The own shares are encoded up front (cold); reassigned variants later, in the background.
  for (Impl::Peer& p : impl->peers) {
    if (p.original.empty()) continue;
    auto s = encode_set(*impl->scene, p.original);
    if (!s) return Error{s.error()};
    impl->remember(s.value());
    p.target_hash = s.value()->hash;
  }
  const auto now = Clock::now();
  for (Impl::Peer& p : impl->peers) impl->heartbeat(p, now);
  return std::unique_ptr<ScatterGather>(new ScatterGather(std::move(impl)));
}

ScatterGather::ScatterGather(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ScatterGather::~ScatterGather() {
  if (impl_) wipe_secret(impl_->cfg.curve_secret);  // kept until now: sockets reopened after a fault need it
}

void ScatterGather::round(std::uint64_t seq, const geom::Pose& pose, Clock::time_point deadline, RoundResult& out) {
  Impl& m = *impl_;
  out.seq = seq;
  out.pairs.clear();
  out.complete = false;
  out.workers_asked = out.workers_replied = out.blocks_covered = 0;
  out.blocks_total = static_cast<std::uint32_t>(m.covered.size());
  out.stale_dropped = out.bad_messages = 0;
  out.stats = {};
  out.blocks_assisted = 0;
  out.assist = {};
  out.worker_stats.assign(m.peers.size(), QueryStats{});
  m.out = &out;
  m.in_round = false;
  m.service_now();  // old replies are dropped here, Hellos applied
  m.cur_seq = seq;
  m.in_round = true;
  m.begin_round_sends(pose, Clock::now());
  m.answer_taken(pose);  // while the workers compute
  const auto spin_until = std::min(deadline, Clock::now() + std::chrono::microseconds(m.cfg.spin_us));
  while (!m.all_replied()) {
    const auto now = Clock::now();
    if (now >= deadline) break;
    m.wait_and_service(now < spin_until ? now : deadline);  // until == now: poll without waiting
  }
  m.in_round = false;
  m.end_round(Clock::now());
  m.out = nullptr;
  std::sort(out.pairs.begin(), out.pairs.end());
  out.pairs.erase(std::unique(out.pairs.begin(), out.pairs.end()), out.pairs.end());
  // The same probe face collides on several workers: merge to distinct faces (paper §3.5).
  out.probe_faces.clear();
  out.object_faces.clear();
  for (const FacePair& f : out.pairs) {
    if (out.probe_faces.empty() || out.probe_faces.back() != f.probe) out.probe_faces.push_back(f.probe);
    out.object_faces.push_back(f.object);
  }
  std::sort(out.object_faces.begin(), out.object_faces.end());
  out.object_faces.erase(std::unique(out.object_faces.begin(), out.object_faces.end()), out.object_faces.end());
  out.blocks_covered = static_cast<std::uint32_t>(std::count(m.covered.begin(), m.covered.end(), 1));
  out.complete = out.blocks_covered == out.blocks_total;
  m.note_block_work(out.pairs);
}

RoundResult ScatterGather::round(std::uint64_t seq, const geom::Pose& pose, Clock::time_point deadline) {
  RoundResult r;
  round(seq, pose, deadline, r);
  return r;
}

bool ScatterGather::wait_ready(Clock::time_point deadline) {
  Impl& m = *impl_;
  for (;;) {
    const auto now = Clock::now();
    m.revive_silent(now);
    if (m.reassign_pending) m.reassign();
    m.refresh_targets();
    bool ready = true;
    for (Impl::Peer& p : m.peers) {
      if (p.link == Link::Down) {
        if (now >= p.heartbeat_due) m.heartbeat(p, now);
        continue;
      }
      if (p.link == Link::Unknown && now >= p.heartbeat_due) m.heartbeat(p, now);
      m.maybe_start_upload(p, now);
      m.pump_upload(p, now);
      if (p.link == Link::Unknown || (!p.target.empty() && !p.holds(p.target_hash))) ready = false;
    }
    const auto up = [](const Impl::Peer& p) { return p.link != Link::Down; };
    if (ready && std::any_of(m.peers.begin(), m.peers.end(), up)) return true;
    if (now >= deadline) return false;
    m.wait_and_service(std::min(deadline, now + std::chrono::milliseconds(10)));
  }
}

std::vector<WorkerStatus> ScatterGather::workers() const {
  std::vector<WorkerStatus> v;
  for (const Impl::Peer& p : impl_->peers)
    v.push_back({p.endpoint, p.link != Link::Down, p.worker_id, p.epoch, p.misses, p.target, p.holds(p.target_hash),
                 p.bytes_sent, p.loads_sent, p.held.size(), p.unreadable});
  return v;
}

std::size_t ScatterGather::encoded_sets() const { return impl_->by_blocks.size(); }

std::uint32_t ScatterGather::blocks_total() const { return static_cast<std::uint32_t>(impl_->covered.size()); }

std::vector<std::uint32_t> choose_assist(std::span<const BlockWork> worked, std::uint32_t workers, std::uint32_t max_blocks) {
  std::vector<double> load(workers, 0.0);
  for (const BlockWork& w : worked)
    if (w.owner < workers && w.work > 0) load[w.owner] += w.work;
  std::vector<std::uint8_t> moved(worked.size(), 0);
  std::vector<std::uint32_t> out;
  double client = 0;
  while (out.size() < max_blocks && workers > 0) {
    const auto busiest = static_cast<std::uint32_t>(std::max_element(load.begin(), load.end()) - load.begin());
    const double gap = load[busiest] - client;  // a block lighter than this shortens the longer of the two
    std::size_t pick = worked.size();
    for (std::size_t i = 0; i < worked.size(); ++i)
      if (!moved[i] && worked[i].owner == busiest && worked[i].work > 0 && worked[i].work < gap &&
          (pick == worked.size() || worked[i].work > worked[pick].work))
        pick = i;
    if (pick == worked.size()) break;
    moved[pick] = 1;
    load[busiest] -= worked[pick].work;
    client += worked[pick].work;
    out.push_back(worked[pick].block);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::size_t count_contacts(const std::vector<FacePair>& pairs) {
  std::vector<std::uint32_t> scratch;
  return geom::count_faces(pairs, scratch).contacts();
}

}  // namespace st::net
