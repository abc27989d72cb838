// spheretouch monitor: watch a live run through its shared-memory segment, read-only. It maps
// the segment PROT_READ and reads only the status area (SeqLocks any number of readers may
// share), never the triple buffers, whose single reader is the servo or the collision thread.
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
#include "rt/clock.hpp"
#include "rt/shm_segment.hpp"

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
  if (lost == 2 || !seg.creator_alive())
    appendf(line, " | collision process %d DEAD", seg.header().creator_pid);
  else if (lost == 1)
    appendf(line, " | collision side SILENT");
  return line;
}

// Reads one status line's worth from the mapping with the SIGBUS jump armed; false when the
// mapping had shrunk (the reads that faulted are abandoned; the string's storage is reserved
// first so the guarded code does not allocate).
bool read_status(const rt::ShmSegment& seg, Reading& rd) {
  rd.line.reserve(512);
  g_bus_armed = 1;
  if (sigsetjmp(g_bus_jump, 1) != 0) {
    g_bus_armed = 0;
    return false;
  }
  rd.line = status_line(seg, rt::now_ns());
  rd.state = rt::ServoState(seg.status().servo_state.load(std::memory_order_acquire));
  rd.servo_pid = seg.status().servo_pid.load(std::memory_order_relaxed);
  rd.servo_start_ticks = seg.status().servo_start_ticks.load();
  g_bus_armed = 0;
  return true;
}

void monitor(const MonitorArgs& a) {
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
  const auto interval = std::chrono::microseconds(std::int64_t(a.interval_ms * 1000));
  for (int i = 0; a.count == 0 || i < a.count; ++i) {
    if (i > 0) std::this_thread::sleep_for(interval);
    if (g_monitor_signal.load()) break;
    Reading rd;
    if (!read_status(seg, rd)) {
      if (tty) std::printf("\n");
      fail_command("spheretouch monitor", 1,
                   seg.name() +
                       ": the segment shrank under the monitor (truncated by another "
                       "process): its contents are gone, stopped");
    }
    if (tty)
      std::printf("\r\033[K%s", rd.line.c_str());
    else
      std::printf("%s\n", rd.line.c_str());
    std::fflush(stdout);
    const auto state = rd.state;
    const int servo_pid = rd.servo_pid;
    const bool servo_gone = servo_pid > 0 && !rt::process_alive(servo_pid, rd.servo_start_ticks);
    if (state == rt::ServoState::finished || servo_gone) {
      if (tty) std::printf("\n");
      std::printf("session %s\n", state == rt::ServoState::finished ? "finished" : "gone (servo process dead)");
      return;
    }
  }
  if (tty) std::printf("\n");
}

}  // namespace

void add_monitor(CLI::App& app) {
  auto a = std::make_shared<MonitorArgs>();
  CLI::App* cmd = app.add_subcommand(
      "monitor",
      "Watch a running `spheretouch run` through its shared-memory segment, read-only: servo ticks and\n"
      "misses, pose and contact-model sequence numbers and ages, contacts, penetration, force.");
  cmd->add_option("--name", a->name, "segment (default: the only running /spheretouch-* session)");
  cmd->add_option("--interval", a->interval_ms, "milliseconds between lines (default 500)")->check(CLI::Range(1.0, 60000.0));
  cmd->add_option("--count", a->count, "lines to print, then exit (0 = until the session ends or Ctrl-C)")
      ->check(CLI::Range(0, 1000000000));
  cmd->callback([a] { monitor(*a); });
}

}  // namespace st::app
