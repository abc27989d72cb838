// SPDX-License-Identifier: BSD-3-Clause
// The split servo process: see servo_process.hpp.
#include <spheretouch/engine/servo_process.hpp>
#include <spheretouch/geom/text_file.hpp>

#include <spawn.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/haptic_servo.hpp>
#include <spheretouch/rt/shm_segment.hpp>
#include <spheretouch/rt/telemetry.hpp>

extern char** environ;

namespace st::inline SPHERETOUCH_ABI::engine {

namespace {

/// Flushes and closes a file written with stdio; the first error (a full disk) named with errno.
Status close_written(std::FILE* f, const std::string& path) {
  bool ok = std::fflush(f) == 0 && std::ferror(f) == 0;
  int err = ok ? 0 : errno;
  if (std::fclose(f) != 0 && ok) {
    ok = false;
    err = errno;
  }
  if (!ok) return fail(path, ": write failed: ", std::strerror(err));
  return Ok{};
}

}  // namespace

Status write_servo_results(const std::string& path, const ServoResults& r) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return fail(path, ": cannot create");
  std::fprintf(f, "# spheretouch servo results: key value\n");
  std::fprintf(f, "seconds %.6f\nticks %llu\nmisses %llu\noverruns %llu\nwake_p99_us %.3f\npeak_force_N %.9g\n",
               r.seconds, static_cast<unsigned long long>(r.ticks), static_cast<unsigned long long>(r.misses),
               static_cast<unsigned long long>(r.overruns), r.wake_p99_us, r.peak_force_N);
  std::fprintf(f, "models %llu\ntelemetry_pushed %llu\ntelemetry_dropped %llu\ndevice_dropped %llu\n",
               static_cast<unsigned long long>(r.models), static_cast<unsigned long long>(r.telemetry_pushed),
               static_cast<unsigned long long>(r.telemetry_dropped), static_cast<unsigned long long>(r.device_dropped));
  std::fprintf(f, "silences %llu\nlongest_silence_ms %.3f\ncollision_died %d\ncollision_died_at_s %.6f\nsignal %d\n",
               static_cast<unsigned long long>(r.silences), r.longest_silence_ms, r.collision_died,
               r.collision_died_at_s, r.signal);
  return close_written(f, path);
}

Result<ServoResults> read_servo_results(const std::string& path) {
  Result<std::string> text = geom::read_text_file(path, 1u << 20, "servo results file");
  if (!text) return fail(text.error(), " (the servo process wrote no results)");
  std::istringstream in(text.value());
  std::map<std::string, double> kv;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    std::string key;
    double v = 0;
    if (!(ls >> key >> v)) return fail(path, ":", n, ": expected 'key number'");
    kv[key] = v;
  }
  // A file cut short (a full disk) must not read as zeros measured.
  for (const char* k : {"seconds", "ticks", "misses", "peak_force_N"})
    if (!kv.count(k)) return fail(path, ": no '", k, "' line (the servo process's results are incomplete)");
  ServoResults r;
  auto u = [&](const char* k, std::uint64_t& x) { x = static_cast<std::uint64_t>(kv[k]); };
  r.seconds = kv["seconds"];
  u("ticks", r.ticks);
  u("misses", r.misses);
  u("overruns", r.overruns);
  r.wake_p99_us = kv["wake_p99_us"];
  r.peak_force_N = kv["peak_force_N"];
  u("models", r.models);
  u("telemetry_pushed", r.telemetry_pushed);
  u("telemetry_dropped", r.telemetry_dropped);
  u("device_dropped", r.device_dropped);
  u("silences", r.silences);
  r.longest_silence_ms = kv["longest_silence_ms"];
  r.collision_died = static_cast<int>(kv["collision_died"]);
  r.collision_died_at_s = kv.count("collision_died_at_s") ? kv["collision_died_at_s"] : -1;
  r.signal = static_cast<int>(kv["signal"]);
  if (!kv.count("ticks")) return fail(path, ": no 'ticks' line (truncated?)");
  return r;
}

std::string SilenceWatch::poll(const rt::ServoStatus& st, std::int64_t now_ns) {
  if (st.model_seq == 0) return "";  // no model yet: nothing to fade
  char buf[160];
  if (st.model_seq != last_seq_) {
    last_seq_ = st.model_seq;
    if (!silent_) return "";
    silent_ = false;
    std::snprintf(buf, sizeof buf, "collision side back: contact models resumed after %.0f ms",
                  double(st.model_received_ns - since_ns_) * 1e-6);
    return buf;
  }
  const std::int64_t idle = now_ns - st.model_received_ns;
  if (silent_) {
    longest_ms_ = std::max(longest_ms_, double(idle) * 1e-6);
    return "";
  }
  // Report once the stale timeout has passed and the tick has faded the force all the way.
  if (idle < stale_ns_ || st.fade != 0.0) return "";
  silent_ = true;
  since_ns_ = st.model_received_ns;
  ++episodes_;
  longest_ms_ = std::max(longest_ms_, double(idle) * 1e-6);
  std::snprintf(buf, sizeof buf, "collision side silent for %.0f ms: force faded to zero", double(idle) * 1e-6);
  return buf;
}

Status write_trajectory(const std::string& path, const rt::Trajectory& t) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return fail(path, ": cannot create");
  std::fprintf(f, "# spheretouch trajectory: t_s then the probe -> object pose, row-major 4x4\n");
  for (const rt::TimedPose& k : t.keys) {
    std::fprintf(f, "%.17g", k.t_s);
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) std::fprintf(f, " %.17g", k.pose.matrix()(r, c));
    std::fprintf(f, "\n");
  }
  return close_written(f, path);
}

Result<pid_t> spawn_servo(const ServoArgs& a) {
  char exe[4096];
  const ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
  if (n <= 0) return fail("servo process: cannot find this executable (/proc/self/exe): ", std::strerror(errno));
  exe[n] = 0;
  char dur[64];
  std::snprintf(dur, sizeof dur, "%.17g", a.duration_s);
  char tcp[160];
  std::snprintf(tcp, sizeof tcp, "%.17g,%.17g,%.17g", a.tcp_mm.x(), a.tcp_mm.y(), a.tcp_mm.z());
  std::vector<std::string> args = {
      "spheretouch", "servo", "--shm", a.shm,        "--scene", a.scene,    "--script",
      a.script,      "--out", a.out,   "--duration", dur,       "--parent", std::to_string(a.parent),
      "--tcp",       tcp};
  std::vector<char*> argv;
  for (std::string& s : args) argv.push_back(s.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (const int e = posix_spawn(&pid, exe, nullptr, nullptr, argv.data(), environ); e != 0)
    return fail("servo process: cannot start ", exe, ": ", std::strerror(e));
  return pid;
}

}  // namespace st::engine
