// WorkerService (worker_service.hpp).
#include "net/worker_service.hpp"

#include "net/worker_config.hpp"

#include <malloc.h>

#include <algorithm>
#include <random>
#include <stdexcept>

#include "net/block_set.hpp"

namespace st::net {

void set_common_options(zmq::socket_t& s, int sndhwm, int rcvhwm, std::int64_t max_message_bytes) {
  s.set(zmq::sockopt::linger, 0);
  s.set(zmq::sockopt::sndhwm, sndhwm);
  s.set(zmq::sockopt::rcvhwm, rcvhwm);
  s.set(zmq::sockopt::maxmsgsize, max_message_bytes);
}

WorkerService::WorkerService(zmq::context_t& ctx, WorkerConfig config, BackendFactory factory)
    : cfg_(std::move(config)), factory_(std::move(factory)), sock_(ctx, zmq::socket_type::router) {
  std::random_device rd;
  do epoch_ = (std::uint64_t{rd()} << 32) ^ rd(); while (epoch_ == 0);
  // The largest legitimate frame a worker receives is a LoadBlocks chunk; anything bigger is cut
  // off by libzmq before it is buffered.
  const std::int64_t max_in = std::int64_t(kHeaderBytes) + 64 + cfg_.limits.max_chunk_bytes;
  set_common_options(sock_, cfg_.sndhwm, cfg_.rcvhwm, std::min<std::int64_t>(max_in, cfg_.limits.max_message_bytes));
  if (cfg_.curve) {
    // ZAP (RFC 27): libzmq asks the handler bound at this inproc address about every CURVE
    // handshake; it must exist before the ROUTER accepts connections.
    try {
      if (Status s = check_z85_key(cfg_.curve->secret_z85, "CURVE secret key"); !s) throw std::runtime_error(s.error());
      for (const std::string& k : cfg_.curve->allowed_clients_z85) {
        if (Status s = check_z85_key(k, "allowed client key " + k); !s) throw std::runtime_error(s.error());
        std::string raw(32, '\0');
        zmq_z85_decode(reinterpret_cast<std::uint8_t*>(raw.data()), k.c_str());
        allowed_.push_back(raw);
      }
      zap_ = zmq::socket_t(ctx, zmq::socket_type::rep);
      zap_.set(zmq::sockopt::linger, 0);
      zap_.bind("inproc://zeromq.zap.01");
      sock_.set(zmq::sockopt::curve_server, true);
      sock_.set(zmq::sockopt::curve_secretkey, cfg_.curve->secret_z85);
      sock_.set(zmq::sockopt::zap_domain, "spheretouch");
    } catch (const std::exception& e) {
      init_error_ = std::string("CURVE set-up: ") + e.what();
    }
  }
  // ZMTP heartbeats drop half-open TCP connections of vanished clients.
  sock_.set(zmq::sockopt::heartbeat_ivl, 1000);
  sock_.set(zmq::sockopt::heartbeat_timeout, 3000);
}

Status WorkerService::bind(const std::string& endpoint) {
  if (!init_error_.empty()) return Error{init_error_};
  try {
    if (needs_ipv6(endpoint)) sock_.set(zmq::sockopt::ipv6, 1);
    sock_.bind(zmq_endpoint(endpoint));
  } catch (const zmq::error_t& e) {
    return fail("bind ", endpoint, ": ", e.what());
  }
  return Ok{};
}

std::string WorkerService::last_endpoint() const { return sock_.get(zmq::sockopt::last_endpoint); }

std::vector<Held> WorkerService::held() const {
  std::vector<Held> h;
  for (const Loaded& l : sets_) h.push_back({l.hash, l.faces});
  return h;
}

HelloMsg WorkerService::hello(std::uint64_t echo) const {
  HelloMsg h{cfg_.worker_id, epoch_, echo, held()};
  if (h.held.size() > cfg_.limits.max_held) h.held.resize(cfg_.limits.max_held);
  return h;
}

void WorkerService::send(const zmq::message_t& peer, const Message& m) {
  encode(m, out_);
  // ROUTER without ROUTER_MANDATORY: a reply to a peer that is gone or over its HWM is dropped,
  // never blocks. The client's deadline and sequence numbers cover the loss.
  try {
    zmq::message_t id(peer.data(), peer.size());
    if (!sock_.send(id, zmq::send_flags::sndmore | zmq::send_flags::dontwait)) return;
    (void)sock_.send(zmq::buffer(out_), zmq::send_flags::dontwait);
  } catch (const zmq::error_t&) {
  }
}

void WorkerService::note_bad(const std::string& why) {
  ++counters_.bad_messages;
  ++bad_unlogged_;
  const auto now = std::chrono::steady_clock::now();
  if (now - bad_logged_ < std::chrono::seconds(1)) return;
  log(4, st::fail(bad_unlogged_, " bad message(s) since the last report; latest: ", why).message);
  bad_logged_ = now;
  bad_unlogged_ = 0;
}

void WorkerService::send_error(const zmq::message_t& peer, ErrorCode code, std::uint64_t ref, std::string text) {
  if (text.size() > cfg_.limits.max_text) text.resize(cfg_.limits.max_text);
  ++counters_.errors_sent;
  send(peer, ErrorMsg{code, ref, std::move(text)});
}

void WorkerService::handle_zap() {
  // Request frames: version, request id, domain, address, routing id, mechanism, credentials.
  std::vector<zmq::message_t> f;
  try {
    do {
      f.emplace_back();
      if (!zap_.recv(f.back(), zmq::recv_flags::dontwait)) return;
    } while (f.back().more() && f.size() < 16);
    while (f.back().more()) { zmq::message_t junk; (void)zap_.recv(junk); }
  } catch (const zmq::error_t&) {
    return;
  }
  bool ok = false;
  if (f.size() >= 7 && f[5].to_string_view() == "CURVE" && f[6].size() == 32) {
    const std::string key(static_cast<const char*>(f[6].data()), 32);
    ok = std::find(allowed_.begin(), allowed_.end(), key) != allowed_.end();
    if (!ok) {
      ++counters_.refused;
      constexpr std::size_t kMaxRefusedKeys = 1024;             // bounds the map under a key-rotating flood
      constexpr auto kRefusalLogInterval = std::chrono::seconds(60);  // a retrying client: one line a minute
      if (refusals_.size() >= kMaxRefusedKeys && !refusals_.count(key)) refusals_.clear();
      Refusal& r = refusals_[key];
      const auto now = std::chrono::steady_clock::now();
      if (r.logged == std::chrono::steady_clock::time_point{} || now - r.logged >= kRefusalLogInterval) {
        char z85[41] = {};
        zmq_z85_encode(z85, static_cast<const std::uint8_t*>(f[6].data()), 32);
        log(4, std::string("refused CURVE client ") + z85 + " from " + std::string(f[3].to_string_view()) +
                   ": not in allowed_clients" +
                   (r.unlogged ? " (" + std::to_string(r.unlogged) + " more refusals of this key not logged)" : ""));
        r.logged = now;
        r.unlogged = 0;
      } else {
        ++r.unlogged;
      }
    }
  }
  const std::string request_id = f.size() > 1 ? f[1].to_string() : std::string();
  const char* status = ok ? "200" : "400";
  try {
    zap_.send(zmq::str_buffer("1.0"), zmq::send_flags::sndmore);
    zap_.send(zmq::buffer(request_id), zmq::send_flags::sndmore);
    zap_.send(zmq::buffer(std::string_view(status)), zmq::send_flags::sndmore);
    zap_.send(zmq::buffer(std::string_view(ok ? "OK" : "client key not allowed")), zmq::send_flags::sndmore);
    zap_.send(zmq::str_buffer(""), zmq::send_flags::sndmore);
    zap_.send(zmq::str_buffer(""), zmq::send_flags::none);
  } catch (const zmq::error_t&) {
  }
}

bool WorkerService::poll_once(std::chrono::milliseconds timeout) {
  zmq::pollitem_t items[2] = {{sock_.handle(), 0, ZMQ_POLLIN, 0}, {zap_.handle(), 0, ZMQ_POLLIN, 0}};
  const int n = zap_ ? 2 : 1;
  try {
    if (zmq::poll(items, n, timeout) <= 0) {
      drop_idle_sets();
      return true;
    }
  } catch (const zmq::error_t& e) {
    return e.num() != ETERM;  // EINTR (a signal): let the caller look at its stop flag
  }
  if (n == 2 && (items[1].revents & ZMQ_POLLIN)) handle_zap();
  drop_idle_sets();
  if (!(items[0].revents & ZMQ_POLLIN)) return true;
  // Handle what is queued now, then return so the caller can tick (watchdog, stop flag).
  for (int budget = 0; budget < 1024; ++budget) {
    zmq::message_t peer, frame;
    try {
      if (!sock_.recv(peer, zmq::recv_flags::dontwait)) break;
      if (!peer.more()) { note_bad("no body frame"); continue; }  // cannot happen on a ROUTER
      (void)sock_.recv(frame, zmq::recv_flags::none);             // parts of a message arrive together
      bool extra = frame.more();
      for (bool more = extra; more;) {                            // discard surplus frames
        zmq::message_t junk;
        (void)sock_.recv(junk, zmq::recv_flags::none);
        more = junk.more();
      }
      if (extra || frame.size() == 0) {
        note_bad(extra ? "more than one frame" : "empty frame");
        send_error(peer, ErrorCode::BadMessage, 0, "expected exactly one non-empty frame per message");
        continue;
      }
      handle(peer, {static_cast<const std::uint8_t*>(frame.data()), frame.size()});
    } catch (const zmq::error_t& e) {
      return e.num() != ETERM;
    }
  }
  return true;
}

void WorkerService::drop_idle_sets() {
  const auto now = std::chrono::steady_clock::now();
  if (cfg_.idle_set_ttl.count() <= 0 || now < next_idle_check_ || sets_.size() < 2) return;
  next_idle_check_ = now + std::chrono::seconds(1);
  std::size_t dropped = 0;
  for (auto it = std::next(sets_.begin()); it != sets_.end();) {  // never the most recently used
    if (now - it->last_used < cfg_.idle_set_ttl) { ++it; continue; }
    log(6, st::fail("dropped block set ", std::hex, it->hash, std::dec, ": not queried for ",
                    std::chrono::duration_cast<std::chrono::seconds>(now - it->last_used).count(), " s").message);
    it = sets_.erase(it);
    ++dropped;
  }
  if (dropped) ::malloc_trim(0);  // give the freed trees back to the system, not just to malloc
}

void WorkerService::run(const std::atomic<bool>& stop, std::chrono::milliseconds period, const std::function<void()>& tick) {
  while (!stop.load(std::memory_order_relaxed)) {
    if (!poll_once(period)) return;
    if (tick) tick();
  }
}

void WorkerService::handle(const zmq::message_t& peer, std::span<const std::uint8_t> frame) {
  Result<Message> m = decode(frame, cfg_.limits);
  if (!m) {
    note_bad(m.error());
    send_error(peer, ErrorCode::BadMessage, 0, m.error());
    return;
  }
  Message& msg = m.value();
  if (auto* q = std::get_if<QueryMsg>(&msg)) return on_query(peer, *q);
  if (auto* l = std::get_if<LoadBlocksMsg>(&msg)) return on_load(peer, *l);
  if (auto* h = std::get_if<HeartbeatMsg>(&msg)) {
    ++counters_.heartbeats;
    return send(peer, hello(h->nonce));
  }
  note_bad(std::string("unexpected ") + type_name(msg));
  send_error(peer, ErrorCode::Unexpected, 0, std::string("a worker does not accept ") + type_name(msg));
}

void WorkerService::on_query(const zmq::message_t& peer, const QueryMsg& q) {
  auto it = std::find_if(sets_.begin(), sets_.end(), [&](const Loaded& l) { return l.hash == q.hash; });
  if (it == sets_.end()) {
    send_error(peer, ErrorCode::NotLoaded, q.seq, st::fail("block set ", std::hex, q.hash, " is not held").message);
    send(peer, hello(0));  // tell the client what is held so it can load the right set
    return;
  }
  sets_.splice(sets_.begin(), sets_, it);  // most recently used first
  it->last_used = std::chrono::steady_clock::now();
  pairs_.clear();
  // The backend stops past max_pairs: a block set of faces piled on each other cannot make the
  // worker compute (and hold) N² pairs before refusing.
  const QueryStats st = it->backend->query(q.pose, pairs_, cfg_.limits.max_pairs);
  if (pairs_.size() > cfg_.limits.max_pairs) {
    ++counters_.too_many_pairs;
    send_error(peer, ErrorCode::TooLarge, q.seq,
               st::fail("more than max_pairs = ", cfg_.limits.max_pairs, " colliding pairs: query refused").message);
    pairs_.clear();
    if (pairs_.capacity() > (std::size_t{1} << 20)) pairs_.shrink_to_fit();  // do not keep an attacker's peak
    return;
  }
  std::sort(pairs_.begin(), pairs_.end());
  pairs_.erase(std::unique(pairs_.begin(), pairs_.end()), pairs_.end());
  ++counters_.queries;
  ResultMsg r{q.seq, cfg_.worker_id, q.hash, st, {}};
  r.pairs.swap(pairs_);
  send(peer, r);
  pairs_.swap(r.pairs);  // keep the capacity for the next query
}

void WorkerService::on_load(const zmq::message_t& peer, const LoadBlocksMsg& m) {
  // decode() has checked total_bytes ≤ max_blockset_bytes and that the chunk lies inside it.
  if (m.offset == 0) {
    asm_ = Assembly{m.hash, m.total_bytes, {}, true};
    // Grow with the bytes that actually arrive: a lying total_bytes costs nothing up front.
    asm_.bytes.reserve(std::min<std::uint64_t>(m.total_bytes, 16u << 20));
  } else if (!asm_.active || asm_.hash != m.hash || asm_.total != m.total_bytes || asm_.bytes.size() != m.offset) {
    const bool was = asm_.active;
    asm_ = Assembly{};
    send_error(peer, ErrorCode::LoadFailed, m.hash,
               st::fail("LoadBlocks chunk at offset ", m.offset, " out of order", was ? " (load abandoned)" : "").message);
    return;
  }
  ++counters_.chunks;
  asm_.bytes.insert(asm_.bytes.end(), m.data.begin(), m.data.end());
  if (asm_.bytes.size() < asm_.total) return;

  const auto t0 = std::chrono::steady_clock::now();
  Assembly done = std::move(asm_);
  asm_ = Assembly{};
  if (block_set_hash(done.bytes) != done.hash) {
    log(4, "load refused: block set bytes do not match their hash");
    send_error(peer, ErrorCode::LoadFailed, done.hash, "block set bytes do not match their hash");
    return;
  }
  Result<BlockSet> set = decode_block_set(done.bytes, cfg_.limits);
  if (!set) {
    log(4, "load refused: " + set.error());
    return send_error(peer, ErrorCode::LoadFailed, done.hash, set.error());
  }
  std::vector<std::uint8_t>().swap(done.bytes);  // free the encoding before building
  std::unique_ptr<CollisionBackend> backend = factory_();
  if (Status s = backend->load(set.value()); !s) {
    log(3, "backend failed to load a block set: " + s.error());
    return send_error(peer, ErrorCode::LoadFailed, done.hash, s.error());
  }
  sets_.remove_if([&](const Loaded& l) { return l.hash == done.hash; });
  while (!sets_.empty() && sets_.size() >= std::max<std::uint32_t>(cfg_.max_sets, 1)) sets_.pop_back();
  sets_.push_front(Loaded{done.hash, static_cast<std::uint32_t>(set.value().object.faces.size()), std::move(backend),
                          std::chrono::steady_clock::now()});
  ++counters_.loads;
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  log(6, st::fail("loaded block set ", std::hex, done.hash, std::dec, ": ", set.value().blocks.size(), " blocks, ",
                  set.value().object.faces.size(), " object faces, ", set.value().probe.faces.size(), " probe faces, in ",
                  ms, " ms; holding ", sets_.size(), " set(s)").message);
  send(peer, hello(0));
}

}  // namespace st::net
