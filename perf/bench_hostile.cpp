// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench hostile: the reproducers of the security review, replayed against a live
// worker daemon on loopback while an honest client keeps querying it. Per case: what the worker
// did with the attack (outcome: refused, answered, restarted, crashed, stalled), its resident
// memory at the peak of the case, and the honest client's round times during the attack against
// its quiet round time measured first in the same run.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <random>
#include <thread>
#include <zmq.hpp>

#include "bench.hpp"
#include "bench_json.hpp"
#include "hostile_surfaces.hpp"
#include "zmtp_attack.hpp"
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/net/block_set.hpp>
#include <spheretouch/net/protocol.hpp>
#include <spheretouch/net/scatter_gather.hpp>
#include <spheretouch/rt/shm_segment.hpp>

namespace st::bench {
namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

// Worst last: `breached` is an attack that got through (a forged pose taken, a foreign page served).
// `restarted`: the worker aborted and re-executed itself in place (same pid, a new epoch).
enum class Outcome { refused, answered, restarted, crashed, stalled, breached };
const char* outcome_name(Outcome o) {
  switch (o) {
    case Outcome::breached:
      return "breached";
    case Outcome::refused:
      return "refused";
    case Outcome::answered:
      return "answered";
    case Outcome::restarted:
      return "restarted";
    case Outcome::crashed:
      return "crashed";
    case Outcome::stalled:
      return "stalled";
  }
  return "?";
}

/// A raw attacker connection (a DEALER with its own routing id).
struct Attacker {
  zmq::socket_t d;
  Attacker(zmq::context_t& ctx, const std::string& ep, const std::string& id, int rcv_ms = 20000)
      : d(ctx, zmq::socket_type::dealer) {
    d.set(zmq::sockopt::linger, 0);
    d.set(zmq::sockopt::rcvtimeo, rcv_ms);
    d.set(zmq::sockopt::sndtimeo, rcv_ms);
    d.set(zmq::sockopt::routing_id, zmq::buffer(id));
    d.connect(ep);
  }
  bool send(const std::vector<std::uint8_t>& b) { return d.send(zmq::buffer(b), zmq::send_flags::none).has_value(); }
  /// The next reply: a message, or nothing (timeout or undecodable).
  std::optional<net::Message> recv() {
    zmq::message_t m;
    if (!d.recv(m)) return std::nullopt;
    auto r = net::decode({static_cast<const std::uint8_t*>(m.data()), m.size()}, net::DefaultLimits());
    if (!r) return std::nullopt;
    return r.value();
  }
  /// Uploads `bytes` in 1 MiB chunks.
  bool upload(const std::vector<std::uint8_t>& bytes, std::uint64_t hash) {
    for (std::size_t off = 0; off < bytes.size(); off += 1u << 20) {
      const std::size_t n = std::min<std::size_t>(1u << 20, bytes.size() - off);
      if (!send(net::encode(net::LoadBlocksMsg{hash, bytes.size(), off, {bytes.begin() + off, bytes.begin() + off + n}})))
        return false;
    }
    return true;
  }
};

bool is_error(const std::optional<net::Message>& m) { return m && std::holds_alternative<net::ErrorMsg>(*m); }
bool is_hello(const std::optional<net::Message>& m) { return m && std::holds_alternative<net::HelloMsg>(*m); }

/// The encoded block set of `probe` against `object` (every block), and its key.
struct Set {
  std::vector<std::uint8_t> bytes;
  std::uint64_t hash = 0;
};
Set encode_set(const geom::Mesh& probe, const geom::Mesh& object, std::uint32_t faces_per_block) {
  const net::Blocks blocks = net::spatial_blocks(object, faces_per_block);
  std::vector<std::uint32_t> all(blocks.size());
  for (std::uint32_t b = 0; b < all.size(); ++b) all[b] = b;
  Set s;
  s.bytes = net::encode_block_set(net::make_block_set(probe, object, blocks, all, 24).value());
  s.hash = net::block_set_hash(s.bytes);
  return s;
}

struct CaseResult {
  std::string name, what;
  Outcome outcome = Outcome::stalled;
  double worker_rss_mb = 0;                     // peak during the case
  double answer_ms_p50 = 0, answer_ms_p99 = 0;  // honest client during the attack
  std::uint32_t honest_rounds = 0, honest_incomplete = 0;
  bool restart_allowed = false;  // a known abort in libzmq the worker survives by restarting in place
  std::string note;
};

}  // namespace

void add_hostile(CLI::App& app) {
  struct Args {
    std::string worker;
    bool json = false, quick = false;
    int quiet_rounds = 300;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "hostile",
      "Replays the security review's reproducers against a live worker daemon on loopback while an honest "
      "client queries it: per case the outcome (refused, answered, crashed, stalled), the worker's peak "
      "resident memory, and the honest client's round times against its quiet ones");
  cmd->add_option("--worker", a->worker, "spheretouch-worker binary (default: beside this program, ../daemons/)");
  cmd->add_option("--quiet-rounds", a->quiet_rounds, "honest rounds for the quiet baseline")->capture_default_str();
  cmd->add_flag("--quick", a->quick, "smaller attacks (CI smoke run)");
  cmd->add_flag("--json", a->json, "print one JSON object");
  cmd->callback([a] {
    std::string worker = a->worker;
    if (worker.empty()) {
      std::error_code ec;
      const auto self = std::filesystem::read_symlink("/proc/self/exe", ec);
      worker = (self.parent_path().parent_path() / "daemons" / "spheretouch-worker").string();
    }
    if (!std::filesystem::exists(worker)) {
      std::fprintf(stderr, "hostile: worker binary %s not found (--worker)\n", worker.c_str());
      throw CLI::RuntimeError(2);
    }
    const std::string ep = "tcp://127.0.0.1:" + std::to_string(free_tcp_port());
    // Room for every case's sets (each attacker identity holds its own), so each case's attack
    // runs instead of being refused for want of a slot; cross_client_eviction fills them all.
    constexpr int kMaxSets = 12;
    char cfg_path[] = "/tmp/spheretouch-hostile-XXXXXX";
    const int cfg_fd = ::mkstemp(cfg_path);
    if (cfg_fd < 0) throw CLI::RuntimeError(2);
    const std::string cfg_text = "max_sets = " + std::to_string(kMaxSets) + "\n";
    const bool cfg_ok = ::write(cfg_fd, cfg_text.data(), cfg_text.size()) == ssize_t(cfg_text.size());
    ::close(cfg_fd);
    struct Unlink {
      const char* p;
      ~Unlink() { ::unlink(p); }
    } unlink_cfg{cfg_path};
    if (!cfg_ok) throw CLI::RuntimeError(2);
    const pid_t pid = ::fork();
    if (pid == 0) {
      ::execl(worker.c_str(), worker.c_str(), "--config", cfg_path, "--bind", ep.c_str(), "--log-level", "error",
              (char*)nullptr);
      ::_exit(127);
    }
    struct Reaper {
      pid_t p;
      ~Reaper() {
        if (p > 0) {
          ::kill(p, SIGTERM);
          int st;
          ::waitpid(p, &st, 0);
        }
      }
    } reaper{pid};
    auto alive = [&] {
      int st = 0;
      return ::waitpid(pid, &st, WNOHANG) == 0;
    };
    auto rss_mb = [&] { return double(rt::resident_bytes(pid)) / double(1 << 20); };

    // The honest client: a capsule against a sphere, one worker.
    zmq::context_t ctx(2);
    const geom::Mesh probe = geom::make_capsule(4, 10, 12), object = geom::make_icosphere(30, 8);
    net::ScatterConfig cfg;
    cfg.endpoints = {ep};
    cfg.heartbeat_period = 50ms;
    auto honest = net::ScatterGather::create(ctx, cfg, probe, object, net::spatial_blocks(object, 32));
    if (!honest || !honest.value()->wait_ready(Clock::now() + 20s)) {
      std::fprintf(stderr, "hostile: the worker at %s did not become ready\n", ep.c_str());
      throw CLI::RuntimeError(2);
    }
    geom::Pose touch = geom::Pose::Identity();
    touch.translation() = geom::Vec3(30, 0, 0);  // the capsule's centre on the sphere's surface
    std::uint64_t seq = 0;
    auto round_ms = [&](bool& complete) {
      const auto t0 = Clock::now();
      net::RoundResult r = honest.value()->round(++seq, touch, t0 + 1s);
      complete = r.complete;
      return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    };
    std::vector<double> quiet;
    for (int i = 0; i < a->quiet_rounds; ++i) {
      bool ok = false;
      quiet.push_back(round_ms(ok));
      std::this_thread::sleep_for(1ms);
    }
    const double quiet_p50 = percentile(quiet, 0.5), quiet_p99 = percentile(quiet, 0.99);
    const double rss_quiet = rss_mb();

    // One case: the attack runs on its own thread, repeated until its window is over (an attack
    // that ends sooner is sent again); the honest client queries only while it runs, so every
    // honest round counted is one inside the attack window; memory is sampled all along.
    std::vector<CaseResult> results;
    const auto window = a->quick ? 1500ms : 3000ms;
    auto run_case = [&](const std::string& name, const std::string& what, const std::function<Outcome()>& attack,
                        bool repeat = true, bool restart_allowed = false) {
      std::fprintf(stderr, "hostile: %s\n", name.c_str());
      CaseResult c;
      c.name = name;
      c.what = what;
      std::atomic<bool> done{false};
      Outcome out = Outcome::stalled;
      const auto until = Clock::now() + window;
      std::thread t([&] {
        int runs = 0;
        do {
          const Outcome o = attack();
          // The worst outcome of the repeats: crashed > stalled > answered > refused.
          if (runs++ == 0 || int(o) > int(out)) out = o;
        } while (repeat && Clock::now() < until && out != Outcome::stalled && out != Outcome::crashed);
        done = true;
      });
      std::vector<double> during;
      double peak = rss_mb();
      const auto give_up = Clock::now() + 120s;
      while (!done && Clock::now() < give_up && alive()) {
        bool ok = false;
        during.push_back(round_ms(ok));
        c.honest_incomplete += !ok;
        peak = std::max(peak, rss_mb());
        std::this_thread::sleep_for(1ms);
      }
      if (!done && Clock::now() >= give_up) c.note = "attack still running after 120 s";
      t.join();
      peak = std::max(peak, rss_mb());
      c.outcome = alive() ? out : Outcome::crashed;
      // After a restart the honest client reloads its set: its rounds meanwhile are incomplete.
      if (c.outcome != Outcome::crashed && c.outcome != Outcome::restarted && c.honest_incomplete * 10 > during.size())
        c.outcome = Outcome::stalled;
      c.restart_allowed = restart_allowed;
      c.worker_rss_mb = peak;
      c.honest_rounds = static_cast<std::uint32_t>(during.size());
      c.answer_ms_p50 = percentile(during, 0.5);
      c.answer_ms_p99 = percentile(during, 0.99);
      results.push_back(c);
    };

    // The piles: uploaded once by their attacker, then queried over and over during the window.
    const int pile_faces = a->quick ? 2500 : 4000;
    auto pile_set = [&](bool touching) {
      geom::Mesh flat, other;
      flat.name = "flat pile";
      flat.local = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}};
      flat.faces.assign(std::size_t(pile_faces), geom::Tri{0, 1, 2});
      other = flat;
      if (!touching) {  // upright, boxes overlapping the flat one's, never touching it
        other.name = "upright pile";
        other.local = {{9, 9, -1}, {9, 9, 1}, {12, 6, 0}};
      }
      net::Blocks one(1);
      for (std::uint32_t f = 0; f < std::uint32_t(pile_faces); ++f) one[0].push_back(f);
      Set set;
      set.bytes = net::encode_block_set(net::make_block_set(flat, other, one, std::vector<std::uint32_t>{0}, 24).value());
      set.hash = net::block_set_hash(set.bytes);
      return set;
    };
    const Set pairs_pile = pile_set(true), no_pairs_pile = pile_set(false);
    geom::Pose shifted = geom::Pose::Identity();
    shifted.translation() = geom::Vec3(1, 1, 0);  // the touching pile: every pair collides
    // One attacker identity per pile; `pipeline` Queries sent before the replies are read.
    auto pile_attack = [&](const std::string& id, const Set& set, const geom::Pose& pose, int pipeline) {
      return [&, id, pose, pipeline] {
        zmq::context_t c(1);
        Attacker x(c, ep, id);
        if (!x.upload(set.bytes, set.hash)) return Outcome::stalled;
        const auto loaded = x.recv();
        if (is_error(loaded)) return Outcome::refused;  // refused at load (too crowded)
        if (!is_hello(loaded)) return Outcome::stalled;
        Outcome worst = Outcome::refused;
        const auto until = Clock::now() + window;
        for (std::uint64_t aseq = 1; Clock::now() < until;) {
          for (int k = 0; k < pipeline; ++k) x.send(net::encode(net::QueryMsg{aseq++, set.hash, pose, {}}));
          // Only the newest of a burst is answered (the others are superseded): one reply a burst.
          const auto r = x.recv();
          if (!r) return Outcome::stalled;
          if (!is_error(r)) worst = Outcome::answered;
        }
        return worst;
      };
    };
    run_case("pile_n2_pairs",
             std::to_string(pile_faces) + " identical triangles on each side: queries of " +
                 std::to_string(pile_faces) + "^2 pairs, one at a time (item 1)",
             pile_attack("attacker-pile", pairs_pile, shifted, 1), false);
    run_case("pile_no_pairs",
             std::to_string(pile_faces) + " triangles on each side whose boxes overlap but never touch: " +
                 std::to_string(pile_faces) + "^2 tests and no pair (item 1)",
             pile_attack("attacker-nopairs", no_pairs_pile, geom::Pose::Identity(), 1), false);
    run_case(
        "pipelined_piles", "4 identities, each sending bursts of 32 pile queries without waiting (both piles; item 1)",
        [&] {
          std::vector<std::thread> ts;
          std::vector<Outcome> outs(4, Outcome::refused);
          for (int k = 0; k < 4; ++k)
            ts.emplace_back([&, k] {
              outs[std::size_t(k)] = pile_attack("attacker-pipe-" + std::to_string(k), k % 2 ? no_pairs_pile : pairs_pile,
                                                 k % 2 ? geom::Pose::Identity() : shifted, 32)();
            });
          for (auto& t : ts) t.join();
          return *std::max_element(outs.begin(), outs.end(), [](Outcome x, Outcome y) { return int(x) < int(y); });
        },
        false);
    run_case(
        "upload_trickle",
        "4 identities each holding an upload slot with a byte every 400 ms while another client loads a set "
        "(item 4)",
        [&] {
          zmq::context_t c(1);
          std::vector<std::unique_ptr<Attacker>> xs;
          for (int k = 0; k < 4; ++k) {
            xs.push_back(std::make_unique<Attacker>(c, ep, "trickler-" + std::to_string(k), 3000));
            xs.back()->send(net::encode(net::LoadBlocksMsg{900u + unsigned(k), 1u << 20, 0, {1}}));
          }
          std::this_thread::sleep_for(400ms);
          for (int k = 0; k < 4; ++k)  // one more byte each: every slot looks alive
            xs[std::size_t(k)]->send(net::encode(net::LoadBlocksMsg{900u + unsigned(k), 1u << 20, 1, {2}}));
          std::this_thread::sleep_for(800ms);  // past upload_stall (1 s) since their first byte
          Attacker loader(c, ep, "second-honest", 20000);
          const Set s2 = encode_set(geom::make_capsule(3, 8, 10), geom::make_icosphere(25, 10), 32);
          if (!loader.upload(s2.bytes, s2.hash)) return Outcome::stalled;
          for (int i = 0; i < 4; ++i) {  // its Hello (the tricklers' errors go to them)
            const auto r = loader.recv();
            if (!r) return Outcome::stalled;
            if (auto* hm = std::get_if<net::HelloMsg>(&*r))
              if (std::any_of(hm->held.begin(), hm->held.end(), [&](const net::Held& h) { return h.hash == s2.hash; }))
                return Outcome::refused;                // the slots were not held: the honest load went through
            if (is_error(r)) return Outcome::answered;  // told busy: the trickling worked
          }
          return Outcome::stalled;
        },
        false);
    const int freq = a->quick ? 120 : 300;
    double set_factor = 0, set_mb = 0;
    run_case(
        "large_legal_load",
        "a legal block set of " + std::to_string(20 * freq * freq) + " faces built while others query (item 3)",
        [&] {
          zmq::context_t c(1);
          Attacker x(c, ep, "big-loader", 120000);
          const Set s = encode_set(geom::make_capsule(4, 10, 12), geom::make_icosphere(40, freq), 64);
          const double before = rss_mb();
          if (!x.upload(s.bytes, s.hash)) return Outcome::stalled;
          // Heartbeats are answered during the build: the first Hello echoes the nonce, the last
          // reports the set.
          x.send(net::encode(net::HeartbeatMsg{77}));
          bool echoed = false, loaded = false;
          for (int i = 0; i < 4 && !loaded; ++i) {
            const auto r = x.recv();
            if (!r) break;
            if (is_error(r)) return Outcome::refused;
            if (auto* hm = std::get_if<net::HelloMsg>(&*r)) {
              echoed |= hm->echo == 77;
              loaded |=
                  std::any_of(hm->held.begin(), hm->held.end(), [&](const net::Held& h) { return h.hash == s.hash; });
            }
          }
          // What a held set costs: the worker's growth per byte of the encoding (the upload buffer
          // is freed before the build; what malloc keeps of it counts too).
          std::this_thread::sleep_for(200ms);
          set_factor = (rss_mb() - before) / (double(s.bytes.size()) / double(1 << 20));
          set_mb = double(s.bytes.size()) / double(1 << 20);
          return echoed && loaded ? Outcome::answered : Outcome::stalled;
        },
        false);
    results.back().note += (results.back().note.empty() ? "" : "; ") + std::string("set of ") +
                           std::to_string(set_mb).substr(0, 5) + " MiB encoded: worker grew " +
                           std::to_string(set_factor).substr(0, 4) + "x that";

    if (!a->quick) {  // 12 s of waiting; the upload timeout has its own test (worker_service_test)
      run_case(
          "abandoned_load",
          "first 1 MiB chunk of a 1 GiB set, then silence; continued after the upload timeout "
          "(item 4)",
          [&] {
            zmq::context_t c(1);
            Attacker x(c, ep, "abandoner");
            std::vector<std::uint8_t> chunk(1u << 20, 0x5a);
            x.send(net::encode(net::LoadBlocksMsg{42, 1ull << 30, 0, chunk}));
            std::this_thread::sleep_for(12s);  // the worker's upload_timeout is 10 s
            x.send(net::encode(net::LoadBlocksMsg{42, 1ull << 30, 1u << 20, chunk}));
            const auto r = x.recv();
            return is_error(r) ? Outcome::refused : Outcome::stalled;
          },
          false);
    }

    const int conns = 20, per_conn = a->quick ? 8 : 32;
    run_case(
        "connection_flood",
        std::to_string(conns) + " connections x " + std::to_string(per_conn) +
            " chunks of 1 MiB claiming 1 GiB sets (item 4)",
        [&] {
          zmq::context_t c(1);
          std::vector<std::unique_ptr<Attacker>> xs;
          for (int i = 0; i < conns; ++i) xs.push_back(std::make_unique<Attacker>(c, ep, "flood-" + std::to_string(i)));
          std::vector<std::uint8_t> chunk(1u << 20, 0x33);
          for (int k = 0; k < per_conn; ++k)
            for (int i = 0; i < conns; ++i)
              xs[std::size_t(i)]->send(
                  net::encode(net::LoadBlocksMsg{100u + unsigned(i), 1ull << 30, std::uint64_t(k) << 20, chunk}));
          int refused = 0;
          for (auto& x : xs) {
            x->d.set(zmq::sockopt::rcvtimeo, 3000);
            refused += is_error(x->recv());
          }
          return refused > 0 ? Outcome::refused : Outcome::answered;
        },
        false);

    run_case("foreign_set",
             "another client queries the honest client's set and sends chunks of it out of order "
             "(item 5)",
             [&] {
               zmq::context_t c(1);
               Attacker x(c, ep, "snooper");
               // The key the honest client uses is public in any capture (and here recomputed from the
               // same scene); knowing it is not enough.
               const Set s = encode_set(probe, object, 32);
               x.send(net::encode(net::QueryMsg{5, s.hash, touch, {}}));
               const auto r = x.recv();     // NotLoaded ...
               const auto list = x.recv();  // ... and the Hello after it: the sets this client may see
               const bool hidden = is_hello(list) && std::get<net::HelloMsg>(*list).held.empty();
               x.send(net::encode(net::LoadBlocksMsg{s.hash, s.bytes.size(), 4096, {1, 2, 3}}));
               const auto r2 = x.recv();  // out of order: its own (absent) upload only
               return is_error(r) && hidden && is_error(r2) ? Outcome::refused : Outcome::answered;
             });

    run_case("garbage_flood", "20,000 random frames of 1-300 bytes on one connection", [&] {
      zmq::context_t c(1);
      Attacker x(c, ep, "garbage");
      std::mt19937_64 rng(7);
      for (int i = 0; i < 20000; ++i) {
        std::vector<std::uint8_t> g(1 + rng() % 300);
        for (auto& b : g) b = static_cast<std::uint8_t>(rng());
        (void)x.d.send(zmq::buffer(g), zmq::send_flags::dontwait);
      }
      // The worker answers the first bad frames and shuts the connection down at the 8th
      // (kMaxBadPerConnection); a new connection is served.
      const bool told = is_error(x.recv());
      Attacker y(c, ep, "garbage-check");
      y.send(net::encode(net::HeartbeatMsg{9}));
      const auto r = y.recv();
      const auto* hm = r ? std::get_if<net::HelloMsg>(&*r) : nullptr;
      return told && hm && hm->echo == 9 ? Outcome::refused : Outcome::stalled;
    });

    run_case("oversized_frame", "one 80 MiB frame (over ZMQ_MAXMSGSIZE)", [&] {
      zmq::context_t c(1);
      Attacker x(c, ep, "big-frame", 3000);
      std::vector<std::uint8_t> big(80u << 20, 0);
      x.send(big);
      return x.recv() ? Outcome::answered : Outcome::refused;  // dropped with the connection
    });

    // The run's other surfaces (items 2, 3), while the honest worker client keeps querying.
    auto surface = [&](const std::string& name, const std::string& what, const std::function<SurfaceOutcome()>& f) {
      SurfaceOutcome so;
      run_case(
          name, what,
          [&] {
            so = f();
            return so.refused ? Outcome::refused : Outcome::breached;
          },
          false);
      results.back().note += (results.back().note.empty() ? "" : "; ") + so.note;
    };
    surface("forged_udp",
            "forged pose datagrams from the UDP driver's own socket (unsigned v1, wrong key, seq 2^64-1) while it "
            "drives at 1 kHz (item 2)",
            [&] { return forged_udp(window); });
    {
      ViewFixture view;
      surface("foreign_origin_ws", "WebSocket handshakes from another site, a rebound host name, no token (item 3)",
              [&] { return view.foreign_origin(window); });
      surface("stalled_page", "one page stops reading the largest frames while another reads (item 3)",
              [&] { return view.stalled_page(window); });
    }

    // Last but one: it fills every set slot, so a later case could not load.
    run_case(
        "cross_client_eviction",
        std::to_string(kMaxSets + 2) +
            " identities each loading a small set of their own and querying it, to push the honest client's "
            "set out (item 4)",
        [&] {
          zmq::context_t c(1);
          int loaded = 0, refused = 0;
          std::vector<std::unique_ptr<Attacker>> xs;
          for (int k = 0; k < kMaxSets + 2; ++k) {
            xs.push_back(std::make_unique<Attacker>(c, ep, "evictor-" + std::to_string(k), 20000));
            Attacker& x = *xs.back();
            const Set sk = encode_set(geom::make_capsule(3, 8, 10), geom::make_icosphere(20, 4 + k), 32);
            if (!x.upload(sk.bytes, sk.hash)) return Outcome::stalled;
            const auto r = x.recv();
            if (!r) return Outcome::stalled;
            loaded += is_hello(r);
            refused += is_error(r);
            if (is_hello(r)) {  // in use: a set only loaded would be fair game for others
              x.send(net::encode(net::QueryMsg{1, sk.hash, geom::Pose::Identity(), {}}));
              if (!x.recv()) return Outcome::stalled;
            }
          }
          // The honest set must survive: its rounds are counted (incomplete ones make this case
          // "stalled"); the evictors fill the free slots, then are told the worker is full.
          return refused > 0 ? Outcome::refused : Outcome::answered;
        },
        false);

    // After every other case: the worker it aborts comes back without the sets they loaded.
    run_case(
        "ping_after_reset",
        "raw ZMTP connections that queue frames and PINGs past rcvhwm, then reset (libzmq 4.3 aborts on the "
        "PING it decodes after the reset; the worker re-executes itself in place)",
        [&] {
          zmq::context_t c(1);
          auto epoch = [&] {
            Attacker x(c, ep, "epoch-check", 5000);
            x.send(net::encode(net::HeartbeatMsg{17}));
            const auto r = x.recv();
            const auto* hm = r ? std::get_if<net::HelloMsg>(&*r) : nullptr;
            return hm && hm->echo == 17 ? std::optional<std::uint64_t>(hm->epoch) : std::nullopt;
          };
          const auto before = epoch();
          if (!before) return Outcome::stalled;
          const int port = std::stoi(ep.substr(ep.rfind(':') + 1));
          for (int k = 0; k < 20; ++k) {
            (void)ping_after_reset(port, 4000);
            const auto now = epoch();
            if (!now) return Outcome::crashed;  // not serving 5 s later
            if (*now != *before) return Outcome::restarted;
          }
          return Outcome::refused;  // 20 resets survived in place (a libzmq without the fault)
        },
        false, true);
    if (results.back().outcome == Outcome::restarted) {  // the honest client must get its set back in
      const auto t0 = Clock::now();
      bool complete = false;
      while (!complete && Clock::now() - t0 < 20s) (void)round_ms(complete);
      const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
      if (!complete) results.back().outcome = Outcome::stalled;
      results.back().note = complete ? "the honest client complete again " + std::to_string(long(ms)) + " ms later"
                                     : "the honest client not complete 20 s later";
    }

    // The target (#32): every case refused or answered (restarted where the case says it may be:
    // a libzmq abort the worker survives in place), and the honest client inside every attack
    // window at p50 < 2x its quiet p50 and p99 < 50 ms.
    bool all_ok = true, honest_ok = true;
    auto within = [&](const CaseResult& c) { return c.answer_ms_p50 < 2 * quiet_p50 && c.answer_ms_p99 < 50; };
    for (const CaseResult& c : results) {
      all_ok &= (c.outcome == Outcome::refused || c.outcome == Outcome::answered ||
                 (c.outcome == Outcome::restarted && c.restart_allowed));
      if (c.outcome != Outcome::restarted) honest_ok &= within(c);
    }
    if (a->json) {
      Json cases = Json::array();
      for (const CaseResult& c : results)
        cases.push_back({{"case", c.name},
                         {"outcome", outcome_name(c.outcome)},
                         {"worker_rss_mb", round_to(c.worker_rss_mb, 1)},
                         {"answer_ms", round_to(c.answer_ms_p50, 4)},
                         {"answer_ms_p99", round_to(c.answer_ms_p99, 4)},
                         {"vs_quiet_p50", round_to(c.answer_ms_p50 / quiet_p50, 2)},
                         {"honest_rounds", c.honest_rounds},
                         {"honest_within_target", within(c)},
                         {"note", c.note},
                         {"honest_incomplete", c.honest_incomplete}});
      print_json({{"worker", ep},
                  {"quiet_ms_p50", round_to(quiet_p50, 4)},
                  {"quiet_ms_p99", round_to(quiet_p99, 4)},
                  {"quiet_rss_mb", round_to(rss_quiet, 1)},
                  {"cases", std::move(cases)},
                  {"set_memory_factor", round_to(set_factor, 2)},
                  {"attack_window_ms", std::chrono::duration<double, std::milli>(window).count()},
                  {"all_refused_or_answered", all_ok},
                  {"honest_within_target", honest_ok}});
    } else {
      std::printf("honest client, quiet: round %.3f ms p50, %.3f ms p99; worker RSS %.1f MiB\n\n", quiet_p50, quiet_p99,
                  rss_quiet);
      std::printf("%-18s %-9s %10s %10s %10s %8s %7s  %s\n", "case", "outcome", "rss_MiB", "answer_ms", "p99_ms",
                  "x_quiet", "rounds", "attack");
      for (const CaseResult& c : results)
        std::printf("%-18s %-9s %10.1f %10.3f %10.3f %8.2f %7u  %s%s%s\n", c.name.c_str(), outcome_name(c.outcome),
                    c.worker_rss_mb, c.answer_ms_p50, c.answer_ms_p99, c.answer_ms_p50 / quiet_p50, c.honest_rounds,
                    c.what.c_str(), c.note.empty() ? "" : "; ", c.note.c_str());
      std::printf(
          "\nanswer_ms: the honest client's round time during the attack (p50; x_quiet = against its quiet p50)\n");
    }
    if (!all_ok) throw CLI::RuntimeError(1);
  });
}

}  // namespace st::bench
