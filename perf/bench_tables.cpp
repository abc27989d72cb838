// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench table1 | table3 | table2 | peers | icosphere: the paper's tables.
//  table1/table3: time of one collision round (median, p95, mean, rounds/s) at the poses of a
//                 pose file, with 0 workers (collide() in the calling thread, as the collision
//                 thread does) and N spheretouch-worker daemons over tcp loopback (scatter-gather
//                 round incl. merge); all worker counts run at once and take turns round by
//                 round, so load drift on the shared machine hits them alike. table1 is hand x elephant at 100..1,500 contacts (paper
//                 §3.5); table3 the same measurement at 100 and 1,500 contacts on four models (§4).
//  table2:        haptic and collision rates along the built-in press/slide script for (a) a
//                 single-thread loop that does collision then force each iteration at most at
//                 1 kHz (the OpenHaptics sample's structure, paper §4) and (b) spheretouch's
//                 HapticLoop + HapticServo + CollisionLoop. Both use the paper's contact model
//                 ([contact] model = "paper", §3.6): this table reproduces the paper's system.
//  peers:         FCL 0.7 OBBRSS all-contacts vs our collide() on the same poses, same run.
//  icosphere:     writes the ~960-face ball as OFF (for --find-poses).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <thread>

#include <spheretouch/engine/collision_loop.hpp>
#include <spheretouch/engine/distributed.hpp>
#include <spheretouch/engine/scene.hpp>
#include "bench.hpp"
#include "bench_tables_common.hpp"
#include <spheretouch/geom/pose_io.hpp>
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/haptic_loop.hpp>
#include <spheretouch/rt/haptic_servo.hpp>
#include <spheretouch/rt/interpolator.hpp>
#include <spheretouch/rt/saturation.hpp>
#ifdef ST_HAVE_FCL
#include "fcl_peer.hpp"
#endif

namespace st::bench {

void add_trade(CLI::App& app);  // bench_trade.cpp

// ------------------------------------------------------------------------------ common helpers

namespace {
// `tok` read whole as a T, or nothing.
template <class T>
std::optional<T> whole_number(const std::string& tok) {
  T v{};
  const char* end = tok.data() + tok.size();
  const auto [p, ec] = std::from_chars(tok.data(), end, v);
  if (ec != std::errc() || p != end) return std::nullopt;
  return v;
}
}  // namespace

Body load_body(const std::string& spec, std::uint32_t leaf_faces) {
  Body b;
  if (spec.rfind("icosphere", 0) == 0) {
    double radius = 50;
    int freq = 7;
    std::stringstream ss(spec);
    std::string tok;
    std::getline(ss, tok, ':');
    if (std::getline(ss, tok, ':')) {
      const auto v = whole_number<double>(tok);
      if (!v || !std::isfinite(*v) || !(*v > 0))
        die("icosphere:RADIUS:FREQ: radius '" + tok + "' is not a positive number");
      radius = *v;
    }
    if (std::getline(ss, tok, ':')) {
      const auto v = whole_number<int>(tok);
      if (!v || *v < 1 || *v > 64) die("icosphere:RADIUS:FREQ: frequency '" + tok + "' is not an integer in [1, 64]");
      freq = *v;
    }
    b.mesh = geom::make_icosphere(radius, freq);
    b.label = "icosphere";
  } else {
    auto m = geom::load_mesh(spec);
    if (!m) die(m.error());
    b.mesh = std::move(m.value().mesh);
    b.label = stem(spec);
  }
  auto t = geom::SphereTree::build(b.mesh, {leaf_faces});
  if (!t) die(t.error());
  b.tree = std::move(t).value();
  return b;
}

std::vector<TaggedPose> read_tagged_poses(const std::string& path) {
  Result<std::vector<geom::PoseLine>> lines = geom::read_pose_lines(path);
  if (!lines) die(lines.error());
  std::vector<TaggedPose> out;
  for (const geom::PoseLine& l : lines.value()) {
    TaggedPose p;
    p.pose = l.pose;
    unsigned c = 0, t = 0;  // "# contacts N (target T)", written by `collide --find-poses`
    if (std::sscanf(l.comment.c_str(), " contacts %u (target %u)", &c, &t) == 2) {
      p.contacts = c;
      p.target = t;
    }
    out.push_back(p);
  }
  return out;
}

rt::Trajectory press_slide_script(const geom::Mesh& probe, const geom::Mesh& object, double duration_s, double press_mm,
                                  double slide_mm) {
  engine::Scene s = engine::DefaultScene();  // fingertip along -z onto the object's top, identity orientation
  s.device.press_mm = press_mm;
  s.device.slide_mm = slide_mm;
  rt::Trajectory t = engine::builtin_script(s, probe, object);
  const double scale = duration_s / t.duration_s();
  for (rt::TimedPose& k : t.keys) k.t_s *= scale;
  return t;
}

Daemons::Daemons(const std::string& binary, int n) {
  if (::access(binary.c_str(), X_OK) != 0) die(binary + ": not an executable (--worker-bin)");
  for (int i = 0; i < n; ++i) {
    const std::string ep = "tcp://127.0.0.1:" + std::to_string(free_tcp_port());
    const pid_t pid = ::fork();
    if (pid == 0) {
      const std::string id = std::to_string(i);
      ::execl(binary.c_str(), binary.c_str(), "--bind", ep.c_str(), "--id", id.c_str(), "--log-level", "error",
              static_cast<char*>(nullptr));
      ::_exit(127);
    }
    pids_.push_back(pid);
    endpoints_.push_back(ep);
  }
}

Daemons::~Daemons() {
  for (pid_t p : pids_) ::kill(p, SIGTERM);
  for (pid_t p : pids_) {
    int status = 0;
    ::waitpid(p, &status, 0);
  }
}

double quantile(std::vector<double>& v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const auto k = std::min(v.size() - 1, static_cast<std::size_t>(q * double(v.size() - 1) + 0.5));
  return v[k];
}

void append_csv(const std::string& path, const std::string& header, const std::string& row) {
  if (path.empty()) return;
  std::ifstream probe(path);
  const bool fresh = !probe.good() || probe.peek() == std::ifstream::traits_type::eof();
  std::ofstream o(path, std::ios::app);
  if (!o) die(path + ": cannot write");
  if (fresh) o << header << '\n';
  o << row << '\n';
}

namespace {
// The comma-separated tokens of `s` (empty ones skipped), each read whole as a T that `fits`;
// anything else is a CLI::ValidationError naming `option`, the token and `what` was expected.
template <class T, class Fits>
std::vector<T> parse_list(const std::string& s, const std::string& option, Fits fits, const char* what) {
  std::vector<T> out;
  std::stringstream ss(s);
  std::string tok;
  while (std::getline(ss, tok, ','))
    if (!tok.empty()) {
      const auto v = whole_number<T>(tok);
      if (!v || !fits(*v)) throw CLI::ValidationError(option, "'" + tok + "' is not " + what);
      out.push_back(*v);
    }
  return out;
}
}  // namespace

std::vector<int> parse_int_list(const std::string& s, const std::string& option) {
  return parse_list<int>(
      s, option, [](int) { return true; }, "an integer (a comma-separated list: 1,2,4)");
}

std::vector<double> parse_positive_list(const std::string& s, const std::string& option) {
  return parse_list<double>(
      s, option, [](double v) { return std::isfinite(v) && v > 0; },
      "a positive number (a comma-separated list: 0.01,0.1)");
}

std::string stem(const std::string& path) {
  std::string s = path.substr(path.find_last_of('/') == std::string::npos ? 0 : path.find_last_of('/') + 1);
  return s.substr(0, s.find('.'));
}

std::size_t mesh_bytes(const geom::Mesh& m) {
  return m.local.size() * sizeof(geom::Vec3) + m.faces.size() * sizeof(geom::Tri);
}

namespace {

std::string fmt(const char* f, auto... v) {
  char buf[512];
  std::snprintf(buf, sizeof buf, f, v...);
  return buf;
}

// ------------------------------------------------------------------------------ table1 / table3

void add_rounds(CLI::App& app, const char* name, const char* what) {
  struct Args {
    std::string probe, object, poses, worker_bin = "build/daemons/spheretouch-worker", csv, workers = "0,1,2,4,8";
    int rounds = 200, warmup = 10;
    std::uint32_t layer = 2, leaf = geom::DefaultTreeConfig().leaf_faces;
  };
  auto a = std::make_shared<Args>();
  const std::string table = name;
  CLI::App* cmd = app.add_subcommand(name, what);
  cmd->add_option("--probe", a->probe, "probe mesh (the hand)")->required();
  cmd->add_option("--object", a->object, "object mesh, or icosphere[:R[:FREQ]]")->required();
  cmd->add_option("--poses", a->poses, "pose file (spheretouch-bench collide --find-poses)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--workers", a->workers, "worker counts; 0 = collide() in this thread")->capture_default_str();
  cmd->add_option("--worker-bin", a->worker_bin, "spheretouch-worker binary (daemons over tcp loopback)")->capture_default_str();
  cmd->add_option("--rounds", a->rounds, "timed rounds per pose")->check(CLI::Range(1, 1000000))->capture_default_str();
  cmd->add_option("--warmup", a->warmup, "untimed rounds per pose first")->capture_default_str();
  cmd->add_option("--layer", a->layer, "sphere layer dealt to workers (paper §3.4)")->capture_default_str();
  cmd->add_option("--leaf-faces", a->leaf, "faces per leaf")->check(CLI::Range(1u, geom::kMaxLeafFaces))->capture_default_str();
  cmd->add_option("--csv", a->csv, "append rows to this CSV");
  cmd->callback([a, table] {
    const Body probe = load_body(a->probe, a->leaf);
    const Body object = load_body(a->object, a->leaf);
    const std::vector<TaggedPose> poses = read_tagged_poses(a->poses);
    const std::string header =
        "table,probe,object,object_faces,target,contacts,workers,transport,rounds,median_ms,p95_ms,mean_ms,rounds_per_"
        "s,incomplete";
    std::printf("%s: %s (%zu faces) x %s (%zu faces), %zu poses, %d rounds each\n", table.c_str(), probe.label.c_str(),
                probe.mesh.num_faces(), object.label.c_str(), object.mesh.num_faces(), poses.size(), a->rounds);
    std::printf("%7s %8s %8s %10s %10s %10s %10s %6s\n", "workers", "target", "contacts", "median_ms", "p95_ms",
                "mean_ms", "rounds/s", "incompl");
    // Every worker count's fleet runs at once and the configurations take turns round by round,
    // so a change in the shared machine's load hits all of them alike (ratios from the same run).
    struct Config {
      int workers = 0;
      std::unique_ptr<Daemons> daemons;
      std::unique_ptr<engine::Fleet> fleet;
      geom::CollideScratch scratch;
      geom::CollideResult result;
      net::RoundResult round;
      std::uint64_t seq = 0;
    };
    std::vector<std::unique_ptr<Config>> configs;
    for (const int w : parse_int_list(a->workers, "--workers")) {
      auto c = std::make_unique<Config>();
      c->workers = w;
      if (w > 0) {
        c->daemons = std::make_unique<Daemons>(a->worker_bin, w);
        engine::FleetSpec spec;
        spec.endpoints = c->daemons->endpoints();
        spec.layer = a->layer;
        spec.leaf_faces = a->leaf;
        spec.ready_timeout = std::chrono::milliseconds(120000);
        auto f = engine::start_fleet(spec, probe.mesh, object.mesh, object.tree);
        if (!f) die(f.error());
        c->fleet = std::move(f).value();
      }
      configs.push_back(std::move(c));
    }
    struct Cell {
      std::vector<double> ms;
      std::uint32_t contacts = 0;
      int incomplete = 0;
    };
    std::vector<std::vector<Cell>> cells(poses.size(), std::vector<Cell>(configs.size()));
    for (std::size_t p = 0; p < poses.size(); ++p) {
      for (int i = 0; i < a->warmup + a->rounds; ++i) {
        for (std::size_t k = 0; k < configs.size(); ++k) {
          Config& c = *configs[k];
          Cell& cell = cells[p][k];
          const auto t0 = std::chrono::steady_clock::now();
          if (c.fleet)
            c.fleet->client().round(++c.seq, poses[p].pose, net::Clock::now() + std::chrono::seconds(10), c.round);
          else
            geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, poses[p].pose, {}, c.scratch, c.result);
          const auto t1 = std::chrono::steady_clock::now();
          if (i < a->warmup) continue;
          cell.ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
          if (c.fleet) {
            cell.contacts = static_cast<std::uint32_t>(c.round.contacts());
            cell.incomplete += !c.round.complete;
          } else {
            cell.contacts = c.result.contacts();
          }
        }
      }
    }
    for (std::size_t k = 0; k < configs.size(); ++k) {
      const int w = configs[k]->workers;
      for (std::size_t p = 0; p < poses.size(); ++p) {
        Cell& cell = cells[p][k];
        double mean = 0;
        for (double v : cell.ms) mean += v;
        mean /= double(cell.ms.size());
        const double med = quantile(cell.ms, 0.5), p95 = quantile(cell.ms, 0.95);
        const TaggedPose& tp = poses[p];
        std::printf("%7d %8u %8u %10.3f %10.3f %10.3f %10.1f %6d\n", w, tp.target, cell.contacts, med, p95, mean,
                    1000.0 / mean, cell.incomplete);
        append_csv(a->csv, header,
                   fmt("%s,%s,%s,%zu,%u,%u,%d,%s,%d,%.4f,%.4f,%.4f,%.2f,%d", table.c_str(), probe.label.c_str(),
                       object.label.c_str(), object.mesh.num_faces(), tp.target, cell.contacts, w, w ? "tcp" : "thread",
                       a->rounds, med, p95, mean, 1000.0 / mean, cell.incomplete));
      }
    }
  });
}

// ------------------------------------------------------------------------------ table2

struct RateResult {
  double haptic_hz = 0, collision_hz = 0, round_p50_ms = 0, peak_force_N = 0;
  std::uint64_t ticks = 0, misses = 0, rounds = 0;
  std::uint32_t max_contacts = 0;
};

void sleep_until_ns(std::int64_t t) {
  const timespec ts = rt::to_timespec(t);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {}
}

// Table 2 reproduces the paper's system: its contact model (§3.6).
geom::ContactConfig paper_contact() {
  geom::ContactConfig c = geom::DefaultContactConfig();
  c.model = geom::ContactModelKind::paper;
  return c;
}

// (a) One thread: read pose, collide, build the contact model, force (hold), command; at most
// one iteration per 1 ms deadline, a late iteration skips the deadlines it overran (the
// OpenHaptics servo callback doing collision detection itself).
RateResult single_thread(const Body& probe, const Body& object, const rt::Trajectory& script, double seconds) {
  rt::SimulatedDevice dev(script, {}, 1 << 16);
  rt::InterpolatorConfig ic = rt::DefaultInterpolatorConfig();
  ic.mode = rt::InterpMode::hold;
  rt::Interpolator interp(rt::ForceLaw{}, ic);
  rt::Saturator sat(rt::DefaultSaturationConfig());
  geom::ContactBuilder builder(paper_contact());
  geom::CollideScratch sc;
  geom::CollideResult r;
  RateResult out;
  std::vector<double> ms;
  const std::int64_t period = 1'000'000, start = rt::now_ns(), end = start + std::int64_t(seconds * 1e9);
  std::int64_t deadline = start, last = 0;
  std::uint64_t seq = 0;
  while (true) {
    const std::int64_t now = rt::now_ns();
    if (now >= end) break;
    Eigen::Isometry3d pose;
    dev.read_pose(now, pose);
    const std::int64_t c0 = rt::now_ns();
    geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, {}, sc, r);
    geom::ContactModel m = builder.build(probe.mesh, object.mesh, pose, r.pairs);
    ms.push_back(double(rt::now_ns() - c0) * 1e-6);
    m.seq = ++seq;
    interp.on_model(m, now);
    const Eigen::Vector3d f = sat.apply(interp.force(pose, now), last ? double(now - last) * 1e-9 : 0.0);
    last = now;
    dev.command_force(now, f);
    out.peak_force_N = std::max(out.peak_force_N, f.norm());
    out.max_contacts = std::max(out.max_contacts, m.contacts);
    ++out.ticks;
    deadline += period;
    const std::int64_t after = rt::now_ns();
    if (after >= deadline) {
      out.misses += std::uint64_t((after - deadline) / period) + 1;
      deadline += ((after - deadline) / period + 1) * period;
    }
    sleep_until_ns(deadline);
  }
  const double secs = double(rt::now_ns() - start) * 1e-9;
  out.haptic_hz = double(out.ticks) / secs;
  out.collision_hz = out.haptic_hz;
  out.rounds = out.ticks;
  out.round_p50_ms = quantile(ms, 0.5);
  return out;
}

// Records the peak commanded force without touching the tick path's rules (relaxed atomics).
class PeakDevice final : public rt::Device {
 public:
  explicit PeakDevice(rt::Device& d) : d_(d) {}
  bool read_pose(std::int64_t t, Eigen::Isometry3d& p) noexcept override { return d_.read_pose(t, p); }
  void command_force(std::int64_t t, const Eigen::Vector3d& f) noexcept override {
    d_.command_force(t, f);
    peak_ = std::max(peak_, f.norm());
  }
  double max_force_N() const noexcept override { return d_.max_force_N(); }
  double peak() const { return peak_; }

 private:
  rt::Device& d_;
  double peak_ = 0;  // written by the loop thread only; read after it stopped
};

// (b) spheretouch: the 1 kHz HapticLoop + HapticServo, and the app's CollisionLoop answering
// poses with collide() in its own thread (0 workers) or scatter-gather over in-process workers.
RateResult spheretouch(const Body& probe, const Body& object, const rt::Trajectory& script, double seconds, int workers) {
  std::unique_ptr<engine::Fleet> fleet;
  if (workers > 0) {
    engine::FleetSpec spec;
    spec.workers = workers;
    spec.leaf_faces = object.tree.params.leaf_faces;
    auto f = engine::start_fleet(spec, probe.mesh, object.mesh, object.tree);
    if (!f) die(f.error());
    fleet = std::move(f).value();
  }
  geom::CollideScratch sc;
  geom::CollideResult r;
  engine::CollideFn fn = [&](std::uint64_t seq, std::uint32_t, const geom::Pose& pose, engine::RoundOutput& out) {
    if (fleet) {
      static thread_local net::RoundResult rr;
      fleet->client().round(seq, pose, net::Clock::now() + std::chrono::milliseconds(50), rr);
      out.pairs.resize(rr.pairs.size());
      for (std::size_t i = 0; i < rr.pairs.size(); ++i) out.pairs[i] = {rr.pairs[i].probe, rr.pairs[i].object};
      out.complete = rr.complete;
    } else {
      geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, {}, sc, r);
      out.pairs.assign(r.pairs.begin(), r.pairs.end());
    }
  };
  rt::SimulatedDevice sim(script, {}, 1 << 16);
  PeakDevice dev(sim);
  auto poses = std::make_unique<rt::TripleBuffer<rt::PoseSample>>();
  auto models = std::make_unique<rt::TripleBuffer<geom::ContactSet>>();
  rt::HapticServo servo(dev, *poses, *models, rt::ForceLaw{}, rt::DefaultInterpolatorConfig(),
                        rt::DefaultSaturationConfig(), nullptr);
  engine::CollisionLoop collision(probe.mesh, object.mesh, *poses, *models, fn, 0, std::size_t(seconds * 20000) + 1000,
                                  paper_contact());
  rt::HapticLoop loop(rt::DefaultHapticLoopConfig());
  collision.start();
  const std::int64_t t0 = rt::now_ns();
  auto started = loop.start(servo);
  if (!started) {
    collision.stop();
    die(started.error());
  }
  std::this_thread::sleep_for(std::chrono::nanoseconds(std::int64_t(seconds * 1e9)));
  loop.stop();
  const double secs = double(rt::now_ns() - t0) * 1e-9;
  collision.stop();
  RateResult out;
  out.ticks = loop.stats().ticks;
  out.misses = loop.stats().misses;
  out.rounds = collision.rounds();
  out.haptic_hz = double(out.ticks) / secs;
  out.collision_hz = double(out.rounds) / secs;
  std::vector<double> ms;
  for (const engine::RoundRecord& rec : collision.records()) {
    ms.push_back(double(rec.end_ns - rec.start_ns) * 1e-6);
    out.max_contacts = std::max(out.max_contacts, rec.contacts);
  }
  out.round_p50_ms = quantile(ms, 0.5);
  out.peak_force_N = dev.peak();
  return out;
}

void add_table2(CLI::App& app) {
  struct Args {
    std::string probe, csv;
    std::vector<std::string> objects;
    double seconds = 5, press_mm = 3;
    int workers = 0;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "table2", "Haptic and collision rates: single-thread collide-then-force loop vs spheretouch (paper Table 2)");
  cmd->add_option("--probe", a->probe, "probe mesh (the hand)")->required();
  cmd->add_option("objects", a->objects, "object meshes, or icosphere[:R[:FREQ]]")->required();
  cmd->add_option("--seconds", a->seconds, "run length per variant (the press/slide script is time-scaled to it)")
      ->check(CLI::Range(0.2, 600.0))
      ->capture_default_str();
  cmd->add_option("--press-mm", a->press_mm, "press depth below the object's top, mm (built-in script: 3)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  cmd->add_option("--workers", a->workers,
                  "spheretouch variant: in-process workers (0 = collide in the collision thread)")
      ->capture_default_str();
  cmd->add_option("--csv", a->csv, "append rows to this CSV");
  cmd->callback([a] {
    const Body probe = load_body(a->probe);
    const std::string header =
        "table,probe,object,object_faces,press_mm,variant,workers,seconds,haptic_hz,collision_hz,round_p50_ms,ticks,"
        "misses,rounds,"
        "max_contacts,peak_force_N";
    std::printf("%-14s %9s %-12s %10s %12s %12s %9s %9s\n", "object", "faces", "variant", "haptic_Hz", "collision_Hz",
                "round_p50_ms", "contacts", "peak_N");
    for (const std::string& spec : a->objects) {
      const Body object = load_body(spec);
      const rt::Trajectory script = press_slide_script(probe.mesh, object.mesh, a->seconds, a->press_mm);
      for (const char* variant : {"single_thread", "spheretouch"}) {
        const bool single = variant[0] == 's' && variant[1] == 'i';
        const RateResult r = single ? single_thread(probe, object, script, a->seconds)
                                    : spheretouch(probe, object, script, a->seconds, a->workers);
        std::printf("%-14s %9zu %-12s %10.1f %12.2f %12.3f %9u %9.3f\n", object.label.c_str(), object.mesh.num_faces(),
                    single ? "single" : "spheretouch", r.haptic_hz, r.collision_hz, r.round_p50_ms, r.max_contacts,
                    r.peak_force_N);
        std::fflush(stdout);
        append_csv(a->csv, header,
                   fmt("table2,%s,%s,%zu,%.1f,%s,%d,%.2f,%.2f,%.2f,%.4f,%llu,%llu,%llu,%u,%.4f", probe.label.c_str(),
                       object.label.c_str(), object.mesh.num_faces(), a->press_mm, variant, single ? 0 : a->workers,
                       a->seconds, r.haptic_hz, r.collision_hz, r.round_p50_ms,
                       static_cast<unsigned long long>(r.ticks), static_cast<unsigned long long>(r.misses),
                       static_cast<unsigned long long>(r.rounds), r.max_contacts, r.peak_force_N));
      }
    }
  });
}

// ------------------------------------------------------------------------------ peers (FCL)

void add_peers(CLI::App& app) {
  struct Args {
    std::string probe, object, poses, csv;
    int runs = 50;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "peers",
      "Our exact collide() vs FCL 0.7 OBBRSS all-contacts on the same poses: time ratio and pair-set agreement");
  cmd->add_option("--probe", a->probe, "probe mesh")->required();
  cmd->add_option("--object", a->object, "object mesh")->required();
  cmd->add_option("--poses", a->poses, "pose file")->required()->check(CLI::ExistingFile);
  cmd->add_option("--runs", a->runs, "queries per pose and library")->check(CLI::Range(1, 100000))->capture_default_str();
  cmd->add_option("--csv", a->csv, "append rows to this CSV");
  cmd->callback([a] {
#ifndef ST_HAVE_FCL
    die("built without FCL (libfcl-dev; meson option fcl): no peer to compare with");
#else
    const Body probe = load_body(a->probe);
    const Body object = load_body(a->object);
    const FclPeer fcl(probe.mesh, object.mesh);
    const std::string header =
        "table,probe,object,target,contacts,ours_median_ms,fcl_median_ms,ratio_ours_over_fcl,ours_pairs,fcl_pairs,"
        "common_pairs,jaccard,identical";
    std::printf("%8s %8s %10s %10s %8s %9s %9s %9s %s\n", "target", "contacts", "ours_ms", "fcl_ms", "ours/fcl",
                "ours_pairs", "fcl_pairs", "jaccard", "identical");
    geom::CollideScratch sc;
    geom::CollideResult r;
    geom::CollideConfig opt;
    opt.sort_pairs = true;
    for (const TaggedPose& tp : read_tagged_poses(a->poses)) {
      std::vector<double> ours, theirs;
      std::vector<std::pair<std::uint32_t, std::uint32_t>> fp;
      geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, tp.pose, opt, sc, r);  // warm
      // Alternate the two libraries query by query so drift in machine load hits both alike.
      for (int i = 0; i < a->runs; ++i) {
        auto t0 = std::chrono::steady_clock::now();
        geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, tp.pose, opt, sc, r);
        auto t1 = std::chrono::steady_clock::now();
        fp = fcl.collide(tp.pose);
        auto t2 = std::chrono::steady_clock::now();
        ours.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
        theirs.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
      }
      std::vector<std::pair<std::uint32_t, std::uint32_t>> op;
      for (const geom::FacePair& p : r.pairs) op.emplace_back(p.probe, p.object);
      std::sort(op.begin(), op.end());
      std::vector<std::pair<std::uint32_t, std::uint32_t>> common;
      std::set_intersection(op.begin(), op.end(), fp.begin(), fp.end(), std::back_inserter(common));
      const std::size_t uni = op.size() + fp.size() - common.size();
      const double jaccard = uni ? double(common.size()) / double(uni) : 1.0;
      const double om = quantile(ours, 0.5), fm = quantile(theirs, 0.5);
      std::printf("%8u %8u %10.3f %10.3f %8.2f %9zu %9zu %9.4f %s\n", tp.target, r.contacts(), om, fm, om / fm,
                  op.size(), fp.size(), jaccard, op == fp ? "yes" : "no");
      append_csv(a->csv, header,
                 fmt("peers,%s,%s,%u,%u,%.4f,%.4f,%.3f,%zu,%zu,%zu,%.5f,%d", probe.label.c_str(), object.label.c_str(),
                     tp.target, r.contacts(), om, fm, om / fm, op.size(), fp.size(), common.size(), jaccard, op == fp));
    }
#endif
  });
}

void add_icosphere(CLI::App& app) {
  struct Args {
    std::string out;
    double radius = 50;
    int frequency = 7;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("icosphere", "Write the ~960-face ball of paper Table 2 (980 faces) as OFF");
  cmd->add_option("out", a->out, "output .off")->required();
  cmd->add_option("--radius", a->radius, "radius, mm")->capture_default_str();
  cmd->add_option("--frequency", a->frequency, "20*f^2 faces")->capture_default_str();
  cmd->callback([a] {
    const geom::Mesh m = geom::make_icosphere(a->radius, a->frequency);
    if (Status s = geom::write_off(m, a->out); !s) die(s.error());
    std::printf("%s: %zu faces, radius %.1f mm\n", a->out.c_str(), m.num_faces(), a->radius);
  });
}

}  // namespace

void add_tables(CLI::App& app) {
  add_rounds(app, "table1",
             "Collision round time (median, p95) vs contacts vs workers (0 = in this thread, N = daemons over tcp), "
             "paper Table 1");
  add_rounds(app, "table3",
             "Collision rounds per second vs workers at given poses (paper Table 3); same measurement as table1");
  add_table2(app);
  add_peers(app);
  add_icosphere(app);
  add_trade(app);
}

}  // namespace st::bench
