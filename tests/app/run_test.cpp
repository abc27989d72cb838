// SPDX-License-Identifier: BSD-3-Clause
// Tests for `spheretouch run` and scene files: a short run of a generated scene asserting counts
// (never timing precision), the force profile of the built-in script, the outputs' formats, and
// an error naming the field for each kind of bad scene file.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "app/commands.hpp"
#include <spheretouch/engine/scene.hpp>
#include <spheretouch/rt/telemetry.hpp>
#include "app/process_util.hpp"
#include "test_util.hpp"

using st::test::contains;
using st::test::run_command;
using st::test::spheretouch_exe;

namespace {

/// Minimal JSON syntax check (RFC 8259 grammar, no semantic checks): true when `s` is one value.
struct Json {
  const std::string& s;
  std::size_t i = 0;
  void ws() {
    while (i < s.size() && std::isspace(static_cast<unsigned char>(s[i]))) ++i;
  }
  bool lit(const char* w) {
    const std::size_t n = std::strlen(w);
    if (s.compare(i, n, w) != 0) return false;
    i += n;
    return true;
  }
  bool str() {
    if (s[i] != '"') return false;
    for (++i; i < s.size(); ++i) {
      if (s[i] == '\\') {
        ++i;
        continue;
      }
      if (s[i] == '"') {
        ++i;
        return true;
      }
      if (static_cast<unsigned char>(s[i]) < 0x20) return false;
    }
    return false;
  }
  bool num() {
    const std::size_t b = i;
    if (s[i] == '-') ++i;
    while (i < s.size() && (std::isdigit(static_cast<unsigned char>(s[i])) || s[i] == '.' || s[i] == 'e' ||
                            s[i] == 'E' || s[i] == '+' || s[i] == '-'))
      ++i;
    return i > b && std::isdigit(static_cast<unsigned char>(s[i - 1]));
  }
  bool value() {
    ws();
    if (i >= s.size()) return false;
    bool ok;
    if (s[i] == '{') {
      ++i;
      ws();
      if (s[i] == '}') {
        ++i;
        return true;
      }
      do {
        ws();
        ok = str();
        ws();
        if (!ok || s[i] != ':') return false;
        ++i;
        if (!value()) return false;
        ws();
      } while (s[i] == ',' && ++i);
      if (s[i] != '}') return false;
      ++i;
      return true;
    }
    if (s[i] == '[') {
      ++i;
      ws();
      if (s[i] == ']') {
        ++i;
        return true;
      }
      do {
        if (!value()) return false;
        ws();
      } while (s[i] == ',' && ++i);
      if (s[i] != ']') return false;
      ++i;
      return true;
    }
    if (s[i] == '"') return str();
    if (lit("true") || lit("false") || lit("null")) return true;
    return num();
  }
  bool document() {
    const bool ok = value();
    ws();
    return ok && i == s.size();
  }
};

const char* kScene = R"(
[probe]
builtin = "capsule"
radius_mm = 6.0
length_mm = 30.0
[object]
builtin = "icosphere"
radius_mm = 40.0
frequency = 20
[workers]
count = 0
[output]
status = "plain"
[run]
duration_s = 5.5
)";

}  // namespace

TEST_CASE("run: a short scene ticks at its rate, presses with force, releases to zero, writes its outputs") {
  st::test::TempDir d;
  st::test::write_file(d.file("scene.toml"), kScene);
  const std::string out = d.file("run");
  const auto r = run_command(spheretouch_exe() + " run " + d.file("scene.toml") + " --out " + out);
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  CHECK(contains(r.output, "summary"));
  CHECK(contains(r.output, " 0 dropped"));
  CHECK(contains(r.output, "memory          RSS "));

  // Counts, not timing: every 1 ms period of the 5.5 s run is a tick or a counted miss (a busy
  // host turns ticks into misses, but the schedule holds).
  const std::vector<st::test::TickCsvRow> ticks = st::test::read_tick_csv(out + "/ticks.csv");
  REQUIRE_FALSE(ticks.empty());
  CHECK(st::test::tick_periods(ticks) >= 5500 - 50);
  CHECK(st::test::tick_periods(ticks) <= 5500 + 50);
  CHECK(ticks.size() > 5500 / 10);

  // The built-in script: approach 1 s, press 0.5 s, hold 0.5 s, slide 2 s, release 0.5 s, rest.
  double press_max = 0, rest_max = 0;
  int contact_ticks = 0;
  for (const st::test::TickCsvRow& t : ticks) {
    CHECK(std::isfinite(t.force_N));
    CHECK(t.force_N <= 3.3 + 1e-9);
    if (t.t_s > 1.6 && t.t_s < 2.0) press_max = std::max(press_max, t.force_N);
    if (t.t_s > 4.9) rest_max = std::max(rest_max, t.force_N);
    contact_ticks += t.flags & 1;
  }
  CHECK(contact_ticks > 0);  // contact updates reached the haptic side
  CHECK(press_max > 0.1);
  CHECK(rest_max == 0.0);

  // rounds.csv: one line per collision round, as many as the summary counts.
  {
    std::ifstream in(out + "/rounds.csv");
    std::string line;
    std::getline(in, line);
    CHECK(line == "start_ns,end_ns,pose_seq,pairs,contacts,pd_mm,complete");
    std::size_t n = 0, with_pairs = 0;
    while (std::getline(in, line)) {
      ++n;
      // pairs is the fourth field
      std::size_t at = 0;
      for (int k = 0; k < 3 && at != std::string::npos; ++k) at = line.find(',', at + 1);
      if (at != std::string::npos && std::stoul(line.substr(at + 1)) > 0) ++with_pairs;
    }
    CHECK(n > 100);
    CHECK(contains(r.output, "collision       " + std::to_string(n) + " rounds"));
    // The rounds in contact are timed apart: as many as rounds.csv has with pairs.
    CHECK(with_pairs > 0);
    CHECK(contains(r.output, "in contact      " + std::to_string(with_pairs) + " rounds with pairs, latency p50 "));
  }

  const std::string trace = st::test::slurp_file(out + "/trace.json");
  CHECK(Json{trace}.document());
  CHECK(contains(trace, "\"name\":\"round\""));
  CHECK(contains(trace, "\"name\":\"tick\""));

  // PLY header consistent with its body: object then probe, counts and lines agree.
  std::ifstream ply(out + "/contact.ply");
  std::string line;
  std::size_t nv = 0, nf = 0, red = 0;
  while (std::getline(ply, line) && line != "end_header") {
    if (line.rfind("element vertex ", 0) == 0) nv = std::stoul(line.substr(15));
    if (line.rfind("element face ", 0) == 0) nf = std::stoul(line.substr(13));
  }
  st::engine::BodySpec ball, finger;
  ball.builtin = "icosphere";
  ball.radius_mm = 40;
  ball.frequency = 20;
  finger.builtin = "capsule";
  finger.radius_mm = 6;
  finger.length_mm = 30;
  const st::geom::Mesh ball_mesh = st::engine::load_body(ball, "object").value();
  const st::geom::Mesh finger_mesh = st::engine::load_body(finger, "probe").value();
  CHECK(nf == ball_mesh.num_faces() + finger_mesh.num_faces());
  CHECK(nv == ball_mesh.num_vertices() + finger_mesh.num_vertices());
  std::size_t vlines = 0, flines = 0;
  for (; vlines < nv && std::getline(ply, line); ++vlines) {
    std::istringstream in(line);
    double x, y, z;
    CHECK(static_cast<bool>(in >> x >> y >> z));
  }
  while (std::getline(ply, line)) {
    std::istringstream in(line);
    int n, a, b, c, cr, cg, cb;
    CHECK(static_cast<bool>(in >> n >> a >> b >> c >> cr >> cg >> cb));
    CHECK(n == 3);
    CHECK((a >= 0 && std::size_t(a) < nv && std::size_t(b) < nv && std::size_t(c) < nv));
    red += cr == 230;
    ++flines;
  }
  CHECK(vlines == nv);
  CHECK(flines == nf);
  CHECK(red > 0);
}

TEST_CASE(
    "run: a material with friction (configs/friction.toml): the slide sticks, breaks away and slides; summary and "
    "ticks.csv say so") {
  st::test::TempDir d;
  const std::string root = std::getenv("ST_SOURCE_ROOT") ? std::getenv("ST_SOURCE_ROOT") : ".";
  const std::string out = d.file("run");
  const auto r =
      run_command(spheretouch_exe() + " run " + root + "/configs/friction.toml --out " + out + " --duration 4");
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  const auto at = r.output.find("friction        static 0.8, dynamic 0.5, stick spring 0.500 N/mm: ");
  REQUIRE(at != std::string::npos);
  unsigned long long stuck = 0, sliding = 0, breakaways = 0;
  REQUIRE(std::sscanf(r.output.c_str() + r.output.find(": ", at) + 2,
                      "%llu ticks stuck, %llu sliding, %llu break-aways", &stuck, &sliding, &breakaways) == 3);
  CHECK(stuck > 50);     // pressing in: stuck where it touched
  CHECK(sliding > 500);  // the 20 mm slide
  CHECK(breakaways >= 1);
  // ticks.csv flags the same ticks: stuck (8) and sliding (16) only in contact (1), never both.
  std::size_t flagged_stuck = 0, flagged_sliding = 0, wrong = 0;
  for (const st::test::TickCsvRow& t : st::test::read_tick_csv(out + "/ticks.csv")) {
    const bool is_stuck = t.flags & st::rt::kTickStuck, is_sliding = t.flags & st::rt::kTickSliding;
    wrong += (is_stuck && is_sliding) || ((is_stuck || is_sliding) && !(t.flags & st::rt::kTickInContact));
    flagged_stuck += is_stuck;
    flagged_sliding += is_sliding;
  }
  CHECK(wrong == 0);
  CHECK(flagged_stuck == stuck);
  CHECK(flagged_sliding == sliding);
}

TEST_CASE("run: [workers] replicas = true deals every block over two in-process workers; every round complete") {
  st::test::TempDir d;
  std::string scene = kScene;
  scene.replace(scene.find("count = 0"), 9, "count = 3\nreplicas = true");
  st::test::write_file(d.file("scene.toml"), scene);
  const auto r =
      run_command(spheretouch_exe() + " run " + d.file("scene.toml") + " --out " + d.file("run") + " --duration 2.5");
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  CHECK(contains(r.output, "3 in-process workers, every block on two workers (replicated deal)"));
  CHECK(contains(r.output, " 0 incomplete"));
  const auto at = r.output.find("force           peak ");
  REQUIRE(at != std::string::npos);
  CHECK(std::atof(r.output.c_str() + at + 21) > 0.1);  // pressed: the replicated rounds found the contact
}

TEST_CASE("run: a full disk is an error naming the file, and the summary is printed whatever happens") {
  // /dev/full accepts the open and fails every write with ENOSPC, as a full disk does.
  REQUIRE(std::filesystem::exists("/dev/full"));
  st::test::TempDir d;
  std::string scene = kScene;
  scene.replace(scene.find("duration_s = 5.5"), 16, "duration_s = 1.0");
  st::test::write_file(d.file("scene.toml"), scene);
  struct Case {
    const char* file;
    bool split;
  };
  for (const Case c : {Case{"ticks.csv", false}, Case{"rounds.csv", false}, Case{"summary.txt", false},
                       Case{"ticks.csv", true}, Case{"servo.txt", true}}) {
    const std::string what = std::string(c.file) + (c.split ? " (split)" : "");
    CAPTURE(what);
    const std::string out = d.file(std::string("run-") + c.file + (c.split ? "-split" : ""));
    std::filesystem::create_directories(out);
    std::filesystem::create_symlink("/dev/full", out + "/" + c.file);
    const auto r =
        run_command(spheretouch_exe() + " run " + d.file("scene.toml") + " --out " + out + (c.split ? " --split" : ""));
    INFO(r.output);
    CHECK(r.exit_code == 1);
    CHECK(contains(r.output, "summary\n"));  // on stdout, whatever happened to the files
    CHECK(contains(r.output, "haptic          "));
    CHECK(contains(r.output, "No space left on device"));
    if (!c.split) {
      CHECK(contains(r.output, "spheretouch run: " + out + "/" + c.file + ": write failed"));
    } else if (std::string(c.file) == "ticks.csv") {
      CHECK(contains(r.output, out + "/ticks.csv: write failed"));  // from the servo process
    } else {
      // The servo's own figures are lost: said so, with its last status, never printed as zeros.
      CHECK(contains(r.output, out + "/servo.txt"));
      CHECK(contains(r.output, "haptic          figures lost (the servo process's servo.txt); its last status: "));
      CHECK_FALSE(contains(r.output, "haptic          0 ticks"));
      CHECK(contains(r.output, "force           (servo figures lost)"));
    }
    // The run directory is private to its user (poses and forces are the user's data).
    const auto perms = std::filesystem::status(out).permissions();
    CHECK((perms & (std::filesystem::perms::group_all | std::filesystem::perms::others_all)) == std::filesystem::perms::none);
  }
}

TEST_CASE("run: another process truncating the shared-memory segment stops the run with a clear error, not SIGBUS") {
  for (const bool split : {false, true}) {
    CAPTURE(split);
    st::test::TempDir d;
    std::string scene = kScene;
    scene.replace(scene.find("duration_s = 5.5"), 16, "duration_s = 30.0");
    st::test::write_file(d.file("scene.toml"), scene);
    const std::string log = d.file("run.log");
    const std::string seg = "/spheretouch-test-truncate-" + std::to_string(getpid()) + (split ? "-s" : "-i");
    std::vector<std::string> args = {"run", d.file("scene.toml"), "--out", d.file("run"), "--shm-name", seg};
    if (split) args.push_back("--split");
    const pid_t pid = st::test::spawn_spheretouch(args, log);
    REQUIRE(st::test::wait_for_ticks(seg, 200, pid, 30.0).ticks >= 200);
    const int fd = shm_open(seg.c_str(), O_RDWR, 0);
    REQUIRE(fd >= 0);
    REQUIRE(ftruncate(fd, 0) == 0);  // what a hostile or careless process of the same user can do
    close(fd);
    const int code = st::test::wait_for(pid, 30.0);
    const std::string out = st::test::slurp_file(log);
    INFO(out);
    CHECK(code == 1);  // an error, not 128 + SIGBUS
    CHECK(contains(out, "was truncated by another process"));
    CHECK(contains(out, "summary\n"));
  }
}

TEST_CASE("run: SIGHUP (a closed terminal) ends the run like Ctrl-C: summary printed, segment removed") {
  st::test::TempDir d;
  std::string scene = kScene;
  scene.replace(scene.find("duration_s = 5.5"), 16, "duration_s = 30.0");
  st::test::write_file(d.file("scene.toml"), scene);
  const std::string log = d.file("run.log");
  const pid_t pid = st::test::spawn_spheretouch({"run", d.file("scene.toml"), "--out", d.file("run")}, log);
  // The segment's name has a random part; the run prints it ("shm /spheretouch-PID-HEX;").
  const std::string prefix = "shm /spheretouch-" + std::to_string(pid) + "-";
  std::string seg;
  for (int i = 0; i < 3000 && seg.empty(); ++i) {
    const std::string text = st::test::slurp_file(log);
    if (const auto at = text.find(prefix); at != std::string::npos && text.find(';', at) != std::string::npos)
      seg = text.substr(at + 4, text.find(';', at) - at - 4);
    else
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  REQUIRE(seg.size() == prefix.size() - 4 + 16);
  const st::rt::ServoStatus st = st::test::wait_for_ticks(seg, 200, pid, 30.0);
  REQUIRE(st.ticks >= 200);
  REQUIRE(kill(pid, SIGHUP) == 0);
  const int code = st::test::wait_for(pid, 20.0);
  const std::string out = st::test::slurp_file(log);
  INFO(out);
  CHECK(code == 0);
  CHECK(contains(out, "stopped by signal " + std::to_string(SIGHUP)));
  CHECK(contains(out, "summary\n"));
  CHECK_FALSE(std::filesystem::exists("/dev/shm" + seg));
}

TEST_CASE("scene files: each kind of mistake gets an error naming the field") {
  const std::pair<const char*, const char*> cases[] = {
      {"[probe]\nbuiltin = \"capsule\"\n", "missing section [object]"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[force]\npeak_n = \"lots\"\n",
       "force.peak_n: expected a number"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[force]\npeak_n = -1\n",
       "force.peak_n: expected a value in"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[haptic]\nrate = 1000\n",
       "unknown key 'haptic.rate' (known in [haptic]:"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[telepathy]\n", "unknown key 'telepathy'"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nmesh = \"nowhere.off\"\n", "object.mesh: file"},
      {"[probe]\nbuiltin = \"sphere\"\n[object]\nbuiltin = \"box\"\n",
       "probe.builtin: expected one of icosphere, box, capsule"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[interpolation]\nmethod = \"magic\"\n",
       "interpolation.method"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\nendpoints = [\"http://x\"]\n",
       "workers.endpoints"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\ncount = 1.5\n",
       "workers.count: expected an integer"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[collision]\ncoherent = \"yes\"\n",
       "collision.coherent: expected true or false"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\nreplicas = 2\n",
       "workers.replicas: expected true or false"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\ntarget = [1, 2]\n",
       "device.target: expected an array of 3 numbers"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[force]\ncontinuous_n = 5\n",
       "force.continuous_n: must not exceed peak_n"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\nkind = \"usb\"\n",
       "device.kind: expected one of simulated, udp"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\nkind = \"udp\"\nfade_ms = 0\n",
       "device.fade_ms: expected a value in"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\nkind = \"udp\"\noffset_mm = [1]\n",
       "device.offset_mm: expected an array of 3 numbers"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\nkind = \"udp\"\nauth = \"pgp\"\n",
       "device.auth: expected one of hmac, none"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\nkind = \"udp\"\nauth = \"none\"\n"
       "key_file = \"k\"\n",
       "device.key_file: is set but auth = \"none\""},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\nkind = \"udp\"\nkey_file = "
       "\"/nowhere/k\"\n",
       "device.key_file: bridge key file /nowhere/k does not exist"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\nkind = \"udp\"\nsilence_ms = 900\n",
       "device.session_timeout_ms: must be >= silence_ms"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\nkind = \"udp\"\nmax_seq_jump = 0\n",
       "device.max_seq_jump: expected a value in"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[device]\nkind = \"udp\"\nmax_force_step_n = -1\n",
       "device.max_force_step_n: expected a value in"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[force]\nstatic_friction = 0.3\ndynamic_friction "
       "= 0.5\n",
       "force.dynamic_friction: dynamic_friction must not exceed static_friction"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[force]\nstatic_friction = 11\n",
       "force.static_friction: expected a value in [0, 10]"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[force]\nfriction_stiffness_n_per_mm = -1\n",
       "force.friction_stiffness_n_per_mm: expected a value in"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\nmaterial = 3\n",
       "object.material: expected a [object.material] table"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[object.material]\nstickiness = 1\n",
       "unknown key 'object.material.stickiness'"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[object.material]\nlaw = \"cubic\"\n",
       "object.material.law: expected one of log, linear"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[object.material]\ndynamic_friction = -0.1\n",
       "object.material.dynamic_friction: expected a value in [0, 10]"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[force]\nstatic_friction = 0.5\ndynamic_friction "
       "= 0.4\n"
       "[object.material]\nstatic_friction = 0.2\n",
       "object.material.static_friction: dynamic_friction must not exceed static_friction"},
      // Scenes of several objects ([[object]]): each field's error names the object by its place.
      {"object = 3\n[probe]\nbuiltin = \"capsule\"\n", "object: expected an [object] table or [[object]] tables"},
      {"object = []\n[probe]\nbuiltin = \"capsule\"\n", "object: expected at least one [[object]] table"},
      {"object = [1, 2]\n[probe]\nbuiltin = \"capsule\"\n", "object[1]: expected a table ([[object]])"},
      {"[probe]\nbuiltin = \"capsule\"\n[[object]]\nbuiltin = \"box\"\n[[object]]\nsize_mm = 3\n",
       "object[2].mesh: expected a mesh path"},
      {"[probe]\nbuiltin = \"capsule\"\n[[object]]\nbuiltin = \"box\"\nname = \"a\"\n[[object]]\nbuiltin = "
       "\"box\"\nname = \"a\"\n",
       "object[2].name: 'a' names an earlier object too"},
      {"[probe]\nbuiltin = \"capsule\"\n[[object]]\nbuiltin = \"box\"\nposition_mm = [1, 2]\n",
       "object[1].position_mm: expected an array of 3 numbers"},
      {"[probe]\nbuiltin = \"capsule\"\n[[object]]\nbuiltin = \"box\"\nposition_mm = [1e10, 0, 0]\n",
       "object[1].position_mm: expected coordinates within 1e9 mm"},
      {"[probe]\nbuiltin = \"capsule\"\n[[object]]\nbuiltin = \"box\"\nrotation_deg = [\"x\", 0, 0]\n",
       "object[1].rotation_deg: expected finite numbers in the array"},
      {"[probe]\nbuiltin = \"capsule\"\n[[object]]\nbuiltin = \"box\"\ncolour = \"red\"\n",
       "unknown key 'object[1].colour'"},
      {"[probe]\nbuiltin = \"capsule\"\n[[object]]\nbuiltin = \"box\"\n[[object]]\nbuiltin = "
       "\"box\"\n[object.material]\nstatic_friction = 11\n",
       "object[2].material.static_friction: expected a value in [0, 10]"},
      {"[probe]\nbuiltin = \"capsule\"\n[[object]]\nbuiltin = \"box\"\n[object.material]\nlaw = \"linear\"\n"
       "spring_n_per_mm = 0\n",
       "object[1].material.spring_n_per_mm: expected a value in"},
      {"[probe]\nbuiltin = \"capsule\"\n[[object]]\nbuiltin = \"box\"\nmaterial = 3\n",
       "object[1].material: expected a [object[1].material] table"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\nposition_mm = [0, 0]\n",
       "object.position_mm: expected an array of 3 numbers"},
      {"[probe]\nbuiltin = \"capsule\"\n[object\n", "TOML syntax"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[contact]\nmodel = \"nearest\"\n",
       "contact.model: expected one of patch, paper"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[contact]\nhold_margin_mm = -1\n",
       "contact.hold_margin_mm"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[contact]\nmax_inside_vertices = 0\n",
       "contact.max_inside_vertices"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[passivity]\ncolgate_margin = -2\n",
       "passivity.colgate_margin"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[passivity]\nenabled = 1\n", "passivity.enabled"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[passivity]\ndamping = 1\n",
       "unknown key 'passivity.damping'"},
      {"[probe]\nbuiltin = \"capsule\"\nmesh = \"a.off\"\n[object]\nbuiltin = \"box\"\n", "probe.mesh"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\nserver_key = \"/nowhere/fleet.pub\"\n",
       "workers.client_key: server_key is set but client_key is not"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\nclient_key = \"c\"\n",
       "workers.server_key: client_key is set but server_key is not"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\nserver_key = \"/nowhere/fleet.pub\"\n"
       "client_key = \"/nowhere/c\"\n",
       "workers.server_key: file /nowhere/fleet.pub does not exist"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\nserver_key = 3\n",
       "workers.server_key: expected a string"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[tree]\nlayer = \"deep\"\n",
       "tree.layer: expected an integer or \"auto\""},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[tree]\nblock_size = 0\n", "tree.block_size"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\nassist_blocks = \"many\"\n",
       "workers.assist_blocks: expected an integer or \"auto\""},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\nassist_blocks = 257\n",
       "workers.assist_blocks: expected a value in [0, 256]"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[tree]\nmapping = \"diagonal\"\n",
       "tree.mapping: expected one of block-cyclic, contiguous, random"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[haptic]\nthread_stack_kb = 16\n",
       "haptic.thread_stack_kb: expected 0 (glibc's default) or at least 64"},
      {"[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[haptic]\nthread_stack_kb = "
       "256\nprefault_stack_kb = 200\n",
       "haptic.prefault_stack_kb: 200 KiB does not fit the haptic thread's stack (thread_stack_kb = 256"},
  };
  for (const auto& item : cases) {
    const auto& text = item.first;  // not a structured binding: INFO captures it (clang < 16)
    const auto& want = item.second;
    auto r = st::engine::parse_scene(text, "bad.toml", ".");
    INFO(text);
    REQUIRE_FALSE(r.ok());
    INFO(r.error());
    CHECK(contains(r.error(), want));
    CHECK(contains(r.error(), "bad.toml"));
  }
  // And through the command: exit code 2 with the message.
  st::test::TempDir d;
  st::test::write_file(d.file("s.toml"),
                       "[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[force]\npeak_n = -1\n");
  const auto r = run_command(spheretouch_exe() + " run " + d.file("s.toml") + " --out " + d.file("o"));
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "s.toml:6: force.peak_n: expected a value in"));
}

TEST_CASE("scene files: [[object]] gives each object its body, placement and material ([force] the default)") {
  const std::string text =
      "[probe]\nbuiltin = \"capsule\"\n"
      "[[object]]\nname = \"left\"\nbuiltin = \"box\"\nsize_mm = 20\nposition_mm = [-15, 0, 0]\n"
      "[[object]]\nbuiltin = \"icosphere\"\nradius_mm = 5\nrotation_deg = [0, 0, 90]\n"
      "[object.material]\nlaw = \"linear\"\nspring_n_per_mm = 0.4\nstatic_friction = 0.5\ndynamic_friction = 0.3\n"
      "[force]\nstatic_friction = 0.2\ndynamic_friction = 0.1\npeak_n = 4\n";
  auto r = st::engine::parse_scene(text, "two.toml", ".");
  REQUIRE_MESSAGE(r.ok(), r.error());
  const st::engine::Scene& s = r.value();
  REQUIRE(s.objects.size() == 2);
  CHECK(s.objects[0].name == "left");
  CHECK(s.objects[1].name == "object 2");
  CHECK(s.objects[0].body.builtin == "box");
  CHECK(s.objects[0].body.size_mm == 20);
  CHECK(s.objects[1].body.radius_mm == 5);
  CHECK(s.objects[0].placement.position_mm.isApprox(Eigen::Vector3d(-15, 0, 0)));
  // A placement maps the object's file coordinates into the world: 90 degrees about z takes +x to +y.
  const st::geom::Pose p1 = s.objects[1].placement.pose();
  CHECK((p1 * Eigen::Vector3d(1, 0, 0) - Eigen::Vector3d(0, 1, 0)).norm() < 1e-12);
  CHECK((s.objects[0].placement.pose() * Eigen::Vector3d(1, 2, 3) - Eigen::Vector3d(-14, 2, 3)).norm() < 1e-12);
  // The first object has [force]'s material; the second overrides law and friction, keeping the peak.
  CHECK(s.objects[0].material.law.kind == st::rt::LawKind::log);
  CHECK(s.objects[0].material.friction.static_mu == 0.2);
  CHECK(s.objects[1].material.law.kind == st::rt::LawKind::linear);
  CHECK(s.objects[1].material.law.spring_N_per_mm == 0.4);
  CHECK(s.objects[1].material.law.max_force_N == 4);
  CHECK(s.objects[1].material.friction.static_mu == 0.5);
  CHECK(s.objects[1].material.friction.dynamic_mu == 0.3);
  // Code that knows one object sees the first.
  CHECK(s.object.builtin == "box");
  CHECK(s.friction.static_mu == 0.2);
  CHECK(st::engine::scene_objects(s).size() == 2);
  // A scene of one [object] keeps `objects` empty; scene_objects() gives that object at the origin.
  auto one = st::engine::parse_scene("[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n", "one.toml", ".");
  REQUIRE(one.ok());
  CHECK(one.value().objects.empty());
  const auto objs = st::engine::scene_objects(one.value());
  REQUIRE(objs.size() == 1);
  CHECK(objs[0].body.builtin == "box");
  CHECK(objs[0].placement.pose().isApprox(st::geom::Pose::Identity()));
}

TEST_CASE("scene files: /dev/zero, a FIFO or an oversized file is refused before it is read") {
  auto z = st::engine::load_scene("/dev/zero");
  REQUIRE_FALSE(z.ok());
  CHECK(z.error() == "/dev/zero: not a regular file (a scene file is a text file)");
  st::test::TempDir d;
  REQUIRE(::mkfifo(d.file("fifo.toml").c_str(), 0600) == 0);
  auto f = st::engine::load_scene(d.file("fifo.toml"));  // would hang reading a FIFO nobody writes
  REQUIRE_FALSE(f.ok());
  CHECK(st::test::contains(f.error(), "not a regular file"));
  { std::ofstream o(d.file("big.toml")); }
  std::filesystem::resize_file(d.file("big.toml"), st::engine::kMaxSceneBytes + 1);
  auto b = st::engine::load_scene(d.file("big.toml"));
  REQUIRE_FALSE(b.ok());
  CHECK(st::test::contains(b.error(), "-byte limit for a scene file"));
}

TEST_CASE("scene files: a path the system cannot look up is an error, not an exception (fuzz finding)") {
  // fuzz_scene: a 300-character file name made std::filesystem::exists throw (ENAMETOOLONG) out of
  // parse_scene, killing the program instead of naming the field.
  const std::string long_name(300, 'a');
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"[probe]\nmesh = \"" + long_name + "\"\n[object]\nbuiltin = \"box\"\n", "probe.mesh: cannot look up"},
      {"[probe]\nbuiltin = \"box\"\n[object]\nmesh = \"model:" + long_name + "\"\n", "object.mesh: cannot look up"},
      {"[probe]\nbuiltin = \"box\"\n[object]\nbuiltin = \"box\"\n[device]\nscript = \"" + long_name + "\"\n",
       "device.script: trajectory cannot look up"},
  };
  for (const auto& [text, want] : cases) {
    st::Result<st::engine::Scene> r = st::engine::parse_scene(text, "long.toml", ".");
    REQUIRE_FALSE(r.ok());
    INFO(r.error());
    CHECK(contains(r.error(), want));
    CHECK(contains(r.error(), "File name too long"));
  }
}

TEST_CASE("scene files: configs/demo.toml and configs/small.toml parse, with the documented values") {
  const std::string root = std::getenv("ST_SOURCE_ROOT") ? std::getenv("ST_SOURCE_ROOT") : ".";
  auto demo = st::engine::load_scene(root + "/configs/demo.toml");
  REQUIRE_MESSAGE(demo.ok(), demo.error());
  CHECK(demo.value().haptic.rate_hz == 1000.0);
  CHECK(demo.value().law.a == 3.0);
  CHECK(demo.value().law.b_N == 0.8);
  CHECK(demo.value().saturation.peak_N == 3.3);
  CHECK(demo.value().tree.leaf_faces == st::geom::DefaultTreeConfig().leaf_faces);
  // The split is chosen for the scene and worker count unless the scene sets it.
  CHECK(demo.value().layer == st::geom::kFree);
  CHECK(demo.value().block_size == 0);
  CHECK(demo.value().mapping == st::geom::Mapping::block_cyclic);
  CHECK_FALSE(demo.value().replicas);  // one holder per block unless a scene asks for two
  // The documented contact and passivity values are the defaults.
  CHECK(demo.value().contact.model == st::geom::DefaultContactConfig().model);
  CHECK(demo.value().contact.hold_margin_mm == st::geom::DefaultContactConfig().hold_margin_mm);
  CHECK(demo.value().contact.max_inside_vertices == st::geom::DefaultContactConfig().max_inside_vertices);
  CHECK(demo.value().passivity.enabled == st::rt::DefaultPassivityConfig().enabled);
  CHECK(demo.value().passivity.colgate_margin == st::rt::DefaultPassivityConfig().colgate_margin);
  CHECK(demo.value().passivity.max_damping_N_s_per_mm == st::rt::DefaultPassivityConfig().max_damping_N_s_per_mm);
  auto paper = st::engine::parse_scene(
      "[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[contact]\nmodel = \"paper\"\n"
      "[passivity]\nenabled = false\n",
      "paper.toml", ".");
  REQUIRE_MESSAGE(paper.ok(), paper.error());
  CHECK(paper.value().contact.model == st::geom::ContactModelKind::paper);
  CHECK_FALSE(paper.value().passivity.enabled);
  // Materials: [force] is the default, [object.material] overrides what it names.
  auto mat = st::engine::parse_scene(
      "[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[object.material]\nlaw = \"linear\"\n"
      "spring_n_per_mm = 0.8\nstatic_friction = 0.6\n"
      "[force]\ndynamic_friction = 0.4\nstatic_friction = 0.5\ndamping_n_s_per_mm = 0.001\n",
      "mat.toml", ".");
  REQUIRE_MESSAGE(mat.ok(), mat.error());
  CHECK(mat.value().law.kind == st::rt::LawKind::linear);
  CHECK(mat.value().law.spring_N_per_mm == 0.8);
  CHECK(mat.value().friction.static_mu == 0.6);   // the object's
  CHECK(mat.value().friction.dynamic_mu == 0.4);  // [force]'s
  CHECK(mat.value().interp.damping_N_s_per_mm == 0.001);
  CHECK(demo.value().friction.static_mu == 0);  // frictionless unless a scene says otherwise
  CHECK(demo.value().friction.dynamic_mu == 0);
  auto fr = st::engine::load_scene(root + "/configs/friction.toml");
  REQUIRE_MESSAGE(fr.ok(), fr.error());
  CHECK(fr.value().friction.static_mu == 0.8);
  CHECK(fr.value().friction.dynamic_mu == 0.5);
  CHECK(fr.value().law.kind == st::rt::LawKind::linear);
  auto small = st::engine::load_scene(root + "/configs/small.toml");
  REQUIRE_MESSAGE(small.ok(), small.error());
  CHECK(small.value().object.builtin == "icosphere");
  // The scene of several objects: three placed meshes, the second with its own material.
  auto objects = st::engine::load_scene(root + "/configs/objects.toml");
  REQUIRE_MESSAGE(objects.ok(), objects.error());
  REQUIRE(objects.value().objects.size() == 3);
  CHECK(objects.value().objects[1].name == "bunny");
  CHECK(objects.value().objects[1].material.law.kind == st::rt::LawKind::linear);
  CHECK(objects.value().objects[0].material.friction.static_mu == 0.3);
  CHECK(objects.value().objects[2].placement.position_mm.x() == 200.0);
}

TEST_CASE("appendf: appends formatted text of any length") {
  std::string out = "summary: ";
  st::app::appendf(out, "%d ticks, %.1f Hz", 42, 999.5);
  CHECK(out == "summary: 42 ticks, 999.5 Hz");
  const std::string long_path(2000, 'x');  // longer than any fixed line buffer
  st::app::appendf(out, " | %s/", long_path.c_str());
  CHECK(out.size() == std::string("summary: 42 ticks, 999.5 Hz | ").size() + 2000 + 1);
  CHECK(out.back() == '/');
  st::app::appendf(out, "%s", "");  // nothing to add
  CHECK(out.back() == '/');
}
