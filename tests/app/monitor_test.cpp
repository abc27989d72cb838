// SPDX-License-Identifier: BSD-3-Clause
// Tests src/app/cmd_monitor.cpp: its refusals (a segment with a bad magic or another layout
// version gets a clear error, never a crash; a live session is watched in servo_process_test.cpp)
// and --view: the live view attached to a running run (meshes, frames with the contacts), a bad
// address, a scene file changed since the run started, and frames forged in a segment.
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <civetweb.h>
#include <sys/socket.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <iterator>
#include <thread>

#include "app/view_client.hpp"
#include <spheretouch/engine/scene.hpp>
#include "process_util.hpp"
#include <spheretouch/rt/shm_segment.hpp>
#include "test_util.hpp"

using namespace st::test;

namespace {

/// A capsule probe pressing an icosphere (2880 faces), no workers, the press repeated.
std::string monitor_view_scene(double seconds, double radius_mm = 50.0) {
  return "[probe]\nbuiltin = \"capsule\"\nradius_mm = 8.0\nlength_mm = 40.0\n"
         "[object]\nbuiltin = \"icosphere\"\nradius_mm = " +
         std::to_string(radius_mm) +
         "\nfrequency = 12\n"
         "[workers]\ncount = 0\n[device]\npress_mm = 4.0\nrepeat = true\n"
         "[output]\nstatus = \"off\"\nply = false\n[run]\nduration_s = " +
         std::to_string(seconds) + "\n";
}

/// Polls `log` until it contains `what` (or `pid` ended, or 60 s passed).
bool monitor_wait_log(const std::string& log, const std::string& what, pid_t pid) {
  for (int i = 0; i < 6000; ++i) {
    if (contains(slurp_file(log), what)) return true;
    if (waitpid(pid, nullptr, WNOHANG) != 0) return contains(slurp_file(log), what);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

/// The probe and object a scene file gives (as the run and the monitor load them).
std::pair<st::geom::Mesh, st::geom::Mesh> monitor_meshes(const std::string& scene) {
  auto s = st::engine::load_scene(scene);
  REQUIRE_MESSAGE(s.ok(), s.error());
  auto p = st::engine::load_body(s.value().probe, "probe");
  auto o = st::engine::load_body(s.value().object, "object");
  REQUIRE(p.ok());
  REQUIRE(o.ok());
  return {std::move(p).value(), std::move(o).value()};
}

}  // namespace

TEST_CASE("monitor: refuses a segment with a bad magic or layout version, and a missing one") {
  const std::string name = "/spheretouch-test-mon-" + std::to_string(getpid());
  // Not ours: a segment of the right size full of zeros.
  {
    const int fd = shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
    REQUIRE(fd >= 0);
    REQUIRE(ftruncate(fd, sizeof(st::rt::ShmLayout)) == 0);
    close(fd);
    const CommandResult r = run_command(spheretouch_exe() + " monitor --name " + name + " --count 1");
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.output, "bad magic"));
    shm_unlink(name.c_str());
  }
  // Ours, but another layout version.
  {
    auto seg = st::rt::ShmSegment::create(name);
    REQUIRE(seg.ok());
    const int fd = shm_open(name.c_str(), O_RDWR, 0);
    REQUIRE(fd >= 0);
    void* p = mmap(nullptr, sizeof(st::rt::ShmLayout), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    REQUIRE(p != MAP_FAILED);
    static_cast<st::rt::ShmHeader*>(p)->layout_version = st::rt::kShmLayoutVersion + 7;
    const CommandResult r = run_command(spheretouch_exe() + " monitor --name " + name + " --count 1");
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.output, "layout version " + std::to_string(st::rt::kShmLayoutVersion + 7)));
    static_cast<st::rt::ShmHeader*>(p)->layout_version = st::rt::kShmLayoutVersion;
    // Restored: now it attaches and prints a line (no servo has ticked in it).
    const CommandResult ok = run_command(spheretouch_exe() + " monitor --name " + name + " --count 1");
    INFO(ok.output);
    CHECK(ok.exit_code == 0);
    CHECK(contains(ok.output, "no ticks yet"));
    munmap(p, sizeof(st::rt::ShmLayout));
  }
  const CommandResult missing = run_command(spheretouch_exe() + " monitor --name " + name + "-absent --count 1");
  CHECK(missing.exit_code == 2);
  CHECK(contains(missing.output, "cannot attach"));
}

TEST_CASE("monitor: a segment truncated under it is reported and stops it, not SIGBUS") {
  const std::string name = "/spheretouch-test-mon-trunc-" + std::to_string(getpid());
  auto seg = st::rt::ShmSegment::create(name);
  REQUIRE(seg.ok());
  TempDir d;
  const std::string log = d.file("monitor.log");
  const pid_t pid = spawn_spheretouch({"monitor", "--name", name, "--interval", "20", "--count", "1000"}, log);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));  // it is printing lines by now
  const int fd = shm_open(name.c_str(), O_RDWR, 0);
  REQUIRE(fd >= 0);
  REQUIRE(ftruncate(fd, 0) == 0);  // what anyone who can write the segment can do
  close(fd);
  const int code = wait_for(pid, 20.0);
  std::ifstream in(log);
  const std::string out((std::istreambuf_iterator<char>(in)), {});
  INFO(out);
  CHECK(code == 1);  // not 128 + SIGBUS
  CHECK(contains(out, "the segment shrank under the monitor"));
  shm_unlink(name.c_str());
}

TEST_CASE(
    "monitor --view: attaches the live view to a running run; the meshes are the run's, frames carry the contacts") {
  mg_init_library(0);
  TempDir d;
  const std::string seg = "/spheretouch-test-monview-" + std::to_string(getpid());
  write_file(d.file("scene.toml"), monitor_view_scene(120.0));
  const pid_t run =
      spawn_spheretouch({"run", d.file("scene.toml"), "--out", d.file("out"), "--shm-name", seg}, d.file("run.log"));
  REQUIRE(wait_for_ticks(seg, 10, run, 60).ticks > 0);
  const int port = free_loopback_port(SOCK_STREAM);
  const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/";
  const pid_t mon =
      spawn_spheretouch({"monitor", "--name", seg, "--view", "127.0.0.1:" + std::to_string(port), "--interval", "200"},
                        d.file("mon.log"));
  const bool up = monitor_wait_log(d.file("mon.log"), "view: " + url, mon);
  INFO(slurp_file(d.file("mon.log")));
  REQUIRE(up);

  ViewMessages msgs;
  char err[256] = "";
  mg_connection* ws = view_connect(port, msgs, err, st::test::view_token(slurp_file(d.file("mon.log"))));
  INFO(err);
  REQUIRE(ws != nullptr);
  // Until frames with colliding object faces came (the press repeats), at most 90 s.
  bool pressed = false;
  for (int i = 0; i < 1800 && !pressed && waitpid(run, nullptr, WNOHANG) == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::lock_guard<std::mutex> l(msgs.mu);
    std::size_t with_faces = 0;
    for (std::size_t k = 1; k < msgs.binary.size(); ++k)
      if (msgs.binary[k].size() >= 248 && view_at<std::uint32_t>(msgs.binary[k], 240) > 0) ++with_faces;
    pressed = with_faces >= 5;
  }
  kill(run, SIGINT);
  const int run_rc = wait_for(run, 30);
  const int mon_rc = wait_for(mon, 30);  // the run ended: the monitor stops by itself
  mg_close_connection(ws);
  const std::string log = slurp_file(d.file("mon.log"));
  INFO(log);
  INFO(slurp_file(d.file("run.log")));
  CHECK(pressed);
  CHECK(run_rc == 0);
  CHECK(mon_rc == 0);
  CHECK(contains(log, "session finished"));
  CHECK_FALSE(contains(log, "DEAD"));  // a run that ended normally is not reported dead
  CHECK(contains(log, "view: " + url + "?t=" + st::test::view_token(log) + ": 1 page(s)"));
  CHECK_FALSE(contains(log, "bad frames"));

  const auto [probe, object] = monitor_meshes(d.file("scene.toml"));
  std::lock_guard<std::mutex> l(msgs.mu);
  REQUIRE(msgs.binary.size() > 20);
  const ViewMeshCounts m = view_mesh_counts(msgs.binary.front());
  CHECK(m.probe_vertices == probe.num_vertices());
  CHECK(m.probe_faces == probe.num_faces());
  CHECK(m.object_vertices == object.num_vertices());
  CHECK(m.object_faces == object.num_faces());
  CHECK(m.object_faces == 2880);  // icosphere, frequency 12: 20 · 12²
  const ViewFrameCounts counts = view_check_frames(msgs.binary, 1, m.probe_faces, m.object_faces);
  CHECK(counts.frames > 20);
  CHECK(counts.with_faces >= 5);
  mg_exit_library();
}

TEST_CASE("monitor --view with a malformed address is refused before it attaches") {
  for (const char* bad : {"nonsense", "127.0.0.1:", ":8080", "127.0.0.1:99999", "127.0.0.1:80a"}) {
    CAPTURE(bad);
    const auto r = run_command(spheretouch_exe() + " monitor --name /spheretouch-test-absent --view '" + bad + "'");
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.output, "expected ADDR:PORT"));
    CHECK_FALSE(contains(r.output, "cannot attach"));
  }
}

TEST_CASE("monitor --view refuses when the run's scene file changed or is gone, naming the file") {
  TempDir d;
  const std::string seg = "/spheretouch-test-monscene-" + std::to_string(getpid());
  const std::string scene = d.file("scene.toml");
  write_file(scene, monitor_view_scene(120.0));
  const pid_t run = spawn_spheretouch({"run", scene, "--out", d.file("out"), "--shm-name", seg}, d.file("run.log"));
  REQUIRE(wait_for_ticks(seg, 10, run, 60).ticks > 0);
  // --count 1: were the meshes wrongly accepted, the monitor would still end.
  const std::string view = " --count 1 --view 127.0.0.1:" + std::to_string(free_loopback_port(SOCK_STREAM));
  // Another radius: the same counts, other coordinates.
  write_file(scene, monitor_view_scene(120.0, 51.0));
  const auto moved = run_command(spheretouch_exe() + " monitor --name " + seg + view);
  // Another frequency: other counts.
  std::string text = monitor_view_scene(120.0);
  text.replace(text.find("frequency = 12"), 14, "frequency = 13");
  write_file(scene, text);
  const auto recounted = run_command(spheretouch_exe() + " monitor --name " + seg + view);
  std::filesystem::remove(scene);
  const auto gone = run_command(spheretouch_exe() + " monitor --name " + seg + view);
  kill(run, SIGINT);
  CHECK(wait_for(run, 30) == 0);
  for (const CommandResult* r : {&moved, &recounted, &gone}) {
    INFO(r->output);
    CHECK(r->exit_code == 2);
    CHECK(contains(r->output, scene));
    CHECK_FALSE(contains(r->output, "view: http"));
  }
  CHECK(contains(moved.output, "the object has the run's 1442 vertices and 2880 faces but other coordinates or faces"));
  CHECK(contains(moved.output, "changed since the run started"));
  CHECK(contains(recounted.output, "the object has 1692 vertices and 3380 faces, the run's had 1442 and 2880"));
  CHECK(contains(recounted.output, "changed since the run started"));
}

TEST_CASE("monitor --view: frames forged in the segment are checked; bad ones are not sent, NaN goes out as 0") {
  mg_init_library(0);
  TempDir d;
  const std::string seg_name = "/spheretouch-test-monforge-" + std::to_string(getpid());
  write_file(d.file("scene.toml"), monitor_view_scene(10.0));
  const auto [probe, object] = monitor_meshes(d.file("scene.toml"));
  // This process plays the run: it created the segment and wrote the scene reference.
  auto seg = st::rt::ShmSegment::create(seg_name);
  REQUIRE(seg.ok());
  st::rt::ShmStatus& status = seg.value()->status();
  status.scene.store(st::engine::scene_ref(d.file("scene.toml"), probe, object));
  const int port = free_loopback_port(SOCK_STREAM);
  const pid_t mon = spawn_spheretouch(
      {"monitor", "--name", seg_name, "--view", "127.0.0.1:" + std::to_string(port), "--interval", "100"},
      d.file("mon.log"));
  REQUIRE(monitor_wait_log(d.file("mon.log"), "view: http://127.0.0.1:" + std::to_string(port) + "/", mon));
  ViewMessages msgs;
  char err[256] = "";
  mg_connection* ws = view_connect(port, msgs, err, st::test::view_token(slurp_file(d.file("mon.log"))));
  REQUIRE(ws != nullptr);
  auto received = [&](const std::function<bool(const std::string&)>& pred) {
    for (int i = 0; i < 3000; ++i) {
      {
        std::lock_guard<std::mutex> l(msgs.mu);
        for (std::size_t k = 1; k < msgs.binary.size(); ++k)
          if (pred(msgs.binary[k])) return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  };
  auto frame = std::make_unique<st::rt::ViewFrame>();
  // A count far beyond the frame, then object ids beyond the object: refused, not sent.
  frame->round = 5;
  frame->contacts = 4;
  frame->n_probe = 1;
  frame->n_object = 0xffffffffu;
  status.view.store(*frame);
  REQUIRE(monitor_wait_log(d.file("mon.log"), "view: a frame failed its checks", mon));
  frame->n_object = 3;
  frame->faces[0] = 0;
  frame->faces[1] = 5;
  frame->faces[2] = 6;
  frame->faces[3] = std::uint32_t(object.num_faces());
  status.view.store(*frame);
  // A good frame with NaN and infinite numbers: sent, the numbers as 0.
  frame->round = 7;
  frame->faces[3] = 7;
  frame->pose[3] = std::nan("");
  frame->penetration_mm = std::numeric_limits<double>::infinity();
  frame->flags = 0xffffffffu;
  status.view.store(*frame);
  CHECK(received([](const std::string& f) { return view_at<std::uint64_t>(f, 8) == 7; }));
  kill(mon, SIGTERM);
  const int rc = wait_for(mon, 30);
  mg_close_connection(ws);
  const std::string log = slurp_file(d.file("mon.log"));
  INFO(log);
  CHECK(rc == 0);
  CHECK(contains(log, "bad frames not sent"));
  std::lock_guard<std::mutex> l(msgs.mu);
  REQUIRE(msgs.binary.size() > 1);
  view_check_frames(msgs.binary, 1, std::uint32_t(probe.num_faces()), std::uint32_t(object.num_faces()));
  bool seen = false;
  for (std::size_t k = 1; k < msgs.binary.size(); ++k) {
    const std::string& f = msgs.binary[k];
    CHECK(view_at<std::uint64_t>(f, 8) != 5);  // the forged round never went out
    if (view_at<std::uint64_t>(f, 8) != 7) continue;
    seen = true;
    CHECK(view_at<double>(f, 16 + 8 * 3) == 0.0);  // pose[3]: NaN
    CHECK(view_at<double>(f, 160) == 0.0);         // penetration: inf
    CHECK(view_at<std::uint32_t>(f, 4) == 3);      // flags: known bits only
    CHECK(view_at<std::uint32_t>(f, 236) == 1);
    CHECK(view_at<std::uint32_t>(f, 240) == 3);
  }
  CHECK(seen);
  mg_exit_library();
}

TEST_CASE("monitor --view: a page that stops reading loses frames and gets cut off; another page keeps its rate") {
  mg_init_library(0);
  TempDir d;
  const std::string seg_name = "/spheretouch-test-monstall-" + std::to_string(getpid());
  std::string scene = monitor_view_scene(10.0);
  scene.replace(scene.find("frequency = 12"), 14, "frequency = 40");  // 32,000 faces: big frames
  write_file(d.file("scene.toml"), scene);
  const auto [probe, object] = monitor_meshes(d.file("scene.toml"));
  REQUIRE(object.num_faces() >= st::rt::kViewMaxFaces);
  auto seg = st::rt::ShmSegment::create(seg_name);
  REQUIRE(seg.ok());
  st::rt::ShmStatus& status = seg.value()->status();
  status.scene.store(st::engine::scene_ref(d.file("scene.toml"), probe, object));
  // The largest frame there is: every object face listed (~64 KiB a frame, 60 a second to each page).
  auto frame = std::make_unique<st::rt::ViewFrame>();
  frame->round = 1;
  frame->flags = st::rt::ViewFrame::kInContact;
  frame->n_probe = 0;
  frame->n_object = st::rt::kViewMaxFaces;
  for (std::uint32_t i = 0; i < st::rt::kViewMaxFaces; ++i) frame->faces[i] = i;
  frame->contacts = st::rt::kViewMaxFaces;
  status.view.store(*frame);
  const int port = free_loopback_port(SOCK_STREAM);
  const pid_t mon = spawn_spheretouch(
      {"monitor", "--name", seg_name, "--view", "127.0.0.1:" + std::to_string(port), "--interval", "100"},
      d.file("mon.log"));
  REQUIRE(monitor_wait_log(d.file("mon.log"), "view: http://127.0.0.1:" + std::to_string(port) + "/", mon));
  const std::string token = st::test::view_token(slurp_file(d.file("mon.log")));
  const std::string self = "127.0.0.1:" + std::to_string(port);
  // A page that reads the meshes and a few frames, then stops reading (its socket fills in a second).
  int stalled = -1;
  REQUIRE(st::test::view_raw(port, st::test::view_upgrade("?t=" + token, self, "http://" + self), &stalled, nullptr,
                             300) == 101);
  ViewMessages msgs;
  char err[256] = "";
  mg_connection* ws = view_connect(port, msgs, err, token);
  REQUIRE(ws != nullptr);
  std::this_thread::sleep_for(std::chrono::seconds(1));
  auto count = [&] {
    std::lock_guard<std::mutex> l(msgs.mu);
    const std::size_t n = msgs.binary.size();
    msgs.binary.clear();  // 4 MB a second: keep only the count
    return n;
  };
  count();
  std::this_thread::sleep_for(std::chrono::seconds(5));
  const std::size_t during = count();
  // The stalled page sends nothing either: after 10 s its connection is closed, its blocked write
  // fails, and it gets no more frames.
  std::this_thread::sleep_for(std::chrono::seconds(7));
  kill(mon, SIGTERM);
  const int rc = wait_for(mon, 30);
  mg_close_connection(ws);
  ::close(stalled);
  const std::string log = slurp_file(d.file("mon.log"));
  INFO(log);
  CHECK(rc == 0);
  CHECK(during > 5 * 60 / 2);  // at least half of 60 frames a second, while the other page stalls
  CHECK(contains(log, "frames dropped for slow pages"));
  const auto failed = log.find(" writes failed");
  REQUIRE(failed != std::string::npos);
  CHECK(log[failed - 1] != '0');  // the stalled page's write failed: it gets no more
  mg_exit_library();
}
