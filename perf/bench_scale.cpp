// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench scale: the scale-out model, measured (issue 17).
//
// For W = 1, 2, 4, ... workers and each mapping of the object's blocks (block-cyclic, contiguous,
// random), every worker's share is built exactly as a worker builds it (make_block_set, then the
// tree backend's load) and its query at each pose is timed alone in one thread, so the critical
// path (the slowest worker) and the total work are measured, not guessed. The gather is measured
// too, on this machine: the raw ZeroMQ fan-out floor over inproc for W workers (what a round here
// costs before any of our code), and the client's CPU per round over tcp with the echoes in a
// separate process (what a client pays per worker on any network). A network adds its round trip
// and its wire time; two published networks are modelled (docs/performance.md):
//   10 GbE, kernel TCP: 16.25 us round trip (netperf TCP_RR, 1-byte, switched; Linux commit
//     3a336cb17183 "cxgb4: Add low latency socket busy_poll support"), 10 Gbit/s;
//   100 GbE with busy polling: 8.79 us round trip (same source, busy_poll on), 100 Gbit/s.
// Per (pose, W, mapping): max and mean worker time, imbalance = max / mean over the W workers,
// redundant work = sum / the single-thread collide(); the same two from the counted sphere-pair
// and triangle-pair tests, weighted by a cost per test measured on the single thread (these do
// not move with the host's speed from one share's timing to the next); and the predicted round
//   compute = max_w (query_w + encode of its Result) + the client's decode and merge
//   network   = compute + client CPU(W) + round trip + largest reply / bandwidth
// with speed-up = single-thread collide() (timed beside each W) / predicted round; and the same
// round simulated event by event as the client runs it (predicted_simulated: Queries out one by
// one, the slowest worker of the round before first, each Result taken when it arrives, so all
// receipts but the last overlap the slower workers' compute, then the merge). The model is
// checked where this machine can: W = 1 and 2 in-process workers over inproc, predicted (our
// empty round + the slowest share's query + encode and merge) against the measured round, same
// poses, the terms and the rounds timed in interleaved blocks so that all see the host at the
// same speed.
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>

#include "bench.hpp"
#include "bench_json.hpp"
#include "fanout_floor.hpp"
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/partition.hpp>
#include <spheretouch/geom/pose_io.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/net/block_set.hpp>
#include <spheretouch/net/local_workers.hpp>
#include <spheretouch/net/protocol.hpp>
#include <spheretouch/net/scatter_gather.hpp>
#include <spheretouch/net/tree_backend.hpp>

namespace st::bench {
namespace {

using Clock = std::chrono::steady_clock;

struct ScaleArgs {
  std::string probe, object, poses;
  std::string layer = "auto", block_size = "auto";
  std::string share_tree = "per-block";
  std::uint32_t partition_leaf_faces = 0;  // 0: the object tree's own leaves
  double ship_motion_mm = 0.1;             // the probe's motion between two rounds, for the shipping model
  std::uint32_t ship_blocks = 8;           // blocks the shipping model may move per round
  std::uint32_t assist_blocks = 8;         // blocks the client assist may answer per round (net::choose_assist)
  std::uint32_t max_workers = 64;
  int runs = 15;
  int gather_rounds = 400;
  bool json = false;
  bool validate = true;
};

struct Network {
  const char* name;
  double rtt_us;        // round trip of a small message
  double bytes_per_us;  // wire bandwidth
  bool vm_client;       // the client's cost per round as this VM measures it (wake-ups included)
};
constexpr Network kNetworks[] = {
    {"10GbE", 16.25, 1250.0, false},
    {"10GbE-vm", 16.25, 1250.0, true},
    {"100GbE-busypoll", 8.79, 12500.0, false},
};

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

template <class F>
double time_median_us(int runs, F&& f) {
  f();  // warm
  std::vector<double> t;
  t.reserve(std::size_t(runs));
  for (int r = 0; r < runs; ++r) {
    const auto t0 = Clock::now();
    f();
    t.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
  }
  return median(std::move(t));
}

/// This process's CPU per call of `round`, over `rounds` calls spaced 200 µs apart (as a collision
/// loop spaces its rounds) in 5 blocks: the median block's mean, so that a block this VM stalled
/// (it once charged a block 70x the others) does not move the figure.
template <class F>
double cpu_per_round(F&& round, int rounds) {
  constexpr int kBlocks = 5;
  const int n = std::max(1, rounds / kBlocks);
  std::vector<double> per;
  for (int b = 0; b < kBlocks; ++b) {
    const double c0 = process_cpu_us();
    for (int r = 0; r < n; ++r) {
      round();
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    per.push_back((process_cpu_us() - c0) / n);
  }
  return median(std::move(per));
}

/// The fan-out ZeroMQ offers besides a DEALER per worker (issue 33, "measure, then choose"): one
/// PUB the workers subscribe to carries the query (one send for all of them), one PULL gathers
/// their replies (no poll over W sockets).
enum class FanOut { dealers, pub_pull };

/// The client's CPU per round over tcp: W DEALERs here (or one PUB and one PULL), W ROUTER echoes
/// (or SUB + PUSH pairs) in a child process (so this process's CPU time is the client's alone:
/// its thread and its ZeroMQ I/O thread). Returns microseconds per round for each W
/// (cpu_per_round). Forks: call it while this process runs no other thread.
std::vector<double> client_cpu_tcp(const std::vector<std::uint32_t>& ws, std::size_t reply_bytes, int rounds,
                                   FanOut how = FanOut::dealers) {
  std::vector<double> out;
  for (std::uint32_t W : ws) {
    std::vector<int> ports;
    const bool pub = how == FanOut::pub_pull;
    for (std::uint32_t i = 0; i < (pub ? 2u : W); ++i) ports.push_back(free_tcp_port());
    auto tcp = [](int port) { return "tcp://127.0.0.1:" + std::to_string(port); };
    const pid_t pid = ::fork();
    if (pid < 0) die("scale", "fork failed");
    if (pid == 0) {
      // The echoes: one thread polling W ROUTERs (or W SUBs, answering on their PUSHes), answering
      // with reply_bytes bytes.
      zmq::context_t ctx(1);
      std::vector<zmq::socket_t> socks, pushes;
      for (std::uint32_t i = 0; i < W; ++i) {
        socks.emplace_back(ctx, pub ? zmq::socket_type::sub : zmq::socket_type::router);
        socks.back().set(zmq::sockopt::linger, 0);
        if (!pub) {
          socks.back().bind(tcp(ports[i]));
          continue;
        }
        socks.back().set(zmq::sockopt::subscribe, "");
        socks.back().connect(tcp(ports[0]));
        pushes.emplace_back(ctx, zmq::socket_type::push);
        pushes.back().set(zmq::sockopt::linger, 0);
        pushes.back().connect(tcp(ports[1]));
      }
      std::vector<std::uint8_t> reply(std::max<std::size_t>(reply_bytes, 8), 0);
      std::vector<zmq::pollitem_t> items(socks.size());
      for (;;) {
        for (std::size_t i = 0; i < socks.size(); ++i) items[i] = {socks[i].handle(), 0, ZMQ_POLLIN, 0};
        if (zmq::poll(items.data(), items.size(), std::chrono::milliseconds(5000)) <= 0) ::_exit(0);
        for (std::size_t i = 0; i < socks.size(); ++i) {
          if (!(items[i].revents & ZMQ_POLLIN)) continue;
          if (!pub) {
            echo_pending(socks[i], reply);
            continue;
          }
          zmq::message_t q;
          while (socks[i].recv(q, zmq::recv_flags::dontwait)) {
            std::memcpy(reply.data(), q.data(), std::min<std::size_t>(q.size(), 8));
            (void)pushes[i].send(zmq::buffer(reply), zmq::send_flags::dontwait);
          }
        }
      }
    }
    double per_round = 0;
    {
      zmq::context_t ctx(1);
      constexpr std::size_t kQueryBytes = 160;  // a Query's size on the wire
      std::function<bool()> round;
      std::unique_ptr<FanOutGather> gather;
      zmq::socket_t pub_sock(ctx, zmq::socket_type::pub), pull(ctx, zmq::socket_type::pull);
      std::vector<std::uint8_t> query(kQueryBytes, 0);
      std::uint64_t seq = 0;
      if (!pub) {
        std::vector<std::string> endpoints;
        for (int p : ports) endpoints.push_back(tcp(p));
        gather = std::make_unique<FanOutGather>(ctx, endpoints);
        round = [&] { return gather->round(std::chrono::seconds(2), kQueryBytes); };
      } else {
        pub_sock.set(zmq::sockopt::linger, 0);
        pull.set(zmq::sockopt::linger, 0);
        pub_sock.bind(tcp(ports[0]));
        pull.bind(tcp(ports[1]));
        round = [&] {  // one send for every worker; the W echoes of this round on one socket
          std::memcpy(query.data(), &++seq, sizeof seq);
          (void)pub_sock.send(zmq::buffer(query), zmq::send_flags::dontwait);
          for (std::uint32_t got = 0; got < W;) {
            zmq::pollitem_t it{pull.handle(), 0, ZMQ_POLLIN, 0};
            if (zmq::poll(&it, 1, std::chrono::milliseconds(2000)) <= 0) return false;
            zmq::message_t m;
            while (pull.recv(m, zmq::recv_flags::dontwait)) {
              std::uint64_t back = 0;
              if (m.size() >= sizeof back) std::memcpy(&back, m.data(), sizeof back);
              got += back == seq;
            }
          }
          return true;
        };
        // A subscription reaches the PUB some time after the connection: until every SUB has
        // one, a round would wait for echoes that never come.
        std::this_thread::sleep_for(std::chrono::milliseconds(300));
      }
      for (int r = 0; r < 50; ++r) round();  // connect and warm
      per_round = cpu_per_round(round, rounds);
    }
    ::kill(pid, SIGTERM);
    int st = 0;
    ::waitpid(pid, &st, 0);
    out.push_back(per_round);
  }
  return out;
}

/// The client's own work per worker message with no wake-up in it (this VM's wake-ups are VM exits
/// that a bare-metal host does not pay): one thread, a ZeroMQ DEALER/ROUTER pair over inproc
/// sending a Query-sized frame and a Result-sized reply without ever blocking, plus the kernel's
/// work for the same two frames on a connected loopback TCP socket pair (write, read, write,
/// read, never blocking). Half of each loop is the client's side. Microseconds per message pair.
double client_message_work_us(std::size_t query_bytes, std::size_t reply_bytes, int n) {
  double zmq_us = 0, tcp_us = 0;
  {
    zmq::context_t ctx(1);
    zmq::socket_t r(ctx, zmq::socket_type::router), d(ctx, zmq::socket_type::dealer);
    r.set(zmq::sockopt::linger, 0);
    d.set(zmq::sockopt::linger, 0);
    r.bind("inproc://scale-work");
    d.connect("inproc://scale-work");
    std::vector<std::uint8_t> q(query_bytes, 1), rep(reply_bytes, 2);
    zmq::message_t id, body;
    auto once = [&] {
      d.send(zmq::buffer(q), zmq::send_flags::none);
      while (!r.recv(id, zmq::recv_flags::dontwait)) {}
      (void)r.recv(body, zmq::recv_flags::none);
      r.send(id, zmq::send_flags::sndmore);
      r.send(zmq::buffer(rep), zmq::send_flags::none);
      while (!d.recv(body, zmq::recv_flags::dontwait)) {}
    };
    for (int i = 0; i < 200; ++i) once();
    const double c0 = process_cpu_us();
    for (int i = 0; i < n; ++i) once();
    zmq_us = (process_cpu_us() - c0) / n / 2;
  }
  {
    const int ls = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof addr;
    if (ls < 0 || ::bind(ls, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(ls, 1) != 0 ||
        ::getsockname(ls, reinterpret_cast<sockaddr*>(&addr), &len) != 0)
      die("scale", "loopback tcp socket for the message-work measurement");
    const int a = ::socket(AF_INET, SOCK_STREAM, 0);
    if (::connect(a, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) die("scale", "loopback connect");
    const int b = ::accept(ls, nullptr, nullptr);
    const int one = 1;
    ::setsockopt(a, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    ::setsockopt(b, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    std::vector<std::uint8_t> q(query_bytes, 1), rep(reply_bytes, 2), buf(std::max(query_bytes, reply_bytes));
    auto xfer = [&](int from, int to, const std::vector<std::uint8_t>& m) {
      if (::write(from, m.data(), m.size()) != ssize_t(m.size())) die("scale", "loopback write");
      std::size_t got = 0;
      while (got < m.size()) {
        const ssize_t k = ::read(to, buf.data(), m.size() - got);
        if (k <= 0) die("scale", "loopback read");
        got += std::size_t(k);
      }
    };
    for (int i = 0; i < 200; ++i) {
      xfer(a, b, q);
      xfer(b, a, rep);
    }
    const double c0 = process_cpu_us();
    for (int i = 0; i < n; ++i) {
      xfer(a, b, q);
      xfer(b, a, rep);
    }
    tcp_us = (process_cpu_us() - c0) / n / 2;
    ::close(a);
    ::close(b);
    ::close(ls);
  }
  return zmq_us + tcp_us;
}

/// Least-squares a + b W.
std::pair<double, double> fit_line(const std::vector<std::uint32_t>& ws, const std::vector<double>& ys) {
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < ws.size() && i < ys.size(); ++i) {
    const double x = ws[i];
    n += 1;
    sx += x;
    sy += ys[i];
    sxx += x * x;
    sxy += x * ys[i];
  }
  const double den = n * sxx - sx * sx;
  if (n < 2 || den == 0) return {n ? sy / n : 0, 0};
  const double b = (n * sxy - sx * sy) / den;
  return {(sy - b * sx) / n, b};
}

struct Split {
  std::uint32_t layer = 0, block_size = 1, blocks = 0;
  bool automatic = false;
};

struct Row {
  std::size_t pose = 0;
  std::uint32_t contacts = 0, workers = 0, busy = 0;
  geom::Mapping mapping = geom::Mapping::block_cyclic;
  Split split;
  // single_us: one thread's collide() at this pose, the mean of the medians timed just before and
  // just after this W's shares (single_beside_us); the speed-ups and the timed redundancy use it.
  double single_us = 0, max_us = 0, mean_us = 0, sum_us = 0;
  std::array<double, 2> single_beside_us{};
  double encode_max_us = 0;     // slowest worker's query + its Result's encoding, minus its query
  double client_us = 0;         // the client's decode of every Result, the merge and the distinct faces
  double compute_round_us = 0;  // max_w (query_w + encode_w) + client
  std::size_t max_reply_bytes = 0, total_reply_bytes = 0;
  // Counted work (deterministic, unlike the times): sphere-pair and triangle-pair tests.
  std::uint64_t single_spheres = 0, single_tris = 0, sum_spheres = 0, sum_tris = 0;
  // Probe leaves transformed and boxed (CollideStats::probe_leaves): one thread's, and summed over
  // the workers (each transforms the probe leaves its blocks meet: work the tests do not count).
  std::uint64_t single_probe_leaves = 0, sum_probe_leaves = 0;
  std::vector<std::array<double, 3>> shares;  // per busy worker: sphere tests, triangle tests, query µs
  // The counted work in µs (tests weighted by the run's fitted cost per test): max and mean over
  // the W workers, and the single thread's.
  double work_max = 0, work_mean = 0, work_single = 0;
  double work_imbalance() const { return work_mean > 0 ? work_max / work_mean : 0; }
  double work_redundancy() const { return work_single > 0 ? work_mean * workers / work_single : 0; }
  // The same blocks dealt by an oracle that knows this pose's work per block (largest first, each
  // to the least loaded worker): what no static mapping can beat; its max / mean. Counted work of
  // each block alone (collide() restricted to the block's spheres of the tree they are cut from).
  const std::vector<std::array<std::uint64_t, 2>>* block_tests = nullptr;
  double oracle_imbalance = 0;
  // Work shipping (a model; not built): before the round, the client moves a few blocks from the
  // busiest worker to the least busy one (their faces travel in the Query), judged by the per-block
  // work of the round before (the pose moved by --ship-motion-mm); ship() below. Imbalance of the
  // deal with and without the moves, on this pose's work of each block alone.
  const std::vector<std::array<std::uint64_t, 2>>* block_tests_before = nullptr;
  const std::vector<std::uint32_t>* owners = nullptr;       // block -> worker of this row's mapping
  const std::vector<std::uint32_t>* block_faces = nullptr;  // faces per block
  double block_imbalance = 0, shipped_imbalance = 0;
  std::uint32_t shipped_blocks = 0, shipped_faces = 0;
  // The replicated deal (built: ScatterConfig::replicas; modelled here on each block's counted
  // work): every block held by two workers (its owner and net::second_holder()), and each round
  // the client gives each block that worked the round before to the less loaded of its two holders
  // (replicated_deal(), a fresh deal without the client's stickiness), judged by the work the
  // workers report for each block (ResultMsg::worked) at the pose of the round before. Each worker
  // holds two shares' memory.
  double replicated_imbalance = 0;
  // Client assist (built: ScatterConfig::assist_blocks): the client answers the blocks
  // net::choose_assist() picks from the work reported for each block at the pose of the round
  // before, their owners skip them. On this pose's work of each block alone: the workers' max / mean
  // after it (assisted), the round's slowest part (a worker or the client) against the whole
  // work dealt evenly over the W workers (assist_critical; `block_imbalance` without assist), and
  // the client's load against the slowest worker's (assist_client: <= 1, the worker stays last).
  const std::vector<std::uint32_t>* block_reported_before = nullptr;
  double assisted_imbalance = 0, assist_critical = 0, assist_client = 0;
  std::uint32_t assisted_blocks = 0;
  // A two-level gather (a model; not built): the workers in groups of `group` consecutive ones (the
  // busy ones first), the first of each a leader that relays the Query to the others, decodes their Results, merges
  // them with its own pairs and sends the client one Result; the client decodes and merges one
  // Result per group. Measured here: the slowest leader's decode + merge + encode, the client's
  // decode + merge + distinct faces, and the largest leader's reply.
  struct TwoLevel {
    std::uint32_t group = 0;
    double leader_us = 0, client_us = 0;
    std::size_t leader_reply_bytes = 0;
  };
  std::vector<TwoLevel> two_level;
  // The flat gather simulated event by event (predicted_simulated): per worker, all W, its query
  // + encode µs (an idle one's empty Result: 0) and its reply's bytes; with the replicated deal,
  // the mean worker's time x its share of the deal's counted load, + the encode; the order the
  // Queries go out in under each deal (ScatterGather sends the slowest worker of the round before
  // first; here by the work each worker's blocks were reported to do at the pose before); the
  // client's work on the W Results as they come (decode, pairs appended as a sorted run), what is
  // left after the last (the k-way merge, the repeats dropped) and the distinct faces, measured.
  // The simulated round is the run's client: it takes no distinct faces (ScatterConfig::
  // distinct_faces off in engine::start_fleet); the flat model's client_us includes them. The
  // replies' bytes and the client's work on them are the plain deal's under either deal.
  std::vector<double> worker_us, replicated_us;
  std::vector<std::size_t> reply_bytes;
  std::vector<std::uint32_t> send_order, replicated_send_order;
  double arrivals_us = 0, tail_us = 0, distinct_us = 0;
  double imbalance() const { return mean_us > 0 ? max_us / mean_us : 0; }
  double redundancy() const { return single_us > 0 ? sum_us / single_us : 0; }
  double sphere_ratio() const { return single_spheres ? double(sum_spheres) / double(single_spheres) : 0; }
  double tri_ratio() const { return single_tris ? double(sum_tris) / double(single_tris) : 0; }
  double probe_leaves_ratio() const {
    return single_probe_leaves ? double(sum_probe_leaves) / double(single_probe_leaves) : 0;
  }
};

/// The client's receipts, as ScatterGather's on_result: each Result of `frames` decoded (into one
/// Message, its room kept from Result to Result, as the client's drain does) into one sorted run
/// appended to `merged` (after the runs already begun in `runs`).
void take_results(std::span<const std::vector<std::uint8_t>> frames, const net::Limits& limits, geom::SortedRuns& runs,
                  std::vector<net::FacePair>& merged) {
  static thread_local net::Message m;
  for (const auto& f : frames)
    if (net::decode(f, limits, m))
      if (const auto* res = std::get_if<net::ResultMsg>(&m)) {
        runs.begin(merged.size());
        merged.insert(merged.end(), res->pairs.begin(), res->pairs.end());
        runs.end(merged);
      }
}
/// The client's merge, as ScatterGather does it: the receipts (take_results), then all the runs
/// merged and the duplicates dropped.
void merge_results(std::span<const std::vector<std::uint8_t>> frames, const net::Limits& limits, geom::SortedRuns& runs,
                   std::vector<net::FacePair>& merged) {
  take_results(frames, limits, runs, merged);
  runs.merge(merged);
  merged.erase(std::unique(merged.begin(), merged.end()), merged.end());
}

/// The client's work on one round's Results `frames`, split as ScatterGather::round does it: the
/// medians over `runs` of its work on them as they come (each decoded, its pairs appended as a
/// sorted run: on_result), of the merge once the last is in (the k-way merge, the repeats
/// dropped) and of the distinct faces (ScatterConfig::distinct_faces).
struct ClientSplit {
  double arrivals_us = 0, merge_us = 0, distinct_us = 0;
};
ClientSplit client_split(std::span<const std::vector<std::uint8_t>> frames, const net::Limits& limits, int runs) {
  geom::SortedRuns sorted_runs;
  std::vector<net::FacePair> merged;
  std::vector<std::uint32_t> probe_faces, object_faces, ids_scratch;
  std::vector<double> arrivals, merges, distincts;
  const auto us = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::micro>(b - a).count();
  };
  for (int k = -1; k < runs; ++k) {  // the first warms the vectors, as the client's are kept
    merged.clear();
    sorted_runs.clear();
    const auto t0 = Clock::now();
    take_results(frames, limits, sorted_runs, merged);
    const auto t1 = Clock::now();
    sorted_runs.merge(merged);
    merged.erase(std::unique(merged.begin(), merged.end()), merged.end());
    const auto t2 = Clock::now();
    geom::distinct_faces(merged, probe_faces, object_faces, ids_scratch);
    const auto t3 = Clock::now();
    if (k < 0) continue;
    arrivals.push_back(us(t0, t1));
    merges.push_back(us(t1, t2));
    distincts.push_back(us(t2, t3));
  }
  return {median(std::move(arrivals)), median(std::move(merges)), median(std::move(distincts))};
}

/// The order a client sends its Queries in: the heaviest worker of the round before first (its
/// load the work reported for each block it answers, `before`, block -> its worker `owner`).
std::vector<std::uint32_t> heaviest_first(const std::vector<double>& before, const std::vector<std::uint32_t>& owner,
                                          std::uint32_t workers) {
  std::vector<double> load(workers, 0.0);
  for (std::size_t k = 0; k < owner.size(); ++k) load[owner[k]] += before[k];
  std::vector<std::uint32_t> order(workers);
  for (std::uint32_t w = 0; w < workers; ++w) order[w] = w;
  std::sort(order.begin(), order.end(),
            [&](std::uint32_t x, std::uint32_t y) { return load[x] != load[y] ? load[x] > load[y] : x < y; });
  return order;
}

/// The two-level gather's costs (Row::TwoLevel) for every group size 2, 4, ... below the number of
/// Results `frames` (one per worker, the busy ones first): for each, the slowest group's leader
/// (decode the other members' Results, merge them with its own pairs as ScatterGather merges,
/// encode one Result) and the client (decode the leaders' Results, merge, distinct faces), each a
/// median over `runs`.
std::vector<Row::TwoLevel> two_level_gather(const std::vector<std::vector<std::uint8_t>>& frames,
                                            const net::Limits& limits, std::vector<std::uint32_t>& probe_faces,
                                            std::vector<std::uint32_t>& object_faces, int runs) {
  std::vector<Row::TwoLevel> out;
  std::vector<std::vector<net::FacePair>> own(frames.size());  // each worker's pairs, as a leader holds its own
  for (std::size_t k = 0; k < frames.size(); ++k)
    if (auto d = net::decode(frames[k], limits))
      if (const auto* res = std::get_if<net::ResultMsg>(&d.value())) own[k] = res->pairs;
  std::vector<net::FacePair> merged;
  std::vector<std::uint32_t> ids_scratch;
  geom::SortedRuns sorted_runs;
  for (std::size_t g = 2; g < frames.size(); g *= 2) {
    Row::TwoLevel t;
    t.group = static_cast<std::uint32_t>(g);
    std::vector<std::vector<std::uint8_t>> leader_frames;
    for (std::size_t first = 0; first < frames.size(); first += g) {
      const std::size_t end = std::min(frames.size(), first + g);
      net::ResultMsg msg;
      msg.seq = 1;
      std::vector<std::uint8_t> frame;
      const double us = time_median_us(runs, [&] {
        merged.clear();
        sorted_runs.begin(0);  // the leader's own pairs, sorted where it computed them
        merged.insert(merged.end(), own[first].begin(), own[first].end());
        sorted_runs.end(merged);
        merge_results(std::span(frames).subspan(first + 1, end - first - 1), limits, sorted_runs, merged);
        msg.pairs = merged;
        net::encode(msg, frame);
      });
      t.leader_us = std::max(t.leader_us, us);
      t.leader_reply_bytes = std::max(t.leader_reply_bytes, frame.size());
      leader_frames.push_back(std::move(frame));
    }
    t.client_us = time_median_us(runs, [&] {
      merged.clear();
      merge_results(leader_frames, limits, sorted_runs, merged);
      geom::distinct_faces(merged, probe_faces, object_faces, ids_scratch);
    });
    out.push_back(t);
  }
  return out;
}

struct Memory {
  std::uint32_t workers = 0;
  geom::Mapping mapping = geom::Mapping::block_cyclic;
  double max_share_faces = 0;  // largest share, faces
  double max_share_bytes = 0;  // its tree + faces + vertices
};

struct Check {
  std::size_t pose = 0;
  std::uint32_t workers = 0;
  double predicted_us = 0, measured_us = 0, floor_us = 0;
  double compute_alone_us = 0;     // the slowest worker's query timed alone (the model's term)
  double compute_in_round_us = 0;  // the slowest worker's query inside the real rounds (median)
  double gather_us = 0;            // our empty round at this W (the model's gather term here)
  // The W shares' queries run at once, one thread each (median of the slowest): what the
  // in-process workers compute when they share this machine's two cores and memory system,
  // which a cluster's workers do not. predicted_corun uses it instead of compute_alone_us.
  double compute_corun_us = 0, predicted_corun_us = 0;
};

/// The slowest of the shares' queries at `pose` when all run at once, one thread each (started
/// together), median over `runs` trials spaced 0.5 ms as the rounds are.
double corun_us(std::vector<std::unique_ptr<net::CollisionBackend>>& shares, const geom::Pose& pose, int runs,
                std::size_t max_pairs) {
  std::vector<double> slowest;
  for (int r = 0; r < runs; ++r) {
    std::vector<double> took(shares.size());
    std::atomic<std::size_t> ready{0};
    std::vector<std::thread> threads;
    for (std::size_t w = 0; w < shares.size(); ++w)
      threads.emplace_back([&, w] {
        std::vector<net::FacePair> out;
        ready.fetch_add(1);
        while (ready.load() < shares.size()) {}
        const auto t0 = Clock::now();
        shares[w]->query(pose, {}, out, {.max_pairs = max_pairs});
        took[w] = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
      });
    for (std::thread& t : threads) t.join();
    slowest.push_back(*std::max_element(took.begin(), took.end()));
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  return median(std::move(slowest));
}

/// Imbalance (max / mean load) of `work` dealt to `workers` by longest processing time first (each
/// item to the least loaded worker): within 4/3 of the best deal (Graham 1969).
double oracle_imbalance(std::vector<double> work, std::uint32_t workers) {
  std::sort(work.begin(), work.end(), std::greater<>());
  std::vector<double> load(workers, 0.0);
  double total = 0;
  for (double w : work) {
    *std::min_element(load.begin(), load.end()) += w;
    total += w;
  }
  return total > 0 ? *std::max_element(load.begin(), load.end()) * workers / total : 1.0;
}

/// The work shipping model: from `owner` (block -> worker), moves up to `max_moves` blocks, each
/// the busiest worker's heaviest block by `before` that is lighter than the gap to the least busy
/// worker (so the move lowers the larger of the two loads), to that worker. Returns the moved
/// blocks' indices; `owner` holds the new deal.
std::vector<std::uint32_t> ship(const std::vector<double>& before, std::vector<std::uint32_t>& owner,
                                std::uint32_t workers, std::uint32_t max_moves) {
  std::vector<double> load(workers, 0.0);
  for (std::size_t k = 0; k < owner.size(); ++k) load[owner[k]] += before[k];
  std::vector<std::uint32_t> moved;
  while (moved.size() < max_moves) {
    const auto busiest = std::uint32_t(std::max_element(load.begin(), load.end()) - load.begin());
    const auto idlest = std::uint32_t(std::min_element(load.begin(), load.end()) - load.begin());
    const double gap = load[busiest] - load[idlest];
    std::size_t pick = owner.size();
    for (std::size_t k = 0; k < owner.size(); ++k)
      if (owner[k] == busiest && before[k] > 0 && before[k] < gap && (pick == owner.size() || before[k] > before[pick]))
        pick = k;
    if (pick == owner.size()) break;
    owner[pick] = idlest;
    load[busiest] -= before[pick];
    load[idlest] += before[pick];
    moved.push_back(std::uint32_t(pick));
  }
  return moved;
}

/// The replicated deal of one round: the blocks with work predicted (by the round before), the
/// heaviest first, each to the less loaded of its owner and net::second_holder() (a two-choice longest
/// processing time first); the others stay with their owner. Returns block -> worker.
std::vector<std::uint32_t> replicated_deal(const std::vector<double>& predicted, std::vector<std::uint32_t> owner,
                                           std::uint32_t workers) {
  std::vector<std::uint32_t> order;
  for (std::uint32_t k = 0; k < predicted.size(); ++k)
    if (predicted[k] > 0) order.push_back(k);
  std::sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) { return predicted[x] > predicted[y]; });
  std::vector<double> load(workers, 0.0);
  for (std::uint32_t k : order) {
    const std::uint32_t other = net::second_holder(k, owner[k], workers);
    if (load[other] < load[owner[k]]) owner[k] = other;
    load[owner[k]] += predicted[k];
  }
  return owner;
}

/// max / mean of the workers' loads when block k (work[k]) is dealt to owner[k].
double deal_imbalance(const std::vector<double>& work, const std::vector<std::uint32_t>& owner, std::uint32_t workers) {
  std::vector<double> load(workers, 0.0);
  double total = 0;
  for (std::size_t k = 0; k < owner.size(); ++k) {
    load[owner[k]] += work[k];
    total += work[k];
  }
  return total > 0 ? *std::max_element(load.begin(), load.end()) * workers / total : 1.0;
}

/// The shares' backends: the workers' tree backend answering every query from scratch. The model
/// times each pose alone, repeated, and compares with one thread's plain collide(); the coherent
/// collider (on in the workers) would reuse the repeated pose's certificates and time nothing.
net::BackendFactory share_backends(bool per_block) {
  return net::tree_backend_factory(per_block, net::kDefaultMaxCrowding, /*coherent=*/false);
}

/// The worker's resident bytes for a share: its object tree and its mesh (the probe is shared by all).
double share_bytes(const geom::Mesh& m, const geom::SphereTree& t) {
  return double(t.bytes()) + double(m.faces.size() * sizeof(m.faces[0])) + double(m.local.size() * sizeof(m.local[0]));
}

/// Our client's CPU per round over tcp, for the model's client side checked against real rounds
/// (issue 33): W in-process workers over tcp in a child process (so this process's CPU time is the
/// client's alone, as in client_cpu_tcp: its thread and its ZeroMQ I/O thread), our ScatterGather
/// here as the run sets it up (no assist, no replicas, no distinct faces), `rounds` rounds at each
/// pose after 50 to warm (cpu_per_round). The workers are the run's `workers` factory: with the
/// coherent collider a pose asked again is answered from its certificates, so the Results are a
/// real round's while the workers' compute, which on two cores takes the CPU from the client and
/// makes each of its wake-ups dearer, stays small. Returns µs per round, per pose. Forks: call it
/// while this process runs no other thread.
std::vector<double> our_client_cpu_tcp(std::uint32_t W, const geom::Mesh& probe, const geom::Mesh& object,
                                       net::Blocks blocks, const net::BackendFactory& workers,
                                       const std::vector<geom::Pose>& poses, int rounds) {
  std::vector<std::string> endpoints;
  for (std::uint32_t i = 0; i < W; ++i) endpoints.push_back("tcp://127.0.0.1:" + std::to_string(free_tcp_port()));
  const pid_t pid = ::fork();
  if (pid < 0) die("scale", "fork failed");
  if (pid == 0) {                        // the workers, until the parent's SIGTERM
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);  // or its end: a parent that dies leaves no workers behind
    if (::getppid() == 1) ::_exit(1);    // it ended before the line above
    zmq::context_t ctx(1);
    auto lw = net::LocalWorkers::start(ctx, int(W), workers, [&](int i) { return endpoints[std::size_t(i)]; });
    if (!lw) {
      std::fprintf(stderr, "scale: workers for the client-CPU check: %s\n", lw.error().c_str());
      ::_exit(1);
    }
    for (;;) ::pause();
  }
  std::vector<double> out;
  {
    zmq::context_t ctx(1);
    net::ScatterConfig cfg;
    cfg.endpoints = endpoints;
    cfg.distinct_faces = false;
    auto sg = net::ScatterGather::create(ctx, cfg, probe, object, std::move(blocks));
    if (!sg) die("scale", sg.error());
    for (const auto until = Clock::now() + std::chrono::seconds(300);
         !sg.value()->wait_ready(Clock::now() + std::chrono::seconds(1));) {
      int st = 0;
      if (::waitpid(pid, &st, WNOHANG) == pid)
        die("scale", "client-CPU check: the process of the " + std::to_string(W) + " workers ended (above: why)");
      if (Clock::now() > until)
        die("scale", "client-CPU check: " + std::to_string(W) + " workers over tcp not ready in 300 s");
    }
    net::RoundResult rr;
    std::uint64_t seq = 0;
    int incomplete = 0;
    for (const geom::Pose& pose : poses) {
      const auto round = [&] {
        sg.value()->round(++seq, pose, Clock::now() + std::chrono::seconds(5), rr);
        incomplete += !rr.complete;
      };
      for (int r = 0; r < 50; ++r) round();
      out.push_back(cpu_per_round(round, rounds));
    }
    if (incomplete)
      die("scale", "client-CPU check: " + std::to_string(incomplete) + " incomplete rounds with " + std::to_string(W) +
                       " workers over tcp");
  }
  ::kill(pid, SIGTERM);
  int st = 0;
  ::waitpid(pid, &st, 0);
  return out;
}

void run_scale(const ScaleArgs& a) {
  geom::Mesh probe, object;
  for (auto [path, mesh] : {std::pair{&a.probe, &probe}, std::pair{&a.object, &object}}) {
    auto m = geom::load_mesh(*path);
    if (!m) die("scale", m.error());
    *mesh = std::move(m.value().mesh);
  }
  auto lines = geom::read_pose_lines(a.poses);
  if (!lines) die("scale", lines.error());
  if (lines.value().empty()) die("scale", a.poses + ": no poses");
  std::vector<geom::Pose> poses;
  for (const auto& l : lines.value()) poses.push_back(l.pose);
  const auto parse_knob = [](const std::string& v, const char* what, std::uint32_t free) -> std::uint32_t {
    if (v == "auto") return free;
    try {
      const unsigned long x = std::stoul(v);
      if (x > (1u << 20)) throw std::out_of_range(what);
      return std::uint32_t(x);
    } catch (const std::exception&) {
      die("scale", std::string("--") + what + ": expected an integer or auto (found '" + v + "')");
    }
  };
  const bool per_block = a.share_tree == "per-block";
  const std::uint32_t fixed_layer = parse_knob(a.layer, "layer", geom::kFree);
  const std::uint32_t fixed_block = parse_knob(a.block_size, "block-size", 0);
  if (fixed_block == 0 && a.block_size != "auto") die("scale", "--block-size must be >= 1 or auto");

  std::vector<std::uint32_t> ws;
  for (std::uint32_t w = 1; w <= a.max_workers; w *= 2) ws.push_back(w);

  // 1. The client's CPU per round over tcp (before any thread of ours exists: it forks).
  const std::vector<std::uint32_t> cpu_ws = {1, 2, 4, 8, 16};
  std::fprintf(stderr, "client CPU per round over tcp (echoes in another process), W = 1..16 ...\n");
  const std::vector<double> cpu_tcp = client_cpu_tcp(cpu_ws, 8 * 64, std::max(50, a.gather_rounds / 2));
  const auto [cpu_a, cpu_b] = fit_line(cpu_ws, cpu_tcp);
  std::fprintf(stderr, "... and with one PUB for the query and one PULL for the replies ...\n");
  const std::vector<double> cpu_pub = client_cpu_tcp(cpu_ws, 8 * 64, std::max(50, a.gather_rounds / 2), FanOut::pub_pull);
  const auto [pub_a, pub_b] = fit_line(cpu_ws, cpu_pub);
  const double msg_work = client_message_work_us(160, 8 * 64, std::max(2000, a.gather_rounds * 10));

  std::fprintf(stderr, "building trees ...\n");
  const geom::SphereTree pt = geom::SphereTree::build(probe).value();
  const geom::SphereTree ot = geom::SphereTree::build(object).value();
  const double object_bytes = share_bytes(object, ot);
  // The tree the blocks are cut from: the object's own, or one with smaller leaves (finer blocks).
  geom::SphereTree finer;
  if (a.partition_leaf_faces) {
    geom::TreeConfig tc = geom::DefaultTreeConfig();
    tc.leaf_faces = a.partition_leaf_faces;
    auto t = geom::SphereTree::build(object, tc);
    if (!t) die("scale", t.error());
    finer = std::move(t).value();
  }
  const geom::SphereTree& part_tree = a.partition_leaf_faces ? finer : ot;
  geom::SplitModelConfig model;
  model.contact_radius = 0.25 * double(pt.nodes[0].radius);

  // 2. Single thread: collide() over the whole object (the collision thread's own mode).
  geom::CollideScratch scratch;
  geom::CollideResult result;
  std::vector<double> single(poses.size());
  std::vector<std::uint32_t> contacts(poses.size());
  std::vector<std::uint64_t> single_spheres(poses.size()), single_tris(poses.size()), single_leaves(poses.size());
  std::vector<double> single_spheres_us(poses.size());  // the same descent stopped at the leaf spheres
  for (std::size_t i = 0; i < poses.size(); ++i) {
    geom::CollideConfig spheres_only = geom::DefaultCollideConfig();
    spheres_only.stop_layer = geom::kLeafSpheres;
    spheres_only.approx_face_pairs = false;
    single_spheres_us[i] =
        time_median_us(a.runs, [&] { geom::collide(probe, pt, object, ot, poses[i], spheres_only, scratch, result); });
    const std::uint64_t sphere_tests = result.stats.node_pairs;
    const geom::CollideConfig full = geom::DefaultCollideConfig();
    single[i] = time_median_us(a.runs, [&] { geom::collide(probe, pt, object, ot, poses[i], full, scratch, result); });
    if (result.stats.node_pairs != sphere_tests)
      die("scale", "pose " + std::to_string(i + 1) + ": the descent stopped at the leaf spheres made " +
                       std::to_string(sphere_tests) + " sphere tests, the exact one " +
                       std::to_string(result.stats.node_pairs));
    contacts[i] = std::uint32_t(result.contacts());
    single_spheres[i] = result.stats.node_pairs;
    single_tris[i] = result.stats.tri_pairs;
    single_leaves[i] = result.stats.probe_leaves;
    std::fprintf(stderr, "pose %zu: %u contacts, %zu pairs, single thread %.1f us\n", i + 1, contacts[i],
                 result.pairs.size(), single[i]);
  }

  // One thread timed again beside each W's shares, before and after them (below): a speed-up
  // compares times of one phase of the host (on a shared VM the one-thread round moved 1.0-1.9x
  // between the start of a run and its end).
  const auto time_single = [&](std::vector<double>& us) {
    us.resize(poses.size());
    const geom::CollideConfig full = geom::DefaultCollideConfig();
    for (std::size_t i = 0; i < poses.size(); ++i)
      us[i] = time_median_us(a.runs, [&] { geom::collide(probe, pt, object, ot, poses[i], full, scratch, result); });
  };

  const auto split_for = [&](std::uint32_t W, geom::Mapping m) -> Split {
    Split s;
    if (fixed_layer != geom::kFree && fixed_block != 0) {
      s.layer = fixed_layer;
      s.block_size = fixed_block;
    } else {
      auto pick = geom::choose_split(part_tree, W, m, model, fixed_layer, fixed_block);
      if (!pick) die("scale", pick.error());
      s.layer = pick.value().layer;
      s.block_size = pick.value().block_size;
      s.automatic = true;
    }
    return s;
  };

  // Counted tests of each block alone at each pose and at the pose of the round before (moved by
  // --ship-motion-mm in a direction drawn per pose), per split (layer, block size): for the oracle
  // deal and the shipping model.
  std::vector<geom::Pose> poses_before = poses;
  {
    std::mt19937_64 rng(17);
    std::normal_distribution<double> normal;
    for (geom::Pose& p : poses_before) {
      geom::Vec3 d(normal(rng), normal(rng), normal(rng));
      p.translation() += a.ship_motion_mm * d.normalized();
    }
  }
  using Tests = std::vector<std::array<std::uint64_t, 2>>;  // per block: sphere tests, triangle tests
  struct BlockTests {
    std::vector<Tests> now, before;  // per pose
    // per pose, per block: the work a worker reports for it (ResultMsg::worked) at the pose before
    std::vector<std::vector<std::uint32_t>> reported_before;
    std::vector<std::uint32_t> faces;               // per block
    std::deque<std::vector<std::uint32_t>> owners;  // block -> worker, one per (W, mapping) dealt (a deque: rows point in)
  };
  std::map<std::pair<std::uint32_t, std::uint32_t>, BlockTests> block_tests;
  const auto tests_per_block = [&](const Split& sp) -> BlockTests& {
    auto [it, fresh] = block_tests.try_emplace({sp.layer, sp.block_size});
    if (!fresh) return it->second;
    auto part = geom::make_partition(part_tree, sp.layer, 1, sp.block_size);
    if (!part) die("scale", part.error());
    BlockTests& bt = it->second;
    for (std::uint32_t b = 0; b < part.value().num_blocks(); ++b) {
      std::uint32_t f = 0;
      for (std::uint32_t n : part.value().block(b)) f += part_tree.cold[n].face_end - part_tree.cold[n].face_begin;
      bt.faces.push_back(f);
    }
    geom::NodeWork node_work;
    node_work.work.assign(part_tree.num_nodes(), 0);
    for (auto [list, out] : {std::pair{&poses, &bt.now}, std::pair{&poses_before, &bt.before}}) {
      out->resize(poses.size());
      for (std::size_t i = 0; i < poses.size(); ++i)
        for (std::uint32_t b = 0; b < part.value().num_blocks(); ++b) {
          geom::CollideConfig c = geom::DefaultCollideConfig();
          c.restrict_object = true;
          c.object_roots = part.value().block(b);
          if (out == &bt.before) c.node_work = &node_work;
          geom::collide(probe, pt, object, part_tree, (*list)[i], c, scratch, result);
          (*out)[i].push_back({result.stats.node_pairs, result.stats.tri_pairs});
          if (out == &bt.before) {
            std::uint64_t reported = 0;
            for (std::uint32_t n : node_work.touched) reported += node_work.work[n];
            node_work.clear();
            bt.reported_before.resize(poses.size());
            bt.reported_before[i].push_back(std::uint32_t(std::min<std::uint64_t>(reported, UINT32_MAX)));
          }
        }
    }
    return bt;
  };

  // 3. Every worker's share, built as a worker builds it, timed alone at every pose.
  const geom::Mapping mappings[] = {geom::Mapping::block_cyclic, geom::Mapping::contiguous, geom::Mapping::random};
  std::vector<Row> rows;
  std::vector<Memory> memory;
  const net::Limits limits = net::DefaultLimits();
  for (std::uint32_t W : ws) {
    for (geom::Mapping m : mappings) {
      Split sp = split_for(W, m);
      auto blocks = net::tree_blocks(part_tree, sp.layer, sp.block_size);
      if (!blocks) die("scale", blocks.error());
      sp.blocks = std::uint32_t(blocks.value().size());
      if (sp.blocks < W) {
        std::fprintf(stderr, "W=%u %s: only %u blocks at layer %u, skipped\n", W, geom::to_string(m), sp.blocks, sp.layer);
        continue;
      }
      std::fprintf(stderr, "W=%u %s: layer %u, block size %u, %u blocks%s\n", W, geom::to_string(m), sp.layer,
                   sp.block_size, sp.blocks, sp.automatic ? " (automatic)" : "");
      const auto share = net::deal_blocks(sp.blocks, W, m, 1);
      std::vector<double> single_before, single_after;
      time_single(single_before);
      BlockTests& per_block_tests = tests_per_block(sp);
      per_block_tests.owners.emplace_back(sp.blocks);
      std::vector<std::uint32_t>& owners = per_block_tests.owners.back();
      for (std::uint32_t w = 0; w < W; ++w)
        for (std::uint32_t k : share[w]) owners[k] = w;
      std::vector<Row> prow(poses.size());
      for (std::size_t i = 0; i < poses.size(); ++i) {
        prow[i].pose = i + 1;
        prow[i].contacts = contacts[i];
        prow[i].workers = W;
        prow[i].mapping = m;
        prow[i].split = sp;
        prow[i].single_spheres = single_spheres[i];
        prow[i].single_tris = single_tris[i];
        prow[i].single_probe_leaves = single_leaves[i];
        prow[i].block_tests = &per_block_tests.now[i];
        prow[i].block_tests_before = &per_block_tests.before[i];
        prow[i].block_reported_before = &per_block_tests.reported_before[i];
        prow[i].owners = &owners;
        prow[i].block_faces = &per_block_tests.faces;
        prow[i].worker_us.assign(W, 0.0);
        prow[i].reply_bytes.assign(W, net::encode(net::ResultMsg{}).size());
      }
      std::vector<std::vector<std::vector<std::uint8_t>>> replies(poses.size());  // encoded Results per pose
      std::vector<std::vector<net::FacePair>> all_pairs(poses.size());
      Memory mem;
      mem.workers = W;
      mem.mapping = m;
      for (std::uint32_t w = 0; w < W; ++w) {
        if (share[w].empty()) continue;
        auto set = net::make_block_set(probe, object, blocks.value(), share[w], geom::DefaultTreeConfig().leaf_faces);
        if (!set) die("scale", set.error());
        std::unique_ptr<net::CollisionBackend> be = share_backends(per_block)();
        if (Status st = be->load(set.value()); !st) die("scale", st.error());
        {
          // What this worker holds of the object: its share's tree (rebuilt here to size it) and mesh.
          const geom::SphereTree st =
              geom::SphereTree::build(set.value().object, geom::DefaultTreeConfig(),
                                      per_block ? set.value().block_faces : std::vector<std::uint32_t>{})
                  .value();
          const double bytes = share_bytes(set.value().object, st);
          if (bytes > mem.max_share_bytes) {
            mem.max_share_bytes = bytes;
            mem.max_share_faces = double(set.value().object.faces.size());
          }
          // The probe leaves this worker transforms at each pose (on the tree it queries).
          for (std::size_t i = 0; i < poses.size(); ++i) {
            geom::collide(probe, pt, set.value().object, st, poses[i], geom::DefaultCollideConfig(), scratch, result);
            prow[i].sum_probe_leaves += result.stats.probe_leaves;
          }
        }
        std::vector<net::FacePair> out;
        for (std::size_t i = 0; i < poses.size(); ++i) {
          net::QueryStats counted;
          const double q = time_median_us(a.runs, [&] {
            out.clear();
            counted = be->query(poses[i], {}, out, {.max_pairs = limits.max_pairs});
          });
          net::ResultMsg msg;
          msg.seq = 1;
          msg.worker_id = w;
          std::vector<std::uint8_t> frame;
          // The worker sorts its pairs (the client merges sorted runs), then encodes them.
          const double enc = time_median_us(a.runs, [&] {
            msg.pairs = out;
            std::sort(msg.pairs.begin(), msg.pairs.end());
            msg.pairs.erase(std::unique(msg.pairs.begin(), msg.pairs.end()), msg.pairs.end());
            net::encode(msg, frame);
          });
          Row& r = prow[i];
          ++r.busy;
          r.sum_us += q;
          r.sum_spheres += counted.sphere_tests;
          r.sum_tris += counted.tri_tests;
          r.shares.push_back({double(counted.sphere_tests), double(counted.tri_tests), q});
          r.max_us = std::max(r.max_us, q);
          r.encode_max_us = std::max(r.encode_max_us, q + enc);  // the slowest worker including its encode
          r.worker_us[w] = q + enc;
          r.reply_bytes[w] = frame.size();
          r.max_reply_bytes = std::max(r.max_reply_bytes, frame.size());
          r.total_reply_bytes += frame.size();
          replies[i].push_back(frame);
          all_pairs[i].insert(all_pairs[i].end(), out.begin(), out.end());
        }
      }
      memory.push_back(mem);
      time_single(single_after);
      for (std::size_t i = 0; i < poses.size(); ++i) {
        Row& r = prow[i];
        r.single_beside_us = {single_before[i], single_after[i]};
        r.single_us = 0.5 * (single_before[i] + single_after[i]);
        r.mean_us = r.sum_us / W;
        // The client: decode every Result and merge their pairs as ScatterGather does (each
        // worker's pairs a sorted run, one k-way merge, duplicates dropped, the distinct faces
        // taken; its vectors are kept from round to round, as the client's are).
        std::vector<net::FacePair> merged;
        std::vector<std::uint32_t> probe_faces, object_faces, ids_scratch;
        geom::SortedRuns runs;
        r.client_us = time_median_us(a.runs, [&] {
          merged.clear();
          merge_results(replies[i], limits, runs, merged);
          geom::distinct_faces(merged, probe_faces, object_faces, ids_scratch);
        });
        r.compute_round_us = r.encode_max_us + r.client_us;
        {  // every worker answers, the idle ones with an empty Result (as in the flat gather)
          std::vector<std::vector<std::uint8_t>> frames = replies[i];
          net::ResultMsg empty;
          empty.seq = 1;
          frames.resize(W, net::encode(empty));
          r.two_level = two_level_gather(frames, limits, probe_faces, object_faces, a.runs);
          const ClientSplit split = client_split(frames, limits, a.runs);
          r.arrivals_us = split.arrivals_us;
          r.tail_us = split.merge_us;
          r.distinct_us = split.distinct_us;
        }
        rows.push_back(r);
      }
    }
  }

  // Counted work: the cost of a sphere-pair test and of a triangle-pair test weights the tests
  // into µs, measured apart on the single thread's queries: the same descent stopped at the leaf
  // spheres (every sphere test, no face test) costs the sphere tests; the rest of the exact query
  // (face boxes and triangle tests of the leaf pairs) costs the triangle tests. Imbalance and
  // redundancy of the counted work are then deterministic for given costs, and the costs, two
  // sums over all poses, move only with the host's speed. (A least-squares fit of both to every
  // query moved them by up to 8x between runs: the two counts grow together.)
  double cost_sphere_us = 0, cost_tri_us = 0;
  {
    double t_exact = 0, t_spheres = 0, n_spheres = 0, n_tris = 0;
    for (std::size_t i = 0; i < poses.size(); ++i) {
      t_exact += single[i];
      t_spheres += single_spheres_us[i];
      n_spheres += double(single_spheres[i]);
      n_tris += double(single_tris[i]);
    }
    if (n_spheres > 0) cost_sphere_us = t_spheres / n_spheres;
    if (n_tris > 0) cost_tri_us = std::max(0.0, t_exact - t_spheres) / n_tris;
    for (Row& r : rows) {
      double sum = 0;
      for (const auto& w : r.shares) {
        const double work = cost_sphere_us * w[0] + cost_tri_us * w[1];
        r.work_max = std::max(r.work_max, work);
        sum += work;
      }
      r.work_mean = sum / r.workers;
      r.work_single = cost_sphere_us * double(r.single_spheres) + cost_tri_us * double(r.single_tris);
      std::vector<double> work, before;
      for (const auto& t : *r.block_tests) work.push_back(cost_sphere_us * double(t[0]) + cost_tri_us * double(t[1]));
      for (const auto& t : *r.block_tests_before)
        before.push_back(cost_sphere_us * double(t[0]) + cost_tri_us * double(t[1]));
      r.block_imbalance = deal_imbalance(work, *r.owners, r.workers);
      std::vector<std::uint32_t> shipped_owner = *r.owners;
      const std::vector<std::uint32_t> moved = ship(before, shipped_owner, r.workers, a.ship_blocks);
      r.shipped_imbalance = deal_imbalance(work, shipped_owner, r.workers);
      r.shipped_blocks = std::uint32_t(moved.size());
      for (std::uint32_t k : moved) r.shipped_faces += r.block_faces->at(k);
      std::vector<net::BlockWork> worked;
      std::vector<double> reported(r.block_reported_before->begin(), r.block_reported_before->end());
      for (std::uint32_t k = 0; k < reported.size(); ++k)
        if (reported[k] > 0) worked.push_back({k, (*r.owners)[k], reported[k]});
      const std::vector<std::uint32_t> taken = net::choose_assist(worked, r.workers, a.assist_blocks);
      std::vector<double> load(r.workers, 0.0);
      double client = 0, total = 0;
      for (std::uint32_t k = 0; k < work.size(); ++k) {
        (std::binary_search(taken.begin(), taken.end(), k) ? client : load[(*r.owners)[k]]) += work[k];
        total += work[k];
      }
      const double max_load = *std::max_element(load.begin(), load.end()), rest = total - client;
      r.assisted_imbalance = rest > 0 ? max_load * r.workers / rest : 1.0;
      r.assist_critical = total > 0 ? std::max(max_load, client) * r.workers / total : 1.0;
      r.assist_client = max_load > 0 ? client / max_load : 0.0;
      r.assisted_blocks = std::uint32_t(taken.size());
      const std::vector<std::uint32_t> replicated_owner = replicated_deal(reported, *r.owners, r.workers);
      r.replicated_imbalance = deal_imbalance(work, replicated_owner, r.workers);
      // The simulated gather's send orders (the client's is by the compute each worker reported the
      // round before; here by the work reported for its blocks at the pose before, summed), and
      // the replicated deal's workers, each the mean worker's time x its load / the mean load.
      r.send_order = heaviest_first(reported, *r.owners, r.workers);
      r.replicated_send_order = heaviest_first(reported, replicated_owner, r.workers);
      std::vector<double> replicated_load(r.workers, 0.0);
      double total_work = 0;
      for (std::size_t k = 0; k < work.size(); ++k) {
        replicated_load[replicated_owner[k]] += work[k];
        total_work += work[k];
      }
      r.replicated_us.resize(r.workers);
      for (std::uint32_t w = 0; w < r.workers; ++w)
        r.replicated_us[w] = (total_work > 0 ? r.mean_us * replicated_load[w] * r.workers / total_work : r.mean_us) +
                             (r.encode_max_us - r.max_us);
      r.oracle_imbalance = oracle_imbalance(std::move(work), r.workers);
    }
  }

  // Client assist in real rounds: W in-process workers (block-cyclic, the automatic split) and two
  // clients, one with assist and one without; at each pose a round at the pose of the round before
  // (--ship-motion-mm away), then the one measured. Each worker's counted tests come from its own
  // Result (its share tree as it is), the client's from its own queries; weighted by the measured
  // cost per test. Deterministic: counts, not times (the 8 workers share this VM's two cores).
  struct AssistRound {
    std::size_t pose = 0;
    std::uint32_t workers = 0, contacts = 0, blocks = 0;
    double imbalance = 0;            // without assist: max / mean of the workers' counted work
    double assisted = 0;             // with assist: the same over the workers
    double critical = 0;             // with assist: max(slowest worker, client) / (all of it / W)
    double client = 0;               // with assist: the client's work / the slowest worker's
    double replicated = 0;           // the replicated deal (ScatterConfig::replicas): workers' max / mean
    double replicated_critical = 0;  // replicas + assist: max(slowest worker, client) / (all of it / W)
    std::uint32_t moved = 0;         // blocks the replicated deal gave to their standby holder
  };
  std::vector<AssistRound> assist_rounds;
  std::vector<std::uint32_t> real_ws;
  for (std::uint32_t w : {8u, 16u, 32u})
    if (w <= a.max_workers) real_ws.push_back(w);
  if (a.assist_blocks > 0 && real_ws.empty() && a.max_workers >= 2) real_ws.push_back(a.max_workers);
  for (const std::uint32_t assist_w : real_ws) {
    if (a.assist_blocks == 0) break;
    std::fprintf(stderr, "scale: real rounds with %u in-process workers (plain, assist, replicas, both)\n", assist_w);
    zmq::context_t actx(1);
    const Split sp = split_for(assist_w, geom::Mapping::block_cyclic);
    auto blocks = net::tree_blocks(part_tree, sp.layer, sp.block_size);
    if (!blocks) die("scale", blocks.error());
    const std::string tag = "assist-" + std::to_string(::getpid()) + "-" + std::to_string(assist_w);
    net::WorkerConfig room;  // four clients, up to two sets each (a share and its standby copies)
    room.max_sets = 8;
    auto lw = net::LocalWorkers::start(
        actx, int(assist_w), share_backends(per_block), [&](int i) { return net::inproc_endpoint(i, tag); }, room);
    if (!lw) die("scale", lw.error());
    constexpr int kClients = 4;  // plain, assist, replicas, replicas + assist
    std::unique_ptr<net::ScatterGather> sg[kClients];
    for (int k = 0; k < kClients; ++k) {
      net::ScatterConfig cfg;
      cfg.endpoints = lw.value()->endpoints();
      cfg.assist_blocks = k % 2 ? a.assist_blocks : 0;
      cfg.replicas = k >= 2;
      auto c = net::ScatterGather::create(actx, cfg, probe, object, blocks.value());
      if (!c) die("scale", c.error());
      sg[k] = std::move(c).value();
      if (!sg[k]->wait_ready(Clock::now() + std::chrono::seconds(300))) die("scale", "in-process workers not ready");
    }
    const auto work = [&](const net::QueryStats& q) {
      return cost_sphere_us * double(q.sphere_tests) + cost_tri_us * double(q.tri_tests);
    };
    std::uint64_t seq = 0;
    net::RoundResult r[kClients];
    for (std::size_t i = 0; i < poses.size(); ++i) {
      for (int k = 0; k < kClients; ++k) {
        sg[k]->round(++seq, poses_before[i], Clock::now() + std::chrono::seconds(60), r[k]);
        sg[k]->round(++seq, poses[i], Clock::now() + std::chrono::seconds(60), r[k]);
        if (!r[k].complete) die("scale", "real rounds check: an incomplete round");
        if (r[k].pairs != r[0].pairs) die("scale", "real rounds check: the pairs differ with assist or replicas");
      }
      AssistRound ar;
      ar.pose = i + 1;
      ar.workers = assist_w;
      ar.contacts = std::uint32_t(r[0].contacts());
      ar.blocks = r[1].blocks_assisted;
      ar.moved = r[2].blocks_moved;
      double load[kClients] = {}, sum[kClients] = {};
      for (int k = 0; k < kClients; ++k)
        for (const net::QueryStats& q : r[k].worker_stats) {
          load[k] = std::max(load[k], work(q));
          sum[k] += work(q);
        }
      const auto critical = [&](int k) {
        const double client = work(r[k].assist), all = sum[k] + client;
        return all > 0 ? std::max(load[k], client) * assist_w / all : 1.0;
      };
      ar.imbalance = sum[0] > 0 ? load[0] * assist_w / sum[0] : 1.0;
      ar.assisted = sum[1] > 0 ? load[1] * assist_w / sum[1] : 1.0;
      ar.critical = critical(1);
      ar.client = load[1] > 0 ? work(r[1].assist) / load[1] : 0.0;
      ar.replicated = sum[2] > 0 ? load[2] * assist_w / sum[2] : 1.0;
      ar.replicated_critical = critical(3);
      assist_rounds.push_back(ar);
    }
  }

  // Over the poses, per (W, mapping): how the imbalance and the redundant work spread (one pose's
  // figure is one draw: which worker a contact's heavy blocks fall to changes with the pose).
  struct Spread {
    double mean = 0, median = 0, max = 0;
  };
  struct Summary {
    std::uint32_t workers = 0;
    geom::Mapping mapping = geom::Mapping::block_cyclic;
    std::size_t poses = 0;
    Spread imbalance_counted, imbalance, redundancy_counted, redundancy, oracle, block, shipped, assisted, critical,
        replicated;
  };
  std::vector<Summary> summaries;
  for (std::uint32_t W : ws)
    for (geom::Mapping m : mappings) {
      std::vector<double> v[10];
      for (const Row& r : rows)
        if (r.workers == W && r.mapping == m) {
          v[0].push_back(r.work_imbalance());
          v[1].push_back(r.imbalance());
          v[2].push_back(r.work_redundancy());
          v[3].push_back(r.redundancy());
          v[4].push_back(r.oracle_imbalance);
          v[5].push_back(r.block_imbalance);
          v[6].push_back(r.shipped_imbalance);
          v[7].push_back(r.assisted_imbalance);
          v[8].push_back(r.assist_critical);
          v[9].push_back(r.replicated_imbalance);
        }
      if (v[0].empty()) continue;
      const auto spread = [](const std::vector<double>& x) {
        Spread sp;
        for (double e : x) sp.mean += e / double(x.size()), sp.max = std::max(sp.max, e);
        sp.median = median(x);
        return sp;
      };
      summaries.push_back({W, m, v[0].size(), spread(v[0]), spread(v[1]), spread(v[2]), spread(v[3]), spread(v[4]),
                           spread(v[5]), spread(v[6]), spread(v[7]), spread(v[8]), spread(v[9])});
    }

  // 4. The gather on this machine: raw inproc fan-out floor for small W, with a reply of the
  //    mean size, and the model checked against real in-process rounds at W = 1 and 2.
  std::vector<std::pair<std::uint32_t, double>> floors;  // W, p50 us (inproc)
  std::vector<Check> checks;
  {
    zmq::context_t ctx(1);
    std::size_t reply = 64;
    for (const Row& r : rows)
      if (r.workers == 1) reply = std::max(reply, r.max_reply_bytes);
    for (std::uint32_t W : {1u, 2u, 4u, 8u}) {
      if (W > a.max_workers) break;
      FanOutFloor fl(ctx, "inproc", int(W), reply / W);
      std::vector<double> t;
      for (int r = 0; r < a.gather_rounds + 50; ++r) {
        const auto t0 = Clock::now();
        fl.round(std::chrono::milliseconds(100));
        if (r >= 50) t.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
        std::this_thread::sleep_for(std::chrono::microseconds(500));
      }
      floors.push_back({W, median(t)});
    }
    if (a.validate) {
      for (std::uint32_t W : {1u, 2u}) {
        if (W > a.max_workers) break;
        const Split sp = split_for(W, geom::Mapping::block_cyclic);
        auto blocks = net::tree_blocks(part_tree, sp.layer, sp.block_size);
        if (!blocks || blocks.value().size() < W) continue;
        static int fleets = 0;
        const std::string tag = "scale-" + std::to_string(::getpid()) + "-" + std::to_string(fleets++);
        auto lw = net::LocalWorkers::start(ctx, int(W), share_backends(per_block),
                                           [&](int i) { return net::inproc_endpoint(i, tag); });
        if (!lw) die("scale", lw.error());
        net::ScatterConfig cfg;
        cfg.endpoints = lw.value()->endpoints();
        auto sg = net::ScatterGather::create(ctx, cfg, probe, object, std::move(blocks).value());
        if (!sg) die("scale", sg.error());
        if (!sg.value()->wait_ready(Clock::now() + std::chrono::seconds(60)))
          die("scale", "in-process workers not ready");
        const double fl = std::find_if(floors.begin(), floors.end(), [&](auto& f) { return f.first == W; })->second;
        net::RoundResult rr;
        std::uint64_t seq = 0;
        // Our own gather: the same workers answering an empty query (probe far away): the floor plus
        // everything of ours in a round (encode, worker service, decode, merge bookkeeping).
        geom::Pose far = geom::Pose::Identity();
        far.translation() = geom::Vec3(1e5, 0, 0);
        // The same shares as the workers hold, queried at once in this process's threads.
        std::vector<std::unique_ptr<net::CollisionBackend>> shares;
        {
          auto bl = net::tree_blocks(part_tree, sp.layer, sp.block_size);
          if (!bl) die("scale", bl.error());
          for (const auto& ids : net::deal_blocks(std::uint32_t(bl.value().size()), W, geom::Mapping::block_cyclic, 1)) {
            if (ids.empty()) continue;
            auto set = net::make_block_set(probe, object, bl.value(), ids, geom::DefaultTreeConfig().leaf_faces);
            if (!set) die("scale", set.error());
            shares.push_back(share_backends(per_block)());
            if (Status st = shares.back()->load(set.value()); !st) die("scale", st.error());
          }
        }
        // Per pose, the real round, the empty round, the shares' queries one after the other
        // (alone) and all at once, interleaved in short blocks: the prediction's terms and the
        // measured round then see the same host (this VM's speed moves by up to 2x in minutes).
        const int block = std::max(5, a.gather_rounds / 16);
        constexpr int kTrials = 4;
        std::vector<net::FacePair> scratch_pairs;
        for (std::size_t i = 0; i < poses.size(); ++i) {
          const auto it = std::find_if(rows.begin(), rows.end(), [&](const Row& r) {
            return r.pose == i + 1 && r.workers == W && r.mapping == geom::Mapping::block_cyclic;
          });
          if (it == rows.end()) continue;
          std::vector<double> t, inside, empty_here, alone, corun;
          auto real_rounds = [&](const geom::Pose& pose, int n, std::vector<double>* into, std::vector<double>* in) {
            for (int r = 0; r < n; ++r) {
              const auto t0 = Clock::now();
              sg.value()->round(++seq, pose, Clock::now() + std::chrono::milliseconds(200), rr);
              if (into && rr.complete) {
                into->push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
                if (in) in->push_back(double(rr.stats.compute_ns) * 1e-3);
              }
              std::this_thread::sleep_for(std::chrono::microseconds(500));
            }
          };
          real_rounds(poses[i], 20, nullptr, nullptr);  // warm
          for (int trial = 0; trial < kTrials; ++trial) {
            real_rounds(poses[i], block, &t, &inside);
            real_rounds(far, block, &empty_here, nullptr);
            for (int r = 0; r < block; ++r) {
              double slowest = 0;
              for (auto& sh : shares) {
                const auto t0 = Clock::now();
                scratch_pairs.clear();
                sh->query(poses[i], {}, scratch_pairs, {.max_pairs = limits.max_pairs});
                slowest = std::max(slowest, std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
              }
              alone.push_back(slowest);
              std::this_thread::sleep_for(std::chrono::microseconds(500));
            }
            corun.push_back(corun_us(shares, poses[i], block, limits.max_pairs));
          }
          // The rest of the compute term as the row measured it: the slowest worker's encode and
          // the client's decode and merge.
          const double rest = it->compute_round_us - it->max_us;
          Check c;
          c.pose = i + 1;
          c.workers = W;
          c.floor_us = fl;
          c.gather_us = median(std::move(empty_here));
          c.compute_alone_us = median(std::move(alone));
          c.predicted_us = c.gather_us + c.compute_alone_us + rest;
          c.measured_us = median(std::move(t));
          c.compute_in_round_us = median(std::move(inside));
          c.compute_corun_us = median(std::move(corun));
          c.predicted_corun_us = c.gather_us + c.compute_corun_us + rest;
          checks.push_back(c);
        }
      }
    }
  }

  // 5. Our client's CPU per round over tcp at the fit's W (our_client_cpu_tcp), at an empty query
  //    and at each pose, bracketed by the raw client's (client_cpu_tcp: the same DEALERs to
  //    echoes, without our protocol, workers or merge) just before and just after (this VM's
  //    speed moves in minutes: the fit above ran long before); against the raw client and against
  //    what the model charges this VM's client: the raw client's CPU and the measured work on the
  //    Results, as they come and after the last. Every context of the sections above is gone: no
  //    thread runs here when they fork.
  struct OurClient {
    std::uint32_t workers = 0;
    double raw_us = 0;       // the raw client's, the mean of the runs before and after ours
    std::vector<double> us;  // ours: the empty query's, then each pose's
  };
  std::vector<OurClient> ours;
  if (a.validate) {
    geom::Pose far = geom::Pose::Identity();
    far.translation() = geom::Vec3(1e5, 0, 0);
    std::vector<geom::Pose> at = {far};
    at.insert(at.end(), poses.begin(), poses.end());
    const int rounds = std::max(50, a.gather_rounds / 2);
    for (std::uint32_t W : cpu_ws) {
      if (W > a.max_workers) break;
      const Split sp = split_for(W, geom::Mapping::block_cyclic);
      auto blocks = net::tree_blocks(part_tree, sp.layer, sp.block_size);
      if (!blocks || blocks.value().size() < W) continue;
      std::fprintf(stderr, "scale: our client's CPU per round over tcp, %u workers in a child process ...\n", W);
      OurClient o{W, client_cpu_tcp({W}, 8 * 64, rounds)[0], {}};
      o.us = our_client_cpu_tcp(W, probe, object, std::move(blocks).value(), net::tree_backend_factory(per_block), at,
                                rounds);
      o.raw_us = 0.5 * (o.raw_us + client_cpu_tcp({W}, 8 * 64, rounds)[0]);
      ours.push_back(std::move(o));
    }
  }
  std::vector<std::uint32_t> ours_ws;
  std::vector<double> ours_far, ours_raw;
  for (const OurClient& o : ours) {
    ours_ws.push_back(o.workers);
    ours_far.push_back(o.us[0]);
    ours_raw.push_back(o.raw_us);
  }
  const auto [ours_a, ours_b] = fit_line(ours_ws, ours_far);
  const auto [raw_a, raw_b] = fit_line(ours_ws, ours_raw);
  // What the model charges this VM's client at pose i (1-based; 0: the empty query) of `o`: the
  // raw client's CPU there, and the work on the Results the row measured.
  const auto client_predicted = [&](std::size_t i, const OurClient& o) {
    if (i == 0) return o.raw_us;
    for (const Row& r : rows)
      if (r.pose == i && r.workers == o.workers && r.mapping == geom::Mapping::block_cyclic)
        return o.raw_us + r.arrivals_us + r.tail_us;
    return 0.0;
  };

  // The client's side of the gather: W message pairs of work (wake-up free), or this VM's measured
  // CPU per round (a + b W, its wake-ups included).
  const auto client_gather = [&](std::uint32_t W, const Network& n) {
    return n.vm_client ? cpu_a + cpu_b * W : msg_work * W;
  };
  const auto predicted = [&](const Row& r, const Network& n) {
    return r.compute_round_us + client_gather(r.workers, n) + n.rtt_us + double(r.max_reply_bytes) / n.bytes_per_us;
  };
  // With the replicated deal (ScatterConfig::replicas): the slowest worker is the mean one times
  // the deal's imbalance (replicated_imbalance, judged by the work reported the round before);
  // its encode and the client's merge as measured.
  const auto compute_replicated = [](const Row& r) {
    return r.mean_us * r.replicated_imbalance + (r.encode_max_us - r.max_us) + r.client_us;
  };
  const auto predicted_replicated = [&](const Row& r, const Network& n) {
    return predicted(r, n) - r.compute_round_us + compute_replicated(r);
  };
  // The flat gather on network n simulated event by event (Row::worker_us), as ScatterGather runs
  // it: the client sends the W Queries in `order`, each half a message pair of its work (the other
  // half is its Result's receipt); worker w starts when its Query has crossed (half a round trip)
  // and its Result is ready after its query and encode; the Results cross back (half a round
  // trip), one at a time on the client's link (their bytes at its bandwidth); the client takes each
  // when it has arrived and the client is free (it is busy sending until all Queries are out): the
  // other half of a message pair and its share of the work on the Results as they come; after the
  // last, the rest of the merge (the run's client: no distinct faces). Unlike `predicted`, the
  // receipts of all but the last Results overlap the slower workers' compute. On this VM's client
  // CPU (vm_client) a message pair costs the fit's b and a round its a (added at the end).
  // Messages taken as they come over one link, the step both simulated gathers share: each (when
  // it leaves its sender, its bytes) crosses half a round trip of n, then its bytes at n's
  // bandwidth, one at a time; the taker, busy until `busy`, spends `cost` on each once it has
  // arrived. Returns when the taker is done with the last.
  const auto take_as_they_come = [](std::vector<std::pair<double, std::size_t>>& sent, const Network& n, double busy,
                                    double cost) {
    std::sort(sent.begin(), sent.end());
    double link = 0;
    for (const auto& [leaves, bytes] : sent) {
      link = std::max(link, leaves + n.rtt_us / 2) + double(bytes) / n.bytes_per_us;
      busy = std::max(busy, link) + cost;
    }
    return busy;
  };
  const auto predicted_simulated = [&](const Row& r, const Network& n, bool replicated) {
    const std::vector<double>& worker = replicated ? r.replicated_us : r.worker_us;
    const std::vector<std::uint32_t>& order = replicated ? r.replicated_send_order : r.send_order;
    if (worker.size() != r.workers || order.size() != r.workers) return 0.0;
    const double half = 0.5 * (n.vm_client ? cpu_b : msg_work), each = r.arrivals_us / r.workers;
    std::vector<std::pair<double, std::size_t>> ready;  // (when its Result leaves the worker, its bytes)
    double t = 0;
    for (const std::uint32_t w : order) {
      t += half;
      ready.push_back({t + n.rtt_us / 2 + worker[w], r.reply_bytes[w]});
    }
    return take_as_they_come(ready, n, t, half + each) + r.tail_us + (n.vm_client ? cpu_a : 0.0);
  };
  // The two-level gather (Row::TwoLevel) on network n: the slowest worker (with its encode), two
  // round trips (client - leader, leader - member), the client's message work for the ceil(W / g)
  // leaders and a leader's for its g - 1 members, the slowest leader's merge and the client's, and
  // the largest member and leader replies on the wire. Without this VM's client CPU (the leaders'
  // wake-ups would be a second client's).
  const auto predicted_two_level = [&](const Row& r, const Row::TwoLevel& t, const Network& n, bool replicated) {
    const double worker = replicated ? r.mean_us * r.replicated_imbalance + (r.encode_max_us - r.max_us) : r.encode_max_us;
    const double leaders = std::ceil(double(r.workers) / t.group);
    return worker + 2 * n.rtt_us + (leaders + t.group - 1) * msg_work + t.leader_us + t.client_us +
           double(r.max_reply_bytes + t.leader_reply_bytes) / n.bytes_per_us;
  };
  // The same gather simulated event by event, as predicted_simulated does the flat one: the W
  // workers in the client's send order dealt round-robin into ceil(W / g) groups (each group a
  // mix of heavy and light workers), the lightest of each its leader. The client sends the leaders'
  // Queries (half a message pair each); a leader relays the Query to its members (half a pair
  // each), then answers its own share; each member's Result crosses back to it over its link; once
  // its own share is done the leader takes them as they come (half a pair each), then merges and
  // encodes (the slowest leader's measured decode + merge + encode, t.leader_us) and sends one
  // Result (the largest leader reply's bytes); the client takes the leaders' Results as they come
  // (half a pair each), then decodes and merges them (t.client_us, after the last: conservative).
  const auto predicted_two_level_simulated = [&](const Row& r, const Row::TwoLevel& t, const Network& n, bool replicated) {
    const std::vector<double>& worker = replicated ? r.replicated_us : r.worker_us;
    const std::vector<std::uint32_t>& order = replicated ? r.replicated_send_order : r.send_order;
    if (worker.size() != r.workers || order.size() != r.workers || t.group < 2) return 0.0;
    const double half = 0.5 * msg_work;
    const std::size_t groups = (r.workers + t.group - 1) / t.group;
    std::vector<std::pair<double, std::size_t>> back;  // (a leader's Result leaves it, its bytes)
    double client = 0;
    for (std::size_t k = 0; k < groups; ++k) {
      std::vector<std::uint32_t> members;
      for (std::size_t i = k; i < order.size(); i += groups) members.push_back(order[i]);
      const auto lead = std::min_element(members.begin(), members.end(),
                                         [&](std::uint32_t x, std::uint32_t y) { return worker[x] < worker[y]; });
      const std::uint32_t leader = *lead;
      members.erase(lead);
      client += half;                                  // the leader's Query out
      double at = client + n.rtt_us / 2;               // ... at the leader
      std::vector<std::pair<double, std::size_t>> in;  // (a member's Result leaves it, its bytes)
      for (const std::uint32_t m : members) {
        at += half;  // relayed
        in.push_back({at + n.rtt_us / 2 + worker[m], r.reply_bytes[m]});
      }
      const double busy = take_as_they_come(in, n, at + worker[leader], half);  // its own share after the relays
      back.push_back({busy + t.leader_us, t.leader_reply_bytes});
    }
    return take_as_they_come(back, n, client, half) + t.client_us;
  };

  if (a.json) {
    // Byte and face counts are whole numbers held in doubles: integers in the JSON, as before.
    auto whole = [](double v) { return static_cast<std::int64_t>(std::llround(v)); };
    Json us_per_round = Json::array();
    for (double v : cpu_tcp) us_per_round.push_back(round_to(v, 2));
    Json pub_per_round = Json::array();
    for (double v : cpu_pub) pub_per_round.push_back(round_to(v, 2));
    Json networks = Json::array();
    for (const Network& n : kNetworks)
      networks.push_back({{"name", n.name},
                          {"rtt_us", round_to(n.rtt_us, 2)},
                          {"bytes_per_us", whole(n.bytes_per_us)},
                          {"vm_client", n.vm_client}});
    Json inproc_floor = Json::array();
    for (const auto& [W, p50] : floors) inproc_floor.push_back({{"workers", W}, {"p50_us", round_to(p50, 2)}});
    Json validation = Json::array();
    for (const Check& c : checks)
      validation.push_back({{"pose", c.pose},
                            {"workers", c.workers},
                            {"floor_us", round_to(c.floor_us, 2)},
                            {"predicted_us", round_to(c.predicted_us, 2)},
                            {"measured_us", round_to(c.measured_us, 2)},
                            {"compute_alone_us", round_to(c.compute_alone_us, 2)},
                            {"compute_in_round_us", round_to(c.compute_in_round_us, 2)},
                            {"gather_us", round_to(c.gather_us, 2)},
                            {"compute_corun_us", round_to(c.compute_corun_us, 2)},
                            {"predicted_corun_us", round_to(c.predicted_corun_us, 2)}});
    Json mem = Json::array();
    for (const Memory& m : memory)
      mem.push_back({{"workers", m.workers},
                     {"mapping", geom::to_string(m.mapping)},
                     {"max_share_faces", whole(m.max_share_faces)},
                     {"max_share_bytes", whole(m.max_share_bytes)},
                     {"per_worker_over_single", round_to(m.max_share_bytes / object_bytes, 4)}});
    Json rws = Json::array();
    for (const Row& r : rows) {
      Json j = {{"pose", r.pose},
                {"contacts", r.contacts},
                {"workers", r.workers},
                {"mapping", geom::to_string(r.mapping)},
                {"layer", r.split.layer},
                {"block_size", r.split.block_size},
                {"blocks", r.split.blocks},
                {"auto_split", r.split.automatic},
                {"busy_workers", r.busy},
                {"single_us", round_to(r.single_us, 2)},
                {"single_beside_us", {round_to(r.single_beside_us[0], 2), round_to(r.single_beside_us[1], 2)}},
                {"max_worker_us", round_to(r.max_us, 2)},
                {"mean_worker_us", round_to(r.mean_us, 2)},
                {"sum_worker_us", round_to(r.sum_us, 2)},
                {"imbalance", round_to(r.imbalance(), 3)},
                {"redundancy", round_to(r.redundancy(), 3)},
                {"client_us", round_to(r.client_us, 2)},
                {"compute_round_us", round_to(r.compute_round_us, 2)},
                {"max_reply_bytes", r.max_reply_bytes},
                {"compute_speedup", round_to(r.single_us / r.compute_round_us, 3)},
                {"sphere_tests_ratio", round_to(r.sphere_ratio(), 3)},
                {"tri_tests_ratio", round_to(r.tri_ratio(), 3)},
                {"probe_leaves_ratio", round_to(r.probe_leaves_ratio(), 3)},
                {"imbalance_counted", round_to(r.work_imbalance(), 3)},
                {"redundancy_counted", round_to(r.work_redundancy(), 3)},
                {"oracle_imbalance", round_to(r.oracle_imbalance, 3)},
                {"block_imbalance", round_to(r.block_imbalance, 3)},
                {"shipped_imbalance", round_to(r.shipped_imbalance, 3)},
                {"shipped_blocks", r.shipped_blocks},
                {"shipped_faces", r.shipped_faces},
                {"replicated_imbalance", round_to(r.replicated_imbalance, 3)},
                {"assisted_imbalance", round_to(r.assisted_imbalance, 3)},
                {"assist_critical", round_to(r.assist_critical, 3)},
                {"assist_client", round_to(r.assist_client, 3)},
                {"assisted_blocks", r.assisted_blocks}};
      for (const Network& n : kNetworks) {
        j[std::string("round_") + n.name + "_us"] = round_to(predicted(r, n), 2);
        j[std::string("speedup_") + n.name] = round_to(r.single_us / predicted(r, n), 3);
      }
      j["client_arrivals_us"] = round_to(r.arrivals_us, 2);
      j["client_tail_us"] = round_to(r.tail_us, 2);
      j["client_distinct_us"] = round_to(r.distinct_us, 2);
      for (const Network& n : kNetworks)
        for (const bool replicated : {false, true})
          if (const double us = predicted_simulated(r, n, replicated); us > 0) {
            const std::string key = std::string(n.name) + "_simulated" + (replicated ? "_replicated" : "");
            j["round_" + key + "_us"] = round_to(us, 2);
            j["speedup_" + key] = round_to(r.single_us / us, 3);
          }
      j["compute_speedup_replicated"] = round_to(r.single_us / compute_replicated(r), 3);
      for (const Network& n : kNetworks)
        j[std::string("speedup_") + n.name + "_replicated"] = round_to(r.single_us / predicted_replicated(r, n), 3);
      Json two = Json::array();
      for (const Row::TwoLevel& t : r.two_level) {
        Json x = {{"group", t.group},
                  {"leader_us", round_to(t.leader_us, 2)},
                  {"client_us", round_to(t.client_us, 2)},
                  {"leader_reply_bytes", t.leader_reply_bytes}};
        for (const Network& n : kNetworks) {
          if (n.vm_client) continue;
          x[std::string("speedup_") + n.name] = round_to(r.single_us / predicted_two_level(r, t, n, false), 3);
          x[std::string("speedup_") + n.name + "_replicated"] =
              round_to(r.single_us / predicted_two_level(r, t, n, true), 3);
          for (const bool rep : {false, true})
            if (const double us = predicted_two_level_simulated(r, t, n, rep); us > 0)
              x[std::string("speedup_") + n.name + "_simulated" + (rep ? "_replicated" : "")] =
                  round_to(r.single_us / us, 3);
        }
        two.push_back(std::move(x));
      }
      j["two_level"] = std::move(two);
      rws.push_back(std::move(j));
    }
    Json assist = Json::array();
    for (const AssistRound& x : assist_rounds)
      assist.push_back({{"pose", x.pose},
                        {"contacts", x.contacts},
                        {"workers", x.workers},
                        {"assist_blocks", a.assist_blocks},
                        {"blocks_assisted", x.blocks},
                        {"imbalance_counted", round_to(x.imbalance, 3)},
                        {"assisted_imbalance", round_to(x.assisted, 3)},
                        {"assist_critical", round_to(x.critical, 3)},
                        {"assist_client", round_to(x.client, 3)},
                        {"replicated_real", round_to(x.replicated, 3)},
                        {"replicated_assist_critical", round_to(x.replicated_critical, 3)},
                        {"blocks_moved", x.moved}});
    Json summary = Json::array();
    for (const Summary& u : summaries) {
      Json j = {{"workers", u.workers}, {"mapping", geom::to_string(u.mapping)}, {"poses", u.poses}};
      for (auto [name, sp] :
           {std::pair{"imbalance_counted", &u.imbalance_counted}, std::pair{"imbalance", &u.imbalance},
            std::pair{"redundancy_counted", &u.redundancy_counted}, std::pair{"redundancy", &u.redundancy},
            std::pair{"oracle_imbalance", &u.oracle}, std::pair{"block_imbalance", &u.block},
            std::pair{"shipped_imbalance", &u.shipped}, std::pair{"assisted_imbalance", &u.assisted},
            std::pair{"assist_critical", &u.critical}, std::pair{"replicated_imbalance", &u.replicated}})
        j[name] = {{"mean", round_to(sp->mean, 3)}, {"median", round_to(sp->median, 3)}, {"max", round_to(sp->max, 3)}};
      summary.push_back(std::move(j));
    }
    // Our client's CPU per round (section 5): per W, the empty query's and each pose's, with what
    // the model charges the client there.
    Json ours_json = Json::object();
    if (!ours.empty()) {
      Json far_us = Json::array(), raw_us = Json::array(), per_pose = Json::array();
      for (const OurClient& o : ours) {
        far_us.push_back(round_to(o.us[0], 2));
        raw_us.push_back(round_to(o.raw_us, 2));
      }
      for (std::size_t i = 1; i <= poses.size(); ++i) {
        Json us = Json::array(), pred = Json::array();
        for (const OurClient& o : ours) {
          us.push_back(round_to(o.us[i], 2));
          pred.push_back(round_to(client_predicted(i, o), 2));
        }
        per_pose.push_back({{"pose", i}, {"us_per_round", std::move(us)}, {"predicted_us", std::move(pred)}});
      }
      ours_json = {{"workers", ours_ws},
                   {"raw_us_per_round", std::move(raw_us)},
                   {"raw_fit_a_us", round_to(raw_a, 2)},
                   {"raw_fit_b_us_per_worker", round_to(raw_b, 3)},
                   {"empty_us_per_round", std::move(far_us)},
                   {"fit_a_us", round_to(ours_a, 2)},
                   {"fit_b_us_per_worker", round_to(ours_b, 3)},
                   {"poses", std::move(per_pose)}};
    }
    print_json({{"bench", "scale"},
                {"probe", a.probe},
                {"object", a.object},
                {"object_faces", object.faces.size()},
                {"runs", a.runs},
                {"share_tree", a.share_tree},
                {"contact_radius_mm", round_to(model.contact_radius, 3)},
                {"object_bytes", whole(object_bytes)},
                {"client_cpu_tcp",
                 {{"workers", cpu_ws},
                  {"us_per_round", std::move(us_per_round)},
                  {"fit_a_us", round_to(cpu_a, 2)},
                  {"fit_b_us_per_worker", round_to(cpu_b, 3)}}},
                {"client_cpu_tcp_pub_pull",
                 {{"workers", cpu_ws},
                  {"us_per_round", std::move(pub_per_round)},
                  {"fit_a_us", round_to(pub_a, 2)},
                  {"fit_b_us_per_worker", round_to(pub_b, 3)}}},
                {"client_message_work_us", round_to(msg_work, 3)},
                {"client_cpu_ours", std::move(ours_json)},
                {"test_cost",
                 {{"us_per_sphere_test", round_to(cost_sphere_us, 6)}, {"us_per_tri_test", round_to(cost_tri_us, 6)}}},
                {"networks", std::move(networks)},
                {"inproc_floor", std::move(inproc_floor)},
                {"validation", std::move(validation)},
                {"memory", std::move(mem)},
                {"rows", std::move(rws)},
                {"assist_rounds", std::move(assist)},
                {"summary", std::move(summary)}});
    return;
  }

  std::printf(
      "scale-out model: %s x %s (%zu faces); %d runs per share (medians); contact radius %.1f mm for the "
      "automatic split; share trees %s\n",
      a.probe.c_str(), a.object.c_str(), object.faces.size(), a.runs, model.contact_radius, a.share_tree.c_str());
  std::printf("client CPU per round over tcp (measured): ");
  for (std::size_t i = 0; i < cpu_tcp.size(); ++i) std::printf("W=%u %.1f us  ", cpu_ws[i], cpu_tcp[i]);
  std::printf("-> %.1f + %.2f W us\n", cpu_a, cpu_b);
  std::printf("... one PUB + one PULL instead of a DEALER per worker: ");
  for (std::size_t i = 0; i < cpu_pub.size(); ++i) std::printf("W=%u %.1f us  ", cpu_ws[i], cpu_pub[i]);
  std::printf("-> %.1f + %.2f W us\nclient work per worker message, no wake-up (measured): %.2f us\n", pub_a, pub_b,
              msg_work);
  if (!ours.empty()) {
    std::printf("our client's CPU per round over tcp (workers in a child process; empty query): ");
    for (const OurClient& o : ours) std::printf("W=%u %.1f us (raw %.1f)  ", o.workers, o.us[0], o.raw_us);
    std::printf("-> %.1f + %.2f W us (raw: %.1f + %.2f W)\n", ours_a, ours_b, raw_a, raw_b);
    for (std::size_t i = 1; i <= poses.size(); ++i) {
      std::printf("  pose %zu: ", i);
      for (const OurClient& o : ours) {
        const double p = client_predicted(i, o);
        std::printf("W=%u %.1f us (model %.1f, %+.1f %%)  ", o.workers, o.us[i], p, 100.0 * (p - o.us[i]) / o.us[i]);
      }
      std::printf("\n");
    }
  }
  std::printf("inproc fan-out floor p50 (measured): ");
  for (auto& f : floors) std::printf("W=%u %.1f us  ", f.first, f.second);
  std::printf(
      "counted work: %.4f us per sphere-pair test, %.4f us per triangle-pair test (measured: the single thread's "
      "queries stopped at the leaf spheres, and the rest of the exact ones)\n",
      cost_sphere_us, cost_tri_us);
  std::printf("\n%4s %8s %3s %-12s %5s %4s %8s %8s %8s %6s %6s %6s %6s %6s %6s %8s %8s %7s %7s %7s %7s\n", "pose",
              "contacts", "W", "mapping", "layer", "B", "single", "max", "mean", "imbal", "redund", "imbal#", "redun#",
              "xsph", "xtri", "compute", "10GbE", "x10GbE", "xvm", "x100GbE", "xrep");
  for (const Row& r : rows)
    std::printf(
        "%4zu %8u %3u %-12s %5u %4u %8.1f %8.1f %8.1f %6.2f %6.2f %6.2f %6.2f %6.2f %6.2f %8.1f %8.1f %7.2f %7.2f "
        "%7.2f %7.2f\n",
        r.pose, r.contacts, r.workers, geom::to_string(r.mapping), r.split.layer, r.split.block_size, r.single_us,
        r.max_us, r.mean_us, r.imbalance(), r.redundancy(), r.work_imbalance(), r.work_redundancy(), r.sphere_ratio(),
        r.tri_ratio(), r.compute_round_us, predicted(r, kNetworks[0]), r.single_us / predicted(r, kNetworks[0]),
        r.single_us / predicted(r, kNetworks[1]), r.single_us / predicted(r, kNetworks[2]),
        r.single_us / predicted_replicated(r, kNetworks[0]));
  std::printf(
      "single/max/mean: us per round (one thread; slowest worker; mean over W); imbal = max/mean; redund = sum "
      "over workers / single (time); imbal#, redun#: the same from the counted tests weighted by the measured cost "
      "per test (deterministic); xsph, xtri = sphere-pair and triangle-pair tests summed over workers / single "
      "(counted); compute = slowest worker with its encode + the client's decode and merge; "
      "10GbE = compute + W x message work + 16.25 us + largest reply at 10 Gbit/s; x = single / predicted "
      "round (xvm: with this VM's client CPU per round instead; xrep: 10GbE with the replicated deal, the slowest "
      "worker = mean x the deal's imbalance)\n");
  std::printf(
      "\ntwo-level gather (a model, not built): groups of g workers, a leader relays the Query and merges its "
      "group's Results; 10GbE with the replicated deal, flat (xrep above) against the best g (its leader's and the "
      "client's decode + merge measured):\n");
  for (const Row& r : rows) {
    if (r.mapping != geom::Mapping::block_cyclic || r.two_level.empty()) continue;
    const Row::TwoLevel* best = nullptr;
    double best_us = 0;
    for (const Row::TwoLevel& t : r.two_level) {
      const double us = predicted_two_level(r, t, kNetworks[0], true);
      if (!best || us < best_us) best = &t, best_us = us;
    }
    std::printf("  pose %zu W=%u: flat %.1f us (x%.2f), g=%u %.1f us (x%.2f): leader %.1f us, client %.1f us\n", r.pose,
                r.workers, predicted_replicated(r, kNetworks[0]), r.single_us / predicted_replicated(r, kNetworks[0]),
                best->group, best_us, r.single_us / best_us, best->leader_us, best->client_us);
  }
  std::printf(
      "\nthe flat gather simulated event by event (the client takes each Result as it comes, the slowest worker of "
      "the round before sent its Query first; receipts overlap the slower workers' compute): 10GbE plain / "
      "replicated deal (the run's client: no distinct faces), and the client's work on the Results as they come / "
      "after the last / the distinct faces it leaves out:\n");
  for (const Row& r : rows) {
    if (r.mapping != geom::Mapping::block_cyclic) continue;
    const double plain = predicted_simulated(r, kNetworks[0], false), rep = predicted_simulated(r, kNetworks[0], true);
    if (plain <= 0 || rep <= 0) continue;
    std::printf("  pose %zu W=%u: %.1f us (x%.2f) / %.1f us (x%.2f); client %.1f / %.1f / %.1f us\n", r.pose, r.workers,
                plain, r.single_us / plain, rep, r.single_us / rep, r.arrivals_us, r.tail_us, r.distinct_us);
  }
  std::printf(
      "\nover the %zu poses (mean / median / max): imbal#, imbal, redun#, redun as above; from the counted work of "
      "each block alone: blocks = the mapping's deal, oracle = the same blocks dealt knowing the pose (largest "
      "first to the least loaded worker: what no static mapping beats), shipped = the deal after the work shipping "
      "model moved up to %u blocks judged by the round before (the probe %.3g mm away; a model, not built); "
      "assisted = the workers' max / mean when the client answers up to %u blocks itself (client assist, built: "
      "net::choose_assist on the work reported per block the round before), critical = the slowest of them and "
      "the client against all the work dealt evenly over W (blocks' own denominator); replicated = every block "
      "also held by a second worker (drawn by a hash of the block) and each round given to the less loaded "
      "holder, judged by the work reported per block the round before (built: ScatterConfig::replicas, modelled here "
      "on each block's work; two shares' memory "
      "per worker)\n",
      poses.size(), a.ship_blocks, a.ship_motion_mm, a.assist_blocks);
  std::printf("%3s %-12s %20s %20s %20s %20s %20s %20s %20s %20s %20s %20s\n", "W", "mapping", "imbal#", "imbal",
              "redun#", "redun", "blocks", "oracle", "shipped", "assisted", "critical", "replicated");
  for (const Summary& u : summaries) {
    std::printf("%3u %-12s", u.workers, geom::to_string(u.mapping));
    for (const Spread* sp : {&u.imbalance_counted, &u.imbalance, &u.redundancy_counted, &u.redundancy, &u.block,
                             &u.oracle, &u.shipped, &u.assisted, &u.critical, &u.replicated})
      std::printf("   %5.2f / %5.2f / %5.2f", sp->mean, sp->median, sp->max);
    std::printf("\n");
  }
  std::printf(
      "model check (in-process workers over inproc, block-cyclic; rounds, empty rounds and the shares' queries "
      "interleaved): predicted = our empty round + the slowest share's query + its encode + the client's merge\n");
  for (const Check& c : checks)
    std::printf(
        "  pose %zu W=%u: predicted %.1f us (empty round %.1f, raw floor %.1f), measured p50 %.1f us, error %+.1f %%; "
        "slowest worker's query alone %.1f us, inside the rounds %.1f us; with the shares' queries run at once "
        "(%.1f us): predicted %.1f us, error %+.1f %%\n",
        c.pose, c.workers, c.predicted_us, c.gather_us, c.floor_us, c.measured_us,
        100.0 * (c.predicted_us - c.measured_us) / c.measured_us, c.compute_alone_us, c.compute_in_round_us,
        c.compute_corun_us, c.predicted_corun_us, 100.0 * (c.predicted_corun_us - c.measured_us) / c.measured_us);
  if (!assist_rounds.empty()) {
    std::printf(
        "real rounds (in-process workers, block-cyclic; assist up to %u blocks; after a round at the pose %.3g mm "
        "away; counted work from each worker's Result): imbalance = workers' max / mean, plain; assisted = with the "
        "client assist; critical = max(slowest worker, client) / (all work / W); client = client / slowest worker; "
        "replicated = with the replicated deal; repl+assist critical = both\n",
        a.assist_blocks, a.ship_motion_mm);
    for (const AssistRound& r : assist_rounds)
      std::printf(
          "  W=%u pose %zu, %u contacts: imbalance %.2f, assisted %.2f, critical %.2f, client %.2f (%u blocks); "
          "replicated %.2f (%u moved), repl+assist critical %.2f\n",
          r.workers, r.pose, r.contacts, r.imbalance, r.assisted, r.critical, r.client, r.blocks, r.replicated, r.moved,
          r.replicated_critical);
  }
  std::printf("memory: largest share / whole object (tree + mesh):");
  for (const Memory& m : memory)
    if (m.mapping == geom::Mapping::block_cyclic)
      std::printf("  W=%u %.3f", m.workers, m.max_share_bytes / object_bytes);
  std::printf("\n");
}

}  // namespace

void add_scale(CLI::App& app) {
  auto a = std::make_shared<ScaleArgs>();
  CLI::App* cmd = app.add_subcommand(
      "scale",
      "Scale-out model: each worker's share of a collision round timed alone, for W = 1, 2, 4, ... workers and the\n"
      "block-cyclic, contiguous and random mappings (critical path, imbalance, redundant work), the gather measured\n"
      "here (inproc floor, client CPU over tcp) and predicted on 10 GbE / 100 GbE, flat and simulated event by\n"
      "event as the client runs it; checked against real rounds at W = 1, 2.\n"
      "Over the poses: the spread of imbalance and redundancy, the oracle deal of the same blocks, and a work\n"
      "shipping model (a few blocks moved each round by the round before's work).");
  cmd->add_option("--probe", a->probe, "probe mesh (the hand)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--object", a->object, "object mesh")->required()->check(CLI::ExistingFile);
  cmd->add_option("--poses", a->poses, "pose file (16 numbers a line)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--layer", a->layer, "sphere layer dealt in blocks, or auto (the run's automatic split per W)")
      ->capture_default_str();
  cmd->add_option("--block-size", a->block_size, "layer spheres per block, or auto")->capture_default_str();
  cmd->add_option("--max-workers", a->max_workers, "largest W (powers of two from 1)")
      ->check(CLI::Range(1u, 1024u))
      ->capture_default_str();
  cmd->add_option("--runs", a->runs, "timed runs per share and pose (median)")->check(CLI::Range(1, 100000))->capture_default_str();
  cmd->add_option("--gather-rounds", a->gather_rounds, "rounds per floor / client-CPU / validation point")
      ->check(CLI::Range(20, 1000000))
      ->capture_default_str();
  cmd->add_flag("!--no-validate", a->validate,
                "skip the checks of the model against real rounds: in-process at W = 1, 2, and our client's CPU per "
                "round over tcp at W = 1..16");
  cmd->add_option("--partition-leaf-faces", a->partition_leaf_faces,
                  "cut the blocks from a tree of the object with leaves this small (finer blocks than the object "
                  "tree's own leaves; 0 = those)")
      ->check(CLI::Range(0, 64))
      ->capture_default_str();
  cmd->add_option("--share-tree", a->share_tree,
                  "how a worker's tree over its share is built: per-block (one subtree per block, what workers do) or "
                  "one (one tree over the whole share, as before; to measure the difference)")
      ->check(CLI::IsMember({"per-block", "one"}))
      ->capture_default_str();
  cmd->add_option("--ship-motion-mm", a->ship_motion_mm,
                  "work shipping model: the probe's motion between two rounds (0.1 mm: 100 mm/s at 1 kHz)")
      ->check(CLI::Range(0.0, 1e3))
      ->capture_default_str();
  cmd->add_option("--ship-blocks", a->ship_blocks, "work shipping model: blocks moved per round at most")
      ->check(CLI::Range(0u, 100000u))
      ->capture_default_str();
  cmd->add_option("--assist-blocks", a->assist_blocks,
                  "client assist: blocks the client answers itself per round at most (net::choose_assist, the same "
                  "rule as [workers] assist_blocks), judged by the pairs per block at the pose --ship-motion-mm away")
      ->check(CLI::Range(0u, 256u))
      ->capture_default_str();
  cmd->add_flag("--json", a->json, "print one JSON object instead of the table");
  cmd->callback([a] { run_scale(*a); });
}

}  // namespace st::bench
