// spheretouch run SCENE: the main job. A probe touches an object with force at 1 kHz: the
// haptic thread (HapticLoop + HapticServo) never waits; the collision thread answers poses with
// contact models; telemetry goes to a per-tick CSV. See DESIGN.md "Data flow".
#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <thread>
#include <unistd.h>

#include "app/collision_loop.hpp"
#include "app/commands.hpp"
#include "app/distributed.hpp"
#include "app/run_outputs.hpp"
#include "app/scene.hpp"
#include "app/tree_cache.hpp"
#include "rt/clock.hpp"
#include "rt/haptic_servo.hpp"
#include "rt/telemetry.hpp"

namespace st::app {
namespace {

std::atomic<int> g_signal{0};
extern "C" void on_signal(int sig) { g_signal.store(sig); }

/// Forwards to the real device and keeps the last and peak commanded force for the status line
/// (relaxed atomic stores: no lock, no syscall on the tick path).
class MonitoredDevice final : public rt::Device {
 public:
  explicit MonitoredDevice(rt::Device& inner) : inner_(inner) {}
  bool read_pose(std::int64_t now_ns, Eigen::Isometry3d& pose) noexcept override { return inner_.read_pose(now_ns, pose); }
  void command_force(std::int64_t now_ns, const Eigen::Vector3d& f) noexcept override {
    inner_.command_force(now_ns, f);
    const double m = f.norm();
    last_.store(m, std::memory_order_relaxed);
    if (m > peak_.load(std::memory_order_relaxed)) peak_.store(m, std::memory_order_relaxed);
  }
  double max_force_N() const noexcept override { return inner_.max_force_N(); }
  double last_N() const { return last_.load(std::memory_order_relaxed); }  ///< newest commanded |F|
  double peak_N() const { return peak_.load(std::memory_order_relaxed); }  ///< largest commanded |F|

 private:
  static_assert(std::atomic<double>::is_always_lock_free);
  rt::Device& inner_;
  std::atomic<double> last_{0}, peak_{0};
};

struct RunArgs {
  std::string scene;
  double duration_s = -1;
  int workers = -1;
  std::string connect, out;
};

[[noreturn]] void die(int code, const std::string& msg) {
  std::fprintf(stderr, "spheretouch: %s\n", msg.c_str());
  throw CLI::RuntimeError(code);
}

/// The built-in script: the probe's fingertip approaches the object's surface point along the
/// normal, presses, slides and releases (rt::builtin_press_slide moves the fingertip).
rt::Trajectory builtin_script(const Scene& s, const geom::Mesh& probe, const geom::Mesh& object) {
  const geom::Vec3 n = s.device.normal;
  geom::Vec3 target = s.device.target;
  if (s.device.target_top) {  // the object's extreme vertex along the normal
    double best = -std::numeric_limits<double>::infinity();
    for (std::uint32_t i = 0; i < object.num_vertices(); ++i)
      if (const double d = object.vertex(i).dot(n); d > best) { best = d; target = object.vertex(i); }
  }
  const geom::Vec3 r = s.probe_rotation_deg * (M_PI / 180.0);
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(r.x(), geom::Vec3::UnitX()) * Eigen::AngleAxisd(r.y(), geom::Vec3::UnitY()) *
                             Eigen::AngleAxisd(r.z(), geom::Vec3::UnitZ())).toRotationMatrix();
  geom::Vec3 tip = s.probe_tip;
  if (s.probe_tip_auto) {  // the probe's lowest vertex along the approach direction
    double best = std::numeric_limits<double>::infinity();
    for (std::uint32_t i = 0; i < probe.num_vertices(); ++i)
      if (const double d = (R * probe.vertex(i)).dot(n); d < best) { best = d; tip = probe.vertex(i); }
  }
  rt::Trajectory t = rt::builtin_press_slide(target, n, s.device.press_mm, s.device.slide_mm);
  for (rt::TimedPose& k : t.keys) {
    geom::Pose p = geom::Pose::Identity();
    p.translate(k.pose.translation());
    p.rotate(R);
    p.translate(-tip);
    k.pose = p;
  }
  return t;
}

std::string new_run_dir(const std::string& wanted) {
  if (!wanted.empty()) return wanted;
  char stamp[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::localtime(&now));
  std::string dir = std::string("runs/") + stamp;
  for (int i = 2; std::filesystem::exists(dir); ++i) dir = std::string("runs/") + stamp + "-" + std::to_string(i);
  return dir;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const auto k = static_cast<std::size_t>(q * double(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
  return v[k];
}

void run(const RunArgs& a) {
  Result<Scene> sr = load_scene(a.scene);
  if (!sr) die(2, sr.error());
  Scene s = std::move(sr).value();
  if (a.duration_s > 0) s.duration_s = a.duration_s;
  if (a.workers >= 0) s.workers = a.workers;
  if (!a.out.empty()) s.out_dir = a.out;
  if (!a.connect.empty()) {
    s.endpoints.clear();
    std::string rest = a.connect;
    for (std::size_t p; !rest.empty(); rest = p == std::string::npos ? "" : rest.substr(p + 1)) {
      p = rest.find(',');
      s.endpoints.push_back(rest.substr(0, p));
    }
  }
  const bool tty = s.status == "tty" || (s.status == "auto" && ::isatty(STDOUT_FILENO));
  const bool show = s.status != "off";

  // Only the bodies the scene names are loaded; trees come from the cache when valid.
  std::fprintf(stderr, "loading probe and object ...\n");
  Result<geom::Mesh> pm = load_body(s.probe, "probe");
  if (!pm) die(2, s.file + ": " + pm.error());
  Result<geom::Mesh> om = load_body(s.object, "object");
  if (!om) die(2, s.file + ": " + om.error());
  const geom::Mesh& probe = pm.value();
  const geom::Mesh& object = om.value();
  const std::string cache = s.tree_cache ? default_tree_cache_dir() : "";
  Result<CachedTree> pt = tree_for(probe, s.tree, cache);
  if (!pt) die(2, pt.error());
  Result<CachedTree> ot = tree_for(object, s.tree, cache);
  if (!ot) die(2, ot.error());
  for (const CachedTree* t : {&pt.value(), &ot.value()})
    if (!t->note.empty()) std::fprintf(stderr, "tree cache: %s\n", t->note.c_str());
  std::fprintf(stderr, "probe %zu faces, object %zu faces; trees %s\n", probe.num_faces(), object.num_faces(),
               ot.value().source == TreeSource::cached ? "from the cache" : "built");

  rt::Trajectory script;
  if (s.device.script == "builtin") {
    script = builtin_script(s, probe, object);
  } else {
    Result<rt::Trajectory> t = rt::load_trajectory(s.device.script);
    if (!t) die(2, t.error());
    script = std::move(t).value();
  }

  // Collision backend. Workers and daemons plug in here (scatter-gather); 0 = this thread.
  geom::CollideScratch scratch;
  geom::CollideResult result;
  geom::CollideOptions copt = geom::DefaultCollideOptions();
  copt.stop_layer = s.approx_layer;
  const geom::SphereTree& ptree = pt.value().tree;
  const geom::SphereTree& otree = ot.value().tree;
  std::string backend = "in the collision thread";
  std::unique_ptr<Fleet> fleet;
  std::atomic<std::uint32_t> replied{0}, asked{0};  // newest round, for the status line
  CollideFn collide_fn = [&](std::uint64_t, const geom::Pose& pose, RoundOutput& out) {
    geom::collide(probe, ptree, object, otree, pose, copt, scratch, result);
    out.pairs.assign(result.pairs.begin(), result.pairs.end());
  };
  if (!s.endpoints.empty() || s.workers > 0) {
    if (s.approx_layer != geom::kExact) die(2, s.file + ": collision.mode = \"approximate\" runs without workers (set workers.count = 0)");
    FleetSpec spec;
    spec.workers = s.workers;
    spec.endpoints = s.endpoints;
    spec.layer = s.layer;
    spec.block_size = s.block_size;
    spec.leaf_faces = s.tree.leaf_faces;
    spec.miss_limit = std::uint32_t(s.down_after);
    std::fprintf(stderr, "starting workers and loading their blocks ...\n");
    Result<std::unique_ptr<Fleet>> f = start_fleet(spec, probe, object, otree);
    if (!f) die(2, f.error());
    fleet = std::move(f).value();
    backend = fleet->description;
    const auto deadline = std::chrono::microseconds(std::int64_t(s.deadline_ms * 1000));
    collide_fn = [&, deadline, round = net::RoundResult{}](std::uint64_t seq, const geom::Pose& pose,
                                                           RoundOutput& out) mutable {
      fleet->client->round(seq, pose, net::Clock::now() + deadline, round);
      out.pairs.resize(round.pairs.size());
      for (std::size_t i = 0; i < round.pairs.size(); ++i) out.pairs[i] = {round.pairs[i].probe, round.pairs[i].object};
      out.complete = round.complete;
      replied.store(round.workers_replied, std::memory_order_relaxed);
      asked.store(round.workers_asked, std::memory_order_relaxed);
    };
  }

  const std::string dir = new_run_dir(s.out_dir);
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) die(2, dir + ": cannot create the run directory (" + ec.message() + ")");

  Result<rt::ForceLaw> law = rt::ForceLaw::make(s.law);
  if (!law) die(2, s.file + ": " + law.error());
  const std::size_t ticks_expected = std::size_t(s.haptic.rate_hz * (s.duration_s + 2));
  rt::SimulatedDevice sim(script, s.device.user, ticks_expected, s.saturation.peak_N);
  MonitoredDevice device(sim);
  std::unique_ptr<rt::Telemetry> telemetry;
  const std::string csv = dir + "/ticks.csv";
  if (s.write_trace || s.write_perfetto) {
    Result<std::unique_ptr<rt::Telemetry>> t = rt::Telemetry::open(csv);
    if (!t) die(2, t.error());
    telemetry = std::move(t).value();
  }
  auto poses = std::make_unique<rt::TripleBuffer<rt::PoseSample>>();
  auto models = std::make_unique<rt::TripleBuffer<geom::ContactModel>>();
  rt::HapticServo servo(device, *poses, *models, law.value(), s.interp, s.saturation, telemetry.get());
  CollisionLoop collision(probe, object, *poses, *models, collide_fn, s.collision_rate_hz,
                          std::size_t(std::max(1.0, s.duration_s) * 20000));

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  rt::HapticLoop loop(s.haptic);
  collision.start();
  Result<rt::RtReport> rep = loop.start(servo);
  if (!rep) {
    collision.stop();
    die(1, "haptic loop: " + rep.error());
  }
  if (!rep.value().all_applied() || rep.value().fifo.requested || rep.value().mlock.requested)
    std::fprintf(stderr, "real-time: %s\n", rep.value().describe().c_str());
  std::fprintf(stderr, "running %.1f s: %s, collision %s; run directory %s (Ctrl-C stops)\n", s.duration_s,
               s.device.script == "builtin" ? "built-in approach/press/slide/release" : s.device.script.c_str(),
               backend.c_str(), dir.c_str());

  const std::int64_t t_start = rt::now_ns();
  std::int64_t last_print = t_start;
  std::uint64_t last_ticks = 0, last_rounds = 0;
  const std::int64_t print_every = tty ? 200'000'000 : 1'000'000'000;
  while (g_signal.load() == 0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const std::int64_t now = rt::now_ns();
    const double elapsed = double(now - t_start) * 1e-9;
    if (elapsed >= s.duration_s) break;
    if (show && now - last_print >= print_every) {
      const double dt = double(now - last_print) * 1e-9;
      const std::uint64_t ticks = loop.ticks(), rounds = collision.rounds();
      char line[256];
      std::snprintf(line, sizeof line,
                    "t %5.1f s | haptic %6.0f Hz, %llu misses | collision %5.0f Hz, %6.2f ms, %u contacts | "
                    "force %5.2f N | %s%s",
                    elapsed, double(ticks - last_ticks) / dt, static_cast<unsigned long long>(loop.misses()),
                    double(rounds - last_rounds) / dt, double(collision.last_latency_ns()) * 1e-6,
                    collision.last_contacts(), device.last_N(), backend.c_str(),
                    fleet ? (", " + std::to_string(replied.load()) + "/" + std::to_string(asked.load()) + " answering").c_str() : "");
      if (tty) std::printf("\r\033[K%s", line);
      else std::printf("%s\n", line);
      std::fflush(stdout);
      last_print = now;
      last_ticks = ticks;
      last_rounds = rounds;
    }
  }
  const std::int64_t t_end = rt::now_ns();
  loop.stop();
  collision.stop();
  if (telemetry) telemetry->close();
  if (tty && show) std::printf("\n");
  if (g_signal.load()) std::fprintf(stderr, "stopped by signal %d\n", g_signal.load());

  // Summary.
  const double secs = double(t_end - t_start) * 1e-9;
  const rt::LoopStats& ls = loop.stats();
  std::vector<double> lat_ms;
  for (const RoundRecord& r : collision.records()) lat_ms.push_back(double(r.end_ns - r.start_ns) * 1e-6);
  const rt::TelemetryStats ts = telemetry ? telemetry->stats() : rt::TelemetryStats{};
  std::string summary;
  char buf[512];
  auto add = [&](const char* fmt, auto... v) {
    std::snprintf(buf, sizeof buf, fmt, v...);
    summary += buf;
  };
  add("summary\n");
  add("  duration        %.2f s\n", secs);
  add("  haptic          %llu ticks (%.1f Hz), %llu misses, %llu overruns, wake-up p99 %.1f us\n",
      static_cast<unsigned long long>(ls.ticks), double(ls.ticks) / secs, static_cast<unsigned long long>(ls.misses),
      static_cast<unsigned long long>(ls.overruns), double(ls.wake_latency.percentile_ns(0.99)) / 1000.0);
  add("  collision       %llu rounds (%.1f Hz), latency p50 %.3f ms, p99 %.3f ms, %llu incomplete; %s\n",
      static_cast<unsigned long long>(collision.rounds()), double(collision.rounds()) / secs, percentile(lat_ms, 0.5),
      percentile(lat_ms, 0.99), static_cast<unsigned long long>(collision.incomplete()), backend.c_str());
  add("  force           peak %.3f N (limit %.2f N), peak penetration %.3f mm\n", device.peak_N(), s.saturation.peak_N,
      std::max(0.0, collision.peak_penetration_mm()));
  add("  telemetry       %llu samples, %llu dropped\n", static_cast<unsigned long long>(ts.pushed),
      static_cast<unsigned long long>(ts.dropped));
  if (sim.dropped_records()) add("  device records  %llu dropped\n", static_cast<unsigned long long>(sim.dropped_records()));
  add("  outputs         %s/\n", dir.c_str());
  if (s.write_perfetto && telemetry) {
    if (Status st = write_trace_json(dir + "/trace.json", csv, collision.records()); !st) add("  trace.json: %s\n", st.error().c_str());
    else add("    trace.json    haptic ticks and collision rounds (open in ui.perfetto.dev or chrome://tracing)\n");
  }
  if (s.write_trace) add("    ticks.csv     one line per haptic tick\n");
  if (s.write_ply) {
    if (collision.peak_pairs().empty()) {
      add("    contact.ply   not written: the probe never touched the object\n");
    } else if (Status st = write_contact_ply(dir + "/contact.ply", probe, object, collision.peak_pose(), collision.peak_pairs()); !st) {
      add("    contact.ply: %s\n", st.error().c_str());
    } else {
      add("    contact.ply   contact state at peak penetration, colliding faces red (MeshLab, Blender)\n");
    }
  }
  std::fputs(summary.c_str(), stdout);
  if (std::FILE* f = std::fopen((dir + "/summary.txt").c_str(), "w")) {
    std::fputs(summary.c_str(), f);
    std::fclose(f);
  }
  if (!s.write_trace && telemetry) std::filesystem::remove(csv, ec);
}

}  // namespace

void add_run(CLI::App& app) {
  auto a = std::make_shared<RunArgs>();
  CLI::App* cmd = app.add_subcommand(
      "run", "Touch an object: haptic loop (1 kHz), collision thread, workers and telemetry, with a simulated\n"
             "device running the scene's script. Writes a run directory: ticks.csv, trace.json, contact.ply,\n"
             "summary.txt.");
  cmd->add_option("scene", a->scene, "scene file (configs/demo.toml documents every field)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--duration", a->duration_s, "seconds to run (overrides [run] duration_s)")->check(CLI::Range(0.01, 1e6));
  cmd->add_option("--workers", a->workers, "in-process workers (overrides [workers] count; 0 = collide in the collision thread)")
      ->check(CLI::Range(0, 64));
  cmd->add_option("--connect", a->connect, "worker daemons EP1,EP2,... (tcp:// or ipc://; overrides [workers])");
  cmd->add_option("--out", a->out, "run directory (default: a new runs/<timestamp>)");
  cmd->callback([a] { run(*a); });
}

}  // namespace st::app
