// SPDX-License-Identifier: BSD-3-Clause
// Helpers for the app suites that drive `spheretouch run --split` as a real process: start it
// with fork+exec (output to a file), wait for its segment's servo to tick, reap with a timeout.
#pragma once
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <sstream>
#include <thread>
#include <vector>

#include <spheretouch/rt/shm_segment.hpp>
#include "test_util.hpp"

namespace st::test {

/// A loopback port (SOCK_STREAM or SOCK_DGRAM) that was free a moment ago.
inline int free_loopback_port(int type) {
  const int fd = ::socket(AF_INET, type, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  REQUIRE(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  socklen_t len = sizeof a;
  getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

/// Starts `spheretouch ARGS...` with stdout and stderr appended to `log`; returns its pid.
inline pid_t spawn_spheretouch(const std::vector<std::string>& args, const std::string& log) {
  std::vector<std::string> all = {spheretouch_exe()};
  all.insert(all.end(), args.begin(), args.end());
  std::fflush(nullptr);  // else the child's freopen flushes our buffered output a second time
  const pid_t pid = fork();
  REQUIRE(pid >= 0);
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);  // a test that dies leaves no run behind
    if (!std::freopen(log.c_str(), "a", stdout) || dup2(fileno(stdout), 2) < 0) _exit(120);
    std::vector<char*> argv;
    for (std::string& s : all) argv.push_back(s.data());
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    _exit(121);
  }
  return pid;
}

/// Waits up to timeout_s for pid (a child of ours) to end; its exit code, 128+signal, or -1 on timeout.
inline int wait_for(pid_t pid, double timeout_s) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < until) {
    int status = 0;
    const pid_t r = waitpid(pid, &status, WNOHANG);
    if (r == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    if (r < 0) return -2;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return -1;
}

/// Polls segment `name` until its servo is running and has ticked at least `ticks` times (or
/// `run_pid` ended, or timeout_s passed); returns the servo's status (ticks 0 = not reached).
inline rt::ServoStatus wait_for_ticks(const std::string& name, std::uint64_t ticks, pid_t run_pid, double timeout_s,
                                      int* servo_pid = nullptr) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < until) {
    if (auto seg = rt::ShmSegment::attach_read_only(name); seg.ok()) {
      rt::ServoStatus st;
      if (seg.value()->status().servo.load(st) && st.ticks >= ticks) {
        if (servo_pid) *servo_pid = seg.value()->status().servo_pid.load();
        return st;
      }
    }
    if (int s = 0; waitpid(run_pid, &s, WNOHANG) == run_pid) break;  // died early: the caller's check fails
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return {};
}

/// One per-tick CSV row (rt::Telemetry's columns).
struct TickCsvRow {
  std::uint64_t tick = 0;    ///< tick number (consecutive when no sample was dropped)
  std::uint64_t misses = 0;  ///< loop misses so far
  double t_s = 0;            ///< since the first row
  std::uint64_t model_seq = 0;
  double force_N = 0;  ///< |force|
  int flags = 0;
};

/// Reads a ticks.csv written by rt::Telemetry.
inline std::vector<TickCsvRow> read_tick_csv(const std::string& csv) {
  std::ifstream in(csv);
  std::vector<TickCsvRow> rows;
  std::string line;
  std::getline(in, line);  // header: the 23 columns below
  REQUIRE(
      line ==
      "tick,t_ns,latency_ns,pose_seq,model_seq,model_age_ns,x_mm,y_mm,z_mm,fx_N,fy_N,fz_N,pd_mm,fade,ceiling_N,flags,"
      "misses,proxy_x_mm,proxy_y_mm,proxy_z_mm,tx_Nm,ty_Nm,tz_Nm");
  double t0 = -1;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<double> v;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');) v.push_back(std::stod(cell));
    REQUIRE(v.size() == 23);
    for (double x : v) REQUIRE(std::isfinite(x));  // the proxy and the torque too
    if (t0 < 0) t0 = v[1];
    rows.push_back({static_cast<std::uint64_t>(v[0]), static_cast<std::uint64_t>(v[16]), (v[1] - t0) * 1e-9,
                    static_cast<std::uint64_t>(v[4]), std::sqrt(v[9] * v[9] + v[10] * v[10] + v[11] * v[11]), int(v[15])});
  }
  return rows;
}

/// Loop periods a ticks.csv covers: every period is a tick (a row) or a counted miss.
inline std::uint64_t tick_periods(const std::vector<TickCsvRow>& rows) {
  return rows.empty() ? 0 : rows.size() + rows.back().misses;
}

/// The whole of a file ("" if it cannot be read).
inline std::string slurp_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// The small generated scene of run_test.cpp (capsule vs icosphere, no workers) for `duration_s`.
inline std::string small_scene(double duration_s) {
  return "[probe]\nbuiltin = \"capsule\"\nradius_mm = 6.0\nlength_mm = 30.0\n"
         "[object]\nbuiltin = \"icosphere\"\nradius_mm = 40.0\nfrequency = 20\n"
         "[workers]\ncount = 0\n[output]\nstatus = \"plain\"\n[run]\nduration_s = " +
         std::to_string(duration_s) + "\n";
}

}  // namespace st::test
