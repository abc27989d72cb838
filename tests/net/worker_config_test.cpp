// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/worker_config.*: TOML parsing (unknown keys named), and the safe-by-default bind policy.
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <doctest/doctest.h>

#include <filesystem>

#include <spheretouch/net/worker_config.hpp>
#include "test_util.hpp"

using namespace st::net;

TEST_CASE("a full config parses; the command line's defaults stay for keys not given") {
  auto c = parse_daemon_config(R"(
bind = "tcp://127.0.0.1:6000"
worker_id = 5
log_level = "debug"
max_sets = 4
max_blockset_mb = 256
coherent = false
)",
                               "w.toml");
  REQUIRE_MESSAGE(c.ok(), c.error());
  CHECK(c.value().bind == "tcp://127.0.0.1:6000");
  CHECK(c.value().worker_id == 5);
  CHECK(c.value().log_level == "debug");
  CHECK(c.value().max_sets == 4);
  CHECK(c.value().max_blockset_mb == 256);
  CHECK_FALSE(c.value().coherent);
  CHECK(DefaultDaemonConfig().coherent);
  CHECK_FALSE(c.value().insecure);
  CHECK(check_daemon_config(c.value()).ok());
}

TEST_CASE("unknown keys, wrong types and bad values are errors naming the key and the line") {
  auto e = [](const char* text) {
    auto c = parse_daemon_config(text, "w.toml");
    REQUIRE_FALSE(c.ok());
    return c.error();
  };
  CHECK(e("bind = \"tcp://127.0.0.1:1\"\nbnid = 3\n").find("w.toml:2: unknown key 'bnid' (known: bind, coherent, curve,") !=
        std::string::npos);
  CHECK(e("worker_id = \"3\"\n").find("worker_id: expected an integer") != std::string::npos);
  CHECK(e("worker_id = -1\n").find("worker_id: expected a value in [0, 1048576] (found -1)") != std::string::npos);
  CHECK(e("insecure = 1\n").find("insecure") != std::string::npos);
  CHECK(e("coherent = \"no\"\n").find("coherent: expected true or false") != std::string::npos);
  CHECK(e("[curve]\nsecret = \"x\"\n").find("unknown key 'curve.secret'") != std::string::npos);
  CHECK(e("bind = \n").find("w.toml:1") != std::string::npos);  // TOML syntax error, with its line
}

TEST_CASE("loopback detection") {
  for (const char* ok : {"tcp://127.0.0.1:5", "tcp://127.1.2.3:5", "tcp://localhost:5", "tcp://[::1]:5",
                         "ipc:///run/x.sock", "inproc://w"})
    CHECK_MESSAGE(is_local_endpoint(ok), ok);
  for (const char* no : {"tcp://0.0.0.0:5", "tcp://*:5", "tcp://10.0.0.1:5", "tcp://eth0:5", "tcp://128.0.0.1:5",
                         "tcp://127.0.0.1.evil.com:5", "tcp://127.0.0.1;10.0.0.1:5", "pgm://x", "tcp://127.0.0.1"})
    CHECK_FALSE_MESSAGE(is_local_endpoint(no), no);
}

TEST_CASE("a non-loopback bind needs --insecure; CURVE is refused until implemented; log_level is checked") {
  DaemonConfig c;
  c.bind = "tcp://0.0.0.0:5555";
  auto s = check_daemon_config(c);
  REQUIRE_FALSE(s.ok());
  CHECK(s.error().find("0.0.0.0") != std::string::npos);
  CHECK(s.error().find("--insecure") != std::string::npos);
  c.insecure = true;
  CHECK(check_daemon_config(c).ok());
  c.curve_secret_key_file = "/etc/k";
  CHECK_FALSE(check_daemon_config(c).ok());
  DaemonConfig d;
  d.log_level = "loud";
  CHECK_FALSE(check_daemon_config(d).ok());
  d = DaemonConfig{};
  d.bind = "udp://127.0.0.1:5";
  CHECK_FALSE(check_daemon_config(d).ok());
}

TEST_CASE("CURVE config: a secret key file needs allowed clients with valid keys; then a network bind is allowed") {
  const std::string k40 = "Yne@$w-vo<fVvi]a<NY6T1ed:M$fCG*[IaLV{hID";  // the libzmq test vector public key
  DaemonConfig c;
  c.bind = "tcp://0.0.0.0:5555";
  c.curve_secret_key_file = "/etc/spheretouch/worker.key";
  CHECK(check_daemon_config(c).error().find("allowed_clients and allowed_clients_files are empty") != std::string::npos);
  c.curve_allowed_clients = {"not a key"};
  CHECK(check_daemon_config(c).error().find("Z85") != std::string::npos);
  c.curve_allowed_clients = {k40};
  CHECK(check_daemon_config(c).ok());
  DaemonConfig d;
  d.curve_allowed_clients = {k40};
  CHECK_FALSE(check_daemon_config(d).ok());
}

TEST_CASE("allowed_clients_files: parsed, resolved against the config's directory, read as public key files") {
  st::test::TempDir dir;
  const std::string k40 = "Yne@$w-vo<fVvi]a<NY6T1ed:M$fCG*[IaLV{hID";
  const std::string other = "rq:rM>}U?@Lns47E1%kR.o@n%FcmmsL/@{H8]yf7";
  std::filesystem::create_directories(dir.file("clients"));
  st::test::write_file(dir.file("clients/alice.pub"), other + "\n");
  st::test::write_file(dir.file("w.toml"), "[curve]\nsecret_key_file = \"fleet.key\"\nallowed_clients = ['" + k40 +
                                               "']\nallowed_clients_files = [\"clients/alice.pub\"]\n");
  auto c = load_daemon_config(dir.file("w.toml"));
  REQUIRE_MESSAGE(c.ok(), c.error());
  CHECK(c.value().curve_secret_key_file == dir.file("fleet.key"));
  REQUIRE(c.value().curve_allowed_clients_files.size() == 1);
  CHECK(c.value().curve_allowed_clients_files[0] == dir.file("clients/alice.pub"));
  CHECK(check_daemon_config(c.value()).ok());
  auto keys = allowed_client_keys(c.value());
  REQUIRE_MESSAGE(keys.ok(), keys.error());
  CHECK(keys.value() == std::vector<std::string>{k40, other});

  // Files alone are enough; a missing or malformed file is an error naming it.
  DaemonConfig d;
  d.curve_secret_key_file = "/etc/k";
  d.curve_allowed_clients_files = {dir.file("clients/bob.pub")};
  CHECK(check_daemon_config(d).ok());
  auto missing = allowed_client_keys(d);
  REQUIRE_FALSE(missing.ok());
  CHECK(missing.error().find("allowed_clients_files: " + dir.file("clients/bob.pub")) != std::string::npos);
  d.curve_allowed_clients_files = {dir.file("fleet.key")};
  CHECK(allowed_client_keys(d).error().find("not a secret key file") != std::string::npos);
  d.curve_secret_key_file.clear();
  CHECK_FALSE(check_daemon_config(d).ok());  // clients without a server key

  auto bad = parse_daemon_config("[curve]\nallowed_clients_files = \"x.pub\"\n", "w.toml");
  REQUIRE_FALSE(bad.ok());
  CHECK(bad.error().find("w.toml:2: curve.allowed_clients_files: expected an array") != std::string::npos);
}

TEST_CASE("ipc: CURVE is allowed over ipc://; ipc_allowed_uids is parsed and checked") {
  const std::string k40 = "Yne@$w-vo<fVvi]a<NY6T1ed:M$fCG*[IaLV{hID";
  DaemonConfig c;
  c.bind = "ipc:///run/spheretouch/w.sock";
  c.curve_secret_key_file = "/etc/spheretouch/worker.key";
  c.curve_allowed_clients = {k40};
  CHECK(check_daemon_config(c).ok());
  auto p = parse_daemon_config("ipc_allowed_uids = [1000, 1001]\n", "w.toml");
  REQUIRE(p.ok());
  CHECK(p.value().ipc_allowed_uids == std::vector<std::uint32_t>{1000, 1001});
  auto bad = parse_daemon_config("ipc_allowed_uids = [\"root\"]\n", "w.toml");
  REQUIRE_FALSE(bad.ok());
  CHECK(bad.error().find("w.toml:1: ipc_allowed_uids: expected an integer") != std::string::npos);
  CHECK_FALSE(parse_daemon_config("ipc_allowed_uids = 5\n", "w.toml").ok());
}

TEST_CASE("a worker config that is /dev/zero, a FIFO or a directory is refused before it is read") {
  auto z = load_daemon_config("/dev/zero");
  REQUIRE_FALSE(z.ok());
  CHECK(z.error() == "/dev/zero: not a regular file (a worker config is a text file)");
  const std::string fifo = "/tmp/st_worker_config_fifo_" + std::to_string(::getpid());
  std::remove(fifo.c_str());
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  auto f = load_daemon_config(fifo);  // would hang reading a FIFO nobody writes
  std::remove(fifo.c_str());
  REQUIRE_FALSE(f.ok());
  CHECK(f.error().find("not a regular file") != std::string::npos);
  auto d = load_daemon_config("/tmp");
  REQUIRE_FALSE(d.ok());
  CHECK(d.error() == "/tmp: is a directory, not a worker config");
}
