// spheretouch run SCENE: the main job. A probe touches an object with force at 1 kHz: the
// haptic thread (HapticLoop + HapticServo) never waits; the collision thread answers poses with
// contact models; telemetry goes to a per-tick CSV.
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <thread>
#include <sys/wait.h>
#include <unistd.h>
#include <cmath>

#include "app/collision_loop.hpp"
#include "app/commands.hpp"
#include "app/distributed.hpp"
#include "app/run_outputs.hpp"
#include "app/scene.hpp"
#include "app/servo_process.hpp"
#include "app/tree_cache.hpp"
#include "rt/clock.hpp"
#include "rt/haptic_servo.hpp"
#include "rt/shm_segment.hpp"
#include "rt/telemetry.hpp"

namespace st::app {
namespace {

std::atomic<int> g_signal{0};
extern "C" void on_signal(int sig) { g_signal.store(sig); }

struct RunArgs {
  std::string scene;
  double duration_s = -1;
  int workers = -1;
  std::string connect, out;
  std::string server_key, client_key;  ///< CURVE key files (override [workers] server_key, client_key)
  bool split = false;                  ///< the servo as its own process
  std::string shm_name;                ///< segment name ("" = /spheretouch-<pid>)
};

[[noreturn]] void die(int code, const std::string& msg) { fail_command("spheretouch", code, msg); }

std::string new_run_dir(const std::string& wanted) {
  if (!wanted.empty()) return wanted;
  char stamp[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::localtime(&now));
  std::string dir = std::string("runs/") + stamp;
  for (int i = 2; std::filesystem::exists(dir); ++i) dir = std::string("runs/") + stamp + "-" + std::to_string(i);
  return dir;
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
  // Before any thread exists (ours, libzmq's): lock_memory keeps every thread's stack resident whole.
  if (s.thread_stack_bytes)
    if (Status st = rt::set_default_thread_stack(s.thread_stack_bytes); !st)
      die(2, s.file + ": haptic.thread_stack_kb: " + st.error());
  // CURVE keys for worker daemons: the flags override the scene; read now, so a bad key file
  // fails before any mesh is loaded. Errors name the flag or the scene field.
  std::string server_what = s.file + ": workers.server_key", client_what = s.file + ": workers.client_key";
  if (!a.server_key.empty()) {
    s.server_key = a.server_key;
    server_what = "--server-key";
  }
  if (!a.client_key.empty()) {
    s.client_key = a.client_key;
    client_what = "--client-key";
  }
  Result<ClientCurve> curve = load_client_curve(s.server_key, s.client_key, server_what, client_what);
  if (!curve) die(2, curve.error());
  if (curve.value().enabled() && s.endpoints.empty())
    die(2, "CURVE keys (" + server_what + ", " + client_what +
               ") are for worker daemons: give their endpoints "
               "([workers] endpoints or --connect)");
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
    if (s.approx_layer != geom::kExact)
      die(2, s.file + ": collision.mode = \"approximate\" runs without workers (set workers.count = 0)");
    FleetSpec spec;
    spec.workers = s.workers;
    spec.endpoints = s.endpoints;
    spec.layer = s.layer;
    spec.block_size = s.block_size;
    spec.leaf_faces = s.tree.leaf_faces;
    spec.miss_limit = std::uint32_t(s.down_after);
    spec.curve = curve.value();
    spec.note = [](const std::string& m) { std::fprintf(stderr, "%s\n", m.c_str()); };
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
  // Run outputs (poses, forces, the contact state) are the user's: the directory is private.
  if (!ec)
    std::filesystem::permissions(dir, std::filesystem::perms::owner_all, std::filesystem::perm_options::replace, ec);
  if (ec) die(2, dir + ": cannot create the run directory (" + ec.message() + ")");

  Result<rt::ForceLaw> law = rt::ForceLaw::make(s.law);
  if (!law) die(2, s.file + ": " + law.error());

  // The triple buffers live in a named shared-memory segment in both modes, so `spheretouch
  // monitor` can watch any run; with --split the servo process attaches to it.
  const std::string shm_name = a.shm_name.empty() ? "/spheretouch-" + std::to_string(getpid()) : a.shm_name;
  Result<std::unique_ptr<rt::ShmSegment>> segr = rt::ShmSegment::create(shm_name);
  if (!segr) die(2, segr.error());
  rt::ShmSegment& shm = *segr.value();
  rt::ShmStatus& status = shm.status();

  const std::string csv = dir + "/ticks.csv";
  // In-process servo (no --split): device, telemetry and loop live here.
  std::unique_ptr<rt::SimulatedDevice> sim;
  std::unique_ptr<rt::Telemetry> telemetry;
  std::unique_ptr<rt::HapticServo> servo;
  rt::HapticLoop loop(s.haptic);
  if (!a.split) {
    // Commanded forces go to the per-tick trace, not into device records: memory stays flat however long the run.
    sim = std::make_unique<rt::SimulatedDevice>(script, s.device.user, 0, s.saturation.peak_N);
    sim->set_repeat(s.device.repeat);
    if (s.write_trace || s.write_perfetto) {
      Result<std::unique_ptr<rt::Telemetry>> t = rt::Telemetry::open(csv);
      if (!t) die(2, t.error());
      telemetry = std::move(t).value();
    }
    servo = std::make_unique<rt::HapticServo>(*sim, shm.poses(), shm.models(), law.value(), s.interp, s.saturation,
                                              telemetry.get(), s.passivity, 1.0 / s.haptic.rate_hz);
    servo->publish_status_to(&status.servo);
  }
  CollisionLoop collision(probe, object, shm.poses(), shm.models(), collide_fn, s.collision_rate_hz, 0, s.contact);
  collision.publish_status_to(&status.collision);
  const std::string rounds_csv = dir + "/rounds.csv";
  if (s.write_trace || s.write_perfetto)
    if (Status st = collision.write_rounds_csv(rounds_csv); !st) die(2, st.error());

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGHUP, &sa, nullptr);  // a closed terminal ends the run like Ctrl-C: summary kept, segment removed

  pid_t servo_pid = 0;
  if (a.split) {
    // The servo gets the trajectory as a file (it loads no meshes) and the scene for its settings.
    const std::string script_file = dir + "/script.txt";
    if (Status w = write_trajectory(script_file, script); !w) die(2, w.error());
    ServoArgs sa_child;
    sa_child.shm = shm.name();
    sa_child.scene = std::filesystem::absolute(a.scene).string();
    sa_child.script = std::filesystem::absolute(script_file).string();
    sa_child.out = std::filesystem::absolute(dir).string();
    sa_child.duration_s = s.duration_s;
    sa_child.parent = getpid();
    Result<pid_t> sp = spawn_servo(sa_child);
    if (!sp) die(1, sp.error());
    servo_pid = sp.value();
    // Wait until the servo ticks (or fails to start): its status says so.
    for (int i = 0; status.servo_state.load(std::memory_order_acquire) < std::uint32_t(rt::ServoState::running); ++i) {
      int ws = 0;
      if (waitpid(servo_pid, &ws, WNOHANG) == servo_pid)
        die(1, "servo process (pid " + std::to_string(servo_pid) + ") failed to start (exit " +
                   std::to_string(WIFEXITED(ws) ? WEXITSTATUS(ws) : 128 + WTERMSIG(ws)) + ")");
      if (i > 1000 || g_signal.load()) {  // 10 s
        kill(servo_pid, SIGKILL);
        waitpid(servo_pid, &ws, 0);
        die(1, "servo process (pid " + std::to_string(servo_pid) + ") did not start ticking within 10 s");
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    collision.start();
  } else {
    status.servo_start_ticks.store(rt::process_start_ticks(getpid()), std::memory_order_relaxed);
    status.servo_pid.store(getpid(), std::memory_order_relaxed);
    status.servo_state.store(std::uint32_t(rt::ServoState::starting), std::memory_order_release);
    collision.start();
    Result<rt::RtReport> rep = loop.start(*servo);
    if (!rep) {
      collision.stop();
      die(1, "haptic loop: " + rep.error());
    }
    if (!rep.value().all_applied() || rep.value().fifo.requested || rep.value().mlock.requested)
      std::fprintf(stderr, "real-time: %s\n", rep.value().describe().c_str());
    status.servo_state.store(std::uint32_t(rt::ServoState::running), std::memory_order_release);
  }
  const std::string servo_where =
      a.split ? "servo process pid " + std::to_string(servo_pid) : std::string("servo thread");
  std::fprintf(stderr, "running %.1f s: %s, collision %s, %s; shm %s; run directory %s (Ctrl-C stops)\n", s.duration_s,
               s.device.script == "builtin" ? "built-in approach/press/slide/release" : s.device.script.c_str(),
               backend.c_str(), servo_where.c_str(), shm.name().c_str(), dir.c_str());

  const std::int64_t t_start = rt::now_ns();
  std::int64_t last_print = t_start;
  std::uint64_t last_ticks = 0, last_rounds = 0;
  const std::int64_t print_every = tty ? 200'000'000 : 1'000'000'000;
  int servo_exit = -1;     // split: the servo process's exit code once it ended
  bool forwarded = false;  // split: a signal was passed on to the servo
  std::int64_t forwarded_ns = 0;
  SilenceWatch silence(s.interp.stale_timeout_ns);
  // Resident memory after one second of running (trees, buffers and connections in place) and at
  // the end: a long run must not grow (the soak test's target is < 1 MB).
  std::uint64_t rss_start = 0, rss_end = 0;
  while (true) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const std::int64_t now = rt::now_ns();
    const double elapsed = double(now - t_start) * 1e-9;
    if (rss_start == 0 && elapsed >= std::min(1.0, s.duration_s / 2)) rss_start = rt::resident_bytes();
    if (a.split) {
      // The servo ends the run (its duration, or a signal we forward); never wait forever.
      int ws = 0;
      if (waitpid(servo_pid, &ws, WNOHANG) == servo_pid) {
        servo_exit = WIFEXITED(ws) ? WEXITSTATUS(ws) : 128 + WTERMSIG(ws);
        break;
      }
      if ((g_signal.load() && !forwarded) || (elapsed > s.duration_s + 10 && !forwarded)) {
        kill(servo_pid, SIGTERM);  // it stops ticking, writes its outputs and exits
        forwarded = true;
        forwarded_ns = now;
      } else if (forwarded && now - forwarded_ns > 5'000'000'000) {
        kill(servo_pid, SIGKILL);  // unresponsive for 5 s: do not hang the run
      }
    } else {
      if (g_signal.load() || elapsed >= s.duration_s) break;
    }
    rt::ServoStatus ss;
    const bool have_ss = status.servo.load(ss);
    if (!a.split && have_ss) {
      const std::string msg = silence.poll(ss, now);
      if (!msg.empty()) std::fprintf(stderr, "%s%s\n", tty && show ? "\n" : "", msg.c_str());
    }
    if (show && now - last_print >= print_every) {
      const double dt = double(now - last_print) * 1e-9;
      const std::uint64_t ticks = have_ss ? ss.ticks : 0, rounds = collision.rounds();
      const double force =
          have_ss
              ? std::sqrt(ss.force_N[0] * ss.force_N[0] + ss.force_N[1] * ss.force_N[1] + ss.force_N[2] * ss.force_N[2])
              : 0.0;
      char line[256];
      std::snprintf(
          line, sizeof line,
          "t %5.1f s | haptic %6.0f Hz, %llu misses | collision %5.0f Hz, %6.2f ms, %u contacts | "
          "force %5.2f N | %s%s",
          elapsed, double(ticks - last_ticks) / dt, static_cast<unsigned long long>(have_ss ? ss.misses : 0),
          double(rounds - last_rounds) / dt, double(collision.last_latency_ns()) * 1e-6, collision.last_contacts(),
          force, backend.c_str(),
          fleet ? (", " + std::to_string(replied.load()) + "/" + std::to_string(asked.load()) + " answering").c_str() : "");
      if (tty)
        std::printf("\r\033[K%s", line);
      else
        std::printf("%s\n", line);
      std::fflush(stdout);
      last_print = now;
      last_ticks = ticks;
      last_rounds = rounds;
    }
  }
  const std::int64_t t_end = rt::now_ns();
  rss_end = rt::resident_bytes();
  ServoResults sres;
  if (!a.split) {
    loop.stop();
    status.servo_state.store(std::uint32_t(rt::ServoState::finished), std::memory_order_release);
  }
  collision.stop();
  if (telemetry) telemetry->close();
  if (tty && show) std::printf("\n");
  if (g_signal.load()) std::fprintf(stderr, "stopped by signal %d\n", g_signal.load());

  const double secs = double(t_end - t_start) * 1e-9;
  // Every failure to write an output is collected and reported after the summary, which is always
  // printed; the exit status is then 1 (a full disk must not look like a good run).
  std::vector<std::string> failures;
  if (a.split) {
    // The summary is printed even when the servo's results cannot be read (its process failed, or
    // the disk was full when it wrote servo.txt): with the collision side's figures and a note.
    if (servo_exit != 0)
      failures.push_back("servo process (pid " + std::to_string(servo_pid) + ") ended with exit " +
                         std::to_string(servo_exit));
    Result<ServoResults> r = read_servo_results(dir + "/servo.txt");
    if (r)
      sres = r.value();
    else
      failures.push_back(r.error() + " (the servo's figures below are missing)");
  } else {
    const rt::LoopStats& ls = loop.stats();
    sres.seconds = secs;
    sres.ticks = ls.ticks;
    sres.misses = ls.misses;
    sres.overruns = ls.overruns;
    sres.wake_p99_us = double(ls.wake_latency.percentile_ns(0.99)) / 1000.0;
    sres.peak_force_N = servo->peak_force_N();
    sres.models = servo->stats().models;
    if (telemetry) {
      sres.telemetry_pushed = telemetry->stats().pushed;
      sres.telemetry_dropped = telemetry->stats().dropped;
    }
    sres.device_dropped = sim->dropped_records();
    if (telemetry && !telemetry->error().empty()) failures.push_back(telemetry->error());
    sres.silences = silence.episodes();
    sres.longest_silence_ms = silence.longest_ms();
  }

  // Summary.
  const rt::LatencyHistogram& lat = collision.latency();
  std::string summary;
  const double servo_secs = sres.seconds > 0 ? sres.seconds : secs;
  appendf(summary, "summary\n");
  appendf(summary, "  duration        %.2f s\n", secs);
  appendf(summary, "  haptic          %llu ticks (%.1f Hz), %llu misses, %llu overruns, wake-up p99 %.1f us; %s\n",
          static_cast<unsigned long long>(sres.ticks), double(sres.ticks) / servo_secs,
          static_cast<unsigned long long>(sres.misses), static_cast<unsigned long long>(sres.overruns),
          sres.wake_p99_us, servo_where.c_str());
  appendf(summary, "  collision       %llu rounds (%.1f Hz), latency p50 %.3f ms, p99 %.3f ms, %llu incomplete; %s\n",
          static_cast<unsigned long long>(collision.rounds()), double(collision.rounds()) / secs,
          double(lat.percentile_ns(0.5)) * 1e-6, double(lat.percentile_ns(0.99)) * 1e-6,
          static_cast<unsigned long long>(collision.incomplete()), backend.c_str());
  if (sres.silences)
    appendf(summary,
            "  silences        %llu: no contact model for the stale timeout, force faded to zero (longest %.0f ms)\n",
            static_cast<unsigned long long>(sres.silences), sres.longest_silence_ms);
  appendf(summary, "  force           peak %.3f N (limit %.2f N), peak penetration %.3f mm\n", sres.peak_force_N,
          s.saturation.peak_N, std::max(0.0, collision.peak_penetration_mm()));
  {
    std::string guard = s.passivity.enabled ? "passivity guard on" : "passivity guard off";
    if (s.passivity.enabled && !a.split)
      appendf(guard, " (controller acted on %llu ticks)",
              static_cast<unsigned long long>(servo->passivity().active_ticks()));
    appendf(summary, "  contact         model %s, interpolation %s, %s\n", geom::to_string(s.contact.model),
            rt::to_string(s.interp.mode), guard.c_str());
  }
  appendf(summary, "  telemetry       %llu samples, %llu dropped\n",
          static_cast<unsigned long long>(sres.telemetry_pushed), static_cast<unsigned long long>(sres.telemetry_dropped));
  if (sres.device_dropped)
    appendf(summary, "  device records  %llu dropped\n", static_cast<unsigned long long>(sres.device_dropped));
  if (rss_start && rss_end)
    appendf(summary, "  memory          RSS %.1f MB after %.1f s, %.1f MB at the end (%+.2f MB)\n", double(rss_start) / 1e6,
            std::min(1.0, s.duration_s / 2), double(rss_end) / 1e6, (double(rss_end) - double(rss_start)) / 1e6);
  appendf(summary, "  outputs         %s/\n", dir.c_str());
  if (!collision.rounds_csv_error().empty()) failures.push_back(collision.rounds_csv_error());
  // ticks.csv is whole when its writer saw no error (in this process, or the servo process's exit).
  const bool ticks_whole =
      (telemetry ? telemetry->error().empty() : !(a.split && servo_exit != 0)) && collision.rounds_csv_error().empty();
  const bool have_csv = (s.write_trace || s.write_perfetto) && std::filesystem::exists(csv);
  if (s.write_perfetto && have_csv && !ticks_whole) {
    appendf(summary, "    trace.json    not written: ticks.csv or rounds.csv is incomplete\n");
  } else if (s.write_perfetto && have_csv) {
    if (Status st = write_trace_json(dir + "/trace.json", csv, rounds_csv); !st) {
      appendf(summary, "  trace.json: %s\n", st.error().c_str());
      failures.push_back(st.error());
    } else
      appendf(summary,
              "    trace.json    haptic ticks and collision rounds (open in ui.perfetto.dev or chrome://tracing)\n");
  }
  if (s.write_trace)
    appendf(summary, "    ticks.csv     one line per haptic tick; rounds.csv one line per collision round\n");
  if (a.split) appendf(summary, "    servo.txt     the servo process's counters; script.txt its trajectory\n");
  if (s.write_ply) {
    if (collision.peak_pairs().empty()) {
      appendf(summary, "    contact.ply   not written: the probe never touched the object\n");
    } else if (Status st =
                   write_contact_ply(dir + "/contact.ply", probe, object, collision.peak_pose(), collision.peak_pairs());
               !st) {
      appendf(summary, "    contact.ply: %s\n", st.error().c_str());
      failures.push_back(st.error());
    } else {
      appendf(summary, "    contact.ply   contact state at peak penetration, colliding faces red (MeshLab, Blender)\n");
    }
  }
  if (!failures.empty())
    appendf(summary, "  FAILED          %zu output(s) not written whole; first: %s\n", failures.size(),
            failures[0].c_str());
  std::fputs(summary.c_str(), stdout);
  std::fflush(stdout);
  const std::string summary_path = dir + "/summary.txt";
  if (std::FILE* f = std::fopen(summary_path.c_str(), "w")) {
    const bool wrote = std::fputs(summary.c_str(), f) >= 0 && std::fflush(f) == 0;
    const int err = errno;
    if ((std::fclose(f) != 0 || !wrote))
      failures.push_back(summary_path + ": write failed: " + std::strerror(wrote ? errno : err));
  } else {
    failures.push_back(summary_path + ": cannot create: " + std::strerror(errno));
  }
  if (!s.write_trace && have_csv && std::filesystem::is_regular_file(csv)) {
    std::filesystem::remove(csv, ec);
    std::filesystem::remove(rounds_csv, ec);
  }
  if (!failures.empty()) {
    for (const std::string& f : failures) std::fprintf(stderr, "spheretouch run: %s\n", f.c_str());
    throw CLI::RuntimeError(1);  // unwinds: workers stop, the shared-memory segment is removed
  }
}

}  // namespace

void add_run(CLI::App& app) {
  auto a = std::make_shared<RunArgs>();
  CLI::App* cmd = app.add_subcommand(
      "run",
      "Touch an object: haptic loop (1 kHz), collision thread, workers and telemetry, with a simulated\n"
      "device running the scene's script. Writes a run directory: ticks.csv, trace.json, contact.ply,\n"
      "summary.txt. --split: the servo runs as its own process on a shared-memory segment\n"
      "(`spheretouch monitor` watches either kind of run).");
  cmd->add_option("scene", a->scene, "scene file (configs/demo.toml documents every field)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--duration", a->duration_s, "seconds to run (overrides [run] duration_s)")->check(CLI::Range(0.01, 1e6));
  cmd->add_option("--workers", a->workers,
                  "in-process workers (overrides [workers] count; 0 = collide in the collision thread)")
      ->check(CLI::Range(0, 64));
  cmd->add_option("--connect", a->connect, "worker daemons EP1,EP2,... (tcp:// or ipc://; overrides [workers])");
  cmd->add_option("--server-key", a->server_key,
                  "CURVE: the workers' public key file, PREFIX.pub from `spheretouch keygen` (overrides [workers] "
                  "server_key)")
      ->type_name("FILE");
  cmd->add_option("--client-key", a->client_key,
                  "CURVE: this client's key pair PREFIX: PREFIX.key (mode 0600) and PREFIX.pub; its public key must be "
                  "in the workers' allowed_clients (overrides [workers] client_key)")
      ->type_name("PREFIX");
  cmd->add_option("--out", a->out, "run directory (default: a new runs/<timestamp>)");
  cmd->add_flag("--split", a->split,
                "run the haptic servo as its own process on the shared-memory segment: it keeps the device\n"
                "safe (force fades to zero) and finishes its run if the collision side dies");
  cmd->add_option(
      "--shm-name", a->shm_name,
      "shared-memory segment of the run (default /spheretouch-<pid>); `spheretouch monitor` attaches to it");
  cmd->callback([a] { run(*a); });
}

}  // namespace st::app
