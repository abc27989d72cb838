// SPDX-License-Identifier: BSD-3-Clause
// ScatterGather (scatter_gather.hpp): the rounds. A worker as the client sees it is a Peer
// (peer.hpp), the encoded block sets are a BlockSetCache (block_set_cache.hpp), the client
// assist is a ClientAssist (client_assist.hpp).
#include <spheretouch/net/scatter_gather.hpp>

#include <algorithm>
#include <random>
#include <thread>
#include <utility>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/net/block_deal.hpp>
#include <spheretouch/net/block_set_cache.hpp>
#include <spheretouch/net/client_assist.hpp>
#include <spheretouch/net/curve_keys.hpp>
#include <spheretouch/net/peer.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

using client::Link;
using client::LinkEvent;
using client::Peer;
using client::Turn;
using client::TurnEvent;

struct ScatterGather::Impl {
  zmq::context_t* ctx = nullptr;
  // This client's ZeroMQ routing id on every worker socket (reconnects keep it); see
  // ScatterConfig::routing_id.
  std::string routing_id;
  ScatterConfig cfg;
  std::shared_ptr<const client::SceneData> scene;
  std::uint32_t probe_faces = 0, object_faces = 0;
  std::vector<Peer> peers;
  std::unique_ptr<client::BlockSetCache> sets;
  std::unique_ptr<client::ClientAssist> assist;  // null unless cfg.assist_blocks
  std::unique_ptr<client::WorkLedger> ledger;    // each block's work the round before (kept only if weigh)
  bool weigh = false;                            // the assist or the replicated deal weighs the blocks' work
  std::unique_ptr<client::BlockDeal> deal;       // who answers each block this round
  bool reassign_pending = false;                 // a worker went down or came back: reassign()
  bool prune_pending = false;                    // a worker dropped a set: prune_sets()
  std::uint64_t cur_seq = 0;
  bool in_round = false;
  // Nothing owed after the last round (every worker Live, its Result in, no heartbeat out): the
  // next skips its drain before the sends (two system calls a socket for nothing).
  bool owed_nothing = false;
  client::Coverage coverage;      // the blocks this round's Results cover
  std::vector<std::uint8_t> buf;  // encode buffer
  Message rx;                     // drain() decodes into it (a Result's room kept: <= Limits::max_pairs)
  std::vector<zmq::pollitem_t> items;
  std::vector<std::uint32_t> polled;  // the peer of each item
  RoundResult* out = nullptr;
  // The round's pairs come in sorted runs (a worker sorts its own; the assist's are sorted as
  // they come), merged at the end without sorting them again.
  geom::SortedRuns runs;
  std::vector<std::uint32_t> ids_scratch;  // distinct_faces()'s room
  std::vector<std::uint32_t> order;        // the peers in the order a round's Queries go out (client::send_order)

  /// A worker's link state changes (Peer::step); entering or leaving Down deals the blocks anew.
  void link(Peer& p, LinkEvent e) {
    if (p.step(e)) reassign_pending = true;
  }

  // ---- receiving ---------------------------------------------------------------------------

  void on_hello(Peer& p, const HelloMsg& h, Clock::time_point now) {
    // A restarted worker's socket can still hold replies of its previous life after the first
    // of its new one (ZeroMQ takes from the old and the new connection in turn): such a Hello
    // would undo the restart (its sets look held again, an upload in progress is dropped) until
    // the next reply says otherwise, and cost a reload.
    if (h.epoch != 0 && h.epoch == p.retired_epoch) {
      if (out) ++out->stale_dropped;
      return;
    }
    if (h.epoch != 0 && p.epoch != 0 && h.epoch != p.epoch) p.retired_epoch = p.epoch;
    if (p.link == Link::Loading && h.epoch != p.epoch) link(p, LinkEvent::LoadEnd);  // restarted: what was sent is gone
    p.epoch = h.epoch;
    p.worker_id = h.worker_id;
    const std::size_t had = p.held.size();
    const bool had_target = p.holds(p.target_hash);
    p.held.clear();
    for (const Held& x : h.held) p.held.push_back(x.hash);
    if (p.held.size() < had) prune_pending = true;  // it dropped a set: maybe ours can go too
    if (had_target && !p.holds(p.target_hash) && p.holds(p.standby_hash)) {
      // Its share gave way to its standby copies: no room for both. The share comes first; the
      // copies wait for load_timeout (else the two would displace each other on every load).
      p.refused_hash = p.standby_hash;
      p.refused = "no room for its standby copies beside its share (max_sets)";
      p.refused_at = now;
    }
    if (p.link == Link::Loading && p.holds(p.upload->hash)) link(p, LinkEvent::LoadEnd);  // load acknowledged
    link(p, h.epoch ? LinkEvent::Hello : LinkEvent::BlankHello);
    p.step(TurnEvent::Hello);
    p.maybe_start_upload(cfg, *sets, now);
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
    p.step(TurnEvent::Result);
    p.misses = 0;
    ++out->workers_replied;
    runs.begin(out->pairs.size());
    out->pairs.insert(out->pairs.end(), r.pairs.begin(), r.pairs.end());
    runs.end(out->pairs);
    coverage.note(p);
    out->worker_stats[std::size_t(&p - peers.data())] = r.stats;
    p.compute_ns = r.stats.compute_ns;
    if (weigh) ledger->note(r.worked);
    out->stats.sphere_tests += r.stats.sphere_tests;
    out->stats.tri_tests += r.stats.tri_tests;
    out->stats.compute_ns = std::max(out->stats.compute_ns, r.stats.compute_ns);
  }

  void on_error(Peer& p, const ErrorMsg& e, Clock::time_point now) {
    const bool query_turn = p.turn == Turn::Queried || p.turn == Turn::Unsent || p.turn == Turn::Answered;
    const bool this_query = in_round && e.ref == cur_seq && query_turn;
    const bool load_refusal = e.code == ErrorCode::LoadFailed || e.code == ErrorCode::TooLarge;
    if (e.code == ErrorCode::NotLoaded && this_query) {
      p.step(TurnEvent::NotLoaded);  // alive, just not holding what we asked for; its Hello follows
      // With a standby set named either set may be the one missing: the Hello says which.
      if (!p.standby_asked)
        p.held.erase(std::remove(p.held.begin(), p.held.end(), p.asked ? p.asked->hash : 0), p.held.end());
    } else if (load_refusal && p.link == Link::Loading && (e.ref == p.upload->hash || e.ref == 0)) {
      p.refused_hash = p.upload->hash;
      p.refused = e.text;
      p.refused_at = now;
      link(p, LinkEvent::LoadEnd);
    } else if (this_query && e.code != ErrorCode::NotLoaded) {
      // This round's Query refused (TooLarge: over max_pairs or the set's work budget, or the
      // penalty after one; BadMessage): the worker is alive and sends no Result for it. The round
      // stops awaiting it (incomplete without its blocks) instead of waiting out its deadline and
      // counting a miss, which marked a refusing worker down; WorkerStatus::refused says why.
      p.step(TurnEvent::NotLoaded);
      p.refused = e.text;
    } else if (!load_refusal && out) {
      ++out->bad_messages;
    }
  }

  void drain(Peer& p, Clock::time_point now) {
    Message& m = rx;
    for (int budget = 0; budget < 256; ++budget) {
      const Peer::Received got = p.receive(cfg.limits, now, m);
      if (got == Peer::Received::none) return;
      if (got == Peer::Received::bad) {
        if (out) ++out->bad_messages;
      } else if (auto* h = std::get_if<HelloMsg>(&m)) {
        on_hello(p, *h, now);
      } else if (auto* r = std::get_if<ResultMsg>(&m)) {
        if (out) on_result(p, *r);
      } else if (auto* e = std::get_if<ErrorMsg>(&m)) {
        on_error(p, *e, now);
      } else if (out) {
        ++out->bad_messages;
      }
    }
  }

  /// Waits until `until` (bounded) for replies or send room, then handles everything waiting. In a
  /// round it polls only the workers it awaits and uploads with room to fill (zmq_poll checks each
  /// socket's mailbox before and after a wait); the others are read when next asked.
  void wait_and_service(Clock::time_point until) {
    items.clear();
    polled.clear();
    for (int all = 0; all < 2 && items.empty(); ++all)
      for (std::uint32_t i = 0; i < peers.size(); ++i) {  // nobody awaited: all of them
        const bool upload = peers[i].upload_has_room();
        if (!all && in_round && !upload && !client::awaited(peers[i].turn)) continue;
        items.push_back({peers[i].sock.handle(), 0, static_cast<short>(ZMQ_POLLIN | (upload ? ZMQ_POLLOUT : 0)), 0});
        polled.push_back(i);
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
    for (std::size_t i = 0; i < items.size(); ++i) {
      if (items[i].revents & ZMQ_POLLIN) drain(peers[polled[i]], t);
      if (items[i].revents & ZMQ_POLLOUT) peers[polled[i]].pump_upload(cfg, t, buf);
    }
  }

  /// Gives a fresh socket to every worker that was asked but has been silent for
  /// reconnect_after (unless it is busy loading what we sent).
  void revive_silent(Clock::time_point now) {
    for (Peer& p : peers) {
      if (p.asked_at <= p.silent_since || now - p.silent_since < cfg.reconnect_after) continue;
      if (p.link == Link::Loading && !p.load_stuck(cfg, now)) continue;
      if (p.link == Link::Loading) link(p, LinkEvent::LoadEnd);  // dropped with the old socket
      (void)p.open(*ctx, cfg, routing_id);
    }
  }

  void begin_round_sends(const geom::Pose& pose, Clock::time_point now) {
    revive_silent(now);
    if (reassign_pending)  // a worker went down or came back (reassign() prunes too)
      client::reassign(peers, *sets);
    else if (prune_pending)  // a worker dropped a set
      client::prune_sets(peers, *sets);
    reassign_pending = prune_pending = false;
    client::refresh_targets(peers, *sets);
    for (Peer& p : peers) p.maybe_start_upload(cfg, *sets, now);
    client::choose_sets(peers, *sets, coverage);
    deal->deal(peers, *ledger);
    out->blocks_moved = deal->moved();
    if (assist) assist->choose(peers, *deal, *ledger);
    coverage.begin_round();
    client::send_order(peers, order);  // the slowest of the round before first
    for (const std::uint32_t i : order) {
      Peer& p = peers[i];
      p.step(TurnEvent::NewRound);
      if (p.link == Link::Down) {
        if (now >= p.heartbeat_due) p.heartbeat(cfg, now, buf);
        continue;
      }
      if (p.asked) {
        ++out->workers_asked;
        p.asked_at = now;
        const std::uint64_t standby = p.standby_asked ? p.standby_asked->hash : 0;
        if (p.send(QueryMsg{cur_seq, p.asked->hash, pose, p.skip, cfg.object, standby, p.take}, buf)) {
          p.step(TurnEvent::QuerySent);
        } else {
          p.asked = nullptr;
          p.step(TurnEvent::QueryUnsent);  // counts as a miss
        }
        if (now >= p.held_refresh_due) {  // the Hello it answers with may arrive in any later round
          p.held_refresh_due = now + cfg.held_refresh_period;
          p.send(HeartbeatMsg{++p.nonce}, buf);
          owed_nothing = false;
        }
      } else if (p.link != Link::Loading && (now >= p.heartbeat_due || p.link == Link::Unknown)) {
        // Unknown, or nothing to ask this round (no blocks: more workers than blocks): it must
        // at least answer a Heartbeat by the deadline. Only a round that sends one waits for the
        // Hello (and counts a miss without it): between Heartbeats the round has nothing of it
        // to await, and awaiting it anyway held every such round to its deadline.
        p.step(TurnEvent::Ping);
        p.heartbeat(cfg, now, buf);
      }
      p.pump_upload(cfg, now, buf);
    }
  }

  // ---- the round's end ---------------------------------------------------------------------

  bool all_replied() const {
    bool any = false;
    for (const Peer& p : peers) {
      if (p.asked) any = true;  // a Query is out (answered or not)
      if (client::awaited(p.turn)) return false;
    }
    return any;  // nobody to wait for: wait out the deadline instead of spinning the caller
  }

  void end_round(Clock::time_point now) {
    for (Peer& p : peers) {
      if (p.link == Link::Down) continue;
      if (!client::missed(p.turn)) {
        if (p.turn != Turn::Idle) p.misses = 0;  // Answered or Greeted
        if (p.load_stuck(cfg, now)) mark_down(p);
        continue;
      }
      if (p.link == Link::Loading && !p.load_stuck(cfg, now)) continue;  // busy loading: exempt
      if (++p.misses >= cfg.miss_limit) mark_down(p);
    }
  }

  void mark_down(Peer& p) {
    // A fresh socket drops whatever is queued for the dead worker, and re-arms the connection:
    // libzmq reconnects tcp:// and ipc:// by itself, but not inproc:// once its binder is gone.
    (void)p.open(*ctx, cfg, routing_id);
    link(p, LinkEvent::MarkDown);
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
  impl->scene = std::make_shared<const client::SceneData>(
      client::SceneData{std::move(probe), std::move(object), std::move(blocks), config.leaf_faces, config.object});
  impl->sets = std::make_unique<client::BlockSetCache>(impl->scene);
  if (config.assist_blocks > config.limits.max_skip)
    return fail("scatter-gather: assist_blocks = ", config.assist_blocks, " exceeds the skip list limit ",
                config.limits.max_skip);
  impl->coverage.marks.assign(nblocks, 0);
  impl->cfg = std::move(config);
  if (impl->cfg.assist_blocks > 0) {
    auto a = client::ClientAssist::create(*impl->scene, impl->cfg.assist_blocks, impl->cfg.limits.max_pairs);
    if (!a) return Error{a.error()};
    impl->assist = std::move(a).value();
  }
  const auto share = deal_blocks(nblocks, static_cast<std::uint32_t>(impl->cfg.endpoints.size()), impl->cfg.mapping,
                                 impl->cfg.mapping_seed);
  const auto standby = impl->cfg.replicas ? standby_shares(share) : decltype(share)(share.size());
  // Without the assist or the replicated deal nothing weighs the blocks: the ledger stays empty,
  // and no round pays for keeping it.
  impl->weigh = impl->cfg.assist_blocks > 0 || impl->cfg.replicas;
  impl->ledger =
      std::make_unique<client::WorkLedger>(impl->scene->blocks, impl->weigh ? impl->scene->object.faces.size() : 0);
  impl->deal = std::make_unique<client::BlockDeal>(nblocks, impl->cfg.limits, impl->cfg.replicas,
                                                   std::max(0.0, impl->cfg.deal_stickiness));
  for (std::size_t i = 0; i < impl->cfg.endpoints.size(); ++i) {
    Peer p;
    p.endpoint = impl->cfg.endpoints[i];
    if (Status st = p.open(ctx, impl->cfg, impl->routing_id); !st) return Error{st.error()};
    p.original = share[i];
    p.target = p.original;
    p.standby = standby[i];
    impl->peers.push_back(std::move(p));
  }
  // The own shares and standby copies are encoded up front (cold); reassigned variants later, in
  // the background.
  for (Peer& p : impl->peers)
    for (auto [list, hash] : {std::pair{&p.original, &p.target_hash}, std::pair{&p.standby, &p.standby_hash}}) {
      if (list->empty()) continue;
      auto s = client::encode_set(*impl->scene, *list);
      if (!s) return Error{s.error()};
      impl->sets->remember(s.value());
      *hash = s.value()->hash;
    }
  const auto now = Clock::now();
  for (Peer& p : impl->peers) p.heartbeat(impl->cfg, now, impl->buf);
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
  out.workers_asked = out.workers_replied = out.blocks_covered = out.stale_dropped = out.bad_messages = 0;
  out.blocks_total = static_cast<std::uint32_t>(m.coverage.marks.size());
  out.blocks_assisted = out.blocks_moved = 0;
  out.stats = out.assist = QueryStats{};
  out.worker_stats.assign(m.peers.size(), QueryStats{});
  m.out = &out;
  m.runs.clear();
  m.in_round = false;
  if (!m.owed_nothing)  // old replies are dropped here, Hellos applied
    for (const auto now = Clock::now(); Peer & p : m.peers) m.drain(p, now);
  m.owed_nothing = true;
  m.cur_seq = seq;
  m.in_round = true;
  m.begin_round_sends(pose, Clock::now());
  if (m.assist) {  // while the workers compute
    m.runs.begin(out.pairs.size());
    m.assist->answer(pose, out, m.coverage.marks, *m.ledger);
    m.runs.end(out.pairs);
  }
  const auto spin_until = std::min(deadline, Clock::now() + std::chrono::microseconds(m.cfg.spin_us));
  while (!m.all_replied()) {
    const auto now = Clock::now();
    if (now >= deadline) break;
    m.wait_and_service(now < spin_until ? now : deadline);  // until == now: poll without waiting
  }
  m.in_round = false;
  m.end_round(Clock::now());
  m.owed_nothing = m.owed_nothing && out.workers_replied == m.peers.size() &&
                   std::all_of(m.peers.begin(), m.peers.end(), [](const Peer& p) { return p.link == Link::Live; });
  m.out = nullptr;
  m.runs.merge(out.pairs);  // a k-way merge of the sorted runs
  out.pairs.erase(std::unique(out.pairs.begin(), out.pairs.end()), out.pairs.end());
  // The same probe face collides on several workers: merge to distinct faces (paper §3.5).
  out.probe_faces.clear();
  out.object_faces.clear();
  if (m.cfg.distinct_faces) geom::distinct_faces(out.pairs, out.probe_faces, out.object_faces, m.ids_scratch);
  out.blocks_covered = static_cast<std::uint32_t>(m.coverage.covered(out.blocks_assisted));
  out.complete = out.blocks_covered == out.blocks_total;
  if (m.weigh) m.ledger->end_round(out.pairs);
}

RoundResult ScatterGather::round(std::uint64_t seq, const geom::Pose& pose, Clock::time_point deadline) {
  RoundResult r;
  round(seq, pose, deadline, r);
  return r;
}

bool ScatterGather::wait_ready(Clock::time_point deadline) {
  Impl& m = *impl_;
  m.owed_nothing = false;  // it sends heartbeats and uploads
  for (;;) {
    const auto now = Clock::now();
    m.revive_silent(now);
    if (m.reassign_pending) {
      m.reassign_pending = false;
      client::reassign(m.peers, *m.sets);
    }
    client::refresh_targets(m.peers, *m.sets);
    bool ready = true;
    for (Peer& p : m.peers) {
      if (p.link == Link::Down) {
        if (now >= p.heartbeat_due) p.heartbeat(m.cfg, now, m.buf);
        continue;
      }
      if (p.link == Link::Unknown && now >= p.heartbeat_due) p.heartbeat(m.cfg, now, m.buf);
      p.maybe_start_upload(m.cfg, *m.sets, now);
      p.pump_upload(m.cfg, now, m.buf);
      const std::uint64_t want = p.wanted();
      if (p.link == Link::Unknown || (want && !(want == p.standby_hash && p.standby_refused(m.cfg, now))) ||
          (!p.target.empty() && !p.holds(p.target_hash)))
        ready = false;
    }
    const auto up = [](const Peer& p) { return p.link != Link::Down; };
    if (ready && std::any_of(m.peers.begin(), m.peers.end(), up)) return true;
    if (now >= deadline) return false;
    m.wait_and_service(std::min(deadline, now + std::chrono::milliseconds(10)));
  }
}

std::vector<WorkerStatus> ScatterGather::workers() const {
  std::vector<WorkerStatus> v;
  for (const Peer& p : impl_->peers)
    v.push_back({p.endpoint, p.link != Link::Down, p.worker_id, p.epoch, p.misses, p.target, p.holds(p.target_hash),
                 p.bytes_sent, p.loads_sent, p.held.size(), p.unreadable, p.refused, p.standby,
                 p.standby.empty() || p.holds(p.standby_hash)});
  return v;
}

std::size_t ScatterGather::encoded_sets() const { return impl_->sets->size(); }

std::uint32_t ScatterGather::blocks_total() const { return static_cast<std::uint32_t>(impl_->coverage.marks.size()); }

}  // namespace st::net
