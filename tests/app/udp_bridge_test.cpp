// SPDX-License-Identifier: BSD-3-Clause
// The UDP device bridge end to end: `spheretouch run` with [device] kind = "udp" (in-process servo
// and --split) driven by examples/udp_device_emulator.py at 1 kHz for two seconds: no pose lost,
// a force back every servo tick, contact felt, nothing refused.
#include <netinet/in.h>
#include <sys/socket.h>

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

}  // namespace

TEST_CASE("run: a device behind the UDP bridge at 1 kHz: no pose lost, a force every tick, contact felt") {
  for (const bool split : {false, true}) {
    CAPTURE(split);
    st::test::TempDir d;
    const int port = st::test::free_loopback_port(SOCK_DGRAM);
    const std::string scene =
        "[probe]\nbuiltin = \"capsule\"\nradius_mm = 8.0\nlength_mm = 40.0\n"
        "[object]\nbuiltin = \"icosphere\"\nradius_mm = 50.0\nfrequency = 12\n"
        "[workers]\ncount = 0\n"
        "[device]\nkind = \"udp\"\nbind = \"127.0.0.1:" +
        std::to_string(port) +
        "\"\n"
        "[output]\nstatus = \"off\"\nply = false\n"
        "[run]\nduration_s = 4.5\n";
    st::test::write_file(d.file("scene.toml"), scene);
    const std::string log = d.file("run.log");
    std::vector<std::string> args = {"run", d.file("scene.toml"), "--out", d.file("out")};
    if (split) args.push_back("--split");
    const pid_t pid = st::test::spawn_spheretouch(args, log);
    bool listening = false;
    for (int i = 0; i < 3000 && !listening; ++i) {  // up to 30 s (sanitizer builds load slowly)
      listening = st::test::contains(st::test::slurp_file(log), "listening on 127.0.0.1:" + std::to_string(port));
      if (!listening) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    REQUIRE(listening);
    const char* root = std::getenv("ST_SOURCE_ROOT");
    const std::string emulator = std::string(root ? root : ".") + "/examples/udp_device_emulator.py";
    const auto em = st::test::run_command("python3 " + emulator + " --to 127.0.0.1:" + std::to_string(port) +
                                          " --seconds 2 --from 0,0,56 --to-point 0,0,46 --period 2 --json");
    INFO(em.output);
    REQUIRE(em.exit_code == 0);
    const int rc = st::test::wait_for(pid, 60);
    const std::string out = st::test::slurp_file(log);
    INFO(out);
    CHECK(rc == 0);

    // The bridge's own count: every pose the driver sent arrived; nothing was refused.
    const auto at = out.find("udp 127.0.0.1:" + std::to_string(port) + ": ");
    REQUIRE(at != std::string::npos);
    unsigned long long poses = 0, gaps = 0, forces = 0, send_failed = 0, fades = 0, malformed = 9, stale = 9, foreign = 9;
    const int n = std::sscanf(out.c_str() + out.find(": ", at + 4) + 2,
                              "%llu poses, %llu seq gaps, %llu forces sent (%llu failed), %llu fade-outs; refused: "
                              "%llu malformed, %llu stale, %llu foreign",
                              &poses, &gaps, &forces, &send_failed, &fades, &malformed, &stale, &foreign);
    REQUIRE(n == 8);
    CHECK(poses == static_cast<unsigned long long>(udp_json_number(em.output, "last_seq")));
    CHECK(malformed == 0);
    CHECK(stale == 0);
    CHECK(foreign == 0);
    CHECK(send_failed == 0);
    // The driver's side: forces came back every servo tick, none lost, and they pressed back.
    CHECK(udp_json_number(em.output, "force_seq_gaps") == 0);
    CHECK(udp_json_number(em.output, "forces_per_s") > 900);
    CHECK(udp_json_number(em.output, "forces_per_s") < 1100);
    CHECK(udp_json_number(em.output, "poses_echoed") > 0.5 * udp_json_number(em.output, "poses_sent"));
    CHECK(udp_json_number(em.output, "max_force_N") > 0.1);
  }
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
