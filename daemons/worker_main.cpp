// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-worker: one worker of the distributed collision (paper §3.4) as a daemon. Binds a
// ZeroMQ endpoint, holds the block sets it is sent in memory and answers queries (WorkerService).
// Logs to stderr (with <N> syslog prefixes when journald reads it); under systemd it sends
// READY=1 once bound and WATCHDOG=1 pings; SIGTERM/SIGINT stop it within 0.1 s. An abort once
// it listens (libzmq asserting on a hostile peer) re-executes it in place: see AbortRestart.
#include <CLI/CLI.hpp>
#include <malloc.h>
#include <sys/prctl.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <fstream>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>
#include <zmq.hpp>
#ifdef ST_HAVE_SYSTEMD
#include <systemd/sd-daemon.h>
#endif

#include <spheretouch/net/tree_backend.hpp>
#include <spheretouch/net/worker_config.hpp>
#include <spheretouch/net/worker_service.hpp>

namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop.store(true); }

int g_max_priority = 6;
bool g_journal = false;
std::uint32_t g_id = 0;

void log_line(int priority, const std::string& text) {
  if (priority > g_max_priority) return;
  static const char* names[] = {"emerg", "alert", "crit", "error", "warning", "notice", "info", "debug"};
  if (g_journal)  // journald reads the <N> prefix as the priority; it adds its own timestamps
    std::fprintf(stderr, "<%d>worker %u: %s\n", priority, g_id, text.c_str());
  else
    std::fprintf(stderr, "spheretouch-worker %u: %s: %s\n", g_id, names[priority & 7], text.c_str());
}

/// memory.max of this process's cgroup (v2) in bytes, 0 when unlimited or unknown.
std::uint64_t cgroup_memory_max() {
  std::ifstream cg("/proc/self/cgroup");
  std::string line;
  while (std::getline(cg, line)) {
    if (line.rfind("0::", 0) != 0) continue;
    std::ifstream f("/sys/fs/cgroup" + line.substr(3) + "/memory.max");
    std::string v;
    if (!(f >> v) || v == "max") return 0;
    return std::strtoull(v.c_str(), nullptr, 10);
  }
  return 0;
}

/// Re-executes the worker in place when libzmq aborts it. libzmq 4.3's I/O thread asserts
/// (`!_io_error`, stream_engine_base.cpp) when it decodes a ZMTP PING from a connection that was
/// reset while its input was stopped (its queue to this process at rcvhwm): any peer past the
/// handshake — any local user on loopback without CURVE, an allowed client with it — can send
/// that, and no socket option avoids it while the queue is bounded (socket_options.hpp). The
/// worker then execs its own binary with the same arguments: same pid (systemd, a test or a
/// bench that started it sees no exit), a new epoch (clients reload their block sets), back to
/// listening in milliseconds. More than `max` aborts within 60 s and the abort proceeds (the
/// unit's Restart=on-failure takes over); 0 turns it off. The history crosses the exec in the
/// environment (ST_WORKER_ABORTS=count:first, CLOCK_MONOTONIC seconds).
class AbortRestart {
 public:
  static void install(char** argv, int max) {
    if (max <= 0) return;
    auto& r = self();
    r.argv_ = argv;
    r.max_ = max;
    if (const char* h = std::getenv("ST_WORKER_ABORTS")) std::sscanf(h, "%ld:%ld", &r.count_, &r.first_);
    for (char** e = ::environ; *e; ++e)
      if (std::string_view(*e).rfind("ST_WORKER_ABORTS=", 0) != 0) r.env_.push_back(*e);
    r.env_.push_back(r.history_);
    r.env_.push_back(nullptr);
    struct sigaction sa {};
    sa.sa_handler = on_abort;
    sa.sa_flags = SA_NODEFER;  // the exec'd image must not start with SIGABRT blocked
    sigemptyset(&sa.sa_mask);
    sigaction(SIGABRT, &sa, nullptr);
  }
  /// Aborts re-executed so far within the current 60 s (0 in a first start).
  static long count() { return self().count_; }

 private:
  static AbortRestart& self() {
    static AbortRestart r;
    return r;
  }
  // Async-signal-safe only: prctl, clock_gettime, write, execve (formatting by hand).
  static void on_abort(int) {
    auto& r = self();
    // Only libzmq's own threads (named "ZMQbg/..."): an abort of the worker's code (a failed
    // assertion in a checking build, std::terminate) stays what it is.
    char name[17] = {};
    if (::prctl(PR_GET_NAME, name) != 0 || std::strncmp(name, "ZMQbg/", 6) != 0) return die();
    timespec now{};
    clock_gettime(CLOCK_MONOTONIC, &now);
    long count = r.count_, first = r.first_;
    if (count == 0 || now.tv_sec - first > 60) count = 0, first = now.tv_sec;
    if (count >= r.max_) {
      say("spheretouch-worker: aborted again: more than max-abort-restarts within 60 s; exiting\n");
      return die();
    }
    char* p = r.history_ + sizeof "ST_WORKER_ABORTS=" - 1;
    p = digits(p, count + 1);
    *p++ = ':';
    *digits(p, first) = '\0';
    say("spheretouch-worker: libzmq aborted (an assertion on a hostile connection); restarting in place\n");
    execve("/proc/self/exe", r.argv_, r.env_.data());
    say("spheretouch-worker: cannot re-execute /proc/self/exe; exiting\n");
    die();
  }
  // The default action, now (SA_NODEFER: not held until the handler returns), whoever sent it.
  static void die() {
    signal(SIGABRT, SIG_DFL);
    raise(SIGABRT);
  }
  static void say(const char* m) {
    std::size_t n = 0;
    while (m[n]) ++n;
    (void)!::write(2, m, n);
  }
  static char* digits(char* p, long v) {
    char t[24];
    int n = 0;
    do t[n++] = char('0' + v % 10);
    while ((v /= 10) > 0);
    while (n) *p++ = t[--n];
    return p;
  }
  char** argv_ = nullptr;
  long max_ = 0, count_ = 0, first_ = 0;
  std::vector<char*> env_;
  char history_[64] = "ST_WORKER_ABORTS=";
};

void notify(const char* state) {
#ifdef ST_HAVE_SYSTEMD
  sd_notify(0, state);
#else
  (void)state;
#endif
}

}  // namespace

int main(int argc, char** argv) {
  {
    // Re-executed from libzmq's I/O thread (AbortRestart), this image inherits that thread's
    // signal mask, which blocks everything (SIGTERM must reach it again), and its pending
    // signals: the SIGPIPEs of its writes to reset connections, discarded by ignoring SIGPIPE
    // (every write of the worker's reports a closed peer as an error instead).
    std::signal(SIGPIPE, SIG_IGN);
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, nullptr);
  }
  // One malloc arena: block-set chunks arrive in buffers allocated by ZeroMQ's I/O thread; in a
  // per-thread arena their freed memory stays resident, in the main one malloc_trim() returns it
  // when idle sets are dropped (perf/soak.sh: worker memory flat across reassignments).
  mallopt(M_ARENA_MAX, 1);
  CLI::App app{
      "spheretouch-worker: holds sphere blocks in memory and answers collision queries "
      "(binds loopback unless told otherwise)"};
  std::string config_file, bind, log_level;
  std::int64_t worker_id = -1;
  std::string key_out;
  bool insecure = false, keygen = false, force = false;
  int max_abort_restarts = 5;
  app.add_option("--config", config_file,
                 "TOML config (bind, worker_id, log_level, insecure, max_sets, idle_set_s, max_blockset_mb, coherent, "
                 "max_sets_per_client, max_client_mb, "
                 "ipc_allowed_uids, [curve])")
      ->check(CLI::ExistingFile);
  app.add_option(
      "--bind", bind,
      "endpoint to bind: tcp://HOST:PORT or ipc://PATH (overrides the config; default tcp://127.0.0.1:5555)");
  app.add_option("--id", worker_id, "worker id (overrides the config)")->check(CLI::Range(0, 1 << 20));
  app.add_option("--log-level", log_level, "error, warning, info or debug (overrides the config)");
  app.add_option("--max-abort-restarts", max_abort_restarts,
                 "once listening, re-execute in place (same pid, a new epoch) when libzmq's I/O thread aborts (an "
                 "assertion some hostile input reaches), at most this many times within 60 s; 0: exit on it")
      ->check(CLI::Range(0, 1000));
  app.add_flag("--insecure", insecure, "allow binding a non-loopback address without CURVE (trusted networks only)");
  auto* kg = app.add_flag("--keygen", keygen,
                          "make a new CURVE key pair and exit: with --out, write PREFIX.key (mode 0600) and PREFIX.pub "
                          "(as `spheretouch keygen`); without, print 'public <Z85>' and 'secret <Z85>'");
  app.add_option("--out", key_out, "--keygen: write the pair to PREFIX.key and PREFIX.pub")->needs(kg);
  app.add_flag("--force", force, "--keygen --out: replace an existing pair")->needs(kg);
  CLI11_PARSE(app, argc, argv);
  if (keygen) {
    auto keys = st::net::generate_curve_key_pair();
    if (!keys) {
      std::fprintf(stderr, "spheretouch-worker: %s\n", keys.error().c_str());
      return 1;
    }
    if (key_out.empty()) {
      std::printf("public %s\nsecret %s\n", keys.value().public_z85.c_str(), keys.value().secret_z85.c_str());
      return 0;
    }
    if (auto s = st::net::write_key_pair(key_out, keys.value(), force); !s) {
      std::fprintf(stderr, "spheretouch-worker: %s\n", s.error().c_str());
      return 2;
    }
    const st::net::KeyFiles f = st::net::key_files(key_out);
    std::printf("wrote %s (secret key, mode 0600: keep it private)\nwrote %s (public key)\npublic key: %s\n",
                f.secret_file.c_str(), f.public_file.c_str(), keys.value().public_z85.c_str());
    return 0;
  }

  g_journal = std::getenv("JOURNAL_STREAM") != nullptr;
  st::net::DaemonConfig cfg;
  if (!config_file.empty()) {
    auto c = st::net::load_daemon_config(config_file);
    if (!c) {
      log_line(3, c.error());
      return 2;
    }
    cfg = std::move(c.value());
  }
  if (!bind.empty()) cfg.bind = bind;
  if (worker_id >= 0) cfg.worker_id = static_cast<std::uint32_t>(worker_id);
  if (!log_level.empty()) cfg.log_level = log_level;
  if (insecure) cfg.insecure = true;
  g_id = cfg.worker_id;
  if (auto s = st::net::check_daemon_config(cfg); !s) {
    log_line(3, s.error());
    return 2;
  }
  g_max_priority = st::net::log_priority(cfg.log_level);

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGINT, &sa, nullptr);

  zmq::context_t ctx(1);
  st::net::WorkerConfig wc;
  wc.worker_id = cfg.worker_id;
  wc.max_sets = cfg.max_sets;
  wc.idle_set_ttl = std::chrono::seconds(cfg.idle_set_s);
  wc.limits.max_blockset_bytes = cfg.max_blockset_mb << 20;
  wc.max_upload_bytes = wc.limits.max_blockset_bytes;  // one largest set in transit (or several smaller)
  wc.ipc_allowed_uids = cfg.ipc_allowed_uids;
  wc.log = log_line;
  wc.max_sets_per_client = cfg.max_sets_per_client;
  wc.max_client_bytes = cfg.max_client_mb << 20;
  {
    // What the limits cost (held sets, one being built, uploads, libzmq's queues) against what
    // the service's cgroup allows (systemd's MemoryMax).
    const st::net::MemoryBound b = st::net::memory_bound(wc);
    const std::string terms = std::to_string(cfg.max_sets) + " held sets " + std::to_string(long(b.held_mib)) +
                              " + one being built " + std::to_string(long(b.build_mib)) + " + uploads " +
                              std::to_string(long(b.upload_mib)) + " + queues " + std::to_string(long(b.queue_mib));
    const std::uint64_t max = cgroup_memory_max();
    const double max_mib = double(max) / double(1 << 20);
    if (max && b.total() > max_mib)
      log_line(4, "memory bound " + std::to_string(long(b.total())) + " MiB (" + terms + ") exceeds this cgroup's " +
                      "memory.max of " + std::to_string(long(max_mib)) +
                      " MiB (MemoryMax): lower max_blockset_mb or max_sets, or raise MemoryMax");
    else
      log_line(6, "memory bound: " + std::to_string(long(b.total())) + " MiB (" + terms + ")" +
                      (max ? "; memory.max " + std::to_string(long(max_mib)) + " MiB" : ""));
  }
  if (!cfg.curve_secret_key_file.empty()) {
    auto key = st::net::read_secret_key(cfg.curve_secret_key_file);
    if (!key) {
      log_line(3, key.error());
      return 2;
    }
    auto clients = st::net::allowed_client_keys(cfg);
    if (!clients) {
      log_line(3, clients.error());
      return 2;
    }
    for (const std::string& k : clients.value()) log_line(7, "allowed CURVE client " + k);
    wc.curve = st::net::CurveServer{key.value(), clients.value()};
    log_line(6, "CURVE on: public key " + st::net::curve_public_of(key.value()).value() + ", " +
                    std::to_string(clients.value().size()) + " allowed client key(s)");
    st::net::wipe_secret(key.value());
  }
  int rc = 0;
  {
    // Sphere trees + collide() (exact); the SAT reference backend stays for tests.
    auto made = st::net::WorkerService::create(
        ctx, wc, st::net::tree_backend_factory(true, st::net::kDefaultMaxCrowding, cfg.coherent));
    if (wc.curve) st::net::wipe_secret(wc.curve->secret_z85);  // the service has handed it to libzmq
    if (!made) {
      log_line(3, made.error());
      return 1;
    }
    st::net::WorkerService& svc = *made.value();
    if (auto s = svc.bind(cfg.bind); !s) {
      log_line(3, s.error());
      return 1;
    }
    const std::string ep = svc.last_endpoint();
    const bool exposed = !st::net::is_local_endpoint(cfg.bind) && !wc.curve;
    log_line(exposed ? 4 : 6, "listening on " + ep + (exposed ? " (INSECURE: no authentication)" : ""));
    if (cfg.bind.rfind("tcp://", 0) == 0 && !exposed && !wc.curve)
      log_line(5,
               "loopback TCP without CURVE: every local user can connect; bind ipc://PATH (this user only) or "
               "configure [curve] to keep other users out");
    AbortRestart::install(argv, max_abort_restarts);
    if (AbortRestart::count() > 0)
      log_line(4, "restarted in place after an abort (" + std::to_string(AbortRestart::count()) +
                      " within the last 60 s): block sets lost, a new epoch");
    notify(("READY=1\nSTATUS=listening on " + ep).c_str());

    // Watchdog: ping at a quarter of WatchdogSec; the loop wakes at least every 100 ms.
    std::chrono::microseconds wd_period{0};
#ifdef ST_HAVE_SYSTEMD
    std::uint64_t usec = 0;
    if (sd_watchdog_enabled(0, &usec) > 0) wd_period = std::chrono::microseconds(usec / 4);
#endif
    auto next_ping = std::chrono::steady_clock::now();
    const auto tick = std::chrono::milliseconds(100);
    const auto on_tick = [&] {
      if (wd_period.count() == 0) return;
      const auto now = std::chrono::steady_clock::now();
      if (now >= next_ping) {
        notify("WATCHDOG=1");
        next_ping = now + wd_period;
      }
    };
    on_tick();
    svc.run(g_stop, tick, on_tick);
    notify("STOPPING=1");
    const auto& c = svc.counters();
    log_line(6, "stopping: " + std::to_string(c.queries) + " queries, " + std::to_string(c.loads) + " loads, " +
                    std::to_string(c.bad_messages) + " bad messages" +
                    (wc.curve ? ", " + std::to_string(c.refused) + " CURVE clients refused" : std::string()));
  }
  return rc;
}
