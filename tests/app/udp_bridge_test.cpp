// SPDX-License-Identifier: BSD-3-Clause
// The UDP device bridge end to end: `spheretouch run` with [device] kind = "udp" (in-process servo
// and --split) driven by examples/udp_device_emulator.py at 1 kHz for two seconds: no pose lost,
// a force back every servo tick, contact felt, nothing refused; the run's own key authenticates
// both ways. A version-1 driver is refused clearly by a bridge that authenticates and still works
// with auth = "none"; a version-2 driver of a 6-DOF scene receives the torque.
#include <netinet/in.h>
#include <sys/socket.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "app/process_util.hpp"
#include "doctest/doctest.h"
#include "test_util.hpp"

namespace {

/// The number after "KEY": in a one-line JSON object (NaN when absent).
double udp_json_number(const std::string& json, const std::string& key) {
  const auto at = json.find("\"" + key + "\": ");
  if (at == std::string::npos) return std::nan("");
  return std::strtod(json.c_str() + at + key.size() + 4, nullptr);
}

/// The emulator's command line (ST_SOURCE_ROOT's copy) for `port` with `args`.
std::string udp_emulator(int port, const std::string& args) {
  const char* root = std::getenv("ST_SOURCE_ROOT");
  return "python3 " + std::string(root ? root : ".") +
         "/examples/udp_device_emulator.py --to 127.0.0.1:" + std::to_string(port) + " " + args;
}

/// A UDP-device scene on `port`: a capsule over an icosphere, `extra` appended to [device].
std::string udp_scene(int port, const std::string& extra, double seconds) {
  return "[probe]\nbuiltin = \"capsule\"\nradius_mm = 8.0\nlength_mm = 40.0\n"
         "[object]\nbuiltin = \"icosphere\"\nradius_mm = 50.0\nfrequency = 12\n"
         "[workers]\ncount = 0\n"
         "[device]\nkind = \"udp\"\nbind = \"127.0.0.1:" +
         std::to_string(port) + "\"\n" + extra +
         "[output]\nstatus = \"off\"\nply = false\n"
         "[run]\nduration_s = " +
         std::to_string(seconds) + "\n";
}

/// Waits (up to 30 s: sanitizer builds load slowly) until the run's log says it listens on `port`.
bool udp_wait_listening(const std::string& log, int port) {
  for (int i = 0; i < 3000; ++i) {
    if (st::test::contains(st::test::slurp_file(log), "listening on 127.0.0.1:" + std::to_string(port))) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

/// Writes `scene` and starts `spheretouch run` on it (with --split when asked), output to d/out,
/// its log in d/run.log; returns once it listens on `port`.
pid_t udp_start(const st::test::TempDir& d, int port, const std::string& scene, bool split = false) {
  st::test::write_file(d.file("scene.toml"), scene);
  std::vector<std::string> args = {"run", d.file("scene.toml"), "--out", d.file("out")};
  if (split) args.push_back("--split");
  const pid_t pid = st::test::spawn_spheretouch(args, d.file("run.log"));
  REQUIRE(udp_wait_listening(d.file("run.log"), port));
  return pid;
}

/// Waits for the run to end by itself; its log (checked: exit 0).
std::string udp_finish(const st::test::TempDir& d, pid_t pid) {
  const int rc = st::test::wait_for(pid, 60);
  const std::string out = st::test::slurp_file(d.file("run.log"));
  CHECK_MESSAGE(rc == 0, out);
  return out;
}

/// The bridge's counts from the run's summary line.
struct UdpCounts {
  unsigned long long poses = 0, gaps = 0, forces = 0, send_failed = 0, fades = 0, malformed = 9, stale = 9, foreign = 9,
                     unauthenticated = 9, old_version = 9, jumps = 9, busy = 9, sessions = 9;
};
UdpCounts udp_counts(const std::string& out, int port) {
  UdpCounts c;
  const auto at = out.find("udp 127.0.0.1:" + std::to_string(port) + ": ");
  REQUIRE(at != std::string::npos);
  const int n = std::sscanf(out.c_str() + out.find(": ", at + 4) + 2,
                            "%llu poses, %llu seq gaps, %llu forces sent (%llu failed), %llu fade-outs; refused: "
                            "%llu malformed, %llu stale, %llu foreign, %llu unauthenticated, %llu old-version, %llu "
                            "seq jumps, %llu busy; %llu sessions",
                            &c.poses, &c.gaps, &c.forces, &c.send_failed, &c.fades, &c.malformed, &c.stale, &c.foreign,
                            &c.unauthenticated, &c.old_version, &c.jumps, &c.busy, &c.sessions);
  REQUIRE(n == 13);
  return c;
}

}  // namespace

TEST_CASE("run: a device behind the UDP bridge at 1 kHz: no pose lost, a force every tick, contact felt") {
  for (const bool split : {false, true}) {
    CAPTURE(split);
    st::test::TempDir d;
    const int port = st::test::free_loopback_port(SOCK_DGRAM);
    const pid_t pid = udp_start(d, port, udp_scene(port, "", 4.5), split);
    CHECK(st::test::contains(st::test::slurp_file(d.file("run.log")),
                             "this run's key is in " + d.file("out") + "/bridge.key"));
    const auto em = st::test::run_command(udp_emulator(
        port, "--key " + d.file("out") + "/bridge.key --seconds 2 --from 0,0,56 --to-point 0,0,46 --period 2 --json"));
    INFO(em.output);
    REQUIRE(em.exit_code == 0);
    const std::string out = udp_finish(d, pid);
    INFO(out);

    // The bridge's own count: every pose the driver sent arrived; nothing was refused.
    const UdpCounts c = udp_counts(out, port);
    CHECK(c.poses == static_cast<unsigned long long>(udp_json_number(em.output, "last_seq")));
    CHECK(c.malformed == 0);
    CHECK(c.stale == 0);
    CHECK(c.foreign == 0);
    CHECK(c.unauthenticated == 0);
    CHECK(c.old_version == 0);
    CHECK(c.jumps == 0);
    CHECK(c.busy == 0);
    CHECK(c.sessions == 1);
    CHECK(c.send_failed == 0);
    CHECK(st::test::contains(out, "authenticated (HMAC-SHA256)"));
    // The driver's side: forces came back every servo tick, none lost or forged, and they pressed back.
    CHECK(udp_json_number(em.output, "force_seq_gaps") == 0);
    CHECK(udp_json_number(em.output, "forged_forces") == 0);
    CHECK(udp_json_number(em.output, "forces_per_s") > 900);
    CHECK(udp_json_number(em.output, "forces_per_s") < 1100);
    CHECK(udp_json_number(em.output, "poses_echoed") > 0.5 * udp_json_number(em.output, "poses_sent"));
    CHECK(udp_json_number(em.output, "max_force_N") > 0.1);
    CHECK(udp_json_number(em.output, "max_torque_Nm") == 0);  // a 3-DOF scene sends no torque
  }
}

TEST_CASE(
    "run: a version-1 driver gets a clear refusal where the bridge authenticates; a version-2 one gets the torque of a "
    "6-DOF scene") {
  st::test::TempDir d;
  const int port = st::test::free_loopback_port(SOCK_DGRAM);
  // The tool centre point 10 mm beside the capsule's axis: pressing the tip down gives a moment.
  const pid_t pid =
      udp_start(d, port, udp_scene(port, "dof = 6\ntorque_limit_nm = 0.5\ntcp_mm = [10.0, 0.0, -20.0]\n", 6));
  const auto old = st::test::run_command(udp_emulator(port, "--protocol 1 --seconds 1 --wait 1 --json"));
  INFO(old.output);
  CHECK(old.exit_code == 3);
  CHECK(st::test::contains(old.output, "the bridge refused: version 1 refused"));
  const auto em = st::test::run_command(udp_emulator(
      port, "--key " + d.file("out") + "/bridge.key --seconds 2 --from 0,0,56 --to-point 0,0,46 --period 2 --json --trace " +
                d.file("forces.csv")));
  INFO(em.output);
  REQUIRE(em.exit_code == 0);
  const std::string out = udp_finish(d, pid);
  INFO(out);
  const UdpCounts c = udp_counts(out, port);
  CHECK(c.old_version >= 1);
  CHECK(c.sessions == 1);
  CHECK(udp_json_number(em.output, "max_force_N") > 0.1);
  CHECK(udp_json_number(em.output, "max_torque_Nm") > 1e-3);
  CHECK(udp_json_number(em.output, "max_torque_Nm") <= 0.5 + 1e-9);
  // The trace the emulator writes holds the torque columns (what a plot reads).
  const std::string csv = st::test::slurp_file(d.file("forces.csv"));
  CHECK(csv.rfind("t_s,fx_N,fy_N,fz_N,tx_Nm,ty_Nm,tz_Nm,flags\n", 0) == 0);
  CHECK(std::count(csv.begin(), csv.end(), '\n') > 1000);
}

TEST_CASE("run: with auth = \"none\" a version-1 driver (an old client) still works") {
  st::test::TempDir d;
  const int port = st::test::free_loopback_port(SOCK_DGRAM);
  const pid_t pid = udp_start(d, port, udp_scene(port, "auth = \"none\"\n", 4));
  CHECK(st::test::contains(st::test::slurp_file(d.file("run.log")), "datagrams are not authenticated"));
  const auto em = st::test::run_command(
      udp_emulator(port, "--protocol 1 --seconds 2 --from 0,0,56 --to-point 0,0,46 --period 2 --json"));
  INFO(em.output);
  REQUIRE(em.exit_code == 0);
  const std::string out = udp_finish(d, pid);
  INFO(out);
  const UdpCounts c = udp_counts(out, port);
  CHECK(c.poses == static_cast<unsigned long long>(udp_json_number(em.output, "last_seq")));
  CHECK(c.old_version == 0);
  CHECK(udp_json_number(em.output, "forces_per_s") > 900);
  CHECK(udp_json_number(em.output, "max_force_N") > 0.1);
  CHECK(st::test::contains(out, "NOT authenticated"));
}

TEST_CASE("run: a UDP device address that cannot be bound is an error naming the field, before anything runs") {
  st::test::TempDir d;
  st::test::write_file(d.file("scene.toml"),
                       "[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\ncount = 0\n"
                       "[device]\nkind = \"udp\"\nbind = \"127.0.0.1\"\n[output]\nstatus = \"off\"\n");
  const auto r = st::test::run_command(st::test::spheretouch_exe() + " run " + d.file("scene.toml") + " --out " +
                                       d.file("out") + " --duration 0.5");
  INFO(r.output);
  CHECK(r.exit_code != 0);
  CHECK(st::test::contains(r.output, "device.bind: '127.0.0.1': expected HOST:PORT"));
  CHECK_FALSE(st::test::contains(r.output, "summary"));
}
