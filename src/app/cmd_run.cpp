// SPDX-License-Identifier: BSD-3-Clause
// spheretouch run SCENE: the main job (engine/run_engine.hpp runs it). This file is what is about
// the terminal: arguments and their overrides of the scene, CURVE key flags, signals, the status
// line, and the summary on stdout.
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <thread>

#include "app/commands.hpp"
#include <spheretouch/view/view_server.hpp>
#include <spheretouch/engine/run_engine.hpp>
#include <spheretouch/rt/clock.hpp>

namespace st::app {
namespace {

std::atomic<int> g_signal{0};
extern "C" void on_signal(int sig) { g_signal.store(sig); }

/// Where --view listens when given without an address.
constexpr const char* kDefaultViewAddress = "127.0.0.1:8080";

struct RunArgs {
  std::string scene;
  double duration_s = -1;
  int workers = -1;
  std::string connect, out;
  std::string server_key, client_key;  ///< CURVE key files (override [workers] server_key, client_key)
  bool split = false;                  ///< the servo as its own process
  std::string shm_name;                ///< segment name ("" = /spheretouch-<pid>-<random>)
  std::string view;                    ///< live view ADDR:PORT ("" = none)
};

[[noreturn]] void die(int code, const std::string& msg) { fail_command("spheretouch", code, msg); }

// `run --view SCENE`: --view's address is optional, so CLI11 hands it the scene. When no scene was
// given and --view's value is no ADDR:PORT but a file, it is the scene and the view takes its
// default address.
RunArgs resolve_view_or_scene(RunArgs a) {
  if (!a.scene.empty()) return a;
  if (!a.view.empty() && !view::check_listen(a.view).empty() && std::filesystem::is_regular_file(a.view)) {
    a.scene = a.view;
    a.view = kDefaultViewAddress;
    return a;
  }
  die(2,
      "run: a scene file is required: spheretouch run [OPTIONS] SCENE.toml (configs/demo.toml documents every "
      "field)");
}

void run(const RunArgs& given) {
  const RunArgs a = resolve_view_or_scene(given);
  Result<engine::Scene> sr = engine::load_scene(a.scene);
  if (!sr) die(2, sr.error());
  engine::Scene s = std::move(sr).value();
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
  Result<engine::ClientCurve> curve = engine::load_client_curve(s.server_key, s.client_key, server_what, client_what);
  if (!curve) die(2, curve.error());
  if (curve.value().enabled() && s.endpoints.empty())
    die(2, "CURVE keys (" + server_what + ", " + client_what +
               ") are for worker daemons: give their endpoints "
               "([workers] endpoints or --connect)");
  if (!a.view.empty())
    if (const std::string bad = view::check_listen(a.view); !bad.empty()) die(2, bad);  // before anything loads
  const bool tty = s.status == "tty" || (s.status == "auto" && ::isatty(STDOUT_FILENO));
  const bool show = s.status != "off";

  engine::RunOptions opt;
  opt.split = a.split;
  opt.scene_path = a.scene;
  opt.shm_name = a.shm_name;
  opt.curve = curve.value();
  opt.note = [](const std::string& m) { std::fprintf(stderr, "%s\n", m.c_str()); };
  opt.stop = &g_signal;
  Result<std::unique_ptr<engine::RunEngine>> made = engine::RunEngine::prepare(s, opt);
  if (!made) die(2, made.error());
  engine::RunEngine& run = *made.value();

  // The live view: frames and figures come from the run's shared-memory status area.
  std::unique_ptr<view::ViewServer> viewer;
  if (run.pose_feed() && a.view.empty())
    die(2, s.file + ": device.kind = \"browser\" is driven from the live view's page: add --view [ADDR:PORT]");
  if (!a.view.empty()) {
    view::ViewServerConfig vc;
    vc.listen = a.view;
    vc.out_dir = run.run_dir();
    for (const auto& [mesh, placement] : run.placed_objects()) vc.objects.push_back({mesh, placement});
    Result<std::unique_ptr<view::ViewServer>> v =
        view::ViewServer::start(vc, run.probe(), run.object(), run.shm_status().view, run.shm_status(), run.pose_feed());
    if (!v) die(2, v.error());
    viewer = std::move(v).value();
    std::fprintf(stderr, "view: %s (open it in a browser)\n", viewer->url().c_str());
  }

  on_stop_signals(on_signal);

  if (Status st = run.start(); !st) die(1, st.error());
  std::fprintf(stderr, "running %.1f s: %s, collision %s, %s; shm %s; run directory %s (Ctrl-C stops)\n", s.duration_s,
               s.device.kind == "udp"         ? "a device over UDP"
               : s.device.kind == "browser"   ? "the live view's page as the device"
               : s.device.script == "builtin" ? "built-in approach/press/slide/release"
                                              : s.device.script.c_str(),
               run.backend().c_str(), run.servo_where().c_str(), run.shm_name().c_str(), run.run_dir().c_str());
  if (const std::string split = run.split(); !split.empty()) std::fprintf(stderr, "split: %s\n", split.c_str());

  std::int64_t last_print = rt::now_ns();
  std::uint64_t last_ticks = 0, last_rounds = 0;
  const std::int64_t print_every = tty ? 200'000'000 : 1'000'000'000;
  std::vector<std::string> notes;
  while (true) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    notes.clear();
    const bool going = run.poll(g_signal.load() != 0, notes);
    for (const std::string& m : notes) std::fprintf(stderr, "%s%s\n", tty && show ? "\n" : "", m.c_str());
    if (!going) break;
    const std::int64_t now = rt::now_ns();
    if (show && now - last_print >= print_every) {
      const double dt = double(now - last_print) * 1e-9;
      const engine::RunStatus st = run.status();
      char line[256];
      std::snprintf(
          line, sizeof line,
          "t %5.1f s | haptic %6.0f Hz, %llu misses | collision %5.0f Hz, %6.2f ms, %u contacts | "
          "force %5.2f N | %s%s",
          st.elapsed_s, double(st.ticks - last_ticks) / dt, static_cast<unsigned long long>(st.misses),
          double(st.rounds - last_rounds) / dt, st.round_ms, st.contacts, st.force_N, run.backend().c_str(),
          run.has_fleet()
              ? (", " + std::to_string(st.workers_replied) + "/" + std::to_string(st.workers_asked) + " answering").c_str()
              : "");
      if (tty)
        std::printf("\r\033[K%s", line);
      else
        std::printf("%s\n", line);
      std::fflush(stdout);
      last_print = now;
      last_ticks = st.ticks;
      last_rounds = st.rounds;
    }
  }
  engine::RunReport report = run.finish(g_signal.load());
  if (viewer) {
    report.summary += "  view            " + viewer->summary() + "\n";
    viewer.reset();  // pages see the stream end
  }
  if (tty && show) std::printf("\n");
  if (g_signal.load()) std::fprintf(stderr, "stopped by signal %d\n", g_signal.load());
  // The summary goes to stdout whatever happened to the files; failures follow on stderr.
  std::fputs(report.summary.c_str(), stdout);
  std::fflush(stdout);
  run.save(report);
  if (!report.failures.empty()) {
    for (const std::string& f : report.failures) std::fprintf(stderr, "spheretouch run: %s\n", f.c_str());
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
  // Not required() here: `run --view SCENE` hands the scene to --view (resolve_view_or_scene).
  cmd->add_option("scene", a->scene, "scene file (configs/demo.toml documents every field)")->check(CLI::ExistingFile);
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
  cmd->add_option("--view", a->view,
                  "serve a live view of the run at ADDR:PORT (default 127.0.0.1:8080): the object, the probe, "
                  "the colliding faces in red, the force, the figures; open the printed URL in a browser")
      ->expected(0, 1)
      ->default_str(kDefaultViewAddress);
  cmd->add_flag("--split", a->split,
                "run the haptic servo as its own process on the shared-memory segment: it keeps the device\n"
                "safe (force fades to zero) and finishes its run if the collision side dies");
  cmd->add_option("--shm-name", a->shm_name,
                  "shared-memory segment of the run (default /spheretouch-<pid>-<16 random hex digits>, which no other "
                  "user can guess or take first); `spheretouch monitor` attaches to it");
  cmd->callback([a] { run(*a); });
}

}  // namespace st::app
