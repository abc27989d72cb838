// SPDX-License-Identifier: BSD-3-Clause
// spheretouch servo (hidden): the haptic servo process of `run --split` (engine/servo_process.hpp
// says what it does and why it is a process of its own).
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <thread>

#include "app/commands.hpp"
#include <spheretouch/engine/scene.hpp>
#include <spheretouch/engine/servo_process.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/haptic_loop.hpp>
#include <spheretouch/rt/haptic_servo.hpp>
#include <spheretouch/rt/shm_segment.hpp>
#include <spheretouch/rt/telemetry.hpp>

namespace st::app {

using engine::load_scene;
using engine::Scene;
using engine::ServoArgs;
using engine::ServoResults;
using engine::SilenceWatch;

namespace {

std::atomic<int> g_servo_signal{0};
extern "C" void on_servo_signal(int sig) { g_servo_signal.store(sig); }

[[noreturn]] void servo_die(int code, const std::string& msg) {
  std::fprintf(stderr, "spheretouch servo: %s\n", msg.c_str());
  throw CLI::RuntimeError(code);
}

void run_servo(const ServoArgs& a) {
  Result<Scene> sr = load_scene(a.scene);
  if (!sr) servo_die(2, sr.error());
  Scene s = std::move(sr).value();
  if (a.duration_s > 0) s.duration_s = a.duration_s;
  if (s.thread_stack_bytes)
    if (Status st = rt::set_default_thread_stack(s.thread_stack_bytes); !st)
      servo_die(2, s.file + ": haptic.thread_stack_kb: " + st.error());
  Result<rt::Trajectory> script = rt::load_trajectory(a.script);
  if (!script) servo_die(2, script.error());
  Result<std::unique_ptr<rt::ShmSegment>> seg = rt::ShmSegment::attach(a.shm);
  if (!seg) servo_die(2, seg.error());
  rt::ShmSegment& shm = *seg.value();
  shm.guard_truncation();  // another process truncating the segment must not kill the servo
  rt::ShmStatus& status = shm.status();
  status.servo_start_ticks.store(rt::process_start_ticks(getpid()), std::memory_order_relaxed);
  status.split.store(1, std::memory_order_relaxed);
  status.servo_pid.store(getpid(), std::memory_order_relaxed);
  status.servo_state.store(std::uint32_t(rt::ServoState::starting), std::memory_order_release);

  Result<rt::ForceLaw> law = rt::ForceLaw::make(s.law);
  if (!law) servo_die(2, s.file + ": " + law.error());
  // Commanded forces go to the per-tick trace, not into device records: memory stays flat.
  rt::SimulatedDevice sim(script.value(), s.device.user, 0, s.saturation.peak_N);
  sim.set_repeat(s.device.repeat);
  // [device] kind = "udp": the driver's poses instead; the trajectory file holds the grip.
  std::unique_ptr<rt::UdpDevice> udp;
  if (s.device.kind == "udp") {
    Result<rt::UdpDeviceConfig> uc = engine::udp_device_config(s, a.out, false);  // the run made the key
    if (!uc) servo_die(2, uc.error());
    Result<std::unique_ptr<rt::UdpDevice>> u = rt::UdpDevice::open(uc.value(), script.value().keys.front().pose);
    if (!u) servo_die(2, s.file + ": " + u.error());
    udp = std::move(u).value();
    std::fprintf(stderr, "spheretouch servo: udp device listening on %s\n", udp->address().c_str());
  }
  rt::Device& device = udp ? static_cast<rt::Device&>(*udp) : static_cast<rt::Device&>(sim);
  std::unique_ptr<rt::Telemetry> telemetry;
  if (s.write_trace || s.write_perfetto) {
    Result<std::unique_ptr<rt::Telemetry>> t = rt::Telemetry::open(a.out + "/ticks.csv");
    if (!t) servo_die(2, t.error());
    telemetry = std::move(t).value();
  }
  rt::HapticServo servo(device, shm.poses(), shm.models(), law.value(), s.interp, s.saturation, telemetry.get(),
                        s.passivity, 1.0 / s.haptic.rate_hz);
  servo.publish_status_to(&status.servo);
  rt::WrenchConfig wrench = s.device.wrench;
  wrench.tcp_mm = a.tcp_mm;  // resolved by the run (the tip needs the probe mesh)
  servo.set_wrench(wrench);
  if (Status m = engine::set_servo_materials(servo, s); !m) servo_die(2, m.error());

  on_stop_signals(on_servo_signal);

  rt::HapticLoop loop(s.haptic);
  Result<rt::RtReport> rep = loop.start(servo);
  if (!rep) servo_die(1, "haptic loop: " + rep.error());
  if (!rep.value().all_applied() || rep.value().fifo.requested || rep.value().mlock.requested)
    std::fprintf(stderr, "spheretouch servo: real-time: %s\n", rep.value().describe().c_str());
  status.servo_state.store(std::uint32_t(rt::ServoState::running), std::memory_order_release);

  // The watcher: this (non-real-time) thread, every 10 ms. The tick path never makes a syscall
  // for it; getppid() and the status snapshot are read here.
  const std::int64_t t_start = rt::now_ns();
  ServoResults res;
  SilenceWatch silence(s.interp.stale_timeout_ns);
  bool parent_dead = false;
  while (g_servo_signal.load() == 0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const std::int64_t now = rt::now_ns();
    const double t = double(now - t_start) * 1e-9;
    if (t >= s.duration_s) break;
    if (rt::ShmSegment::truncated()) {
      std::fprintf(stderr,
                   "spheretouch servo: the shared-memory segment %s was truncated by another process at t %.2f s: "
                   "its data is gone (zero force); stopping\n",
                   shm.name().c_str(), t);
      break;
    }
    if (!parent_dead && getppid() != a.parent) {  // reparented: the collision process is gone
      parent_dead = true;
      res.collision_died = 1;
      res.collision_died_at_s = t;
      status.collision_lost.store(2, std::memory_order_relaxed);
      std::fprintf(stderr,
                   "spheretouch servo: collision process (pid %d) died at t %.2f s; the force fades to zero "
                   "after the %.0f ms stale timeout; ticking on to the end of the run (%.1f s)\n",
                   a.parent, t, double(s.interp.stale_timeout_ns) * 1e-6, s.duration_s);
    }
    rt::ServoStatus st;
    if (status.servo.load(st)) {
      const std::string msg = silence.poll(st, now);
      if (!msg.empty()) {
        std::fprintf(stderr, "spheretouch servo: %s\n", msg.c_str());
        if (!parent_dead) status.collision_lost.store(silence.silent() ? 1 : 0, std::memory_order_relaxed);
      }
    }
  }
  const std::int64_t t_end = rt::now_ns();
  loop.stop();
  if (telemetry) telemetry->close();
  status.servo_state.store(std::uint32_t(rt::ServoState::finished), std::memory_order_release);

  const rt::LoopStats& ls = loop.stats();
  res.seconds = double(t_end - t_start) * 1e-9;
  res.ticks = ls.ticks;
  res.misses = ls.misses;
  res.overruns = ls.overruns;
  res.wake_p99_us = double(ls.wake_latency.percentile_ns(0.99)) / 1000.0;
  res.peak_force_N = servo.peak_force_N();
  res.models = servo.stats().models;
  if (telemetry) {
    res.telemetry_pushed = telemetry->stats().pushed;
    res.telemetry_dropped = telemetry->stats().dropped;
  }
  res.device_dropped = sim.dropped_records();
  if (udp)
    std::fprintf(stderr, "spheretouch servo: device %s; %llu ticks without a pose\n", udp->summary().c_str(),
                 static_cast<unsigned long long>(servo.stats().pose_failures));
  res.silences = silence.episodes();
  res.longest_silence_ms = silence.longest_ms();
  res.signal = g_servo_signal.load();
  // A full disk: ticks.csv incomplete is an error (exit 1, named on stderr) once servo.txt is
  // written, so the collision process still prints the run's summary with the servo's figures.
  const std::string ticks_error = telemetry ? telemetry->error() : std::string();
  if (Status w = write_servo_results(a.out + "/servo.txt", res); !w) servo_die(1, w.error());
  if (parent_dead) {
    // Nobody else will report this run: the servo's own summary, and the segment's name removed.
    char buf[1024];
    std::snprintf(buf, sizeof buf,
                  "summary (servo process only: the collision process died)\n"
                  "  duration        %.2f s\n"
                  "  haptic          %llu ticks (%.1f Hz), %llu misses, %llu overruns, wake-up p99 %.1f us\n"
                  "  collision side  died at t %.2f s; %llu silence(s), longest %.0f ms, force faded to zero\n"
                  "  force           peak %.3f N\n"
                  "  telemetry       %llu samples, %llu dropped\n"
                  "  outputs         %s/ (ticks.csv, servo.txt; no trace.json or contact.ply)\n",
                  res.seconds, static_cast<unsigned long long>(res.ticks), double(res.ticks) / res.seconds,
                  static_cast<unsigned long long>(res.misses), static_cast<unsigned long long>(res.overruns),
                  res.wake_p99_us, res.collision_died_at_s, static_cast<unsigned long long>(res.silences),
                  res.longest_silence_ms, res.peak_force_N, static_cast<unsigned long long>(res.telemetry_pushed),
                  static_cast<unsigned long long>(res.telemetry_dropped), a.out.c_str());
    std::fputs(buf, stdout);
    std::fflush(stdout);
    if (std::FILE* f = std::fopen((a.out + "/summary.txt").c_str(), "w")) {
      std::fputs(buf, f);
      std::fclose(f);
    }
    if (shm.unlink_if_orphaned())
      std::fprintf(stderr, "spheretouch servo: removed the orphaned segment %s\n", shm.name().c_str());
  }
  if (!ticks_error.empty()) servo_die(1, ticks_error);
  if (rt::ShmSegment::truncated()) servo_die(1, "the shared-memory segment " + shm.name() + " was truncated");
}

}  // namespace

void add_servo(CLI::App& app) {
  auto a = std::make_shared<ServoArgs>();
  CLI::App* cmd = app.add_subcommand("servo", "internal: the haptic servo process of `run --split`");
  cmd->group("");  // hidden: started by `run --split`, not by hand
  cmd->add_option("--shm", a->shm, "segment")->required();
  cmd->add_option("--scene", a->scene, "scene file")->required();
  cmd->add_option("--script", a->script, "trajectory file")->required();
  cmd->add_option("--out", a->out, "run directory")->required();
  cmd->add_option("--duration", a->duration_s, "seconds")->required();
  cmd->add_option("--parent", a->parent, "collision process pid")->required();
  auto tcp = std::make_shared<std::vector<double>>();
  cmd->add_option("--tcp", *tcp, "tool centre point x,y,z (probe mm)")->delimiter(',')->expected(3);
  cmd->callback([a, tcp] {
    if (tcp->size() == 3) a->tcp_mm = geom::Vec3((*tcp)[0], (*tcp)[1], (*tcp)[2]);
    run_servo(*a);
  });
}

}  // namespace st::app
