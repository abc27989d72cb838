// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench scatter: round trip of an empty query through N workers (scatter-gather
// overhead), over inproc, ipc or tcp loopback. Rounds are spaced like the collision loop spaces
// them (--gap-us between the end of one round and the start of the next): ZeroMQ latency rises
// when sends are spaced out (wake-ups from idle), so back-to-back bursts would flatter it.
// Three references, measured in the same run, spaced the same way and alternating with it in
// blocks of 100 rounds:
//  * baseline: one plain request-reply (Heartbeat -> Hello) with worker 0 over the same transport;
//  * floor: the same N-way fan-out and gather done with raw ZeroMQ sockets (N ROUTER echo
//    threads, one 8-byte frame each), i.e. what the machine and libzmq cost before any of ours;
//  * sized floor: the same raw fan-out with frames of our messages' sizes (the encoded Query out,
//    an empty Result back): what carrying a pose and an answer costs before any of ours (libzmq
//    keeps frames of up to 33 bytes inside the message and allocates larger ones).
// And a split of the overhead, alternating with them: the floor's raw client sending our encoded
// Query to our workers (split - sized floor, the same bytes both ways: what our workers add;
// ours - split: what our client adds).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <cstdio>
#include <fstream>
#include <map>
#include <string>
#include <thread>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

#include "bench.hpp"
#include "bench_json.hpp"
#include "fanout_floor.hpp"
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/net/local_workers.hpp>
#include <spheretouch/net/scatter_gather.hpp>
#include <spheretouch/net/tree_backend.hpp>

namespace st::bench {

namespace {

using Clock = std::chrono::steady_clock;

struct Stats {
  double p50 = 0, p99 = 0, max = 0, mean = 0;
};

Stats summarise(std::vector<double> us) {
  Stats s;
  if (us.empty()) return s;
  std::sort(us.begin(), us.end());
  auto at = [&](double q) { return us[std::min(us.size() - 1, static_cast<std::size_t>(q * double(us.size())))]; };
  s.p50 = at(0.50);
  s.p99 = at(0.99);
  s.max = us.back();
  for (double v : us) s.mean += v;
  s.mean /= double(us.size());
  return s;
}

}  // namespace

int free_tcp_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  ::close(fd);
  return ntohs(addr.sin_port);
}

/// The hidden `echo` subcommand: one raw ROUTER echo in its own process (the floor of
/// `scatter --spawn`), until SIGTERM.
void add_echo(CLI::App& app) {
  auto bind = std::make_shared<std::string>();
  auto reply_bytes = std::make_shared<std::size_t>(8);
  CLI::App* cmd = app.add_subcommand("echo", "raw ZeroMQ echo process: scatter --spawn's floor")->group("");
  cmd->add_option("--bind", *bind, "endpoint")->required();
  cmd->add_option("--reply-bytes", *reply_bytes, "bytes of each reply (at least 8)")->check(CLI::Range(8, 1 << 20));
  cmd->callback([bind, reply_bytes] {
    zmq::context_t ctx(1);
    zmq::socket_t s(ctx, zmq::socket_type::router);
    s.set(zmq::sockopt::linger, 0);
    s.bind(*bind);
    std::vector<std::uint8_t> reply(*reply_bytes, 0);
    for (;;) {
      zmq::pollitem_t it{s.handle(), 0, ZMQ_POLLIN, 0};
      if (zmq::poll(&it, 1, std::chrono::milliseconds(20)) > 0) echo_pending(s, reply);
    }
  });
}

void add_scatter(CLI::App& app) {
  struct Args {
    int workers = 4;
    std::string transport = "tcp";
    int rounds = 5000;
    int warmup = 200;
    int gap_us = 1000;
    int deadline_ms = 50;
    int spin_us = 0;
    bool json = false;
    std::string csv;
    std::string spawn;         // worker daemon binary: run workers as processes (tcp/ipc)
    bool own_context = false;  // threads, but each worker with its own ZeroMQ context (I/O thread)
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "scatter", "Round trip of an empty query through N workers (scatter-gather overhead), p50/p99");
  cmd->add_option("--workers", a->workers, "workers (threads of this process)")->check(CLI::Range(1, 64))->capture_default_str();
  cmd->add_option("--transport", a->transport, "inproc, ipc or tcp (loopback)")
      ->check(CLI::IsMember({"inproc", "ipc", "tcp"}))
      ->capture_default_str();
  cmd->add_option("--rounds", a->rounds, "measured rounds")->check(CLI::Range(10, 10000000))->capture_default_str();
  cmd->add_option("--warmup", a->warmup, "unmeasured rounds first")->check(CLI::Range(0, 1000000))->capture_default_str();
  cmd->add_option("--gap-us", a->gap_us, "idle time between rounds, us (the collision loop's own work)")
      ->check(CLI::Range(0, 1000000))
      ->capture_default_str();
  cmd->add_option("--deadline-ms", a->deadline_ms, "round deadline, ms")->check(CLI::Range(1, 10000))->capture_default_str();
  cmd->add_option("--spin-us", a->spin_us, "client busy-polls this long before blocking (ScatterConfig::spin_us)")
      ->capture_default_str();
  cmd->add_flag("--json", a->json, "print one JSON object");
  cmd->add_option("--spawn", a->spawn, "run the workers as processes of this spheretouch-worker binary (tcp/ipc)");
  cmd->add_flag("--own-context", a->own_context, "worker threads each get their own ZeroMQ context, as processes would");
  cmd->add_option("--csv", a->csv, "append one CSV row to this file (header written if new)");
  cmd->callback([a] {
    zmq::context_t ctx(1);
    // A tiny object far from the probe: every query is empty, the backend does almost nothing,
    // so the round trip is the scatter-gather overhead.
    const geom::Mesh probe = geom::make_capsule(4, 10, 8);
    const geom::Mesh object = geom::make_icosphere(20, 2);
    const net::Blocks blocks = net::spatial_blocks(object, 1);  // 80 blocks: every worker holds some
    std::vector<std::unique_ptr<zmq::context_t>> wctx;
    std::vector<std::unique_ptr<net::LocalWorkers>> local;
    std::vector<pid_t> procs;
    std::vector<std::string> endpoints, echo_endpoints, sized_echo_endpoints;
    // The sized floor's frames: our Query (no skip, no take, as this bench sends) and an empty
    // Result, as encoded (their sizes do not depend on the values).
    const std::size_t query_bytes = net::encode(net::QueryMsg{}).size();
    const std::size_t result_bytes = net::encode(net::ResultMsg{}).size();
    if (!a->spawn.empty()) {
      if (a->transport == "inproc") {
        std::fprintf(stderr, "--spawn needs tcp or ipc\n");
        throw CLI::RuntimeError(2);
      }
      for (int i = 0; i < a->workers; ++i) {
        std::string ep =
            a->transport == "ipc" ? endpoint_for("ipc", i) : "tcp://127.0.0.1:" + std::to_string(free_tcp_port());
        const pid_t pid = ::fork();
        if (pid == 0) {
          const std::string id = std::to_string(i);
          ::execl(a->spawn.c_str(), a->spawn.c_str(), "--bind", ep.c_str(), "--id", id.c_str(), "--log-level",
                  "warning", (char*)nullptr);
          ::_exit(127);
        }
        procs.push_back(pid);
        endpoints.push_back(ep);
      }
      // The floor's echoes as processes too (this binary's hidden `echo` subcommand): a round to
      // daemons crosses processes, each with its own ZeroMQ I/O thread, which echo threads of this
      // process would not.
      for (const std::size_t reply : {std::size_t{8}, result_bytes})
        for (int i = 0; i < a->workers; ++i) {
          const std::string tag = reply == 8 ? "floor" : "sized-floor";
          std::string ep = a->transport == "ipc" ? endpoint_for("ipc", i, tag)
                                                 : "tcp://127.0.0.1:" + std::to_string(free_tcp_port());
          const std::string bytes = std::to_string(reply);
          const pid_t pid = ::fork();
          if (pid == 0) {
            ::execl("/proc/self/exe", "spheretouch-bench", "echo", "--bind", ep.c_str(), "--reply-bytes", bytes.c_str(),
                    (char*)nullptr);
            ::_exit(127);
          }
          procs.push_back(pid);
          (reply == 8 ? echo_endpoints : sized_echo_endpoints).push_back(ep);
        }
    } else {
      for (int i = 0; i < a->workers; ++i) {
        zmq::context_t* wc = &ctx;
        if (a->own_context) {
          wctx.push_back(std::make_unique<zmq::context_t>(1));
          wc = wctx.back().get();
        }
        const std::string ep = endpoint_for(a->own_context && a->transport == "inproc" ? "tcp" : a->transport, i);
        // The backend the worker daemon runs (tree_backend_factory()'s defaults, as
        // spheretouch-worker's): on the far probe, a sphere test per root.
        auto w = net::LocalWorkers::start(*wc, 1, net::tree_backend_factory(), [&](int) { return ep; });
        if (!w) {
          std::fprintf(stderr, "%s\n", w.error().c_str());
          throw CLI::RuntimeError(2);
        }
        endpoints.push_back(w.value()->endpoints()[0]);
        local.push_back(std::move(w.value()));
      }
    }
    struct Reaper {
      std::vector<pid_t>& p;
      ~Reaper() {
        for (pid_t x : p) {
          ::kill(x, SIGTERM);
          int st;
          ::waitpid(x, &st, 0);
        }
      }
    } reaper{procs};
    net::ScatterConfig cfg;
    cfg.endpoints = endpoints;
    cfg.spin_us = static_cast<std::uint32_t>(a->spin_us);
    auto c = net::ScatterGather::create(ctx, cfg, probe, object, blocks);
    if (!c) {
      std::fprintf(stderr, "%s\n", c.error().c_str());
      throw CLI::RuntimeError(2);
    }
    if (!c.value()->wait_ready(Clock::now() + std::chrono::seconds(10))) {
      std::fprintf(stderr, "workers not ready after 10 s\n");
      throw CLI::RuntimeError(2);
    }
    geom::Pose far = geom::Pose::Identity();
    far.translation() = geom::Vec3(1000, 0, 0);
    const auto gap = std::chrono::microseconds(a->gap_us);
    const auto deadline = std::chrono::milliseconds(a->deadline_ms);

    // The three variants alternate in blocks of kBlock rounds, so a change of machine load
    // (this is a shared 2-vCPU VM) hits all of them alike.
    int incomplete = 0;
    net::RoundResult r;
    std::uint64_t seq = 0;
    auto scatter_round = [&](bool measured) {
      c.value()->round(++seq, far, Clock::now() + deadline, r);
      if (measured) incomplete += !r.complete;
      return true;
    };

    // Baseline: one plain request-reply (Heartbeat -> Hello) with worker 0.
    zmq::socket_t d(ctx, zmq::socket_type::dealer);
    d.set(zmq::sockopt::linger, 0);
    d.connect(endpoints[0]);
    const auto hb = net::encode(net::HeartbeatMsg{1});
    auto baseline_round = [&](bool) {
      d.send(zmq::buffer(hb), zmq::send_flags::none);
      zmq::message_t m;
      zmq::pollitem_t it{d.handle(), 0, ZMQ_POLLIN, 0};
      return zmq::poll(&it, 1, deadline) > 0 && d.recv(m, zmq::recv_flags::dontwait).has_value();
    };

    // Split: raw DEALERs (the floor's client) sending our pre-encoded Query to our workers and
    // waiting for their Results undecoded. Against the sized floor it is what our workers add; against
    // our rounds, what our client adds. It queries block sets a second client (routing id
    // "split") loaded and left on the workers.
    std::vector<zmq::socket_t> raw;
    std::vector<std::vector<std::uint8_t>> raw_query;
    {
      net::ScatterConfig scfg = cfg;
      scfg.routing_id = "bench-split-client";
      auto loader = net::ScatterGather::create(ctx, scfg, probe, object, blocks);
      if (!loader || !loader.value()->wait_ready(Clock::now() + std::chrono::seconds(10))) {
        std::fprintf(stderr, "split client: workers not ready\n");
        throw CLI::RuntimeError(2);
      }
    }
    for (const std::string& ep : endpoints) {
      zmq::socket_t s(ctx, zmq::socket_type::dealer);
      s.set(zmq::sockopt::linger, 0);
      s.set(zmq::sockopt::routing_id, "bench-split-client");
      s.connect(ep);
      s.send(zmq::buffer(net::encode(net::HeartbeatMsg{7})), zmq::send_flags::none);
      std::uint64_t hash = 0;
      for (int tries = 0; tries < 100 && !hash; ++tries) {
        zmq::pollitem_t it{s.handle(), 0, ZMQ_POLLIN, 0};
        zmq::message_t m;
        if (zmq::poll(&it, 1, std::chrono::milliseconds(100)) <= 0 || !s.recv(m, zmq::recv_flags::dontwait)) continue;
        auto reply = net::decode({static_cast<const std::uint8_t*>(m.data()), m.size()}, net::DefaultLimits());
        if (reply)
          if (const auto* h = std::get_if<net::HelloMsg>(&reply.value()); h && !h->held.empty()) hash = h->held[0].hash;
      }
      if (!hash) {
        std::fprintf(stderr, "split client: %s holds no set for it\n", ep.c_str());
        throw CLI::RuntimeError(2);
      }
      raw_query.push_back(net::encode(net::QueryMsg{0, hash, far, {}}));
      raw.push_back(std::move(s));
    }
    std::uint64_t raw_seq = 1u << 30;
    AwaitReplies raw_wait;
    auto split_round = [&](bool) {  // the floor's client, our Query
      ++raw_seq;
      for (std::size_t i = 0; i < raw.size(); ++i) {
        std::memcpy(raw_query[i].data() + net::kHeaderBytes, &raw_seq, sizeof raw_seq);  // the Query's seq
        raw[i].send(zmq::buffer(raw_query[i]), zmq::send_flags::dontwait);
      }
      // A Result's seq follows the header, as a Query's does.
      return raw_wait.all(raw, raw_seq, net::kHeaderBytes, Clock::now() + deadline);
    };

    // Floor: the same fan-out with nothing of ours in it: N raw ROUTER echo threads on the same
    // transport and context, and N DEALERs sending one 8-byte frame each and waiting for all N
    // echoes. No ZeroMQ scatter-gather to N separate workers can be cheaper on this machine.
    // The sized floor: the same, its frames as large as our Query and Result.
    // Either kind: echo threads of this process, or the echo processes of --spawn at `echoes`.
    struct Floor {
      std::unique_ptr<FanOutFloor> threads;
      std::unique_ptr<FanOutGather> procs;
      std::size_t query_bytes = 8;
      bool round(std::chrono::milliseconds d) {
        return threads ? threads->round(d, query_bytes) : procs->round(d, query_bytes);
      }
    };
    auto make_floor = [&](const std::vector<std::string>& echoes, std::size_t query, std::size_t reply) {
      Floor f;
      f.query_bytes = query;
      if (echoes.empty())
        f.threads = std::make_unique<FanOutFloor>(ctx, a->transport, a->workers, reply);
      else
        f.procs = std::make_unique<FanOutGather>(ctx, echoes);
      return f;
    };
    Floor floor8 = make_floor(echo_endpoints, 8, 8),
          sized_floor = make_floor(sized_echo_endpoints, query_bytes, result_bytes);
    auto floor_round = [&](bool) { return floor8.round(deadline); };
    auto sized_round = [&](bool) { return sized_floor.round(deadline); };

    std::vector<double> us, base, flo, sized, split;
    int lost = 0;  // baseline or floor rounds with no reply by the deadline (counted, not timed)
    // This process's CPU time over each variant's measured blocks (client, worker threads, echo
    // threads and ZeroMQ's I/O threads; the idle gaps' few wake-ups included): with threads, every
    // variant's whole cost per round. Daemons (--spawn) spend theirs in other processes.
    std::map<const std::vector<double>*, double> cpu;
    auto run_block = [&](auto& one, std::vector<double>* into, int n, bool measured) {
      const double c0 = process_cpu_us();
      for (int i = 0; i < n; ++i) {
        const auto t0 = Clock::now();
        const bool ok = one(measured);
        const auto t1 = Clock::now();
        if (measured && into) {
          if (ok)
            into->push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
          else
            ++lost;
        }
        if (gap.count()) std::this_thread::sleep_until(t1 + gap);
      }
      if (measured && into) cpu[into] += process_cpu_us() - c0;
    };
    run_block(scatter_round, nullptr, a->warmup, false);
    run_block(baseline_round, nullptr, a->warmup, false);
    run_block(floor_round, nullptr, a->warmup, false);
    run_block(sized_round, nullptr, a->warmup, false);
    run_block(split_round, nullptr, a->warmup, false);
    constexpr int kBlock = 100;
    for (int done = 0; done < a->rounds; done += kBlock) {
      const int n = std::min(kBlock, a->rounds - done);
      run_block(scatter_round, &us, n, true);
      run_block(baseline_round, &base, n, true);
      run_block(floor_round, &flo, n, true);
      run_block(sized_round, &sized, n, true);
      run_block(split_round, &split, n, true);
    }
    const Stats s = summarise(us);
    const Stats b = summarise(base);
    const Stats f = summarise(flo);
    const Stats fs = summarise(sized);
    const Stats sp = summarise(split);
    const bool threads = procs.empty();
    auto cpu_per_round = [&](const std::vector<double>& v) { return v.empty() ? 0.0 : cpu[&v] / double(v.size()); };

    if (a->json)
      print_json({{"bench", "scatter"},
                  {"workers", a->workers},
                  {"transport", a->transport},
                  {"gap_us", a->gap_us},
                  {"rounds", a->rounds},
                  {"incomplete", incomplete},
                  {"p50_us", round_to(s.p50, 1)},
                  {"p99_us", round_to(s.p99, 1)},
                  {"max_us", round_to(s.max, 1)},
                  {"mean_us", round_to(s.mean, 1)},
                  {"baseline_p50_us", round_to(b.p50, 1)},
                  {"baseline_p99_us", round_to(b.p99, 1)},
                  {"floor_p50_us", round_to(f.p50, 1)},
                  {"floor_p99_us", round_to(f.p99, 1)},
                  {"sized_floor_p50_us", round_to(fs.p50, 1)},
                  {"sized_floor_p99_us", round_to(fs.p99, 1)},
                  {"query_bytes", query_bytes},
                  {"result_bytes", result_bytes},
                  {"split_p50_us", round_to(sp.p50, 1)},
                  {"split_p99_us", round_to(sp.p99, 1)},
                  {"cpu_per_round_us", threads ? Json(round_to(cpu_per_round(us), 1)) : Json(nullptr)},
                  {"floor_cpu_per_round_us", threads ? Json(round_to(cpu_per_round(flo), 1)) : Json(nullptr)},
                  {"sized_floor_cpu_per_round_us", threads ? Json(round_to(cpu_per_round(sized), 1)) : Json(nullptr)},
                  {"split_cpu_per_round_us", threads ? Json(round_to(cpu_per_round(split), 1)) : Json(nullptr)},
                  {"lost", lost}});
    else
      std::printf(
          "scatter  %d workers  %-6s gap %5d us  %d rounds (%d incomplete)  p50 %7.1f us  p99 %7.1f us  max %8.1f us"
          "\n  baseline 1 req-rep: p50 %6.1f us  p99 %6.1f us\n  floor, raw %d-way fan-out: p50 %6.1f us  p99 %6.1f us"
          "  (ours / floor: p50 x%.2f, p99 x%.2f)%s\n  sized floor, frames of %zu / %zu bytes: p50 %6.1f us  p99 %6.1f "
          "us"
          "  (ours / sized floor: p50 x%.2f, p99 x%.2f)\n  split, the floor's raw client to our workers: p50 %6.1f us  "
          "p99 %6.1f us  (our workers add %+.1f us at p50 over the sized floor, our client %+.1f us)\n",
          a->workers, a->transport.c_str(), a->gap_us, a->rounds, incomplete, s.p50, s.p99, s.max, b.p50, b.p99,
          a->workers, f.p50, f.p99, f.p50 > 0 ? s.p50 / f.p50 : 0.0, f.p99 > 0 ? s.p99 / f.p99 : 0.0,
          lost ? "  (some baseline/floor rounds lost: see --json)" : "", query_bytes, result_bytes, fs.p50, fs.p99,
          fs.p50 > 0 ? s.p50 / fs.p50 : 0.0, fs.p99 > 0 ? s.p99 / fs.p99 : 0.0, sp.p50, sp.p99, sp.p50 - fs.p50,
          s.p50 - sp.p50);
    if (!a->json && threads)
      std::printf(
          "  CPU per round, this process (client, workers, ZeroMQ's threads): ours %.1f us, floor %.1f us, sized floor "
          "%.1f us, split %.1f us (our workers add %+.1f us over the sized floor, our client %+.1f us)\n",
          cpu_per_round(us), cpu_per_round(flo), cpu_per_round(sized), cpu_per_round(split),
          cpu_per_round(split) - cpu_per_round(sized), cpu_per_round(us) - cpu_per_round(split));
    if (!a->csv.empty()) {
      const bool fresh = !std::ifstream(a->csv).good();
      std::ofstream o(a->csv, std::ios::app);
      if (fresh)
        o << "bench,workers,transport,gap_us,rounds,incomplete,p50_us,p99_us,max_us,mean_us,baseline_p50_us,baseline_"
             "p99_us,"
             "floor_p50_us,floor_p99_us\n";
      o << "scatter," << a->workers << ',' << a->transport << ',' << a->gap_us << ',' << a->rounds << ',' << incomplete
        << ',' << s.p50 << ',' << s.p99 << ',' << s.max << ',' << s.mean << ',' << b.p50 << ',' << b.p99 << ',' << f.p50
        << ',' << f.p99 << '\n';
    }
  });
}

}  // namespace st::bench
