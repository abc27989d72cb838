// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/curve_keys.*: key pair files (modes whatever the umask, no overwrite without
// force, force ends 0600), and the readers (permissions, non-regular files, size, pairs that do
// not match, a secret key offered as a public one).
#include <doctest/doctest.h>

#include <algorithm>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include <spheretouch/net/curve_keys.hpp>
#include "test_util.hpp"

using namespace st;
using namespace st::net;

namespace {

mode_t mode_of(const std::string& path) {
  struct stat st {};
  REQUIRE(::stat(path.c_str(), &st) == 0);
  return st.st_mode & 07777;
}

bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Sets the umask for a scope.
struct Umask {
  mode_t old;
  explicit Umask(mode_t m) : old(::umask(m)) {}
  ~Umask() { ::umask(old); }
};

// The libzmq test vector (tests/test_security_curve.cpp): a secret key and its public key.
const std::string kSecret = "JTKVSB%%)wK0E.X)V>+}o?pNmC{O&4W4b!Ni{Lh6";
const std::string kPublic = "rq:rM>}U?@Lns47E1%kR.o@n%FcmmsL/@{H8]yf7";

}  // namespace

TEST_CASE("curve_public_of derives the public key; a fresh pair is consistent") {
  auto p = curve_public_of(kSecret);
  REQUIRE_MESSAGE(p.ok(), p.error());
  CHECK(p.value() == kPublic);
  auto k = generate_curve_key_pair();
  REQUIRE_MESSAGE(k.ok(), k.error());
  CHECK(curve_public_of(k.value().secret_z85).value() == k.value().public_z85);
  CHECK_FALSE(check_z85_key("short", "k").ok());
  CHECK(check_z85_key(kPublic, "k").ok());
}

TEST_CASE("key_files drops a trailing .key or .pub") {
  CHECK(key_files("dir/client").secret_file == "dir/client.key");
  CHECK(key_files("dir/client").public_file == "dir/client.pub");
  CHECK(key_files("dir/client.key").public_file == "dir/client.pub");
  CHECK(key_files("dir/client.pub").secret_file == "dir/client.key");
}

TEST_CASE("write_key_pair: .key is 0600 and .pub 0644 whatever the umask; the pair reads back") {
  st::test::TempDir dir;
  const auto k = generate_curve_key_pair().value();
  for (mode_t um : {mode_t(0), mode_t(022), mode_t(0777)}) {
    CAPTURE(um);
    const std::string prefix = dir.file(std::to_string(um) + "k");
    {
      Umask u(um);
      Status s = write_key_pair(prefix, k, false);
      REQUIRE_MESSAGE(s.ok(), s.error());
    }
    CHECK(mode_of(prefix + ".key") == 0600);
    CHECK(mode_of(prefix + ".pub") == 0644);
    CHECK(slurp(prefix + ".key") == k.secret_z85 + "\n");
    CHECK(slurp(prefix + ".pub") == k.public_z85 + "\n");
    auto pair = read_key_pair(prefix);
    REQUIRE_MESSAGE(pair.ok(), pair.error());
    CHECK(pair.value().secret_z85 == k.secret_z85);
    CHECK(pair.value().public_z85 == k.public_z85);
    CHECK(read_public_key(prefix + ".pub").value() == k.public_z85);
  }
}

TEST_CASE("write_key_pair refuses to overwrite without force; with force the new key is 0600") {
  st::test::TempDir dir;
  const std::string prefix = dir.file("fleet");
  const auto a = generate_curve_key_pair().value(), b = generate_curve_key_pair().value();
  REQUIRE(write_key_pair(prefix, a, false).ok());
  Status again = write_key_pair(prefix, b, false);
  REQUIRE_FALSE(again.ok());
  CHECK(has(again.error(), prefix + ".key"));
  CHECK(has(again.error(), "already exists"));
  CHECK(slurp(prefix + ".key") == a.secret_z85 + "\n");  // untouched
  CHECK(slurp(prefix + ".pub") == a.public_z85 + "\n");

  // Only the .pub exists: refused, and no lone .key is left behind.
  const std::string lone = dir.file("lone");
  st::test::write_file(lone + ".pub", a.public_z85 + "\n");
  Status l = write_key_pair(lone, b, false);
  REQUIRE_FALSE(l.ok());
  CHECK(has(l.error(), lone + ".pub"));
  CHECK_FALSE(std::filesystem::exists(lone + ".key"));

  // A symlink planted at the .key path is not followed.
  const std::string planted = dir.file("planted");
  std::filesystem::create_symlink(dir.file("elsewhere"), planted + ".key");
  CHECK_FALSE(write_key_pair(planted, b, false).ok());
  CHECK_FALSE(std::filesystem::exists(dir.file("elsewhere")));

  // --force over a key someone made world-readable: replaced, and 0600 again.
  ::chmod((prefix + ".key").c_str(), 0644);
  Status f = write_key_pair(prefix, b, true);
  REQUIRE_MESSAGE(f.ok(), f.error());
  CHECK(mode_of(prefix + ".key") == 0600);
  CHECK(mode_of(prefix + ".pub") == 0644);
  CHECK(slurp(prefix + ".key") == b.secret_z85 + "\n");
  CHECK(read_key_pair(prefix).value().public_z85 == b.public_z85);
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path))
    files += e.path().filename().string().rfind("fleet", 0) == 0;
  CHECK(files == 2);  // no temporaries left
  // A pair that does not belong together is never written.
  CHECK_FALSE(write_key_pair(dir.file("mixed"), {a.public_z85, b.secret_z85}, false).ok());
}

TEST_CASE("read_secret_key refuses group/world access, non-regular files, big and empty files; reads the first line") {
  st::test::TempDir dir;
  const std::string f = dir.file("k");
  st::test::write_file(f, "  " + kSecret + " \r\nsecond line ignored\n");
  for (mode_t m : {0644, 0640, 0604, 0620, 0602}) {
    CAPTURE(m);
    ::chmod(f.c_str(), m);
    auto r = read_secret_key(f);
    REQUIRE_FALSE(r.ok());
    CHECK(has(r.error(), f));
    CHECK(has(r.error(), "chmod 600"));
  }
  ::chmod(f.c_str(), 0600);
  auto k = read_secret_key(f);
  REQUIRE_MESSAGE(k.ok(), k.error());
  CHECK(k.value() == kSecret);
  ::chmod(f.c_str(), 0400);
  CHECK(read_secret_key(f).ok());

  CHECK(has(read_secret_key(dir.path.string()).error(), "not a regular file"));
  const std::string fifo = dir.file("fifo");
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  CHECK(has(read_secret_key(fifo).error(), "not a regular file"));  // and does not hang
  CHECK(has(read_secret_key(dir.file("missing")).error(), "cannot open"));

  const std::string big = dir.file("big");
  st::test::write_file(big, kSecret + "\n" + std::string(10000, 'x'));
  ::chmod(big.c_str(), 0600);
  CHECK(has(read_secret_key(big).error(), "too big"));
  const std::string empty = dir.file("empty");
  st::test::write_file(empty, "\n");
  ::chmod(empty.c_str(), 0600);
  CHECK(has(read_secret_key(empty).error(), "empty"));
  const std::string bad = dir.file("bad");
  st::test::write_file(bad, "not a key\n");
  ::chmod(bad.c_str(), 0600);
  CHECK(has(read_secret_key(bad).error(), "Z85"));
}

TEST_CASE("read_public_key refuses a secret key file; read_key_pair checks that .key and .pub belong together") {
  st::test::TempDir dir;
  const std::string prefix = dir.file("c");
  st::test::write_file(prefix + ".key", kSecret + "\n");
  ::chmod((prefix + ".key").c_str(), 0600);
  CHECK(has(read_public_key(prefix + ".key").error(), "not a secret key file"));
  // Without .pub the public key is derived.
  auto p = read_key_pair(prefix);
  REQUIRE_MESSAGE(p.ok(), p.error());
  CHECK(p.value().public_z85 == kPublic);
  CHECK(read_key_pair(prefix + ".key").ok());
  // A .pub of another pair is an error naming both files.
  st::test::write_file(prefix + ".pub", generate_curve_key_pair().value().public_z85 + "\n");
  auto m = read_key_pair(prefix);
  REQUIRE_FALSE(m.ok());
  CHECK(has(m.error(), prefix + ".pub: does not match " + prefix + ".key"));
  st::test::write_file(prefix + ".pub", kPublic + "\n");
  CHECK(read_key_pair(prefix).ok());
  // A group-readable .key is refused here too.
  ::chmod((prefix + ".key").c_str(), 0640);
  CHECK(has(read_key_pair(prefix).error(), "chmod 600"));
}

TEST_CASE("$CREDENTIALS_DIRECTORY is expanded in key paths") {
  st::test::TempDir dir;
  st::test::write_file(dir.file("worker.key"), kSecret + "\n");
  ::chmod(dir.file("worker.key").c_str(), 0600);
  ::unsetenv("CREDENTIALS_DIRECTORY");
  CHECK(has(read_secret_key("$CREDENTIALS_DIRECTORY/worker.key").error(), "LoadCredential"));
  ::setenv("CREDENTIALS_DIRECTORY", dir.path.c_str(), 1);
  auto k = read_secret_key("$CREDENTIALS_DIRECTORY/worker.key");
  ::unsetenv("CREDENTIALS_DIRECTORY");
  REQUIRE_MESSAGE(k.ok(), k.error());
  CHECK(k.value() == kSecret);
}

TEST_CASE("wipe_secret zeroes a key's characters in place and empties the string") {
  CurveKeyPair k = generate_curve_key_pair().value();
  std::string& s = k.secret_z85;
  REQUIRE(s.size() == 40);
  const char* buf = s.data();  // clear() keeps the buffer: its bytes can be read afterwards
  wipe_secret(s);
  CHECK(s.empty());
  CHECK(s.data() == buf);
  CHECK(std::all_of(buf, buf + 40, [](char c) { return c == 0; }));
}
