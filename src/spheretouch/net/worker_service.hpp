// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// WorkerService: one worker of the distributed collision (paper §3.4). Binds a ZeroMQ ROUTER,
/// keeps the block sets it was sent in memory (content-addressed, LRU), and answers each Query
/// with its backend's pairs for the block set the Query names. The same code runs on a thread
/// over inproc:// (the embedded default, local_workers.hpp) and in the spheretouch-worker daemon
/// over tcp:// or ipc://. It never blocks on a send: replies to a peer that is gone or slow are
/// dropped by the ROUTER, and every malformed message gets an Error reply or is dropped.
//
// Clients are kept apart: each has its own upload in progress, and a block set is visible (in
// Hello, to Query) only to the client that sent its bytes. A client is its CURVE public key when
// CURVE is on, else its ZeroMQ routing id (ScatterGather sets a random 16-byte one). A backend is
// shared only between a client's own sets (the same bytes sent twice): another client's load of
// the same bytes is built again, so its load time reveals nothing about what others hold.
// Hashing, decoding and building a set run on a loader thread, so the worker keeps answering
// heartbeats, queries and its watchdog while a large set is built.
//
// One client cannot starve another: each Query has a work budget sized from its set (refused
// TooLarge past it); of a burst of Queries from one client only the newest is answered (a haptic
// client wants the newest pose, never a backlog); and the Queries waiting at once are answered
// in the order of their clients' recent work, least first, so an honest client waits for at most
// one budget-bounded query of another. Quotas per client bound its uploads, sets and bytes; a set
// another client queried recently is never evicted for a load.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <deque>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>
#include <zmq.hpp>

#include <spheretouch/net/backend.hpp>
#include <spheretouch/net/block_set.hpp>
#include <spheretouch/net/curve_keys.hpp>
#include <spheretouch/net/protocol.hpp>
#include <spheretouch/net/socket_options.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// CURVE on the worker's socket: its secret key and the client public keys it admits (a ZAP
/// handler in the service's context checks each connecting client against the list).
struct CurveServer {
  std::string secret_z85;                        ///< the worker's secret key, Z85 (40 characters)
  std::vector<std::string> allowed_clients_z85;  ///< admitted client public keys, Z85; empty: none
};

/// What a worker is and how much it may hold.
struct WorkerConfig {
  std::uint32_t worker_id = 0;  ///< reported in Hello and Result
  std::uint32_t max_sets = 3;   ///< block sets kept in memory (LRU): own share + reassigned variants
  /// A held set not queried for this long is dropped and its memory returned to the system (the
  /// most recently used set is always kept). Reassigned variants live through a fault and go
  /// once it is over; a variant needed again is sent again. Zero: keep sets until LRU evicts them.
  std::chrono::milliseconds idle_set_ttl{30'000};
  /// Decode limits. What the worker holds is bounded by: max_sets loaded sets, each about
  /// kSetMemoryFactor × its encoded size (≤ max_blockset_bytes); one set being built
  /// (kBuildMemoryFactor × its size at the peak); max_upload_bytes of uploads in progress or
  /// waiting for the loader; and, queued inside libzmq, at most rcvhwm frames of at most
  /// max_chunk_bytes per connection, max_connections connections.
  Limits limits = DefaultLimits();
  /// Uploads in progress or waiting for the loader, over all clients (a client has at most one);
  /// when all are taken, an upload stalled for upload_stall or slower than min_upload_rate gives
  /// its slot to the new one (a client trickling bytes cannot hold a slot), else the new one is
  /// told TooLarge ("busy") and may retry.
  std::uint32_t max_uploads = 4;
  /// See max_uploads: no chunk for this long makes an upload's slot free for another.
  std::chrono::milliseconds upload_stall{1000};
  /// See max_uploads: bytes per second an upload must average (after upload_stall) to keep its
  /// slot when another client needs one.
  std::uint64_t min_upload_rate = 1u << 20;
  /// Block sets one client may hold (0: max_sets) and their encoded bytes (0: max_sets ×
  /// limits.max_blockset_bytes); a load past either evicts the client's own least recently used
  /// sets first.
  ///@{
  std::uint32_t max_sets_per_client = 0;
  std::uint64_t max_client_bytes = 0;
  ///@}
  /// A set queried within this long is never evicted for another client's load: that load is
  /// refused ("worker full") instead. A set only loaded, never queried, does not count.
  std::chrono::milliseconds active_set{2000};
  /// Work one Query may cost (geom::CollideStats::work(), 3-15 ns a unit): query_work_base
  /// plus query_work_per_face per face of its set (probe and share), at most max_query_work. A
  /// Query past it is answered TooLarge: faces piled so their boxes overlap but never touch cost
  /// N² triangle tests and give no pair, so the pair cap alone does not bound a query.
  ///@{
  std::uint64_t query_work_base = 1u << 20;
  std::uint32_t query_work_per_face = 16;
  std::uint64_t max_query_work = 1u << 24;
  ///@}
  /// Bytes buffered for uploads (in progress and waiting), over all clients.
  std::uint64_t max_upload_bytes = 2ull << 30;
  /// An upload with no chunk for this long is abandoned and its bytes freed.
  std::chrono::milliseconds upload_timeout{10'000};
  int sndhwm = 64;  ///< messages queued per client before replies are dropped
  int rcvhwm = 4;   ///< messages queued inside libzmq per connection (4 × 1 MiB chunks at most)

  /// TCP and ipc connections held at once; one more is shut down as it is accepted, so what
  /// libzmq may queue is bounded by max_connections × rcvhwm frames in total.
  std::uint32_t max_connections = 64;
  /// Log sink (syslog priority 3 error … 7 debug, message); empty: silent. Bad messages are
  /// summarised at most once a second so a flood cannot flood the log.
  std::function<void(int, const std::string&)> log;
  /// On ipc:// endpoints, the users (besides the worker's own effective uid) whose processes may
  /// connect: libzmq checks each connection's SO_PEERCRED. A filesystem path's missing directories
  /// are created 0700 and the socket file is made 0600.
  std::vector<std::uint32_t> ipc_allowed_uids;
  /// Encrypt and authenticate with CURVE (any transport, ipc:// too); the service then owns its
  /// context's ZAP endpoint, so only one CURVE service per context (the daemon's case).
  std::optional<CurveServer> curve;
  /// After a query refused as too large (pairs or work), the client's next queries are refused
  /// unanswered for penalty_factor × that query's compute time, so a client sending such queries
  /// back to back holds the worker at most 1/(1 + penalty_factor) of the time; 0: no penalty.
  double penalty_factor = 20;
};

/// Counters since start (read on the service's thread, or after it stopped).
struct WorkerCounters {
  std::uint64_t queries = 0;              ///< Query messages answered with a Result
  std::uint64_t loads = 0;                ///< block sets loaded
  std::uint64_t chunks = 0;               ///< LoadBlocks messages accepted
  std::uint64_t bad_messages = 0;         ///< undecodable or misframed messages
  std::uint64_t errors_sent = 0;          ///< Error replies sent
  std::uint64_t heartbeats = 0;           ///< Heartbeats answered
  std::uint64_t refused = 0;              ///< CURVE handshakes refused (client key not allowed)
  std::uint64_t too_many_pairs = 0;       ///< queries refused at max_pairs (the traversal stopped there)
  std::uint64_t uploads_refused = 0;      ///< uploads refused: max_uploads or max_upload_bytes reached
  std::uint64_t uploads_abandoned = 0;    ///< uploads dropped after upload_timeout without a chunk
  std::uint64_t loads_shared = 0;         ///< loads served by a backend already built for the same bytes
  std::uint64_t connections_refused = 0;  ///< connections shut down at max_connections
  std::uint64_t over_budget = 0;          ///< queries refused at their work budget
  std::uint64_t superseded = 0;           ///< queries not answered: a newer one of the same client was waiting
  std::uint64_t penalised = 0;            ///< queries refused unanswered after the client's too-large one
  std::uint64_t uploads_displaced = 0;    ///< stalled or trickling uploads that lost their slot to another
  std::uint64_t loads_refused_full = 0;   ///< loads refused: every set slot held by sets other clients use
  std::uint64_t out_of_memory = 0;        ///< allocations that failed (answered, nothing lost)
  std::uint64_t connections_cut = 0;      ///< connections shut down after kMaxBadPerConnection bad messages
};

/// Resident memory of a held block set (tree backend) per byte of its encoding, rounded up from
/// `spheretouch-bench hostile`: 2.7 for a 48 MiB set of 1.8 M faces, 4.8–5.3 for 7.7 MiB ones
/// (perf/RESULTS.md).
inline constexpr double kSetMemoryFactor = 6.0;
/// Peak while a set is being built (encoding, decoded set and tree together): 4.8 measured for
/// the 48 MiB set.
inline constexpr double kBuildMemoryFactor = 6.5;

/// Bound on the coherent collider's cache (geom::CoherentConfig::max_bytes) of each held set: the
/// tree backend carries certificates between a client's rounds (the same pairs, less work when
/// the probe moves a little), within this.
inline constexpr std::size_t kCoherentCacheBytes = std::size_t(8) << 20;

/// What a worker with `cfg` may hold at most, MiB: max_sets held sets (each with its coherent
/// cache), one being built, uploads
/// and libzmq's queues (the terms of WorkerConfig::limits' comment), for the daemon's log and
/// its check against its cgroup's memory.max.
struct MemoryBound {
  ///@{
  double held_mib = 0, build_mib = 0, upload_mib = 0, queue_mib = 0;  ///< the terms, in that order
  ///@}
  double total() const { return held_mib + build_mib + upload_mib + queue_mib; }  ///< the sum
};
MemoryBound memory_bound(const WorkerConfig& cfg);  ///< see MemoryBound

/// Bad messages (undecodable, misframed) a TCP or ipc connection may send before the worker shuts
/// it down: a client speaking the protocol sends none (one of another version is told so first),
/// and a connection flooding refused frames stops costing the worker its reading.
inline constexpr std::uint32_t kMaxBadPerConnection = 8;

/// One worker; not thread-safe: create, bind and run it on one thread.
class WorkerService {
 public:
  /// A service in `ctx` that makes one backend per loaded block set with `factory`; an error
  /// names what is wrong in `config` (a CURVE key) or what libzmq refused.
  static Result<std::unique_ptr<WorkerService>> create(zmq::context_t& ctx, WorkerConfig config, BackendFactory factory);
  /// Binds the ROUTER to `endpoint` (tcp://, ipc://, inproc://); error names the endpoint.
  Status bind(const std::string& endpoint);
  /// The endpoint last bound, resolved (a tcp wildcard port becomes the real one).
  std::string last_endpoint() const;
  /// Stops a load in progress at its next step (a set being built is left to finish on its own
  /// thread, which owns everything it touches).
  ~WorkerService();
  WorkerService(const WorkerService&) = delete;
  WorkerService& operator=(const WorkerService&) = delete;
  /// Waits up to `timeout` for messages and handles all that are waiting; false when the context
  /// is being terminated (the caller should stop).
  bool poll_once(std::chrono::milliseconds timeout);
  /// Polls until `stop` is set, calling `tick` (if any) at least every `period`.
  void run(const std::atomic<bool>& stop, std::chrono::milliseconds period = std::chrono::milliseconds(100),
           const std::function<void()>& tick = {});
  /// Handles one frame as if the client with routing id `peer` had sent it on the socket (no
  /// CURVE identity); replies go to that routing id and are dropped if no such client is
  /// connected. For the message-sequence fuzzer: the whole handler without a socket round trip.
  void handle_message(const std::string& peer, std::span<const std::uint8_t> frame);
  std::uint64_t epoch() const { return epoch_; }                ///< random per instance
  const WorkerCounters& counters() const { return counters_; }  ///< counters so far
  std::vector<Held> held() const;                               ///< block sets in memory (all clients), MRU first
  std::size_t clients() const { return clients_.size(); }       ///< clients with state (bounded: kMaxClients)
  std::uint64_t upload_bytes() const { return buffered_; }      ///< bytes buffered for uploads now
  bool loading() const { return job_ != nullptr; }              ///< a set is being hashed, decoded or built

 private:
  WorkerService(zmq::context_t& ctx, WorkerConfig config, BackendFactory factory);  // create()'s first step
  Status init(zmq::context_t& ctx);                                                 // CURVE, monitor, options

  /// A client's loaded set; a client that sent the same bytes twice shares the backend.
  struct Loaded {
    std::string owner;  // the client that loaded it (owner_of)
    std::uint64_t hash;
    Digest digest;
    std::uint32_t faces;
    std::uint32_t object;  // the scene object it is a share of (BlockSet::object)
    std::uint64_t bytes;   // its encoded size (the client's byte quota)
    std::uint64_t work;    // a Query's work budget (WorkerConfig::query_work_*)
    std::shared_ptr<CollisionBackend> backend;
    std::chrono::steady_clock::time_point last_used;  // loaded or last queried (LRU, idle_set_ttl)
    std::chrono::steady_clock::time_point queried{};  // last queried (active_set): never, for a set only loaded
  };
  /// What the service knows of a client between its messages.
  struct Client {
    // What its queries cost: the most compute ns of one, decaying by e each second, from `seen`.
    // A client that sends cheap queries (a haptic loop) keeps a small cost whatever its rate.
    double cost_ns = 0;
    std::chrono::steady_clock::time_point seen;
    // After a query refused as too large, its queries are refused unanswered until then
    // (WorkerConfig::penalty_factor).
    std::chrono::steady_clock::time_point penalty_until{};
    double cost_at(std::chrono::steady_clock::time_point now) const {  ///< cost_ns decayed to now
      return cost_ns * std::exp(-std::chrono::duration<double>(now - seen).count());
    }
  };
  /// A Query waiting for the end of the batch it arrived in (serve_queries()).
  struct Pending {
    std::string peer, owner;
    QueryMsg q;
  };
  /// A block set arriving in chunks from one client.
  struct Upload {
    std::string owner, peer;  // who sends it, and the routing id to answer
    std::uint64_t hash = 0, total = 0;
    std::vector<std::uint8_t> bytes;
    std::chrono::steady_clock::time_point started, last_chunk;
  };
  struct LoadJob;  // a complete upload on the loader thread (worker_service.cpp)
  void handle(const zmq::message_t& peer, const std::string& owner, std::span<const std::uint8_t> frame);
  void serve_queries();  ///< the batch's waiting Queries, cheapest clients first
  void answer(const Pending& p);
  Client& client(const std::string& owner);
  bool free_upload_slot();  ///< displaces a stalled or trickling upload; false if none is
  /// Makes room for `owner`'s new backend of `bytes` (its own LRU sets over its quota first, then
  /// sets no one used for active_set, then its own LRU set); false when the worker is full of
  /// sets others use.
  bool make_room(const std::string& owner, std::uint64_t bytes);
  bool handle_zap();      ///< answers one ZAP request; false when none was waiting
  bool handle_monitor();  ///< connection accepted / closed: counts, enforces max_connections; true when drained
  void drain_side_sockets();
  void on_load(const zmq::message_t& peer, const std::string& owner, const LoadBlocksMsg& m);
  void send(const zmq::message_t& peer, const Message& m);
  void send(const std::string& peer, const Message& m);
  void send_error(const zmq::message_t& peer, ErrorCode code, std::uint64_t ref, std::string text);
  void send_error(const std::string& peer, ErrorCode code, std::uint64_t ref, std::string text);
  HelloMsg hello(const std::string& owner, std::uint64_t echo) const;
  const std::string& owner_of(const zmq::message_t& peer, const zmq::message_t& frame);  ///< into owner_
  void log(int priority, const std::string& text) const {
    if (cfg_.log) cfg_.log(priority, text);
  }
  void note_bad(const std::string& why);
  void log_refusal(const std::string& what);     ///< a refused upload, load or query (rate-limited)
  void cut_if_bad(const zmq::message_t& frame);  ///< counts a bad message against its connection
  void drop_idle();                              ///< at most once a second: idle_set_ttl, upload_timeout
  void drop_upload(std::unordered_map<std::string, Upload>::iterator it);
  void start_job();   ///< hands the next waiting upload to the loader thread
  void finish_job();  ///< installs (or refuses) the loader's result
  std::size_t distinct_backends() const;

  WorkerConfig cfg_;
  BackendFactory factory_;
  zmq::socket_t sock_;
  zmq::socket_t zap_;      // ZAP handler (CURVE client allow-list), or empty
  zmq::socket_t monitor_;  // events of sock_ (accepted, disconnected), or empty
  // zap_ and monitor_ are polled by their ZMQ_FD (a plain descriptor, readable when their command
  // mailbox is signalled) and drained to EAGAIN when it fires: zmq_poll on a socket checks its
  // mailbox with two system calls before and after every wait, for every Query.
  // A socket's descriptor is signalled only for what comes after a read found its queues empty
  // (a pipe new to a reader does not signal its first message): so the first poll drains both,
  // as does the one after a drain stopped at its budget.
  int zap_fd_ = -1, monitor_fd_ = -1;
  bool side_pending_ = true;
  std::uint32_t connections_ = 0;                     // TCP/ipc connections open now
  std::unordered_map<int, std::uint32_t> bad_by_fd_;  // bad messages per open connection (its descriptor)
  std::vector<std::string> allowed_;                  // admitted client public keys, 32 raw bytes each
  std::uint64_t epoch_;
  std::list<Loaded> sets_;                           // MRU first
  std::unordered_map<std::string, Upload> uploads_;  // in progress, by owner
  std::deque<Upload> waiting_;                       // complete, waiting for the loader
  std::uint64_t buffered_ = 0;                       // Σ capacity of uploads_ and waiting_ bytes, and the job's
  std::shared_ptr<LoadJob> job_;                     // on the loader thread, or null
  std::thread loader_;
  WorkerCounters counters_;
  std::unordered_map<std::string, Client> clients_;  // by owner; bounded (kMaxClients)
  std::vector<Pending> pending_;                     // this batch's Queries (the first npending_), one per client
  std::size_t npending_ = 0;
  std::string owner_;                // owner_of()'s result
  std::vector<FacePair> pairs_;      // reused per query
  std::vector<WorkedBlock> worked_;  // reused per query: the Result's worked blocks
  std::vector<std::uint8_t> out_;    // reused encode buffer
  std::chrono::steady_clock::time_point bad_logged_{};
  std::chrono::steady_clock::time_point next_idle_check_{};
  std::uint64_t bad_unlogged_ = 0;
  std::chrono::steady_clock::time_point refusal_logged_{};
  std::uint64_t refusals_unlogged_ = 0;
  // Refused CURVE handshakes by source address: the first is logged, then at most one line a
  // minute with a count, so a client retrying or rotating keys cannot flood the log. Bounded:
  // cleared when full.
  struct Refusal {
    std::chrono::steady_clock::time_point logged{};
    std::uint64_t unlogged = 0;
  };
  std::unordered_map<std::string, Refusal> refusals_;
};

}  // namespace st::net
