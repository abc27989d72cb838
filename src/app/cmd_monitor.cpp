// SPDX-License-Identifier: BSD-3-Clause
// spheretouch monitor: watch a live run through its shared-memory segment, read-only. It maps
// the segment PROT_READ and reads only the status area (SeqLocks any number of readers may
// share), never the triple buffers, whose single reader is the servo or the collision thread.
// --view also serves the run's live view: the meshes come from the scene file the run recorded
// (checked against the run's counts and hashes), the frames and figures from the status area,
// copied by this thread (SIGBUS guard armed) into a process-local status area the view reads.
#include <dirent.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csetjmp>
#include <csignal>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "app/commands.hpp"
#include <spheretouch/engine/scene.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/shm_segment.hpp>
#include <spheretouch/view/view_server.hpp>

namespace st::app {
namespace {

std::atomic<int> g_monitor_signal{0};
extern "C" void on_monitor_signal(int sig) { g_monitor_signal.store(sig); }

// A segment truncated under the monitor (by its creator going away oddly, or by anyone who can
// write it) turns the next read of the mapping into SIGBUS. The reads of one status line run
// with this jump armed: the handler returns to the loop, which reports the segment and stops.
sigjmp_buf g_bus_jump;
volatile std::sig_atomic_t g_bus_armed = 0;
extern "C" void on_monitor_bus(int sig) {
  if (g_bus_armed) siglongjmp(g_bus_jump, 1);
  std::signal(sig, SIG_DFL);  // not ours: die of it as before
  std::raise(sig);
}

/// What one status line needs from the segment.
struct Reading {
  std::string line;
  rt::ServoState state = rt::ServoState::starting;
  int servo_pid = 0;
  std::uint64_t servo_start_ticks = 0;
};

struct MonitorArgs {
  std::string name;
  double interval_ms = 500;
  int count = 0;
  std::string view;  ///< live view ADDR:PORT ("" = none)
};

/// Segments named /dev/shm/spheretouch-* that attach read-only and whose servo has not finished.
std::vector<std::string> live_sessions() {
  std::vector<std::string> out;
  DIR* d = opendir("/dev/shm");
  if (!d) return out;
  while (dirent* e = readdir(d)) {
    const std::string n = e->d_name;
    if (n.rfind("spheretouch-", 0) != 0 || n.rfind("spheretouch-test-", 0) == 0) continue;
    auto seg = rt::ShmSegment::attach_read_only("/" + n);
    if (!seg) continue;
    const auto state = rt::ServoState(seg.value()->status().servo_state.load(std::memory_order_acquire));
    if (state != rt::ServoState::finished) out.push_back("/" + n);
  }
  closedir(d);
  return out;
}

double ms(std::int64_t ns) { return double(ns) * 1e-6; }

std::string status_line(const rt::ShmSegment& seg, std::int64_t now) {
  const rt::ShmStatus& st = seg.status();
  const int servo_pid = st.servo_pid.load(std::memory_order_relaxed);
  const bool split = st.split.load(std::memory_order_relaxed) != 0;
  const auto state = rt::ServoState(st.servo_state.load(std::memory_order_acquire));
  rt::ServoStatus sv;
  rt::CollisionStatus co;
  const bool have_sv = st.servo.load(sv), have_co = st.collision.load(co);
  std::string line;
  appendf(line, "t %6.2f s | ", double(now - seg.header().created_ns) * 1e-9);
  const char* state_name = state == rt::ServoState::running    ? ""
                           : state == rt::ServoState::starting ? " starting"
                           : state == rt::ServoState::finished ? " finished"
                                                               : " not started";
  appendf(line, "servo %s %d%s: ", split ? "process" : "thread of", servo_pid, state_name);
  if (have_sv) {
    const double f =
        std::sqrt(sv.force_N[0] * sv.force_N[0] + sv.force_N[1] * sv.force_N[1] + sv.force_N[2] * sv.force_N[2]);
    appendf(line, "%llu ticks, %llu misses | pose #%llu age %.1f ms | ", static_cast<unsigned long long>(sv.ticks),
            static_cast<unsigned long long>(sv.misses), static_cast<unsigned long long>(sv.pose_seq),
            ms(now - sv.pose_sampled_ns));
    appendf(line, "force %.3f N (peak %.3f), PD %.3f mm, fade %.2f | ", f, sv.peak_force_N, sv.penetration_mm, sv.fade);
  } else {
    appendf(line, "no ticks yet | ");
  }
  if (have_co)
    appendf(line, "model #%llu age %.1f ms, %u contacts, %llu rounds, %.2f ms",
            static_cast<unsigned long long>(co.model_seq), ms(now - co.updated_ns), co.contacts,
            static_cast<unsigned long long>(co.rounds), ms(co.latency_ns));
  else
    appendf(line, "no contact model yet");
  const std::uint32_t lost = st.collision_lost.load(std::memory_order_relaxed);
  // A run that ended normally (its servo finished) exits: that is no death.
  if (state == rt::ServoState::finished)
    appendf(line, seg.creator_alive() ? " | run ending" : " | run ended");
  else if (lost == 2 || !seg.creator_alive())
    appendf(line, " | collision process %d DEAD", seg.header().creator_pid);
  else if (lost == 1)
    appendf(line, " | collision side SILENT");
  return line;
}

// Runs `read` (reads of the mapping, no allocation) with the SIGBUS jump armed; false when the
// mapping had shrunk (the reads that faulted are abandoned).
template <class F>
bool guarded(F&& read) {
  g_bus_armed = 1;
  if (sigsetjmp(g_bus_jump, 1) != 0) {
    g_bus_armed = 0;
    return false;
  }
  read();
  g_bus_armed = 0;
  return true;
}

// Reads one status line's worth from the mapping, guarded (the string's storage is reserved
// first so the guarded code does not allocate).
bool read_status(const rt::ShmSegment& seg, Reading& rd) {
  rd.line.reserve(512);
  return guarded([&] {
    rd.line = status_line(seg, rt::now_ns());
    rd.state = rt::ServoState(seg.status().servo_state.load(std::memory_order_acquire));
    rd.servo_pid = seg.status().servo_pid.load(std::memory_order_relaxed);
    rd.servo_start_ticks = seg.status().servo_start_ticks.load();
  });
}

[[noreturn]] void shrank(const rt::ShmSegment& seg, bool tty) {
  if (tty) std::printf("\n");
  fail_command("spheretouch monitor", 1,
               seg.name() +
                   ": the segment shrank under the monitor (truncated by another "
                   "process): its contents are gone, stopped");
}

/// What --view serves: the run's meshes, loaded from its scene file and checked against it.
struct ViewMeshes {
  std::string scene;
  geom::Mesh probe, object;
  std::vector<geom::Mesh> more;        ///< a scene's other objects (the run checked only the first)
  std::vector<geom::Pose> placements;  ///< every object's, the first's first
};

// The scene reference the run wrote (it writes it right after creating the segment: a monitor
// that attached in between waits a moment), then the meshes the way the run loads them.
ViewMeshes load_view_meshes(const rt::ShmSegment& seg, bool tty) {
  auto ref = std::make_unique<rt::SceneRef>();
  bool have = false;
  for (int i = 0; i < 100 && !have && !g_monitor_signal.load(); ++i) {
    if (i > 0) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (!guarded([&] { have = seg.status().scene.load(*ref); })) shrank(seg, tty);
  }
  ref->scene_path[rt::SceneRef::kMaxPath - 1] = 0;  // whoever wrote it
  if (!have || ref->scene_path[0] == 0) {
    const char* why = have ? "the run recorded no scene file (not started from one, or its path is too long)"
                           : "the run has not recorded its scene file";
    fail_command("spheretouch monitor", 2, seg.name() + ": " + why + "; --view loads the run's meshes from it");
  }
  ViewMeshes m;
  m.scene = ref->scene_path;
  std::fprintf(stderr, "view: loading the run's probe and object from %s ...\n", m.scene.c_str());
  Result<engine::Scene> sr = engine::load_scene(m.scene);
  if (!sr)
    fail_command("spheretouch monitor", 2,
                 "cannot load the run's scene (--view loads the run's meshes from it): " + sr.error());
  const engine::Scene& s = sr.value();
  Result<geom::Mesh> pm = engine::load_body(s.probe, "probe");
  if (!pm) fail_command("spheretouch monitor", 2, s.file + ": " + pm.error());
  Result<geom::Mesh> om = engine::load_body(s.object, "object");
  if (!om) fail_command("spheretouch monitor", 2, s.file + ": " + om.error());
  m.probe = std::move(pm).value();
  m.object = std::move(om).value();
  // A scene of several objects: the others too, to draw them where the run has them.
  const std::vector<engine::ObjectSpec> objs = engine::scene_objects(s);
  for (std::size_t k = 0; k < objs.size(); ++k) {
    m.placements.push_back(objs[k].placement.pose());
    if (k == 0) continue;
    Result<geom::Mesh> more = engine::load_body(objs[k].body, "object[" + std::to_string(k + 1) + "]");
    if (!more) fail_command("spheretouch monitor", 2, s.file + ": " + more.error());
    m.more.push_back(std::move(more).value());
  }
  if (const std::string diff = engine::compare_scene_ref(*ref, m.probe, m.object); !diff.empty())
    fail_command("spheretouch monitor", 2,
                 m.scene + ": " + diff +
                     ": the scene file or its mesh files changed since the run started (the view needs the run's "
                     "meshes)");
  return m;
}

void monitor(const MonitorArgs& a) {
  if (!a.view.empty())
    if (const std::string bad = view::check_listen(a.view); !bad.empty())
      fail_command("spheretouch monitor", 2, bad);  // before anything attaches or loads
  std::string name = a.name;
  if (name.empty()) {
    const std::vector<std::string> live = live_sessions();
    if (live.empty())
      fail_command("spheretouch monitor", 2,
                   "no running spheretouch session in /dev/shm (start `spheretouch run`, or give --name)");
    if (live.size() > 1) {
      std::string list;
      for (const std::string& n : live) list += " " + n;
      fail_command("spheretouch monitor", 2, "several running sessions, choose one with --name:" + list);
    }
    name = live.front();
  }
  Result<std::unique_ptr<const rt::ShmSegment>> r = rt::ShmSegment::attach_read_only(name);
  if (!r) fail_command("spheretouch monitor", 2, r.error());
  const rt::ShmSegment& seg = *r.value();
  const bool tty = ::isatty(STDOUT_FILENO);
  struct sigaction sa {};
  sa.sa_handler = on_monitor_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  struct sigaction bus {};
  bus.sa_handler = on_monitor_bus;
  sigemptyset(&bus.sa_mask);
  sigaction(SIGBUS, &bus, nullptr);
  std::fprintf(stderr, "monitoring %s (created by pid %d, layout version %u)%s\n", seg.name().c_str(),
               seg.header().creator_pid, seg.header().layout_version, tty ? "; Ctrl-C stops" : "");

  // --view: the run's meshes, a process-local status area the view reads, and the server.
  // Declared in this order so the server (which reads the others) goes first.
  ViewMeshes meshes;
  std::unique_ptr<rt::ShmStatus> local;
  std::unique_ptr<rt::ViewFrame> frame;
  std::unique_ptr<view::ViewServer> viewer;
  if (!a.view.empty()) {
    meshes = load_view_meshes(seg, tty);
    local = std::make_unique<rt::ShmStatus>();
    frame = std::make_unique<rt::ViewFrame>();
    view::ViewServerConfig vc;
    vc.listen = a.view;
    if (!meshes.placements.empty()) {
      vc.objects.push_back({&meshes.object, meshes.placements[0]});
      for (std::size_t k = 0; k < meshes.more.size(); ++k)
        vc.objects.push_back({&meshes.more[k], meshes.placements[k + 1]});
    }
    Result<std::unique_ptr<view::ViewServer>> v =
        view::ViewServer::start(vc, meshes.probe, meshes.object, local->view, *local, nullptr);
    if (!v) fail_command("spheretouch monitor", 2, v.error());
    viewer = std::move(v).value();
    std::fprintf(stderr, "view: %s (open it in a browser; read-only, the run keeps its device)\n", viewer->url().c_str());
  }

  // Status lines every interval; with --view the frames and figures are copied at the view's rate.
  using Clock = std::chrono::steady_clock;
  const auto interval = std::chrono::microseconds(std::int64_t(a.interval_ms * 1000));
  const auto copy_period = std::chrono::nanoseconds(std::int64_t(1e9 / rt::kViewRateHz));
  auto next_line = Clock::now();
  std::uint64_t seen_frame = 0;  // the segment's view SeqLock version last copied
  const char* ended = nullptr;
  for (int lines = 0; a.count == 0 || lines < a.count;) {
    if (g_monitor_signal.load()) break;
    if (viewer) {
      rt::ServoStatus sv;
      rt::CollisionStatus co;
      bool have_sv = false, have_co = false, have_frame = false;
      std::uint64_t version = 0;
      if (!guarded([&] {
            const rt::ShmStatus& st = seg.status();
            have_sv = st.servo.load(sv);
            have_co = st.collision.load(co);
            version = st.view.version();
            if (version != seen_frame) have_frame = st.view.load(*frame, 8);
          })) {
        viewer.reset();
        shrank(seg, tty);
      }
      if (have_sv) local->servo.store(sv);
      if (have_co) local->collision.store(co);
      if (have_frame) {
        local->view.store(*frame, frame->used_bytes());  // the counts clamped; the view checks the rest
        seen_frame = version;
      }
    }
    if (Clock::now() >= next_line) {
      Reading rd;
      if (!read_status(seg, rd)) {
        viewer.reset();
        shrank(seg, tty);
      }
      if (tty)
        std::printf("\r\033[K%s", rd.line.c_str());
      else
        std::printf("%s\n", rd.line.c_str());
      std::fflush(stdout);
      ++lines;
      const bool servo_gone = rd.servo_pid > 0 && !rt::process_alive(rd.servo_pid, rd.servo_start_ticks);
      // A creator that died before any servo started leaves a session that will never run.
      const bool never_ran = rd.servo_pid == 0 && !seg.creator_alive();
      if (rd.state == rt::ServoState::finished || servo_gone || never_ran) {
        ended = rd.state == rt::ServoState::finished ? "finished"
                : servo_gone                         ? "gone (servo process dead)"
                                                     : "gone (its creator died before the servo started)";
        break;
      }
      next_line += interval;
      if (next_line < Clock::now()) next_line = Clock::now() + interval;  // late: no burst of lines
    }
    std::this_thread::sleep_until(viewer ? std::min(next_line, Clock::now() + copy_period) : next_line);
  }
  if (tty) std::printf("\n");
  if (ended) std::printf("session %s\n", ended);
  if (viewer) {
    const std::string summary = viewer->summary();
    viewer.reset();  // pages see the stream end
    std::printf("view: %s\n", summary.c_str());
  }
  std::fflush(stdout);
}

}  // namespace

void add_monitor(CLI::App& app) {
  auto a = std::make_shared<MonitorArgs>();
  CLI::App* cmd = app.add_subcommand(
      "monitor",
      "Watch a running `spheretouch run` through its shared-memory segment, read-only: servo ticks and\n"
      "misses, pose and contact-model sequence numbers and ages, contacts, penetration, force.\n"
      "--view also serves the run's live view (the page of `run --view`) from this process: it loads\n"
      "the probe and object from the scene file the run recorded, refuses if they are no longer the\n"
      "run's meshes, and shows the run's frames and figures; the page cannot drive the run's device.\n"
      "It stops when the run ends or on Ctrl-C, and prints the view's summary line.");
  cmd->add_option("--name", a->name, "segment (default: the only running /spheretouch-* session)");
  cmd->add_option("--interval", a->interval_ms, "milliseconds between lines (default 500)")->check(CLI::Range(1.0, 60000.0));
  cmd->add_option("--count", a->count, "lines to print, then exit (0 = until the session ends or Ctrl-C)")
      ->check(CLI::Range(0, 1000000000));
  cmd->add_option("--view", a->view,
                  "serve the run's live view at ADDR:PORT (default 127.0.0.1:8080), read-only; open the printed URL "
                  "in a browser")
      ->expected(0, 1)
      ->default_str("127.0.0.1:8080");
  cmd->callback([a] { monitor(*a); });
}

}  // namespace st::app
