// SPDX-License-Identifier: BSD-3-Clause
// Fault injection into `spheretouch run` with four worker daemons over tcp loopback:
// a worker killed with SIGKILL and restarted, a worker frozen with SIGSTOP and thawed, and all
// traffic to a worker held by a relay (the link is down) and released. The same run without
// faults is the reference. Asserted: the haptic loop misses no more ticks than the fault-free
// run (up to scheduler noise, see kMissNoise), force stays finite and within the device limit,
// the per-tick trace has every tick, telemetry drops nothing, the faults were seen (incomplete
// rounds), and rounds are complete again once blocks are reassigned and workers are back.
#include <cmath>
#include <regex>

#include "app/process_util.hpp"
#include "net/process_util.hpp"
#include "net/tcp_proxy.hpp"
#include "test_util.hpp"

namespace {

using namespace std::chrono_literals;

/// Counters from `spheretouch run`'s summary.
struct Summary {
  std::uint64_t ticks = 0, misses = 0, rounds = 0, incomplete = 0, samples = 0, dropped = 0;
  double peak_N = -1;
};

std::uint64_t capture(const std::string& text, const char* pattern) {
  std::smatch m;
  const std::regex re(pattern);
  INFO("summary line not found: " << pattern);
  REQUIRE(std::regex_search(text, m, re));
  return std::stoull(m[1].str());
}

Summary parse_summary(const std::string& log) {
  Summary s;
  s.ticks = capture(log, R"(haptic +(\d+) ticks)");
  s.misses = capture(log, R"(haptic +\d+ ticks [^,]*, (\d+) misses)");
  s.rounds = capture(log, R"(collision +(\d+) rounds)");
  s.incomplete = capture(log, R"((\d+) incomplete)");
  s.samples = capture(log, R"(telemetry +(\d+) samples)");
  s.dropped = capture(log, R"(telemetry +\d+ samples, (\d+) dropped)");
  return s;
}

/// Four worker daemons on loopback; worker 2 is reached through a relay that can drop the link.
struct Fleet {
  st::test::TempDir dir;
  std::vector<int> ports;
  std::vector<std::unique_ptr<st::test::Process>> procs;
  std::unique_ptr<st::test::TcpProxy> relay;
  static constexpr int kRelayed = 2;

  Fleet() {
    for (int i = 0; i < 4; ++i) {
      ports.push_back(st::test::free_port());
      procs.emplace_back();
      start(i);
    }
    relay = std::make_unique<st::test::TcpProxy>(ports[kRelayed]);
  }
  void start(int i) {
    const std::string log = dir.file("worker" + std::to_string(i) + ".log");
    procs[std::size_t(i)] = std::make_unique<st::test::Process>(
        std::vector<std::string>{st::test::worker_binary(), "--bind",
                                 "tcp://127.0.0.1:" + std::to_string(ports[std::size_t(i)]), "--id", std::to_string(i),
                                 "--log-level", "info"},
        log);
    const auto until = std::chrono::steady_clock::now() + 20s;
    while (procs[std::size_t(i)]->log().find("listening on") == std::string::npos) {
      INFO(procs[std::size_t(i)]->log());
      REQUIRE(std::chrono::steady_clock::now() < until);
      std::this_thread::sleep_for(10ms);
    }
  }
  std::string endpoints() const {
    std::string s;
    for (int i = 0; i < 4; ++i) {
      const int port = i == kRelayed ? relay->port() : ports[std::size_t(i)];
      s += std::string(s.empty() ? "" : ", ") + "\"tcp://127.0.0.1:" + std::to_string(port) + "\"";
    }
    return s;
  }
};

std::string fleet_scene(const Fleet& f, double duration_s) {
  return "[probe]\nbuiltin = \"capsule\"\nradius_mm = 6.0\nlength_mm = 30.0\n"
         "[object]\nbuiltin = \"icosphere\"\nradius_mm = 40.0\nfrequency = 20\n"
         "[tree]\ncache = false\n"
         "[workers]\nendpoints = [" +
         f.endpoints() +
         "]\ndeadline_ms = 50.0\ndown_after = 3\n"
         // Real-time options, asked for, not required (a refusal is reported and the run goes on).
         // lock_memory matters here: while a fault is handled the client encodes and frees
         // megabytes of block sets; without mlockall a page fault in the haptic thread can wait
         // for those (un)mappings (measured under load: 50/35/74 misses with faults vs 1/20/5
         // without; with mlockall 30/87/6 vs 119/95/35).
         "[haptic]\nfifo_priority = 80\nlock_memory = true\nprefault_stack_kb = 256\n"
         "[device]\nrepeat = true\n"
         "[output]\nstatus = \"plain\"\nperfetto = false\nply = false\n"
         "[run]\nduration_s = " +
         std::to_string(duration_s) + "\n";
}

/// Steal time of the whole VM so far and all CPU time, in clock ticks (/proc/stat "cpu" line).
struct CpuTicks {
  std::uint64_t total = 0, steal = 0;
};
CpuTicks cpu_ticks() {
  std::ifstream in("/proc/stat");
  std::string cpu;
  CpuTicks t;
  in >> cpu;
  for (int i = 0; i < 8 && in; ++i) {  // user nice system idle iowait irq softirq steal
    std::uint64_t v = 0;
    in >> v;
    t.total += v;
    if (i == 7) t.steal = v;
  }
  return t;
}

struct RunResult {
  double steal_pct = 0;  ///< share of the VM's CPU time the hypervisor gave to other guests
  Summary summary;
  std::vector<st::test::TickCsvRow> ticks;
  std::vector<std::vector<double>> rounds;  ///< rounds.csv rows
  std::string log;
};

/// Runs the scene against the fleet; `faults` is called once the haptic loop ticks, from this thread.
template <class Faults>
RunResult run_scene(Fleet& f, const std::string& name, double duration_s, Faults&& faults) {
  const std::string scene = f.dir.file(name + ".toml"), out = f.dir.file(name), log = f.dir.file(name + ".log");
  st::test::write_file(scene, fleet_scene(f, duration_s));
  const std::string shm = "/st-fault-" + std::to_string(::getpid()) + "-" + name;
  const CpuTicks before = cpu_ticks();
  const pid_t pid = st::test::spawn_spheretouch({"run", scene, "--out", out, "--shm-name", shm}, log);
  struct Reaper {  // a failed REQUIRE below must not leave the run behind
    pid_t pid;
    ~Reaper() {
      if (pid > 0) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, nullptr, 0);
      }
    }
  } reaper{pid};
  const st::rt::ServoStatus st = st::test::wait_for_ticks(shm, 50, pid, 60);
  {
    INFO(st::test::slurp_file(log));
    REQUIRE(st.ticks >= 50);
  }
  const auto t0 = std::chrono::steady_clock::now();
  faults(t0);
  const int code = st::test::wait_for(pid, duration_s + 30);
  if (code >= 0) reaper.pid = 0;  // reaped
  RunResult r;
  const CpuTicks after = cpu_ticks();
  if (after.total > before.total)
    r.steal_pct = 100.0 * double(after.steal - before.steal) / double(after.total - before.total);
  r.log = st::test::slurp_file(log);
  INFO(r.log);
  REQUIRE(code == 0);
  r.summary = parse_summary(r.log);
  r.ticks = st::test::read_tick_csv(out + "/ticks.csv");
  std::ifstream in(out + "/rounds.csv");
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::vector<double> v;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');) v.push_back(std::stod(cell));
    REQUIRE(v.size() == 7);
    r.rounds.push_back(v);
  }
  return r;
}

}  // namespace

TEST_CASE("run with 4 daemons survives kill -9, SIGSTOP, a dropped link and a restart") {
  Fleet f;
  constexpr double kSeconds = 9.0;
  // Faults, relative to the first ticks: kill -9 worker 0 at 1 s and restart it at 2 s; freeze
  // worker 1 from 2.5 s to 3.5 s; hold all traffic to worker 2 from 4.5 s to 6 s.
  auto at = [](std::chrono::steady_clock::time_point t0, double s) {
    std::this_thread::sleep_until(
        t0 + std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(s)));
  };
  auto faults = [&](std::uint64_t& relayed_before_drop, std::uint64_t& relayed_during_drop) {
    return [&](std::chrono::steady_clock::time_point t0) {
      at(t0, 1.0);
      f.procs[0]->signal(SIGKILL);
      CHECK(f.procs[0]->wait(2000ms) != -1);
      at(t0, 2.0);
      f.start(0);  // same port, new epoch: the client reloads it
      at(t0, 2.5);
      f.procs[1]->signal(SIGSTOP);
      at(t0, 3.5);
      f.procs[1]->signal(SIGCONT);
      at(t0, 4.5);
      f.relay->set_forwarding(false);
      relayed_before_drop = f.relay->bytes_relayed();
      at(t0, 6.0);
      relayed_during_drop = f.relay->bytes_relayed() - relayed_before_drop;
      f.relay->set_forwarding(true);
    };
  };

  // The faults must be seen by the collision side and not by the haptic loop: no more misses
  // than a fault-free run of the same scene on the same fleet just before. Both runs share a
  // 2-core machine with 5 other processes and SCHED_FIFO is asked for, not guaranteed: under
  // other load the misses of two identical runs differ by scheduler noise (55 vs 136 seen with a
  // compiler and two fuzzers running). Even without steal (below) the faults cost a few ticks:
  // +13, +19 and +5 in three pairs of one CI run, from the restarted worker and the reloads
  // competing for the 2 vCPUs. kMissNoise (30 ticks, or 0.33 % of ticks if more) allows that;
  // a haptic loop that waited on the network would miss >= 50 ticks (one round deadline) per
  // fault, >= 150 per faulted run, in every pair. A noisy pair is run again, up to 3. Under a
  // sanitizer every process runs several times slower and the misses of two runs differ by
  // hundreds either way: there one pair runs and its counts are reported, not compared (the
  // release build asserts them). On a shared host the hypervisor also runs other guests on our
  // vCPUs (steal time): a 9 s run then loses hundreds of ticks at random (15 vs 602 seen in two
  // fault-free runs), which no comparison of two runs can tell from a fault. A pair counts as
  // judged when both runs had under kStealLimitPct of steal; the comparison fails the test only
  // when some pair was judged, and otherwise is reported with the steal it saw.
  constexpr int kPairs = st::test::kSanitizerBuild ? 1 : 3;
  constexpr double kStealLimitPct = 1.0;
  RunResult clean, faulted;
  bool quiet = false, judged = false;
  for (int pair = 1; pair <= kPairs && !quiet; ++pair) {
    std::uint64_t relayed_before_drop = 0, relayed_during_drop = 0;
    clean = run_scene(f, "clean" + std::to_string(pair), kSeconds, [](auto) {});
    faulted = run_scene(f, "faulted" + std::to_string(pair), kSeconds, faults(relayed_before_drop, relayed_during_drop));
    INFO(faulted.log);
    CHECK(relayed_before_drop > 0);         // worker 2 was served through the relay
    CHECK(relayed_during_drop == 0);        // and cut off while the link was down
    CHECK(faulted.summary.incomplete > 0);  // the faults were seen by the collision side
    const std::uint64_t kMissNoise = std::max<std::uint64_t>(30, clean.summary.ticks / 300);
    quiet = faulted.summary.misses <= clean.summary.misses + kMissNoise;
    judged = judged || (clean.steal_pct < kStealLimitPct && faulted.steal_pct < kStealLimitPct);
    MESSAGE("pair " << pair << ": haptic misses " << faulted.summary.misses << " with faults, " << clean.summary.misses
                    << " without; host steal " << faulted.steal_pct << " % and " << clean.steal_pct << " %");
  }
  INFO("fault-free run: " << clean.log);
  INFO("faulted run: " << faulted.log);
  if (!st::test::kSanitizerBuild) {
    if (judged)
      CHECK(quiet);
    else if (!quiet)
      MESSAGE("every pair ran with host steal >= " << kStealLimitPct << " %: misses reported, not compared");
  }
  CHECK(faulted.summary.ticks + faulted.summary.misses >= std::uint64_t(kSeconds * 1000 * 0.95));

  for (const RunResult* r : {&clean, &faulted}) {
    // The per-tick trace has every tick, in order; telemetry dropped nothing.
    CHECK(r->summary.dropped == 0);
    CHECK(r->summary.samples == r->summary.ticks);
    REQUIRE(r->ticks.size() == r->summary.ticks);
    std::size_t gaps = 0, bad_force = 0, touching = 0;
    for (std::size_t i = 0; i < r->ticks.size(); ++i) {
      gaps += r->ticks[i].tick != i;
      bad_force += !std::isfinite(r->ticks[i].force_N) || r->ticks[i].force_N > 3.3 + 1e-9;
      touching += r->ticks[i].force_N > 0.1;
    }
    CHECK(gaps == 0);
    CHECK(bad_force == 0);
    CHECK(touching > 1000);  // the repeated script presses twice in 9 s
    CHECK(r->summary.misses == r->ticks.back().misses);
  }

  // Recovery: in the last second every round is complete again (worker 0 reloaded, worker 1
  // and worker 2 back, or their blocks reassigned), and the fleet answered throughout the end.
  // A fleet that has not recovered (blocks nobody answers) leaves every round incomplete; under a
  // sanitizer, where every process runs several times slower on the 2 cores, a round still misses
  // its deadline now and then (1 of > 100 seen once), so there up to 2 % of them may.
  REQUIRE(!faulted.rounds.empty());
  const double end_ns = faulted.rounds.back()[1];
  std::size_t last_second = 0, last_incomplete = 0;
  for (const auto& row : faulted.rounds)
    if (row[1] > end_ns - 1e9) {
      ++last_second;
      last_incomplete += row[6] == 0;
    }
  CHECK(last_second > 100);
  CHECK(last_incomplete <= (st::test::kSanitizerBuild ? last_second / 50 : 0));
  // Worker 0's second life loaded its blocks; worker 1 came back from SIGSTOP.
  CHECK(f.procs[0]->log().find("loaded block set") != std::string::npos);
}
