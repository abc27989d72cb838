// WorkerService: one worker of the distributed collision (paper §3.4). Binds a ZeroMQ ROUTER,
// keeps the block sets it was sent in memory (content-addressed, LRU), and answers each Query
// with its backend's pairs for the block set the Query names. The same code runs on a thread
// over inproc:// (the embedded default, local_workers.hpp) and in the spheretouch-worker daemon
// over tcp:// or ipc://. It never blocks on a send: replies to a peer that is gone or slow are
// dropped by the ROUTER, and every malformed message gets an Error reply or is dropped.
#pragma once
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>
#include <zmq.hpp>

#include "net/backend.hpp"
#include "net/curve_keys.hpp"
#include "net/protocol.hpp"

namespace st::net {

/// CURVE on the worker's socket: its secret key and the client public keys it admits (a ZAP
/// handler in the service's context checks each connecting client against the list).
struct CurveServer {
  std::string secret_z85;                        ///< the worker's secret key, Z85 (40 characters)
  std::vector<std::string> allowed_clients_z85;  ///< admitted client public keys, Z85; empty: none
};

/// What a worker is and how much it may hold.
struct WorkerConfig {
  std::uint32_t worker_id = 0;     ///< reported in Hello and Result
  std::uint32_t max_sets = 3;      ///< block sets kept in memory (LRU): own share + reassigned variants
  /// A held set not queried for this long is dropped and its memory returned to the system (the
  /// most recently used set is always kept). Reassigned variants live through a fault and go
  /// once it is over; a variant needed again is sent again. Zero: keep sets until LRU evicts them.
  std::chrono::milliseconds idle_set_ttl{30'000};
  /// Decode limits. Memory is bounded by (max_sets + 1) · max_blockset_bytes for block sets plus
  /// rcvhwm frames of at most max_chunk_bytes queued per client connection.
  Limits limits = default_limits();
  int sndhwm = 64;                 ///< messages queued per client before replies are dropped
  int rcvhwm = 32;                 ///< messages queued per client (32 × 1 MiB chunks at most)
  /// Log sink (syslog priority 3 error … 7 debug, message); empty: silent. Bad messages are
  /// summarised at most once a second so a flood cannot flood the log.
  std::function<void(int, const std::string&)> log;
  /// Encrypt and authenticate with CURVE; the service then owns its context's ZAP endpoint, so
  /// only one CURVE service per context (the daemon's case).
  std::optional<CurveServer> curve;
};

/// Counters since start (read on the service's thread, or after it stopped).
struct WorkerCounters {
  std::uint64_t queries = 0;       ///< Query messages answered with a Result
  std::uint64_t loads = 0;         ///< block sets loaded
  std::uint64_t chunks = 0;        ///< LoadBlocks messages accepted
  std::uint64_t bad_messages = 0;  ///< undecodable or misframed messages
  std::uint64_t errors_sent = 0;   ///< Error replies sent
  std::uint64_t heartbeats = 0;    ///< Heartbeats answered
  std::uint64_t refused = 0;       ///< CURVE handshakes refused (client key not allowed)
  std::uint64_t too_many_pairs = 0;  ///< queries refused at max_pairs (the traversal stopped there)
};

/// One worker; not thread-safe: construct, bind and run it on one thread.
class WorkerService {
 public:
  /// A service in `ctx` that makes one backend per loaded block set with `factory`.
  WorkerService(zmq::context_t& ctx, WorkerConfig config, BackendFactory factory);
  /// Binds the ROUTER to `endpoint` (tcp://, ipc://, inproc://); error names the endpoint.
  Status bind(const std::string& endpoint);
  /// The endpoint last bound, resolved (a tcp wildcard port becomes the real one).
  std::string last_endpoint() const;
  /// Waits up to `timeout` for messages and handles all that are waiting; false when the context
  /// is being terminated (the caller should stop).
  bool poll_once(std::chrono::milliseconds timeout);
  /// Polls until `stop` is set, calling `tick` (if any) at least every `period`.
  void run(const std::atomic<bool>& stop, std::chrono::milliseconds period = std::chrono::milliseconds(100),
           const std::function<void()>& tick = {});
  std::uint64_t epoch() const { return epoch_; }                 ///< random per instance
  const WorkerCounters& counters() const { return counters_; }   ///< counters so far
  std::vector<Held> held() const;                                ///< block sets in memory, MRU first

 private:
  struct Loaded {
    std::uint64_t hash;
    std::uint32_t faces;
    std::unique_ptr<CollisionBackend> backend;
    std::chrono::steady_clock::time_point last_used;
  };
  struct Assembly {
    std::uint64_t hash = 0, total = 0;
    std::vector<std::uint8_t> bytes;
    bool active = false;
  };
  void handle(const zmq::message_t& peer, std::span<const std::uint8_t> frame);
  void handle_zap();
  void on_load(const zmq::message_t& peer, const LoadBlocksMsg& m);
  void on_query(const zmq::message_t& peer, const QueryMsg& m);
  void send(const zmq::message_t& peer, const Message& m);
  void send_error(const zmq::message_t& peer, ErrorCode code, std::uint64_t ref, std::string text);
  HelloMsg hello(std::uint64_t echo) const;
  void log(int priority, const std::string& text) const { if (cfg_.log) cfg_.log(priority, text); }
  void note_bad(const std::string& why);
  void drop_idle_sets();  ///< at most once a second: idle_set_ttl

  WorkerConfig cfg_;
  BackendFactory factory_;
  zmq::socket_t sock_;
  zmq::socket_t zap_;             // ZAP handler (CURVE client allow-list), or empty
  std::vector<std::string> allowed_;  // admitted client public keys, 32 raw bytes each
  std::string init_error_;        // a CURVE set-up failure, reported by bind()
  std::uint64_t epoch_;
  std::list<Loaded> sets_;        // MRU first
  Assembly asm_;
  WorkerCounters counters_;
  std::vector<FacePair> pairs_;   // reused per query
  std::vector<std::uint8_t> out_; // reused encode buffer
  std::chrono::steady_clock::time_point bad_logged_{};
  std::chrono::steady_clock::time_point next_idle_check_{};
  std::uint64_t bad_unlogged_ = 0;
  // Refused client keys (raw): each is logged when first seen, then at most once a minute with a
  // count, so a client retrying with a wrong key cannot flood the log. Bounded: cleared when full.
  struct Refusal {
    std::chrono::steady_clock::time_point logged{};
    std::uint64_t unlogged = 0;
  };
  std::unordered_map<std::string, Refusal> refusals_;
};

/// Sets the socket options every spheretouch socket uses: LINGER 0, the given high-water marks,
/// ZMQ_MAXMSGSIZE = max_message_bytes (libzmq drops a peer that sends more).
void set_common_options(zmq::socket_t& s, int sndhwm, int rcvhwm, std::int64_t max_message_bytes);

}  // namespace st::net
