// SPDX-License-Identifier: BSD-3-Clause
// WorkerService (worker_service.hpp).
#include <spheretouch/net/worker_service.hpp>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/net/worker_config.hpp>

#include <malloc.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <random>
#include <set>
#include <span>
#include <stdexcept>

namespace st::inline SPHERETOUCH_ABI::net {

namespace {
/// Adds `more` (ascending by block) to `into` (ascending by block): a block in both sums its work.
void add_worked(std::vector<WorkedBlock>& into, const std::vector<WorkedBlock>& more) {
  if (more.empty()) return;
  const std::size_t mid = into.size();
  into.insert(into.end(), more.begin(), more.end());
  const auto by_block = [](const WorkedBlock& a, const WorkedBlock& b) { return a.block < b.block; };
  std::inplace_merge(into.begin(), into.begin() + std::ptrdiff_t(mid), into.end(), by_block);
  std::size_t n = 0;
  for (std::size_t i = 0; i < into.size(); ++i) {
    if (n > 0 && into[n - 1].block == into[i].block) {
      const std::uint32_t w = into[i].work;
      into[n - 1].work = into[n - 1].work > UINT32_MAX - w ? UINT32_MAX : into[n - 1].work + w;
    } else {
      into[n++] = into[i];
    }
  }
  into.resize(n);
}
}  // namespace

/// A complete upload being hashed, decoded and built on the loader thread. The thread owns a
/// reference, so a service destroyed mid-build leaves it to finish on its own.
struct WorkerService::LoadJob {
  Upload up;
  std::vector<Digest> known;  // digests the same client held when the job started: not rebuilt
  Limits limits;
  BackendFactory factory;
  int fd = -1;                // eventfd written once when done
  std::uint64_t counted = 0;  // the upload's bytes as counted in buffered_
  std::atomic<bool> cancel{false}, done{false};
  // Results (written by the loader before `done`, read after it).
  Digest digest{};
  bool reuse = false;  // the digest was known: a held backend serves these bytes
  std::unique_ptr<CollisionBackend> backend;
  std::string error;  // non-empty: refused
  bool oom = false;   // the error is an allocation failure
  std::uint32_t faces = 0, probe_faces = 0, blocks = 0, object = 0;
  double ms = 0;
  ~LoadJob() {
    if (fd >= 0) ::close(fd);
  }
  void run() {
    const auto t0 = std::chrono::steady_clock::now();
    try {
      build();
    } catch (const std::bad_alloc&) {
      // Out of memory while decoding or building: this set is refused, the worker and every
      // other client's sets carry on (what the build allocated is freed with the backend).
      backend.reset();
      reuse = false;
      oom = true;
      error = st::fail("out of memory while building the block set (", up.total, " bytes encoded)").message;
    } catch (const std::exception& e) {
      backend.reset();
      reuse = false;
      error = std::string("building the block set failed: ") + e.what();
    }
    // The encoding, the decoded set and the build's scratch are gone: give the pages back, so a
    // worker's resident memory is what it holds (its share), not its peak during the load.
    if (!reuse) ::malloc_trim(0);
    ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    done.store(true, std::memory_order_release);
    const std::uint64_t one = 1;
    if (fd >= 0) (void)!::write(fd, &one, sizeof one);
  }
  void build() {
    digest = block_set_digest(up.bytes);
    if (digest_key(digest) != up.hash) {
      error = "block set bytes do not match their hash";
    } else if (std::find(known.begin(), known.end(), digest) != known.end()) {
      reuse = true;  // keep the bytes: if that backend is gone by the time this job is installed, it is rebuilt
    } else if (!cancel.load()) {
      Result<BlockSet> set = decode_block_set(up.bytes, limits);
      if (!set) {
        error = set.error();
      } else {
        std::vector<std::uint8_t>().swap(up.bytes);  // free the encoding before building
        faces = static_cast<std::uint32_t>(set.value().object.faces.size());
        object = set.value().object_id;
        probe_faces = static_cast<std::uint32_t>(set.value().probe.faces.size());
        blocks = static_cast<std::uint32_t>(set.value().blocks.size());
        if (!cancel.load()) {
          backend = factory();
          if (Status s = backend->load(set.value()); !s) {
            error = "backend failed to load the block set: " + s.error();
            backend.reset();
          }
        }
      }
    }
    if (cancel.load() && error.empty() && !reuse && !backend) error = "worker stopping";
  }
};

MemoryBound memory_bound(const WorkerConfig& cfg) {
  const double set_mib = double(cfg.limits.max_blockset_bytes) / double(1 << 20);
  MemoryBound b;
  b.held_mib = (kSetMemoryFactor * set_mib + double(kCoherentCacheBytes) / double(1 << 20)) * cfg.max_sets;
  b.build_mib = kBuildMemoryFactor * set_mib;
  b.upload_mib = double(cfg.max_upload_bytes) / double(1 << 20);
  b.queue_mib = double(cfg.max_connections) * cfg.rcvhwm * double(cfg.limits.max_chunk_bytes) / double(1 << 20);
  return b;
}

Result<std::unique_ptr<WorkerService>> WorkerService::create(zmq::context_t& ctx, WorkerConfig config,
                                                             BackendFactory factory) {
  if (!factory) return fail("worker: no backend factory");
  std::unique_ptr<WorkerService> w;
  try {
    w.reset(new WorkerService(ctx, std::move(config), std::move(factory)));
  } catch (const zmq::error_t& e) { return fail("worker: cannot create its socket: ", e.what()); }
  if (Status s = w->init(ctx); !s) return Error{s.error()};
  return w;
}

WorkerService::WorkerService(zmq::context_t& ctx, WorkerConfig config, BackendFactory factory)
    : cfg_(std::move(config)), factory_(std::move(factory)), sock_(ctx, zmq::socket_type::router) {
  std::random_device rd;
  do epoch_ = (std::uint64_t{rd()} << 32) ^ rd();
  while (epoch_ == 0);
}

Status WorkerService::init(zmq::context_t& ctx) {
  // The largest legitimate frame a worker receives is a LoadBlocks chunk; anything bigger is cut
  // off by libzmq before it is buffered.
  const std::int64_t max_in = std::int64_t(kHeaderBytes) + 64 + cfg_.limits.max_chunk_bytes;
  try {
    set_common_options(sock_, cfg_.sndhwm, cfg_.rcvhwm, std::min<std::int64_t>(max_in, cfg_.limits.max_message_bytes));
  } catch (const zmq::error_t& e) { return fail("worker: socket options: ", e.what()); }
  if (cfg_.curve) {
    // ZAP (RFC 27): libzmq asks the handler bound at this inproc address about every CURVE
    // handshake; it must exist before the ROUTER accepts connections.
    if (Status s = check_z85_key(cfg_.curve->secret_z85, "CURVE secret key"); !s)
      return fail("CURVE set-up: ", s.error());
    for (const std::string& k : cfg_.curve->allowed_clients_z85) {
      if (Status s = check_z85_key(k, "allowed client key " + k); !s) return fail("CURVE set-up: ", s.error());
      std::string raw(32, '\0');
      zmq_z85_decode(reinterpret_cast<std::uint8_t*>(raw.data()), k.c_str());
      allowed_.push_back(raw);
    }
    try {
      zap_ = zmq::socket_t(ctx, zmq::socket_type::rep);
      zap_.set(zmq::sockopt::linger, 0);
      zap_.bind("inproc://zeromq.zap.01");
      sock_.set(zmq::sockopt::curve_server, true);
      sock_.set(zmq::sockopt::curve_secretkey, cfg_.curve->secret_z85);
      wipe_secret(cfg_.curve->secret_z85);  // libzmq holds it now
      sock_.set(zmq::sockopt::zap_domain, "spheretouch");
      zap_fd_ = zap_.get(zmq::sockopt::fd);
    } catch (const zmq::error_t& e) { return fail("CURVE set-up: ", e.what()); }
  }
  // Connection events: libzmq has no limit on the connections a ROUTER accepts, so the service
  // counts them and shuts down those past max_connections (what each may queue is bounded by
  // rcvhwm). Best effort: the descriptor of an accepted connection is shut down from this thread
  // when its event arrives.
  {
    static std::atomic<std::uint64_t> serial{0};
    const std::string addr =
        "inproc://spheretouch-worker-monitor-" + std::to_string(::getpid()) + "-" + std::to_string(serial.fetch_add(1));
    if (zmq_socket_monitor(sock_.handle(), addr.c_str(), ZMQ_EVENT_ACCEPTED | ZMQ_EVENT_DISCONNECTED) == 0) {
      monitor_ = zmq::socket_t(ctx, zmq::socket_type::pair);
      monitor_.set(zmq::sockopt::linger, 0);
      monitor_.connect(addr);
      monitor_fd_ = monitor_.get(zmq::sockopt::fd);
    }
  }
  try {
    // A client that reconnects with its routing id takes it over at once (a half-open old
    // connection would otherwise hold it until TCP keepalive drops it).
    sock_.set(zmq::sockopt::router_handover, 1);
    // No ZMTP heartbeats (socket_options.hpp): TCP keepalive drops the half-open connections of
    // vanished clients (after about 10 + 3 x 2 s of silence).
    sock_.set(zmq::sockopt::tcp_keepalive, 1);
    sock_.set(zmq::sockopt::tcp_keepalive_idle, 10);
    sock_.set(zmq::sockopt::tcp_keepalive_intvl, 2);
    sock_.set(zmq::sockopt::tcp_keepalive_cnt, 3);
  } catch (const zmq::error_t& e) { return fail("worker: socket options: ", e.what()); }
  return Ok{};
}

WorkerService::~WorkerService() {
  if (!job_) return;
  job_->cancel.store(true);
  if (job_->done.load(std::memory_order_acquire))
    loader_.join();
  else
    loader_.detach();  // the thread holds the job; a daemon exiting need not wait for a build
}

Status WorkerService::bind(const std::string& endpoint) {
  const bool ipc = endpoint.rfind("ipc://", 0) == 0;
  const std::string path = ipc ? endpoint.substr(6) : std::string();
  const bool file = ipc && !path.empty() && path[0] != '@';  // "@name": Linux abstract namespace
  if (ipc) {
    // Only this user (and the configured ones) may connect: libzmq compares SO_PEERCRED of each
    // accepted connection with these filters (the option is deprecated upstream, still in 4.3).
    std::vector<std::uint32_t> uids = cfg_.ipc_allowed_uids;
    uids.push_back(static_cast<std::uint32_t>(::geteuid()));
    for (std::uint32_t u : uids) {
      const int v = static_cast<int>(u);
      if (zmq_setsockopt(sock_.handle(), ZMQ_IPC_FILTER_UID, &v, sizeof v) != 0)
        return fail("bind ", endpoint, ": cannot restrict ipc peers to uid ", u, ": ", zmq_strerror(zmq_errno()));
    }
  }
  if (file) {
    // Missing directories are created 0700; an existing one open to others is reported.
    const std::filesystem::path dir = std::filesystem::path(path).parent_path();
    if (!dir.empty()) {
      std::vector<std::filesystem::path> missing;
      for (std::filesystem::path d = dir; !d.empty() && !std::filesystem::exists(d); d = d.parent_path())
        missing.push_back(d);
      for (auto it = missing.rbegin(); it != missing.rend(); ++it)
        if (::mkdir(it->c_str(), 0700) != 0 && errno != EEXIST)
          return fail("bind ", endpoint, ": cannot create ", it->string(), ": ", std::strerror(errno));
      struct stat st {};
      if (::stat(dir.c_str(), &st) == 0 && (st.st_mode & 0002) && !(st.st_mode & S_ISVTX))
        log(4, st::fail(dir.string(), " is writable by every user (mode ", std::oct, (st.st_mode & 07777),
                        "): another user could replace ", path, "; use a 0700 directory")
                   .message);
    }
  }
  try {
    if (needs_ipv6(endpoint)) sock_.set(zmq::sockopt::ipv6, 1);
    sock_.bind(zmq_endpoint(endpoint));
  } catch (const zmq::error_t& e) { return fail("bind ", endpoint, ": ", e.what()); }
  if (file && ::chmod(path.c_str(), 0600) != 0)
    return fail("bind ", endpoint, ": cannot make the socket file 0600: ", std::strerror(errno));
  return Ok{};
}

std::string WorkerService::last_endpoint() const { return sock_.get(zmq::sockopt::last_endpoint); }

std::vector<Held> WorkerService::held() const {
  std::vector<Held> h;
  for (const Loaded& l : sets_) h.push_back({l.hash, l.faces});
  return h;
}

HelloMsg WorkerService::hello(const std::string& owner, std::uint64_t echo) const {
  HelloMsg h{cfg_.worker_id, epoch_, echo, {}};
  for (const Loaded& l : sets_)
    if (l.owner == owner && h.held.size() < cfg_.limits.max_held) h.held.push_back({l.hash, l.faces});
  return h;
}

const std::string& WorkerService::owner_of(const zmq::message_t& peer, const zmq::message_t& frame) {
  // Under CURVE the ZAP handler names each connection by its client key (User-Id), which a
  // client cannot choose; else the routing id, which ScatterGather draws at random. Into one
  // string kept from message to message (no allocation a message).
  if (zap_) {
    if (const char* id = zmq_msg_gets(frame.handle(), "User-Id"); id && *id) return owner_.assign("key:").append(id);
  }
  return owner_.assign("id:").append(static_cast<const char*>(peer.data()), peer.size());
}

void WorkerService::send(const std::string& peer, const Message& m) {
  send(zmq::message_t(peer.data(), peer.size()), m);
}

void WorkerService::send_error(const std::string& peer, ErrorCode code, std::uint64_t ref, std::string text) {
  send_error(zmq::message_t(peer.data(), peer.size()), code, ref, std::move(text));
}

void WorkerService::send(const zmq::message_t& peer, const Message& m) {
  encode(m, out_);
  // ROUTER without ROUTER_MANDATORY: a reply to a peer that is gone or over its HWM is dropped,
  // never blocks. The client's deadline and sequence numbers cover the loss.
  try {
    zmq::message_t id(peer.data(), peer.size());
    if (!sock_.send(id, zmq::send_flags::sndmore | zmq::send_flags::dontwait)) return;
    (void)sock_.send(zmq::buffer(out_), zmq::send_flags::dontwait);
  } catch (const zmq::error_t&) {}
}

void WorkerService::log_refusal(const std::string& what) {
  // At most one line a second, with how many were not logged: refusals are what an attacker
  // causes, and must not flood the journal.
  ++refusals_unlogged_;
  const auto now = std::chrono::steady_clock::now();
  if (now - refusal_logged_ < std::chrono::seconds(1)) return;
  log(5, refusals_unlogged_ > 1 ? st::fail(what, " (", refusals_unlogged_ - 1, " more refusals since the last report)").message
                                : what);
  refusal_logged_ = now;
  refusals_unlogged_ = 0;
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

bool WorkerService::handle_zap() {
  // Request frames: version, request id, domain, address, routing id, mechanism, credentials.
  std::vector<zmq::message_t> f;
  try {
    do {
      f.emplace_back();
      if (!zap_.recv(f.back(), zmq::recv_flags::dontwait)) return false;
    } while (f.back().more() && f.size() < 16);
    while (f.back().more()) {
      zmq::message_t junk;
      (void)zap_.recv(junk);
    }
  } catch (const zmq::error_t&) { return false; }
  bool ok = false;
  if (f.size() >= 7 && f[5].to_string_view() == "CURVE" && f[6].size() == 32) {
    const std::string key(static_cast<const char*>(f[6].data()), 32);
    ok = std::find(allowed_.begin(), allowed_.end(), key) != allowed_.end();
    if (!ok) {
      ++counters_.refused;
      // Rate-limited per source address, not per key: a client rotating keys gets one line, then
      // one a minute with a count, however many keys it tries.
      constexpr std::size_t kMaxRefusedSources = 1024;  // bounds the map under a spoofed flood
      constexpr auto kRefusalLogInterval = std::chrono::seconds(60);
      const std::string source(f[3].to_string_view());
      if (refusals_.size() >= kMaxRefusedSources && !refusals_.count(source)) refusals_.clear();
      Refusal& r = refusals_[source];
      const auto now = std::chrono::steady_clock::now();
      if (r.logged == std::chrono::steady_clock::time_point{} || now - r.logged >= kRefusalLogInterval) {
        char z85[41] = {};
        zmq_z85_encode(z85, static_cast<const std::uint8_t*>(f[6].data()), 32);
        log(4, std::string("refused CURVE client ") + z85 + " from " + source + ": not in allowed_clients" +
                   (r.unlogged ? " (" + std::to_string(r.unlogged) + " more refusals from this address not logged)" : ""));
        r.logged = now;
        r.unlogged = 0;
      } else {
        ++r.unlogged;
      }
    }
  }
  const std::string request_id = f.size() > 1 ? f[1].to_string() : std::string();
  const char* status = ok ? "200" : "400";
  char user[41] = {};  // the client's key, Z85: the User-Id of its messages (owner_of)
  if (ok) zmq_z85_encode(user, static_cast<const std::uint8_t*>(f[6].data()), 32);
  try {
    zap_.send(zmq::str_buffer("1.0"), zmq::send_flags::sndmore);
    zap_.send(zmq::buffer(request_id), zmq::send_flags::sndmore);
    zap_.send(zmq::buffer(std::string_view(status)), zmq::send_flags::sndmore);
    zap_.send(zmq::buffer(std::string_view(ok ? "OK" : "client key not allowed")), zmq::send_flags::sndmore);
    zap_.send(zmq::buffer(std::string_view(user)), zmq::send_flags::sndmore);
    zap_.send(zmq::str_buffer(""), zmq::send_flags::none);
  } catch (const zmq::error_t&) {}
  return true;
}

bool WorkerService::handle_monitor() {
  for (int budget = 0; budget < 256; ++budget) {
    zmq::message_t ev, addr;
    try {
      if (!monitor_.recv(ev, zmq::recv_flags::dontwait)) return true;
      if (ev.more()) (void)monitor_.recv(addr, zmq::recv_flags::none);
    } catch (const zmq::error_t&) { return true; }
    if (ev.size() < 6) continue;
    std::uint16_t event = 0;
    std::uint32_t value = 0;
    std::memcpy(&event, ev.data(), 2);
    std::memcpy(&value, static_cast<const char*>(ev.data()) + 2, 4);
    bad_by_fd_.erase(static_cast<int>(value));  // a new connection, or the end of one, on this descriptor
    if (event == ZMQ_EVENT_ACCEPTED) {
      if (++connections_ > cfg_.max_connections) {
        ::shutdown(static_cast<int>(value), SHUT_RDWR);  // libzmq sees the end of the stream and closes it
        ++counters_.connections_refused;
        if (counters_.connections_refused == 1 || counters_.connections_refused % 1000 == 0)
          log(4, st::fail("more than max_connections = ", cfg_.max_connections, " connections: refused ",
                          counters_.connections_refused, " so far")
                     .message);
      }
    } else if (event == ZMQ_EVENT_DISCONNECTED) {
      if (connections_ > 0) --connections_;
    }
  }
  return false;  // more may be waiting
}

void WorkerService::drain_side_sockets() {
  // Their descriptors signal only when a mailbox goes from empty to not empty, so each is read
  // until EAGAIN (or again at the next poll, without waiting, when a budget stopped it first).
  bool drained = true;
  if (zap_) {
    int budget = 256;
    while (budget > 0 && handle_zap()) --budget;
    drained = budget > 0;
  }
  if (monitor_) drained = handle_monitor() && drained;
  side_pending_ = !drained;
}

bool WorkerService::poll_once(std::chrono::milliseconds timeout) {
  // An absent descriptor is polled as -1 (ignored), never as descriptor 0 (stdin). Only sock_ is
  // polled as a socket; the ZAP handler and the monitor by their descriptors (zap_fd_).
  zmq::pollitem_t items[4] = {{sock_.handle(), 0, ZMQ_POLLIN, 0},
                              {nullptr, zap_fd_, ZMQ_POLLIN, 0},
                              {nullptr, job_ ? job_->fd : -1, ZMQ_POLLIN, 0},
                              {nullptr, monitor_fd_, ZMQ_POLLIN, 0}};
  // The loader's eventfd wakes the poll when a set is built; without one (eventfd failed) the
  // poll is kept short while a load runs.
  if (job_ && job_->fd < 0) timeout = std::min(timeout, std::chrono::milliseconds(5));
  if (side_pending_) timeout = std::chrono::milliseconds(0);
  try {
    zmq::poll(items, 4, timeout);  // (a timeout leaves every revents 0)
  } catch (const zmq::error_t& e) {
    return e.num() != ETERM;  // EINTR (a signal): let the caller look at its stop flag
  }
  if (side_pending_ || (items[1].revents | items[3].revents) & ZMQ_POLLIN) drain_side_sockets();
  if (job_ && job_->done.load(std::memory_order_acquire)) finish_job();
  drop_idle();
  if (!(items[0].revents & ZMQ_POLLIN)) return true;
  // Handle what is queued now (at most 1024 messages or 4 MiB: the Queries among them are answered
  // after the batch, so a flood of large frames must not hold them up), then return so the caller
  // can tick (watchdog, stop flag).
  std::size_t batch_bytes = 0;
  for (int budget = 0; budget < 1024 && batch_bytes < (std::size_t{4} << 20); ++budget) {
    zmq::message_t peer, frame;
    try {
      if (!sock_.recv(peer, zmq::recv_flags::dontwait)) break;
      ST_ASSERT(peer.more(), "a ROUTER prepends the routing id to every message");
      if (!peer.more()) {
        note_bad("no body frame");
        continue;
      }
      (void)sock_.recv(frame, zmq::recv_flags::none);  // parts of a message arrive together
      bool extra = frame.more();
      for (bool more = extra; more;) {  // discard surplus frames
        zmq::message_t junk;
        (void)sock_.recv(junk, zmq::recv_flags::none);
        more = junk.more();
      }
      const std::uint64_t bad_before = counters_.bad_messages;
      if (extra || frame.size() == 0) {
        note_bad(extra ? "more than one frame" : "empty frame");
        send_error(peer, ErrorCode::BadMessage, 0, "expected exactly one non-empty frame per message");
      } else {
        batch_bytes += frame.size();
        handle(peer, owner_of(peer, frame), {static_cast<const std::uint8_t*>(frame.data()), frame.size()});
      }
      if (counters_.bad_messages != bad_before) cut_if_bad(frame);
    } catch (const zmq::error_t& e) { return e.num() != ETERM; } catch (const std::bad_alloc&) {
      ++counters_.out_of_memory;  // this message is lost (its client retries); nothing held is
      log(3, "out of memory handling a message: dropped");
    }
  }
  serve_queries();
  return true;
}

void WorkerService::cut_if_bad(const zmq::message_t& frame) {
  // The descriptor the message came in on (-1 over inproc://, which has none to cut).
  const int fd = zmq_msg_get(const_cast<zmq_msg_t*>(frame.handle()), ZMQ_SRCFD);
  if (fd < 0) return;
  constexpr std::size_t kMaxTracked = 4096;  // bounded; a DISCONNECTED event clears an entry
  if (bad_by_fd_.size() >= kMaxTracked && !bad_by_fd_.count(fd)) bad_by_fd_.clear();
  if (++bad_by_fd_[fd] < kMaxBadPerConnection) return;
  bad_by_fd_.erase(fd);
  ::shutdown(fd, SHUT_RDWR);  // libzmq sees the end of the stream and closes it (as for max_connections)
  ++counters_.connections_cut;
  if (counters_.connections_cut == 1 || counters_.connections_cut % 1000 == 0)
    log(4, st::fail("shut down a connection after ", kMaxBadPerConnection, " bad messages (", counters_.connections_cut,
                    " so far)")
               .message);
}

void WorkerService::drop_upload(std::unordered_map<std::string, Upload>::iterator it) {
  buffered_ -= it->second.bytes.capacity();
  uploads_.erase(it);
}

void WorkerService::drop_idle() {
  const auto now = std::chrono::steady_clock::now();
  if (now < next_idle_check_) return;
  next_idle_check_ = now + std::chrono::seconds(1);
  for (auto it = uploads_.begin(); it != uploads_.end();) {
    if (now - it->second.last_chunk < cfg_.upload_timeout) {
      ++it;
      continue;
    }
    log(5, st::fail("upload of block set ", std::hex, it->second.hash, std::dec, " abandoned after ",
                    it->second.bytes.size(), " of ", it->second.total, " bytes: no chunk for ",
                    cfg_.upload_timeout.count(), " ms")
               .message);
    ++counters_.uploads_abandoned;
    auto gone = it++;
    drop_upload(gone);
  }
  if (cfg_.idle_set_ttl.count() <= 0 || sets_.size() < 2) return;
  std::size_t dropped = 0;
  for (auto it = std::next(sets_.begin()); it != sets_.end();) {  // never the most recently used
    if (now - it->last_used < cfg_.idle_set_ttl) {
      ++it;
      continue;
    }
    log(6, st::fail("dropped block set ", std::hex, it->hash, std::dec, ": not queried for ",
                    std::chrono::duration_cast<std::chrono::seconds>(now - it->last_used).count(), " s")
               .message);
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

void WorkerService::handle_message(const std::string& peer, std::span<const std::uint8_t> frame) {
  const zmq::message_t id(peer.data(), peer.size());
  handle(id, "id:" + peer, frame);
  serve_queries();
}

void WorkerService::handle(const zmq::message_t& peer, const std::string& owner, std::span<const std::uint8_t> frame) {
  Result<Message> m = decode(frame, cfg_.limits);
  if (!m) {
    note_bad(m.error());
    // A chunk of a block set larger than this worker takes is well-formed otherwise: refuse the
    // load as TooLarge with the limit, so the client stops sending it and can say why.
    Limits any_size = cfg_.limits;
    any_size.max_blockset_bytes = UINT64_MAX;
    if (Result<Message> big = decode(frame, any_size); big)
      if (const auto* l = std::get_if<LoadBlocksMsg>(&big.value()))
        return send_error(peer, ErrorCode::TooLarge, l->hash,
                          st::fail("block set of ", l->total_bytes, " bytes is over this worker's max_blockset_bytes = ",
                                   cfg_.limits.max_blockset_bytes, " (the daemon's max_blockset_mb): load refused")
                              .message);
    send_error(peer, ErrorCode::BadMessage, 0, m.error());
    return;
  }
  Message& msg = m.value();
  if (auto* q = std::get_if<QueryMsg>(&msg)) {
    // Answered at the end of the batch (serve_queries); a newer Query of the same client takes
    // the place of one still waiting.
    // Slots are kept from batch to batch, so their strings are assigned without allocating.
    auto p = std::find_if(pending_.begin(), pending_.begin() + std::ptrdiff_t(npending_),
                          [&](const Pending& x) { return x.owner == owner; });
    if (p != pending_.begin() + std::ptrdiff_t(npending_)) {
      ++counters_.superseded;
    } else {
      if (npending_ == pending_.size()) pending_.emplace_back();
      p = pending_.begin() + std::ptrdiff_t(npending_++);
      p->owner = owner;
    }
    p->peer.assign(static_cast<const char*>(peer.data()), peer.size());
    p->q = std::move(*q);
    return;
  }
  if (auto* l = std::get_if<LoadBlocksMsg>(&msg)) return on_load(peer, owner, *l);
  if (auto* h = std::get_if<HeartbeatMsg>(&msg)) {
    ++counters_.heartbeats;
    return send(peer, hello(owner, h->nonce));
  }
  note_bad(std::string("unexpected ") + type_name(msg));
  send_error(peer, ErrorCode::Unexpected, 0, std::string("a worker does not accept ") + type_name(msg));
}

WorkerService::Client& WorkerService::client(const std::string& owner) {
  // Bounded: a flood of identities (free without CURVE) clears the map; what is lost is only
  // the fairness history, re-learnt within a second.
  constexpr std::size_t kMaxClients = 4096;
  if (clients_.size() >= kMaxClients && !clients_.count(owner)) clients_.clear();
  return clients_[owner];
}

void WorkerService::serve_queries() {
  if (npending_ == 0) return;
  // Cheapest clients first: a client whose queries kept the worker busy waits behind those
  // whose queries are cheap (an unknown client counts as 1 ms), so an honest haptic client waits
  // for at most the one budget-bounded query in progress.
  constexpr double kUnknownCostNs = 1e6;
  const auto now = std::chrono::steady_clock::now();
  auto recent = [&](const std::string& owner) {
    const auto it = clients_.find(owner);
    return it == clients_.end() ? kUnknownCostNs : it->second.cost_at(now);
  };
  const auto batch = std::span(pending_).first(npending_);
  npending_ = 0;         // answer() adds none
  if (batch.size() > 1)  // (a sort of one still asks for a buffer)
    std::stable_sort(batch.begin(), batch.end(),
                     [&](const Pending& a, const Pending& b) { return recent(a.owner) < recent(b.owner); });
  for (const Pending& p : batch) {
    try {
      answer(p);
    } catch (const std::bad_alloc&) {
      ++counters_.out_of_memory;
      pairs_ = {};
      send_error(p.peer, ErrorCode::TooLarge, p.q.seq, "worker out of memory answering the query");
    }
  }
  // The slots of a batch of many clients (a flood of identities) are not all kept with what
  // their Queries held: a few cover honest use.
  constexpr std::size_t kKeptSlots = 16;
  if (pending_.size() > kKeptSlots) pending_.resize(kKeptSlots);
}

void WorkerService::answer(const Pending& p) {
  const QueryMsg& q = p.q;
  const zmq::message_t peer(p.peer.data(), p.peer.size());
  auto it =
      std::find_if(sets_.begin(), sets_.end(), [&](const Loaded& l) { return l.hash == q.hash && l.owner == p.owner; });
  if (it == sets_.end()) {
    send_error(peer, ErrorCode::NotLoaded, q.seq, st::fail("block set ", std::hex, q.hash, " is not held").message);
    send(peer, hello(p.owner, 0));  // tell the client what is held so it can load the right set
    return;
  }
  // The standby set (ScatterConfig::replicas): this client's too, held, of the same object.
  auto sb = sets_.end();
  if (q.standby != 0) {
    sb = std::find_if(sets_.begin(), sets_.end(),
                      [&](const Loaded& l) { return l.hash == q.standby && l.owner == p.owner; });
    if (sb == sets_.end()) {
      send_error(peer, ErrorCode::NotLoaded, q.seq,
                 st::fail("standby block set ", std::hex, q.standby, " is not held").message);
      send(peer, hello(p.owner, 0));
      return;
    }
  }
  for (const auto& l : {it, sb})
    if (l != sets_.end() && l->object != q.object) {  // another object than the set's: its pairs would be misread
      send_error(peer, ErrorCode::BadMessage, q.seq,
                 st::fail("Query names object ", q.object, " but block set ", std::hex, l->hash, std::dec,
                          " is a share of object ", l->object)
                     .message);
      return;
    }
  Client& c = client(p.owner);
  const auto now = std::chrono::steady_clock::now();
  if (now < c.penalty_until) {  // its last query was refused as too large: no work for it yet
    ++counters_.penalised;
    send_error(peer, ErrorCode::TooLarge, q.seq,
               st::fail("refused unanswered for ",
                        std::chrono::duration_cast<std::chrono::milliseconds>(c.penalty_until - now).count(),
                        " ms more: this client's last query was over its limits")
                   .message);
    return;
  }
  if (sb != sets_.end()) {
    sets_.splice(sets_.begin(), sets_, sb);
    sb->last_used = sb->queried = now;
  }
  sets_.splice(sets_.begin(), sets_, it);  // most recently used first
  it->last_used = it->queried = now;
  pairs_.clear();
  // The backend stops past max_pairs (a block set of faces piled on each other cannot make the
  // worker compute and hold N² pairs before refusing) and past the set's work budget (nor N²
  // tests that find no pair).
  QueryStats st = it->backend->query(q.pose, q.skip, pairs_, {cfg_.limits.max_pairs, it->work});
  worked_.assign(it->backend->worked().begin(), it->backend->worked().end());
  if (sb != sets_.end() && !q.take.empty() && pairs_.size() <= cfg_.limits.max_pairs && !st.work_limit_hit) {
    const QueryStats more = sb->backend->query_only(q.pose, q.take, pairs_, {cfg_.limits.max_pairs, sb->work});
    st.sphere_tests += more.sphere_tests;
    st.tri_tests += more.tri_tests;
    st.compute_ns += more.compute_ns;
    st.work_limit_hit = more.work_limit_hit;
    add_worked(worked_, sb->backend->worked());
  }
  c.cost_ns = std::max(c.cost_at(now), double(st.compute_ns));
  c.seen = now;
  const bool too_many = pairs_.size() > cfg_.limits.max_pairs;
  if (too_many || st.work_limit_hit) {
    c.penalty_until = now + std::chrono::nanoseconds(std::int64_t(cfg_.penalty_factor * double(st.compute_ns)));
    const std::string why =
        too_many ? st::fail("more than max_pairs = ", cfg_.limits.max_pairs, " colliding pairs: query refused").message
                 : st::fail("query over its work budget (", it->work, " units for a set of ", it->faces,
                            " faces): refused; are the set's faces piled on each other?")
                       .message;
    ++(too_many ? counters_.too_many_pairs : counters_.over_budget);
    log_refusal(why);
    send_error(peer, ErrorCode::TooLarge, q.seq, why);
    pairs_.clear();
    if (pairs_.capacity() > (std::size_t{1} << 20)) pairs_.shrink_to_fit();  // do not keep an attacker's peak
    return;
  }
  std::sort(pairs_.begin(), pairs_.end());
  pairs_.erase(std::unique(pairs_.begin(), pairs_.end()), pairs_.end());
  ++counters_.queries;
  ResultMsg r{q.seq, cfg_.worker_id, q.hash, st, {}, q.object, {}};
  r.worked.swap(worked_);
  if (r.worked.size() > cfg_.limits.max_worked) {  // the heaviest, by ascending id again
    std::nth_element(r.worked.begin(), r.worked.begin() + cfg_.limits.max_worked, r.worked.end(),
                     [](const WorkedBlock& a, const WorkedBlock& b) { return a.work > b.work; });
    r.worked.resize(cfg_.limits.max_worked);
    std::sort(r.worked.begin(), r.worked.end(),
              [](const WorkedBlock& a, const WorkedBlock& b) { return a.block < b.block; });
  }
  r.pairs.swap(pairs_);
  send(peer, r);
  pairs_.swap(r.pairs);  // keep the capacity for the next query
  worked_.swap(r.worked);
}

void WorkerService::on_load(const zmq::message_t& peer, const std::string& owner, const LoadBlocksMsg& m) {
  // decode() has checked total_bytes ≤ max_blockset_bytes and that the chunk lies inside it.
  auto it = uploads_.find(owner);
  if (m.offset == 0) {
    if (it != uploads_.end()) drop_upload(it);  // this client starts over (its own upload only)
    const std::uint64_t quota =
        cfg_.max_client_bytes ? cfg_.max_client_bytes : std::uint64_t(cfg_.max_sets) * cfg_.limits.max_blockset_bytes;
    if (m.total_bytes > quota) {
      ++counters_.uploads_refused;
      log_refusal(
          st::fail("upload of ", m.total_bytes, " bytes refused: over the client's quota of ", quota, " bytes").message);
      return send_error(
          peer, ErrorCode::TooLarge, m.hash,
          st::fail("block set of ", m.total_bytes, " bytes is over this client's quota (max_client_bytes = ", quota, ")")
              .message);
    }
    std::size_t busy = uploads_.size() + waiting_.size() + (job_ ? 1 : 0);
    if (busy >= cfg_.max_uploads && free_upload_slot()) --busy;
    if (busy >= cfg_.max_uploads) {
      ++counters_.uploads_refused;
      log_refusal(st::fail("upload refused: ", busy, " uploads in progress (max_uploads = ", cfg_.max_uploads, ")").message);
      return send_error(peer, ErrorCode::TooLarge, m.hash,
                        st::fail("worker busy: ", busy, " block-set uploads in progress (max_uploads = ", cfg_.max_uploads,
                                 "); send again later")
                            .message);
    }
    Upload u;
    u.owner = owner;
    u.hash = m.hash;
    u.total = m.total_bytes;
    it = uploads_.emplace(owner, std::move(u)).first;
  } else if (it == uploads_.end() || it->second.hash != m.hash || it->second.total != m.total_bytes ||
             it->second.bytes.size() != m.offset) {
    const bool was = it != uploads_.end();
    if (was) drop_upload(it);
    return send_error(
        peer, ErrorCode::LoadFailed, m.hash,
        st::fail("LoadBlocks chunk at offset ", m.offset, " out of order", was ? " (load abandoned)" : "").message);
  }
  Upload& u = it->second;
  // Capacity grows with the bytes that actually arrive (a lying total_bytes costs nothing up
  // front) and is counted against max_upload_bytes over every client's uploads.
  const std::size_t need = u.bytes.size() + m.data.size(), cap = u.bytes.capacity();
  if (need > cap) {
    const std::size_t grown = std::min<std::uint64_t>(u.total, std::max<std::uint64_t>({need, 2 * cap, 1u << 20}));
    if (buffered_ - cap + grown > cfg_.max_upload_bytes) {
      ++counters_.uploads_refused;
      const std::uint64_t hash = u.hash;
      drop_upload(it);
      return send_error(peer, ErrorCode::TooLarge, hash,
                        st::fail("worker busy: uploads would buffer more than max_upload_bytes = ", cfg_.max_upload_bytes,
                                 " bytes; load refused, send again later")
                            .message);
    }
    try {
      u.bytes.reserve(grown);
    } catch (const std::bad_alloc&) {
      ++counters_.out_of_memory;
      const std::uint64_t hash = u.hash;
      drop_upload(it);
      log(3, st::fail("out of memory buffering an upload of ", grown, " bytes: refused").message);
      return send_error(peer, ErrorCode::TooLarge, hash, "worker out of memory: load refused, send again later");
    }
    buffered_ += u.bytes.capacity() - cap;
  }
  ++counters_.chunks;
  u.bytes.insert(u.bytes.end(), m.data.begin(), m.data.end());
  u.last_chunk = std::chrono::steady_clock::now();
  if (m.offset == 0) u.started = u.last_chunk;
  u.peer.assign(static_cast<const char*>(peer.data()), peer.size());  // answer where the last chunk came from
  if (u.bytes.size() < u.total) return;
  waiting_.push_back(std::move(u));
  uploads_.erase(it);  // its bytes stay counted in buffered_ until the loader is done with them
  start_job();
}

bool WorkerService::free_upload_slot() {
  // The upload that has waited longest for a chunk, if it has waited upload_stall, else the
  // slowest one under min_upload_rate: a client trickling bytes to hold a slot loses it.
  const auto now = std::chrono::steady_clock::now();
  auto victim = uploads_.end();
  double worst = 0;
  for (auto it = uploads_.begin(); it != uploads_.end(); ++it) {
    const Upload& u = it->second;
    const double idle = std::chrono::duration<double>(now - u.last_chunk).count();
    const double age = std::chrono::duration<double>(now - u.started).count();
    const double stall = std::chrono::duration<double>(cfg_.upload_stall).count();
    const bool stalled = idle >= stall;
    const bool slow = age >= stall && double(u.bytes.size()) < double(cfg_.min_upload_rate) * age;
    if (!stalled && !slow) continue;
    const double badness = stalled ? 1e9 + idle : 1.0 / (1.0 + double(u.bytes.size()) / age);
    if (badness > worst) worst = badness, victim = it;
  }
  if (victim == uploads_.end()) return false;
  ++counters_.uploads_displaced;
  log_refusal(st::fail("upload of block set ", std::hex, victim->second.hash, std::dec, " (",
                       victim->second.bytes.size(), " of ", victim->second.total,
                       " bytes) gave its slot to another: stalled or under min_upload_rate")
                  .message);
  drop_upload(victim);
  return true;
}

void WorkerService::start_job() {
  if (job_ || waiting_.empty()) return;
  auto job = std::make_shared<LoadJob>();
  job->up = std::move(waiting_.front());
  waiting_.pop_front();
  job->counted = job->up.bytes.capacity();
  for (const Loaded& l : sets_)
    if (l.owner == job->up.owner) job->known.push_back(l.digest);  // shared within a client only
  job->limits = cfg_.limits;
  job->factory = factory_;
  job->fd = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);  // −1: poll_once polls every 5 ms instead
  job_ = job;
  loader_ = std::thread([job] { job->run(); });
}

std::size_t WorkerService::distinct_backends() const {
  std::set<const CollisionBackend*> d;
  for (const Loaded& l : sets_) d.insert(l.backend.get());
  return d.size();
}

bool WorkerService::make_room(const std::string& owner, std::uint64_t bytes) {
  const std::uint32_t max_sets = std::max<std::uint32_t>(cfg_.max_sets, 1);
  const std::uint32_t per_client = cfg_.max_sets_per_client ? std::min(cfg_.max_sets_per_client, max_sets) : max_sets;
  const std::uint64_t quota =
      cfg_.max_client_bytes ? cfg_.max_client_bytes : std::uint64_t(max_sets) * cfg_.limits.max_blockset_bytes;
  // The client's own quota first: its least recently used sets make room for its new one.
  std::uint32_t own = 0;
  std::uint64_t own_bytes = 0;
  for (const Loaded& l : sets_)
    if (l.owner == owner) ++own, own_bytes += l.bytes;
  for (auto it = sets_.end(); it != sets_.begin() && (own >= per_client || own_bytes + bytes > quota);) {
    if ((--it)->owner != owner) continue;
    --own;
    own_bytes -= it->bytes;
    it = sets_.erase(it);
  }
  // Then the worker's, from the least recently used: a set nobody has queried for active_set
  // (this client's or another's), else this client's own least recently used set. A set another
  // client uses is never evicted for this one, and this client's sets in use go last: a client
  // that queries two sets at once (its share and its standby copies, ScatterConfig::replicas)
  // would otherwise trade one for the other on every load while an idle set kept its slot.
  const auto now = std::chrono::steady_clock::now();
  while (distinct_backends() >= max_sets) {
    auto victim = sets_.end(), own_lru = sets_.end();
    for (auto it = sets_.end(); it != sets_.begin();) {
      --it;
      if (now - it->queried >= cfg_.active_set) {
        victim = it;
        break;
      }
      if (own_lru == sets_.end() && it->owner == owner) own_lru = it;
    }
    if (victim == sets_.end()) victim = own_lru;
    if (victim == sets_.end()) return false;
    sets_.erase(victim);
  }
  return true;
}

void WorkerService::finish_job() {
  loader_.join();
  std::shared_ptr<LoadJob> job = std::move(job_);
  job_ = nullptr;
  Upload& u = job->up;
  std::shared_ptr<CollisionBackend> backend;
  const Loaded* same = nullptr;  // the client's held set with these bytes (job->reuse)
  if (job->error.empty() && job->reuse) {
    for (const Loaded& l : sets_)
      if (l.digest == job->digest && l.owner == u.owner) same = &l;
    if (!same) {  // evicted while this job ran: build it after all
      waiting_.push_front(std::move(u));
      start_job();
      return;
    }
    backend = same->backend;
    ++counters_.loads_shared;
  }
  buffered_ -= job->counted;  // the upload's bytes are gone now
  if (!job->error.empty()) {
    counters_.out_of_memory += job->oom;
    log(job->oom ? 3 : 4, "load refused: " + job->error);
    send_error(u.peer, ErrorCode::LoadFailed, u.hash, job->error);
    start_job();
    return;
  }
  Loaded entry{
      u.owner, u.hash, job->digest, job->faces, job->object, u.total, 0, backend, std::chrono::steady_clock::now()};
  if (same) {  // the same bytes as a held set: its face count, object and budget
    entry.faces = same->faces;
    entry.object = same->object;
    entry.work = same->work;
  } else {
    entry.backend = std::move(job->backend);
    entry.work = std::min(cfg_.max_query_work, cfg_.query_work_base + std::uint64_t(cfg_.query_work_per_face) *
                                                                          (job->faces + job->probe_faces));
  }
  sets_.remove_if([&](const Loaded& l) { return l.hash == u.hash && l.owner == u.owner; });
  if (!same && !make_room(u.owner, u.total)) {
    ++counters_.loads_refused_full;
    const std::string why =
        st::fail("worker full: its ", cfg_.max_sets,
                 " set slots hold sets other clients queried within active_set = ", cfg_.active_set.count(),
                 " ms; load refused, send again later")
            .message;
    log_refusal(why);
    send_error(u.peer, ErrorCode::TooLarge, u.hash, why);
    start_job();
    return;
  }
  sets_.push_front(std::move(entry));
  ++counters_.loads;
  log(6, st::fail("loaded block set ", std::hex, u.hash, std::dec, same ? " (same bytes as a held set)" : "", ": ",
                  job->blocks, " blocks, ", sets_.front().faces, " object faces, ", job->probe_faces,
                  " probe faces, in ", job->ms, " ms; holding ", sets_.size(), " set(s)")
             .message);
  send(u.peer, hello(u.owner, 0));
  start_job();
}

}  // namespace st::net
