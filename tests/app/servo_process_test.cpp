// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/engine/servo_process.* and src/app/cmd_servo.cpp through `spheretouch run --split`: the servo as its own process
// produces the outputs of a normal run; with the collision process SIGKILLed mid-press it ticks
// on to its duration, its force fades to exactly zero, and it says the collision side died.
// Counts and states only, never wall-clock precision.
#include <fcntl.h>
#include <sys/mman.h>

#include <cerrno>
#include <cmath>

#include <spheretouch/engine/servo_process.hpp>
#include "process_util.hpp"

using namespace st::test;

namespace {
bool shm_exists(const std::string& name) {
  const int fd = shm_open(name.c_str(), O_RDONLY, 0);
  if (fd >= 0) close(fd);
  return fd >= 0;
}
}  // namespace

TEST_CASE(
    "run --split: the servo process ticks at the rate, presses with force, writes the usual outputs; monitor watches "
    "it") {
  TempDir d;
  write_file(d.file("scene.toml"), small_scene(3.0));
  const std::string out = d.file("run"), log = d.file("run.log");
  const std::string name = "/spheretouch-test-split-" + std::to_string(getpid());
  const pid_t run = spawn_spheretouch({"run", d.file("scene.toml"), "--split", "--out", out, "--shm-name", name}, log);

  // A monitor attached while it runs prints lines with increasing tick counts.
  int servo_pid = 0;
  const st::rt::ServoStatus first = wait_for_ticks(name, 200, run, 15, &servo_pid);
  INFO(slurp_file(log));
  REQUIRE(first.ticks >= 200);
  CHECK(servo_pid != run);  // the servo is its own process
  const CommandResult mon = run_command(spheretouch_exe() + " monitor --name " + name + " --interval 100 --count 5");
  INFO(mon.output);
  CHECK(mon.exit_code == 0);
  std::vector<unsigned long long> ticks;
  std::istringstream lines(mon.output);
  for (std::string line; std::getline(lines, line);) {
    const auto at = line.find(" ticks, ");
    if (at == std::string::npos) continue;
    const auto colon = line.rfind(": ", at);
    ticks.push_back(std::stoull(line.substr(colon + 2, at - colon - 2)));
    CHECK(contains(line, "servo process " + std::to_string(servo_pid)));
    CHECK(contains(line, "model #"));
    CHECK(contains(line, "contacts"));
  }
  REQUIRE(ticks.size() == 5);
  for (std::size_t i = 1; i < ticks.size(); ++i) CHECK(ticks[i] > ticks[i - 1]);

  const int code = wait_for(run, 20);
  const std::string output = slurp_file(log);
  INFO(output);
  REQUIRE(code == 0);
  CHECK(contains(output, "servo process pid " + std::to_string(servo_pid)));
  CHECK(contains(output, "shm " + name));
  CHECK(contains(output, "summary"));
  CHECK(contains(output, " 0 dropped"));
  CHECK_FALSE(shm_exists(name));  // a clean run removes its segment

  const std::vector<TickCsvRow> rows = read_tick_csv(out + "/ticks.csv");
  // Counts, not timing: every 1 ms period of the 3 s run is a tick or a counted miss (a busy
  // host turns ticks into misses, but the schedule holds).
  REQUIRE_FALSE(rows.empty());
  CHECK(tick_periods(rows) >= 3000 - 50);
  CHECK(tick_periods(rows) <= 3000 + 50);
  CHECK(rows.size() > 3000 / 10);
  double press_max = 0;
  int contact = 0;
  for (const TickCsvRow& r : rows) {
    CHECK(std::isfinite(r.force_N));
    if (r.t_s > 1.6 && r.t_s < 2.0) press_max = std::max(press_max, r.force_N);
    contact += r.flags & 1;
  }
  CHECK(contact > 0);
  CHECK(press_max > 0.1);
  auto res = st::engine::read_servo_results(out + "/servo.txt");
  REQUIRE_MESSAGE(res.ok(), res.error());
  CHECK(res.value().ticks == rows.size());
  CHECK(res.value().collision_died == 0);
  CHECK(res.value().models > 0);
  for (const char* f : {"/trace.json", "/contact.ply", "/summary.txt", "/script.txt"})
    CHECK_MESSAGE(std::filesystem::exists(out + f), f);

  // After the run the name is gone: monitor says it cannot attach.
  const CommandResult gone = run_command(spheretouch_exe() + " monitor --name " + name + " --count 1");
  CHECK(gone.exit_code == 2);
  CHECK(contains(gone.output, "cannot attach"));
}

TEST_CASE(
    "run --split: collision process SIGKILLed mid-press, the servo fades the force to zero, says so, runs to its end") {
  // Orphans are re-parented to us, so the test can reap the servo after killing its parent.
  REQUIRE(prctl(PR_SET_CHILD_SUBREAPER, 1) == 0);
  TempDir d;
  const double duration = 4.0;
  write_file(d.file("scene.toml"), small_scene(duration));
  const std::string out = d.file("run"), log = d.file("run.log");
  const std::string name = "/spheretouch-test-kill-" + std::to_string(getpid());
  const pid_t run = spawn_spheretouch({"run", d.file("scene.toml"), "--split", "--out", out, "--shm-name", name}, log);

  // The built-in script presses from 1.0 s and holds from 1.5 s to 2.0 s: kill at ~1.7 s.
  int servo_pid = 0;
  const st::rt::ServoStatus before = wait_for_ticks(name, 1700, run, 15, &servo_pid);
  INFO(slurp_file(log));
  REQUIRE(before.ticks >= 1700);
  REQUIRE(servo_pid > 0);
  REQUIRE(kill(run, SIGKILL) == 0);
  CHECK(wait_for(run, 5) == 128 + SIGKILL);

  const int code = wait_for(servo_pid, 15);  // now our child
  const std::string output = slurp_file(log);
  INFO(output);
  REQUIRE(code == 0);
  CHECK(contains(output, "collision process (pid " + std::to_string(run) + ") died"));
  CHECK(contains(output, "force faded to zero"));
  CHECK(contains(output, "summary (servo process only: the collision process died)"));
  CHECK_FALSE(shm_exists(name));  // the survivor removed the orphaned name

  auto res = st::engine::read_servo_results(out + "/servo.txt");
  REQUIRE_MESSAGE(res.ok(), res.error());
  CHECK(res.value().collision_died == 1);
  CHECK(res.value().silences >= 1);

  // ticks.csv: the servo ran its whole duration; after the last contact model arrived plus the
  // stale timeout (200 ms) and fade (100 ms), every tick commands exactly zero force.
  const std::vector<TickCsvRow> rows = read_tick_csv(out + "/ticks.csv");
  REQUIRE_FALSE(rows.empty());
  CHECK(tick_periods(rows) >= std::size_t(duration * 1000 - 50));  // periods: ticks + counted misses
  CHECK(tick_periods(rows) <= std::size_t(duration * 1000 + 50));
  CHECK(rows.size() > std::size_t(duration * 1000 / 10));
  CHECK(res.value().ticks == rows.size());
  const std::uint64_t last_model = rows.back().model_seq;
  std::size_t arrived = 0;
  while (arrived < rows.size() && rows[arrived].model_seq != last_model) ++arrived;
  REQUIRE(arrived < rows.size());
  const double t_last = rows[arrived].t_s;
  double pressing = 0, faded_max = 0;
  std::size_t faded_ticks = 0;
  for (const TickCsvRow& r : rows) {
    if (r.t_s > 1.5 && r.t_s <= t_last) pressing = std::max(pressing, r.force_N);
    if (r.t_s > t_last + 0.302) {
      faded_max = std::max(faded_max, r.force_N);
      ++faded_ticks;
    }
  }
  CHECK(pressing > 0.1);      // killed while pressing
  CHECK(faded_max == 0.0);    // exactly zero after the fade
  CHECK(faded_ticks > 1000);  // and it kept ticking (about 2 s more)
  CHECK(t_last < duration - 1.0);
}

TEST_CASE("SilenceWatch: reports a silent collision side once the force has faded, and its return") {
  st::engine::SilenceWatch w(200'000'000);
  st::rt::ServoStatus st;
  CHECK(w.poll(st, 1'000'000'000).empty());  // no model yet: nothing to report
  st.model_seq = 5;
  st.model_received_ns = 1'000'000'000;
  st.fade = 1.0;
  CHECK(w.poll(st, 1'100'000'000).empty());  // fresh
  CHECK(w.poll(st, 1'250'000'000).empty());  // past the timeout but still fading
  st.fade = 0.0;
  const std::string m = w.poll(st, 1'300'000'000);
  CHECK(m == "collision side silent for 300 ms: force faded to zero");
  CHECK(w.silent());
  CHECK(w.poll(st, 1'500'000'000).empty());  // once per episode
  st.model_seq = 6;
  st.model_received_ns = 1'600'000'000;
  CHECK(w.poll(st, 1'600'000'000) == "collision side back: contact models resumed after 600 ms");
  CHECK_FALSE(w.silent());
  CHECK(w.episodes() == 1);
  CHECK(w.longest_ms() == doctest::Approx(500).epsilon(1e-9));
}
