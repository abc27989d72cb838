// SPDX-License-Identifier: BSD-3-Clause
// Peer (peer.hpp).
#include <spheretouch/net/peer.hpp>

#include <algorithm>
#include <unordered_map>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/net/socket_options.hpp>
#include <spheretouch/net/worker_config.hpp>

namespace st::inline SPHERETOUCH_ABI::net::client {

Status Peer::open(zmq::context_t& ctx, const ScatterConfig& cfg, const std::string& routing_id) {
  silent_since = std::max(silent_since, Clock::now());
  sock = zmq::socket_t(ctx, zmq::socket_type::dealer);
  set_common_options(sock, cfg.sndhwm, cfg.rcvhwm, cfg.limits.max_message_bytes);
  sock.set(zmq::sockopt::routing_id, zmq::buffer(routing_id));
  sock.set(zmq::sockopt::immediate, 1);        // no queueing to a worker that is not connected
  sock.set(zmq::sockopt::reconnect_ivl, 100);  // a restarted worker is found within 0.1 s
  sock.set(zmq::sockopt::reconnect_ivl_max, 1000);
  // No ZMTP heartbeats (socket_options.hpp): a worker that stops answering the client's own
  // Heartbeat messages gets a fresh socket (ScatterGather's revive_silent).
  if (!cfg.curve_server_public.empty()) {
    sock.set(zmq::sockopt::curve_serverkey, cfg.curve_server_public);
    sock.set(zmq::sockopt::curve_publickey, cfg.curve_public);
    sock.set(zmq::sockopt::curve_secretkey, cfg.curve_secret);
  }
  try {
    if (needs_ipv6(endpoint)) sock.set(zmq::sockopt::ipv6, 1);
    sock.connect(zmq_endpoint(endpoint));
  } catch (const zmq::error_t& e) { return fail("scatter-gather: connect ", endpoint, ": ", e.what()); }
  return Ok{};
}

bool Peer::send(const Message& m, std::vector<std::uint8_t>& buf) {
  encode(m, buf);
  try {
    return sock.send(zmq::buffer(buf), zmq::send_flags::dontwait).has_value();
  } catch (const zmq::error_t&) { return false; }
}

bool Peer::step(LinkEvent e) {
  const Link next = link_after(link, e);
  ST_ASSERT(next != kNoLink, "a worker's link state changes only as the table says");
  if (next == kNoLink) return false;
  if (link == Link::Loading && next != Link::Loading) upload = nullptr;
  const bool down_changed = (link == Link::Down) != (next == Link::Down);
  if (down_changed) misses = 0;
  link = next;
  ST_ASSERT((link == Link::Loading) == (upload != nullptr), "a set is being sent exactly while Loading");
  return down_changed;
}

void Peer::step(TurnEvent e) {
  const Turn next = turn_after(turn, e);
  ST_ASSERT(next != kNoTurn, "a worker's turn changes only as the table says");
  if (next != kNoTurn) turn = next;
  ST_ASSERT(turn != Turn::Queried || asked, "a Query is out only with the set it named");
}

void Peer::heartbeat(const ScatterConfig& cfg, Clock::time_point now, std::vector<std::uint8_t>& buf) {
  asked_at = now;
  const bool sent = send(HeartbeatMsg{++nonce}, buf);
  // A first contact's Heartbeat sent before the connection is up is dropped (the sockets do not
  // queue for a peer not connected): tried again soon, not a whole period later (a tcp:// worker
  // connects within a few ms; wait_ready() would otherwise wait out heartbeat_period).
  heartbeat_due =
      now + (sent || link != Link::Unknown ? cfg.heartbeat_period
                                           : std::min<Clock::duration>(cfg.heartbeat_period, kFirstContactRetry));
}

void Peer::maybe_start_upload(const ScatterConfig& cfg, const BlockSetCache& sets, Clock::time_point now) {
  const std::uint64_t want = wanted();
  if (!heard(link) || !want) return;
  if (link == Link::Loading && upload->hash == want) return;
  if (refused_hash == want && now - refused_at < cfg.load_timeout) return;
  SetPtr s = sets.find(want);
  if (!s) return;
  upload = std::move(s);
  upload_off = 0;
  load_progress_at = now;
  ++loads_sent;
  (void)step(LinkEvent::LoadStart);  // never into or out of Down
}

void Peer::pump_upload(const ScatterConfig& cfg, Clock::time_point now, std::vector<std::uint8_t>& buf) {
  if (!upload_has_room()) return;
  const auto& bytes = upload->bytes;
  const std::size_t chunk = std::max<std::size_t>(1, std::min(cfg.chunk_bytes, cfg.limits.max_chunk_bytes));
  LoadBlocksMsg m{upload->hash, bytes.size(), 0, {}};
  while (upload_off < bytes.size()) {
    const std::size_t n = std::min(chunk, bytes.size() - upload_off);
    m.offset = upload_off;
    m.data.assign(bytes.begin() + static_cast<std::ptrdiff_t>(upload_off),
                  bytes.begin() + static_cast<std::ptrdiff_t>(upload_off + n));
    if (!send(m, buf)) break;  // queue full or not connected: resume on POLLOUT / next round
    upload_off += n;
    bytes_sent += n;
    load_progress_at = now;
  }
}

Peer::Received Peer::receive(const Limits& limits, Clock::time_point now, Message& m) {
  zmq::message_t msg;
  try {
    if (!sock.recv(msg, zmq::recv_flags::dontwait)) return Received::none;
  } catch (const zmq::error_t&) { return Received::none; }
  if (msg.more()) {  // a worker sends one frame per message; drop the rest
    for (bool more = true; more;) {
      zmq::message_t junk;
      try {
        (void)sock.recv(junk, zmq::recv_flags::dontwait);
      } catch (const zmq::error_t&) { return Received::bad; }
      more = junk.more();
    }
    unreadable = "more than one frame";
    return Received::bad;
  }
  if (Status st = decode({static_cast<const std::uint8_t*>(msg.data()), msg.size()}, limits, m); !st) {
    unreadable = st.error();
    return Received::bad;
  }
  silent_since = std::max(silent_since, now);
  return Received::message;
}

namespace {
bool is_superset(const std::vector<std::uint32_t>& big, const std::vector<std::uint32_t>& small) {
  return std::includes(big.begin(), big.end(), small.begin(), small.end());
}
}  // namespace

void choose_sets(std::vector<Peer>& peers, const BlockSetCache& sets, Coverage& cover) {
  std::vector<std::uint8_t>& covered = cover.marks;
  std::vector<SetPtr>& last = cover.partition;
  // A held set the worker may be queried with: any but its standby set, which is taken from.
  const auto queryable = [&](const Peer& p, std::uint64_t h) { return h != p.standby_hash ? sets.find(h) : nullptr; };
  bool same = last.size() == peers.size();
  for (std::size_t i = 0; i < peers.size(); ++i) {
    Peer& p = peers[i];
    p.asked = nullptr;
    if (heard(p.link)) {
      if (p.holds(p.target_hash))
        p.asked = sets.find(p.target_hash);
      else
        for (std::uint64_t h : p.held)
          if (SetPtr s = queryable(p, h); s && (!p.asked || s->blocks.size() > p.asked->blocks.size())) p.asked = s;
    }
    same = same && p.asked == last[i];
  }
  const auto standby = [&] {
    for (Peer& p : peers) {
      p.standby_asked = nullptr;
      if (p.asked && p.standby_hash != p.asked->hash && p.holds(p.standby_hash))
        p.standby_asked = sets.find(p.standby_hash);
    }
  };
  cover.counting = true;
  if (same) {  // sets are immutable: the same ones are the same partition
    standby();
    return;
  }
  std::fill(covered.begin(), covered.end(), 0);
  std::size_t held = 0;
  for (const Peer& p : peers)
    if (p.asked) {
      held += p.asked->blocks.size();
      for (std::uint32_t b : p.asked->blocks) covered[b] = 1;
    }
  const bool all = std::all_of(covered.begin(), covered.end(), [](std::uint8_t c) { return c; });
  if (all && held == covered.size()) {
    last.clear();  // each block in some set, as many blocks as the sets hold: in exactly one
    for (const Peer& p : peers) last.push_back(p.asked);
    standby();
    return;
  }
  last.clear();
  cover.counting = false;
  if (!all)
    for (Peer& p : peers) {
      if (!heard(p.link)) continue;
      SetPtr best;
      std::size_t best_gain = 0;
      for (std::uint64_t h : p.held) {
        const SetPtr s = queryable(p, h);
        if (!s || (p.asked && !is_superset(s->blocks, p.asked->blocks))) continue;
        std::size_t gain = 0;
        for (std::uint32_t b : s->blocks) gain += !covered[b];
        if (gain > best_gain) {
          best_gain = gain;
          best = s;
        }
      }
      if (best) {
        p.asked = best;
        for (std::uint32_t b : best->blocks) covered[b] = 1;
      }
    }
  standby();
}

void refresh_targets(std::vector<Peer>& peers, BlockSetCache& sets) {
  for (Peer& p : peers)
    if (p.link != Link::Down && !p.target_hash && !p.target.empty())
      if (SetPtr s = sets.get(p.target)) p.target_hash = s->hash;
}

void reassign(std::vector<Peer>& peers, BlockSetCache& sets) {
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
    SetPtr s = p.target.empty() ? nullptr : sets.get(p.target);
    p.target_hash = s ? s->hash : 0;
  }
  prune_sets(peers, sets);
}

void prune_sets(const std::vector<Peer>& peers, BlockSetCache& sets) {
  std::unordered_map<std::uint64_t, bool> keep;
  for (const Peer& p : peers) {
    for (std::uint64_t h : p.held) keep[h] = true;
    if (p.target_hash) keep[p.target_hash] = true;
    if (p.standby_hash) keep[p.standby_hash] = true;
    if (p.link == Link::Loading) keep[p.upload->hash] = true;
  }
  sets.prune([&](const EncodedSet& s) {
    return keep.count(s.hash) || std::any_of(peers.begin(), peers.end(), [&](const Peer& p) {
             return p.original == s.blocks || p.target == s.blocks || p.standby == s.blocks;
           });
  });
}

void send_order(const std::vector<Peer>& peers, std::vector<std::uint32_t>& order) {
  order.resize(peers.size());
  for (std::uint32_t i = 0; i < peers.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return peers[a].compute_ns != peers[b].compute_ns ? peers[a].compute_ns > peers[b].compute_ns : a < b;
  });
}

}  // namespace st::net::client
