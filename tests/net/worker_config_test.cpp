// Tests src/net/worker_config.*: TOML parsing (unknown keys named), and the safe-by-default bind policy.
#include <doctest/doctest.h>

#include <sys/stat.h>

#include "net/worker_config.hpp"
#include "test_util.hpp"

using namespace st::net;

TEST_CASE("a full config parses; the command line's defaults stay for keys not given") {
  auto c = parse_daemon_config(R"(
bind = "tcp://127.0.0.1:6000"
worker_id = 5
log_level = "debug"
max_sets = 4
max_blockset_mb = 256
)", "w.toml");
  REQUIRE_MESSAGE(c.ok(), c.error());
  CHECK(c.value().bind == "tcp://127.0.0.1:6000");
  CHECK(c.value().worker_id == 5);
  CHECK(c.value().log_level == "debug");
  CHECK(c.value().max_sets == 4);
  CHECK(c.value().max_blockset_mb == 256);
  CHECK_FALSE(c.value().insecure);
  CHECK(check_daemon_config(c.value()).ok());
}

TEST_CASE("unknown keys, wrong types and bad values are errors naming the key and the line") {
  auto e = [](const char* text) {
    auto c = parse_daemon_config(text, "w.toml");
    REQUIRE_FALSE(c.ok());
    return c.error();
  };
  CHECK(e("bind = \"tcp://127.0.0.1:1\"\nbnid = 3\n").find("w.toml:2: unknown key 'bnid'") != std::string::npos);
  CHECK(e("worker_id = \"3\"\n").find("worker_id: expected an integer") != std::string::npos);
  CHECK(e("worker_id = -1\n").find("outside") != std::string::npos);
  CHECK(e("insecure = 1\n").find("insecure") != std::string::npos);
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
  CHECK(check_daemon_config(c).error().find("allowed_clients is empty") != std::string::npos);
  c.curve_allowed_clients = {"not a key"};
  CHECK(check_daemon_config(c).error().find("Z85") != std::string::npos);
  c.curve_allowed_clients = {k40};
  CHECK(check_daemon_config(c).ok());
  DaemonConfig d;
  d.curve_allowed_clients = {k40};
  CHECK_FALSE(check_daemon_config(d).ok());
}

TEST_CASE("read_secret_key refuses world-readable files and reads the first line") {
  st::test::TempDir dir;
  const std::string f = dir.file("k");
  st::test::write_file(f, "JTKVSB%%)wK0E.X)V>+}o?pNmC{O&4W4b!Ni{Lh6\n");  // libzmq test vector secret key
  ::chmod(f.c_str(), 0644);
  CHECK(read_secret_key(f).error().find("chmod 600") != std::string::npos);
  ::chmod(f.c_str(), 0600);
  auto k = read_secret_key(f);
  REQUIRE_MESSAGE(k.ok(), k.error());
  CHECK(k.value() == "JTKVSB%%)wK0E.X)V>+}o?pNmC{O&4W4b!Ni{Lh6");
}
