// SPDX-License-Identifier: BSD-3-Clause
// The live view (spheretouch run --view): the page and its scripts are served, the WebSocket
// stream carries the meshes and frames whose colliding faces match the run's contacts, a page's
// bad messages are refused without harm, and a real browser (Debian's headless Chromium) draws
// the colliding faces in red (a snapshot the page sends back, checked pixel by pixel).
#include <civetweb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <functional>
#include <fstream>
#include <mutex>
#include <sstream>

#include "app/process_util.hpp"
#include "app/view_client.hpp"
#include "doctest/doctest.h"
#include "test_util.hpp"

namespace {

using st::test::view_at;
using st::test::view_on_data;
using st::test::ViewMessages;

/// Starts a pressing run with --view on a free port; returns its pid once the view is up.
pid_t view_start_run(const st::test::TempDir& d, int port, double seconds, const std::string& object,
                     const std::string& device = "press_mm = 4.0\n") {
  const std::string scene = "[probe]\nbuiltin = \"capsule\"\nradius_mm = 8.0\nlength_mm = 40.0\n" + object +
                            "[workers]\ncount = 0\n[device]\n" + device +
                            "[output]\nstatus = \"off\"\nply = false\n[run]\nduration_s = " + std::to_string(seconds) +
                            "\n";
  st::test::write_file(d.file("scene.toml"), scene);
  const pid_t pid = st::test::spawn_spheretouch(
      {"run", d.file("scene.toml"), "--out", d.file("out"), "--view", "127.0.0.1:" + std::to_string(port)},
      d.file("run.log"));
  bool up = false;
  for (int i = 0; i < 3000 && !up; ++i) {
    up = st::test::contains(st::test::slurp_file(d.file("run.log")),
                            "view: http://127.0.0.1:" + std::to_string(port) + "/");
    if (!up) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  INFO(st::test::slurp_file(d.file("run.log")));
  REQUIRE(up);
  return pid;
}

/// Debian's Chromium, headless with software WebGL, on the view's page (its token) with `query`; its pid.
pid_t view_chromium(const st::test::TempDir& d, int port, const std::string& token, const std::string& query) {
  const pid_t browser = fork();
  REQUIRE(browser >= 0);
  if (browser == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (!std::freopen(d.file("chromium.log").c_str(), "a", stdout) || dup2(fileno(stdout), 2) < 0) _exit(120);
    const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/?t=" + token + "&" + query;
    const std::string user = "--user-data-dir=" + d.file("chromium-profile");
    execl("/usr/bin/chromium", "chromium", "--headless=new", "--no-sandbox", "--disable-gpu",
          "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--disable-quic", "--no-first-run",
          "--disable-background-networking", "--disable-component-update", "--disable-sync", "--window-size=800,600",
          "--remote-debugging-port=0", user.c_str(), url.c_str(), nullptr);
    _exit(121);
  }
  return browser;
}

/// GET path from the view; the body ("" on failure) and the status code.
std::pair<int, std::string> view_get(int port, const std::string& path) {
  char err[256] = "";
  mg_connection* c = mg_download("127.0.0.1", port, 0, err, sizeof err, "GET %s HTTP/1.0\r\nHost: 127.0.0.1:%d\r\n\r\n",
                                 path.c_str(), port);
  if (!c) return {0, err};
  const mg_response_info* ri = mg_get_response_info(c);
  const int code = ri ? ri->status_code : 0;
  std::string body;
  char buf[65536];
  for (int n; (n = mg_read(c, buf, sizeof buf)) > 0;) body.append(buf, std::size_t(n));
  mg_close_connection(c);
  return {code, body};
}

/// A run with --view (a long one: the simulated device repeats its press) and headless Chromium
/// on its page (`query`), until `done()` holds (polled every 50 ms, for at most 90 s, so that a
/// browser slow to start under load still gets its turn) and a second more (the page reports its
/// frame rate once a second); then the run is stopped by SIGINT. The run's log (its summary);
/// checks that the run ended well.
std::string view_run_with_browser(const st::test::TempDir& d, int port, const std::string& device,
                                  const std::string& query, const std::function<bool()>& done) {
  const pid_t pid =
      view_start_run(d, port, 120.0, "[object]\nbuiltin = \"icosphere\"\nradius_mm = 50.0\nfrequency = 24\n", device);
  const pid_t browser = view_chromium(d, port, st::test::view_token(st::test::slurp_file(d.file("run.log"))), query);
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(90);
  bool reached = false;
  while (!(reached = done()) && std::chrono::steady_clock::now() < until && waitpid(pid, nullptr, WNOHANG) == 0)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  if (reached) std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  kill(pid, SIGINT);
  const int rc = st::test::wait_for(pid, 30);
  kill(browser, SIGKILL);
  st::test::wait_for(browser, 10);
  const std::string log = st::test::slurp_file(d.file("run.log"));
  INFO(log);
  INFO(st::test::slurp_file(d.file("chromium.log")));
  CHECK(reached);
  CHECK(rc == 0);
  return log;
}

}  // namespace

TEST_CASE("run --view: the page and scripts are served; the stream carries the meshes and frames with the contacts") {
  mg_init_library(0);
  st::test::TempDir d;
  const int port = st::test::free_loopback_port(SOCK_STREAM);
  const pid_t pid =
      view_start_run(d, port, 4.0, "[object]\nbuiltin = \"icosphere\"\nradius_mm = 50.0\nfrequency = 12\n");

  const auto page = view_get(port, "/");
  CHECK(page.first == 200);
  CHECK(st::test::contains(page.second, "<script src=\"/view.js\">"));
  const auto js = view_get(port, "/view.js");
  CHECK(js.first == 200);
  CHECK(st::test::contains(js.second, "STVF"));
  const auto three = view_get(port, "/three.min.js");
  CHECK(three.first == 200);
  CHECK(three.second.size() > 100000);
  CHECK(view_get(port, "/../../etc/passwd").first == 404);
  CHECK(view_get(port, "/nothing").first == 404);

  ViewMessages msgs;
  char err[256] = "";
  const std::string token = st::test::view_token(st::test::slurp_file(d.file("run.log")));
  REQUIRE(token.size() == 32);
  mg_connection* ws = st::test::view_connect(port, msgs, err, token);
  INFO(err);
  REQUIRE(ws != nullptr);
  // A page's bad messages: refused, counted, and the stream goes on.
  const char junk_text[] = "not json at all";
  mg_websocket_client_write(ws, MG_WEBSOCKET_OPCODE_TEXT, junk_text, sizeof junk_text - 1);
  const std::string junk_bin(1000, '\x7f');
  mg_websocket_client_write(ws, MG_WEBSOCKET_OPCODE_BINARY, junk_bin.data(), junk_bin.size());
  // Read as JSON (not by searching for keys): the keys in a nested object, a number as a string
  // and a report that is not an object are refused; key order and spacing do not matter.
  for (const char* bad : {"{\"nested\": {\"fps\": 1, \"frames\": 2}}", "{\"fps\": \"30\", \"frames\": 2}", "[30, 2]"})
    mg_websocket_client_write(ws, MG_WEBSOCKET_OPCODE_TEXT, bad, std::strlen(bad));
  const char report[] = "{ \"red\": 3, \"frames\" : 17, \"fps\": 42.5 }";
  mg_websocket_client_write(ws, MG_WEBSOCKET_OPCODE_TEXT, report, sizeof report - 1);
  const int rc = st::test::wait_for(pid, 60);
  mg_close_connection(ws);
  const std::string log = st::test::slurp_file(d.file("run.log"));
  INFO(log);
  CHECK(rc == 0);

  std::lock_guard<std::mutex> l(msgs.mu);
  REQUIRE(msgs.binary.size() > 20);
  // The meshes first.
  const st::test::ViewMeshCounts m = st::test::view_mesh_counts(msgs.binary.front());
  CHECK(m.probe_faces > 0);
  CHECK(m.object_faces == 2880);  // icosphere, frequency 12: 20 · 12²
  // Then frames: face ids in range, distinct and ascending; contact seen, its faces listed.
  const st::test::ViewFrameCounts counts = st::test::view_check_frames(msgs.binary, 1, m.probe_faces, m.object_faces);
  const std::size_t frames = counts.frames, with_faces = counts.with_faces;
  CHECK(frames > 20);
  CHECK(with_faces > 5);
  CHECK(st::test::contains(log, "page drew 42.5 fps (last second; 17 frames in 0.0 s"));
  CHECK(st::test::contains(log, "5 bad messages refused"));
  mg_exit_library();
}

TEST_CASE(
    "run --view answers only its own page: another Host, Origin or no token gets a 403, one page too many a 503; a "
    "page that stops reading does not slow another") {
  mg_init_library(0);
  st::test::TempDir d;
  const int port = st::test::free_loopback_port(SOCK_STREAM);
  // A fine ball pressed again and again. (Its frames are small: over this test's seconds a page
  // that stops reading only fills the kernel's socket buffers, so its sender never blocks here;
  // that no write happens under the server's lock is by construction, view_server.cpp.)
  const pid_t pid =
      view_start_run(d, port, 14.0, "[object]\nbuiltin = \"icosphere\"\nradius_mm = 50.0\nfrequency = 40\n",
                     "press_mm = 4.0\nrepeat = true\n");
  const std::string token = st::test::view_token(st::test::slurp_file(d.file("run.log")));
  REQUIRE(token.size() == 32);
  const std::string self = "127.0.0.1:" + std::to_string(port);
  // DNS rebinding: a request naming another host (the attacker's name, resolving to us).
  CHECK(st::test::view_raw(port, "GET / HTTP/1.1\r\nHost: evil.example:" + std::to_string(port) + "\r\n\r\n") == 403);
  CHECK(st::test::view_raw(port, "GET / HTTP/1.1\r\n\r\n") == 403);  // no Host at all
  CHECK(st::test::view_raw(port, "GET / HTTP/1.1\r\nHost: " + self + "\r\n\r\n") == 200);
  CHECK(st::test::view_raw(port, "GET /view.js HTTP/1.1\r\nHost: localhost:" + std::to_string(port) + "\r\n\r\n") == 200);
  // The socket: no token, a wrong one, another site's page (cross-site WebSocket hijacking), another Host.
  CHECK(st::test::view_raw(port, st::test::view_upgrade("", self, "http://" + self)) == 403);
  CHECK(st::test::view_raw(port, st::test::view_upgrade("?t=" + std::string(32, '0'), self, "http://" + self)) == 403);
  std::string reply;
  CHECK(st::test::view_raw(port, st::test::view_upgrade("?t=" + token, self, "http://evil.example"), nullptr, &reply,
                           300) == 403);
  CHECK(st::test::contains(reply, "another origin"));
  CHECK(st::test::view_raw(port, st::test::view_upgrade("?t=" + token, "evil.example:" + std::to_string(port),
                                                        "http://evil.example:" + std::to_string(port))) == 403);

  // Its own page is taken; this one reads the meshes and frames for 1.5 s, then stops reading.
  int stalled = -1;
  REQUIRE(st::test::view_raw(port, st::test::view_upgrade("?t=" + token, self, "http://" + self), &stalled, nullptr,
                             1500) == 101);
  // A second page reads on: it must get frames at the view's rate while the first stalls.
  ViewMessages msgs;
  char err[256] = "";
  mg_connection* ws = st::test::view_connect(port, msgs, err, token);
  INFO(err);
  REQUIRE(ws != nullptr);
  std::this_thread::sleep_for(std::chrono::seconds(2));  // the stalled page's socket fills
  std::size_t before = 0;
  {
    std::lock_guard<std::mutex> l(msgs.mu);
    before = msgs.binary.size();
  }
  std::this_thread::sleep_for(std::chrono::seconds(4));
  std::size_t during = 0;
  {
    std::lock_guard<std::mutex> l(msgs.mu);
    during = msgs.binary.size() - before;
  }
  CHECK(during > 4 * 60 / 2);  // at least half the 60 frames a second over those 4 s
  // The page limit (4): two more pages are taken, the next gets a clear 503.
  int more[2] = {-1, -1};
  CHECK(st::test::view_raw(port, st::test::view_upgrade("?t=" + token, self, ""), &more[0]) == 101);
  CHECK(st::test::view_raw(port, st::test::view_upgrade("?t=" + token, self, ""), &more[1]) == 101);
  CHECK(st::test::view_raw(port, st::test::view_upgrade("?t=" + token, self, ""), nullptr, &reply, 300) == 503);
  CHECK(st::test::contains(reply, "already serves 4 pages"));
  const int rc = st::test::wait_for(pid, 60);
  mg_close_connection(ws);
  for (int fd : {stalled, more[0], more[1]}) ::close(fd);
  const std::string log = st::test::slurp_file(d.file("run.log"));
  INFO(log);
  CHECK(rc == 0);
  CHECK(st::test::contains(log, "refused: 6 forbidden (Host, Origin or token), 1 over the page limit"));
  mg_exit_library();
}

TEST_CASE(
    "run --view with a scene of several objects: the stream carries every object, placed, and each one's "
    "colliding faces") {
  mg_init_library(0);
  st::test::TempDir d;
  const int port = st::test::free_loopback_port(SOCK_STREAM);
  // The ball at the origin (the press lands on its top, the highest point of the scene), a box
  // whose top is level with it just beside the press (the capsule touches both), and a box far
  // away, turned 90 degrees about z.
  const pid_t pid =
      view_start_run(d, port, 4.0,
                     "[[object]]\nbuiltin = \"icosphere\"\nradius_mm = 50.0\nfrequency = 12\n"
                     "[[object]]\nname = \"beside\"\nbuiltin = \"box\"\nsize_mm = 20\nposition_mm = [12, "
                     "0, 40]\n"
                     "[[object]]\nname = \"far\"\nbuiltin = \"box\"\nsize_mm = 20\nposition_mm = [200, 0, "
                     "0]\nrotation_deg = [0, 0, 90]\n");
  ViewMessages msgs;
  char err[256] = "";
  mg_connection* ws =
      st::test::view_connect(port, msgs, err, st::test::view_token(st::test::slurp_file(d.file("run.log"))));
  INFO(err);
  REQUIRE(ws != nullptr);
  const int rc = st::test::wait_for(pid, 60);
  mg_close_connection(ws);
  INFO(st::test::slurp_file(d.file("run.log")));
  CHECK(rc == 0);
  std::lock_guard<std::mutex> l(msgs.mu);
  REQUIRE(msgs.binary.size() > 20);
  const st::test::ViewMeshCounts m = st::test::view_mesh_counts(msgs.binary.front());
  CHECK(m.object_faces == 2880);
  // The first object unplaced: no rotation.
  const double identity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  for (int i = 0; i < 9; ++i) CHECK(m.rotation[i] == identity[i]);
  REQUIRE(m.more.size() == 2);
  CHECK(m.more[0].faces == 12);
  CHECK(m.more[1].faces == 12);
  // Rows of [R | t]: the box beside, not turned; the far one Rz(90) = [[0, -1, 0], [1, 0, 0], [0, 0, 1]].
  const double beside[12] = {1, 0, 0, 12, 0, 1, 0, 0, 0, 0, 1, 40};
  const double far[12] = {0, -1, 0, 200, 1, 0, 0, 0, 0, 0, 1, 0};
  for (int i = 0; i < 12; ++i) {
    CHECK(m.more[0].place[i] == doctest::Approx(beside[i]).epsilon(1e-9));
    CHECK(m.more[1].place[i] == doctest::Approx(far[i]).epsilon(1e-9));
  }
  // Frames: object ids distinct and ascending below every object's faces; the ball's ids first,
  // then the box beside it offset by the ball's 2,880; the far box never touched.
  std::size_t frames = 0, both = 0;
  for (std::size_t i = 1; i < msgs.binary.size(); ++i) {
    const std::string& f = msgs.binary[i];
    REQUIRE(f.size() >= st::test::kFacesAt);
    ++frames;
    const std::uint32_t np = view_at<std::uint32_t>(f, 236), no = view_at<std::uint32_t>(f, 240);
    REQUIRE(f.size() == st::test::kFacesAt + 4 * std::size_t(np + no));
    bool ball = false, box = false;
    for (std::uint32_t k = 0; k < no; ++k) {
      const std::uint32_t id = view_at<std::uint32_t>(f, st::test::kFacesAt + 4 * (np + k));
      if (k > 0) CHECK(view_at<std::uint32_t>(f, st::test::kFacesAt + 4 * (np + k - 1)) < id);
      CHECK(id < 2880 + 12);  // the far box's ids (2,892 and up) never appear
      ball = ball || id < 2880;
      box = box || id >= 2880;
    }
    both += ball && box;
  }
  CHECK(frames > 20);
  CHECK(both > 5);  // pressed on the ball and the box beside it at once, both shown
  mg_exit_library();
}

TEST_CASE("run --view in headless Chromium: the page draws, reports its frame rate, and paints the contact red") {
  // The browser is not instrumented and the run under a sanitizer is covered by the stream test
  // above; the sanitizer suites skip the ~10 s this costs (CI time), the release suite runs it.
  if (st::test::kSanitizerBuild) return;
  mg_init_library(0);
  REQUIRE(std::filesystem::exists("/usr/bin/chromium"));  // scripts/setup.sh installs it
  st::test::TempDir d;
  const std::string png = d.file("out") + "/view.png";
  const std::string log =
      view_run_with_browser(d, st::test::free_loopback_port(SOCK_STREAM), "press_mm = 4.0\nrepeat = true\n",
                            "snapshot=1", [&] { return std::filesystem::exists(png); });
  INFO(log);
  CHECK(st::test::contains(log, "1 page(s)"));
  // The page's own frame count reached the server (whatever the rate; the rate is a benchmark).
  const auto at = log.find("page drew ");
  REQUIRE(at != std::string::npos);
  CHECK(std::strtod(log.c_str() + at + 10, nullptr) > 0);
  // Its snapshot, taken on a frame with colliding faces: red pixels where the contact is.
  REQUIRE(std::filesystem::exists(png));
  const char* root = std::getenv("ST_SOURCE_ROOT");
  const auto red = st::test::run_command("python3 " + std::string(root ? root : ".") + "/tests/app/png_red.py " + png);
  INFO(red.output);
  REQUIRE(red.exit_code == 0);
  CHECK(std::strtol(red.output.c_str(), nullptr, 10) > 20);  // red pixels (the page's red is #ff1a1a)
  mg_exit_library();
}

TEST_CASE("device kind browser: synthetic wheel events in headless Chromium press the probe into the object") {
  // The browser is not instrumented and the run under a sanitizer is covered by the stream test
  // above; the sanitizer suites skip the ~10 s this costs (CI time), the release suite runs it.
  if (st::test::kSanitizerBuild) return;
  mg_init_library(0);
  REQUIRE(std::filesystem::exists("/usr/bin/chromium"));
  st::test::TempDir d;
  // Watch the run's own stream (a second page) for the pressed contact.
  const int port = st::test::free_loopback_port(SOCK_STREAM);
  ViewMessages msgs;
  mg_connection* ws = nullptr;
  const auto pressed = [&] {
    char err[256] = "";
    if (!ws)
      ws = st::test::view_connect(port, msgs, err, st::test::view_token(st::test::slurp_file(d.file("run.log"))));
    std::lock_guard<std::mutex> l(msgs.mu);
    for (const std::string& f : msgs.binary)
      if (f.size() >= st::test::kFacesAt && f.compare(0, 4, "STVF") == 0 && view_at<double>(f, 160) > 1.5) return true;
    msgs.binary.clear();
    return false;
  };
  const std::string log = view_run_with_browser(d, port, "kind = \"browser\"\n", "drive=press", pressed);
  if (ws) mg_close_connection(ws);
  INFO(log);
  CHECK(st::test::contains(log, "the live view's page as the device"));
  const auto taken = log.find("browser device: ");
  REQUIRE(taken != std::string::npos);
  CHECK(std::strtol(log.c_str() + taken + 16, nullptr, 10) > 10);  // poses taken
  // The page pressed until it saw the contact, then 3 mm more: the run felt it.
  const auto pd = log.find("peak penetration ");
  REQUIRE(pd != std::string::npos);
  CHECK(std::strtod(log.c_str() + pd + 17, nullptr) > 1.0);
  const auto force = log.find("force           peak ");
  REQUIRE(force != std::string::npos);
  CHECK(std::strtod(log.c_str() + force + 21, nullptr) > 0.1);
  mg_exit_library();
}

TEST_CASE("run --view with a malformed address is refused before anything loads") {
  for (const char* bad : {"nonsense", "127.0.0.1:", ":8080", "127.0.0.1:99999", "127.0.0.1:80a"}) {
    CAPTURE(bad);
    const auto r = st::test::run_command(st::test::spheretouch_exe() + " run " +
                                         std::string(std::getenv("ST_SOURCE_ROOT") ? std::getenv("ST_SOURCE_ROOT") : ".") +
                                         "/configs/small.toml --duration 0.5 --view '" + bad + "'");
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(st::test::contains(r.output, "expected ADDR:PORT"));
    CHECK_FALSE(st::test::contains(r.output, "loading probe"));
  }
}

TEST_CASE("device kind browser without --view is refused, naming what to add") {
  st::test::TempDir d;
  st::test::write_file(d.file("scene.toml"),
                       "[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\ncount = 0\n"
                       "[device]\nkind = \"browser\"\n[output]\nstatus = \"off\"\n");
  const auto r = st::test::run_command(st::test::spheretouch_exe() + " run " + d.file("scene.toml") + " --out " +
                                       d.file("out") + " --duration 0.5");
  INFO(r.output);
  CHECK(r.exit_code == 2);
  CHECK(st::test::contains(r.output, "device.kind = \"browser\" is driven from the live view's page: add --view"));
}
