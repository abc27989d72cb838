// SPDX-License-Identifier: BSD-3-Clause
// Tests `spheretouch keygen` (src/app/cmd_keygen.cpp) and the client side of CURVE in the app
// (src/spheretouch/engine/distributed.*, query/run --server-key/--client-key, scene [workers] keys) with real
// processes: a spheretouch-worker daemon with a CURVE config on a free tcp loopback port.
#include <sys/stat.h>

#include <chrono>
#include <filesystem>

#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/primitives.hpp>
#include "app/query_meshes.hpp"
#include <spheretouch/net/curve_keys.hpp>
#include <spheretouch/rt/udp_device.hpp>
#include "net/process_util.hpp"
#include "net/old_worker.hpp"
#include "test_util.hpp"

using namespace st;
using st::test::contains;
using st::test::run_command;
using st::test::spheretouch_exe;
using namespace std::chrono_literals;

namespace {

mode_t mode_of(const std::string& path) {
  struct stat st {};
  REQUIRE(::stat(path.c_str(), &st) == 0);
  return st.st_mode & 07777;
}

std::string first_line(const std::string& path) {
  std::ifstream in(path);
  std::string l;
  std::getline(in, l);
  return l;
}

/// Runs `spheretouch keygen --out PREFIX` and checks it worked.
void keygen(const std::string& prefix) {
  const auto r = run_command(spheretouch_exe() + " keygen --out " + prefix);
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
}

/// query_test.cpp's small meshes and poses, queried without the tree cache.
struct Meshes : st::test::QueryMeshes {
  std::string query(const std::string& extra) const {
    return spheretouch_exe() + " query " + probe + " " + object + " --poses " + poses + " --no-cache " + extra;
  }
};

/// A worker daemon with CURVE on 127.0.0.1:<free port>: the fleet's pair and one allowed client
/// (given as a public key file), made with `spheretouch keygen`, in `dir`.
struct CurveWorker {
  st::test::TempDir dir;
  int port = st::test::free_port();
  std::string endpoint = "tcp://127.0.0.1:" + std::to_string(port);
  std::string fleet = dir.file("fleet"), client = dir.file("client"), log = dir.file("worker.log");
  std::unique_ptr<st::test::Process> proc;

  CurveWorker() {
    keygen(fleet);
    keygen(client);
    // Paths relative to the config's directory: the daemon starts in the test's cwd.
    st::test::write_file(dir.file("worker.toml"),
                         "bind = \"" + endpoint +
                             "\"\nlog_level = \"debug\"\n[curve]\nsecret_key_file = \"fleet.key\"\n"
                             "allowed_clients_files = [\"client.pub\"]\n");
  }
  void start() {
    proc = std::make_unique<st::test::Process>(
        std::vector<std::string>{st::test::worker_binary(), "--config", dir.file("worker.toml")}, log);
    // Ready once it logs the bind (or it died: the caller's checks say why).
    for (int i = 0; i < 500 && !contains(proc->log(), "listening on"); ++i) {
      if (proc->wait(0ms) != -1) break;
      std::this_thread::sleep_for(10ms);
    }
    INFO(proc->log());
    REQUIRE(contains(proc->log(), "listening on " + endpoint));
  }
  std::string keys(const std::string& client_prefix) const {
    return "--connect " + endpoint + " --server-key " + fleet + ".pub --client-key " + client_prefix;
  }
};

}  // namespace

TEST_CASE("keygen --out writes a 0600 .key and a .pub, refuses to overwrite, --force replaces; the pair loads") {
  st::test::TempDir d;
  const std::string prefix = d.file("fleet");
  auto r = run_command(spheretouch_exe() + " keygen --out " + prefix);
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  CHECK(mode_of(prefix + ".key") == 0600);
  CHECK(mode_of(prefix + ".pub") == 0644);
  const std::string pub = first_line(prefix + ".pub");
  CHECK(pub.size() == 40);
  CHECK(contains(r.output, prefix + ".key"));
  CHECK(contains(r.output, prefix + ".pub"));
  CHECK(contains(r.output, "public key: " + pub));
  CHECK_FALSE(contains(r.output, first_line(prefix + ".key")));  // the secret is never printed
  auto pair = net::read_key_pair(prefix);
  REQUIRE_MESSAGE(pair.ok(), pair.error());
  CHECK(pair.value().public_z85 == pub);

  const std::string secret = first_line(prefix + ".key");
  r = run_command(spheretouch_exe() + " keygen --out " + prefix);
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, prefix + ".key: already exists"));
  CHECK(first_line(prefix + ".key") == secret);

  ::chmod((prefix + ".key").c_str(), 0644);
  r = run_command(spheretouch_exe() + " keygen --out " + prefix + ".key --force");  // a .key suffix names the same pair
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  CHECK(mode_of(prefix + ".key") == 0600);
  CHECK(first_line(prefix + ".key") != secret);
  CHECK(net::read_key_pair(prefix).ok());

  // The worker's --keygen --out is the same code and format.
  const std::string w = d.file("worker");
  r = run_command(st::test::worker_binary() + " --keygen --out " + w);
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  CHECK(mode_of(w + ".key") == 0600);
  CHECK(net::read_key_pair(w).value().public_z85 == first_line(w + ".pub"));
  CHECK(run_command(st::test::worker_binary() + " --keygen --out " + w).exit_code == 2);
  CHECK(run_command(spheretouch_exe() + " keygen").exit_code != 0);  // --out is required
}

TEST_CASE("keygen --bridge writes a 0600 bridge key that the bridge reads; it refuses to overwrite without --force") {
  st::test::TempDir d;
  const std::string path = d.file("bridge.key");
  auto r = run_command(spheretouch_exe() + " keygen --bridge --out " + path);
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  CHECK(mode_of(path) == 0600);
  const std::string line = first_line(path);
  CHECK(line.size() == 64);
  CHECK(line.find_first_not_of("0123456789abcdef") == std::string::npos);
  CHECK_FALSE(contains(r.output, line));  // the secret is never printed
  REQUIRE(st::rt::read_bridge_key(path).ok());
  r = run_command(spheretouch_exe() + " keygen --bridge --out " + path);
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, path + ": already exists"));
  CHECK(first_line(path) == line);
  r = run_command(spheretouch_exe() + " keygen --bridge --force --out " + path);
  REQUIRE(r.exit_code == 0);
  CHECK(first_line(path) != line);
  CHECK(mode_of(path) == 0600);
}

TEST_CASE("a worker whose secret key file is group-readable refuses to start, naming the file") {
  CurveWorker w;
  ::chmod((w.fleet + ".key").c_str(), 0640);
  st::test::Process p({st::test::worker_binary(), "--config", w.dir.file("worker.toml")}, w.log);
  const int st = p.wait(10s);
  REQUIRE(st != -1);
  CHECK(WIFEXITED(st));
  CHECK(WEXITSTATUS(st) == 2);
  INFO(p.log());
  CHECK(contains(p.log(), w.fleet + ".key"));
  CHECK(contains(p.log(), "chmod 600"));
  CHECK_FALSE(contains(p.log(), "listening"));
}

TEST_CASE("query --connect to a CURVE worker: an allowed client gets the single-process pairs") {
  Meshes m;
  CurveWorker w;
  w.start();
  const auto single = run_command(m.query(""));
  REQUIRE(single.exit_code == 0);
  CHECK_FALSE(contains(single.output, "pose 1 pairs 0 "));  // pressed in: there are pairs
  const auto r = run_command(m.query(w.keys(w.client)));
  INFO(r.output.substr(0, 400));
  CHECK(r.exit_code == 0);
  CHECK(r.output == single.output);
  CHECK_FALSE(contains(w.proc->log(), "refused"));
  // The keys are needed: without them the worker gives no service (a security mismatch).
  const auto plain = run_command(m.query("--connect " + w.endpoint));
  INFO(plain.output);
  CHECK(plain.exit_code == 2);
  CHECK(contains(plain.output, "worker " + w.endpoint + " did not answer Hello"));
  CHECK(contains(plain.output, "CURVE"));
}

TEST_CASE(
    "query --connect with an unknown client key: no service, a clear error naming the endpoint, the refusal logged") {
  Meshes m;
  CurveWorker w;
  w.start();
  const std::string rogue = w.dir.file("rogue");
  keygen(rogue);
  const std::string rogue_pub = first_line(rogue + ".pub");
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = run_command(m.query(w.keys(rogue)));
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  INFO(r.output);
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "worker " + w.endpoint + " did not answer Hello within 2 s"));
  CHECK(contains(r.output, "refused this client's CURVE key"));
  CHECK(contains(r.output, rogue_pub));  // what to add to allowed_clients
  CHECK(contains(r.output, "allowed_clients"));
  CHECK_FALSE(contains(r.output, "pose 0"));  // no service
  CHECK(secs < 15);                           // fails fast, well before the 30 s ready timeout
  INFO(w.proc->log());
  CHECK(contains(w.proc->log(), "refused CURVE client " + rogue_pub + " from 127.0.0.1"));
  CHECK(w.proc->wait(0ms) == -1);  // the worker is still serving
  // The allowed client is still served afterwards.
  CHECK(run_command(m.query(w.keys(w.client) + " --count-only")).exit_code == 0);
}

TEST_CASE("the client side refuses a group-readable client key, a .key given as server key, and half a key pair") {
  Meshes m;
  CurveWorker w;  // keys only: the errors come before any connection
  ::chmod((w.client + ".key").c_str(), 0640);
  auto r = run_command(m.query(w.keys(w.client)));
  INFO(r.output);
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "--client-key: " + w.client + ".key"));
  CHECK(contains(r.output, "chmod 600"));
  ::chmod((w.client + ".key").c_str(), 0600);

  r = run_command(m.query("--connect " + w.endpoint + " --server-key " + w.fleet + ".key --client-key " + w.client));
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "--server-key: " + w.fleet + ".key: expected a public key file"));
  r = run_command(m.query("--connect " + w.endpoint + " --server-key " + w.fleet + ".pub"));
  CHECK(r.exit_code != 0);  // --server-key needs --client-key (CLI11)
  r = run_command(m.query("--server-key " + w.fleet + ".pub --client-key " + w.client));
  CHECK(r.exit_code != 0);  // and both need --connect
}

TEST_CASE(
    "run with [workers] server_key and client_key (relative to the scene) reaches a CURVE worker; --client-key "
    "overrides") {
  CurveWorker w;
  w.start();
  const std::string scene = w.dir.file("scene.toml");
  st::test::write_file(scene,
                       "[probe]\nbuiltin = \"capsule\"\nradius_mm = 6.0\nlength_mm = 30.0\n"
                       "[object]\nbuiltin = \"icosphere\"\nradius_mm = 40.0\nfrequency = 12\n"
                       "[workers]\nendpoints = [\"" +
                           w.endpoint +
                           "\"]\nserver_key = \"fleet.pub\"\n"
                           "client_key = \"client\"\ndeadline_ms = 500\n"
                           "[output]\nstatus = \"off\"\ntrace = false\nperfetto = false\nply = false\n"
                           "[run]\nduration_s = 0.5\n");
  auto r = run_command(spheretouch_exe() + " run " + scene + " --out " + w.dir.file("run1"));
  INFO(r.output);
  CHECK(r.exit_code == 0);
  CHECK(contains(r.output, "1 worker daemon"));
  CHECK_FALSE(contains(w.proc->log(), "refused"));

  const std::string rogue = w.dir.file("rogue");
  keygen(rogue);
  r = run_command(spheretouch_exe() + " run " + scene + " --client-key " + rogue + " --out " + w.dir.file("run2"));
  INFO(r.output);
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "worker " + w.endpoint + " did not answer Hello"));
  CHECK(contains(r.output, first_line(rogue + ".pub")));
  CHECK(contains(w.proc->log(), "refused CURVE client " + first_line(rogue + ".pub")));

  // Keys without daemons are a mistake, said as such.
  st::test::write_file(w.dir.file("inproc.toml"),
                       "[probe]\nbuiltin = \"capsule\"\n[object]\nbuiltin = \"box\"\n[workers]\ncount = 1\n"
                       "server_key = \"fleet.pub\"\nclient_key = \"client\"\n");
  r = run_command(spheretouch_exe() + " run " + w.dir.file("inproc.toml") + " --out " + w.dir.file("run3"));
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "are for worker daemons"));
}

TEST_CASE("query --connect to a worker of another protocol version: the error says it cannot read it, and why") {
  Meshes m;
  zmq::context_t ctx;
  test::OldVersionWorker old(ctx);
  const std::string ep = old.endpoint();
  const auto r = run_command(m.query("--connect " + ep));
  INFO(r.output);
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "worker " + ep + " answers with messages this client cannot read"));
  CHECK(contains(r.output, "version: 1 not supported (this build speaks " + std::to_string(st::net::kVersion) + ")"));
  CHECK(contains(r.output, "Upgrade the daemons and the clients together"));
}
