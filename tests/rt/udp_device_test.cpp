// SPDX-License-Identifier: BSD-3-Clause
// The UDP device bridge: the wire format (every refusal), and a live UdpDevice on loopback fed by
// a driver socket: poses taken, forces echoed, the peer latched, stale/malformed/foreign datagrams
// counted and dropped, silence faded out and back in without a step, floods survived.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <sys/stat.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>
#include <vector>

#include "doctest/doctest.h"
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/udp_device.hpp>

namespace {

using st::rt::BridgeKey;
using st::rt::ForcePacket;
using st::rt::PosePacket;
using st::rt::PoseReject;

/// The key the tests' bridges and drivers share.
BridgeKey udp_test_key(std::uint8_t salt = 0) {
  BridgeKey k;
  for (std::size_t i = 0; i < k.size(); ++i) k[i] = std::uint8_t(i * 7 + 1 + salt);
  return k;
}

std::vector<std::uint8_t> udp_pose_bytes(const PosePacket& p, const BridgeKey* key) {
  std::vector<std::uint8_t> b(st::rt::kPoseBytes);
  b.resize(st::rt::encode_pose(p, key, b.data()));
  return b;
}

/// A driver's socket on loopback, sending to the device's port: version 2 signed with `key`
/// (the test key by default), or version 1 (legacy).
struct UdpDriver {
  int fd = -1;
  sockaddr_in to{};
  std::uint16_t version = st::rt::kBridgeVersion;
  std::uint64_t session = 0x5e55'1011'0000'0001ull;
  BridgeKey key = udp_test_key();
  bool sign = true;
  explicit UdpDriver(const std::string& device_addr) {
    fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    const auto colon = device_addr.rfind(':');
    to.sin_family = AF_INET;
    to.sin_port = htons(std::uint16_t(std::stoi(device_addr.substr(colon + 1))));
    inet_pton(AF_INET, device_addr.substr(0, colon).c_str(), &to.sin_addr);
  }
  ~UdpDriver() { ::close(fd); }
  void send(const std::vector<std::uint8_t>& b) const {
    ::sendto(fd, b.data(), b.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  }
  void send_pose(std::uint64_t seq, std::array<double, 3> tip, std::array<double, 4> q = {1, 0, 0, 0}) const {
    PosePacket p;
    p.version = version;
    p.session = session;
    p.seq = seq;
    p.device_ns = std::int64_t(1000 + seq);
    p.tip = tip;
    p.q = q;
    send(udp_pose_bytes(p, sign ? &key : nullptr));
  }
  /// The next datagram within timeout_ms (empty if none).
  std::vector<std::uint8_t> recv(int timeout_ms = 2000) const {
    pollfd pf{fd, POLLIN, 0};
    if (::poll(&pf, 1, timeout_ms) <= 0) return {};
    std::vector<std::uint8_t> b(256);
    const ssize_t n = ::recv(fd, b.data(), b.size(), 0);
    b.resize(n > 0 ? std::size_t(n) : 0);
    return b;
  }
  /// The next force datagram within timeout_ms (checked under the key); false if none.
  bool recv_force(ForcePacket& f, int timeout_ms = 2000) const {
    const std::vector<std::uint8_t> b = recv(timeout_ms);
    return !b.empty() && st::rt::decode_force(b.data(), b.size(), sign ? &key : nullptr, f);
  }
};

/// A bridge on a free loopback port with the test key.
st::rt::UdpDeviceConfig udp_test_config() {
  st::rt::UdpDeviceConfig c;
  c.bind = "127.0.0.1:0";
  c.key = udp_test_key();
  return c;
}

/// Calls read_pose until it delivers a pose whose translation is near `x` (the receiver thread
/// runs on its own); false after 2 s.
bool udp_wait_pose(st::rt::UdpDevice& d, const Eigen::Vector3d& x, Eigen::Isometry3d& pose) {
  for (int i = 0; i < 2000; ++i) {
    if (d.read_pose(st::rt::now_ns(), pose) && (pose.translation() - x).norm() < 1e-9) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return false;
}

bool udp_wait_count(const std::atomic<std::uint64_t>& c, std::uint64_t n) {
  for (int i = 0; i < 2000 && c.load() < n; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  return c.load() >= n;
}

}  // namespace

TEST_CASE("udp bridge wire format: a pose round-trips; every kind of bad datagram is refused with its reason") {
  const BridgeKey key = udp_test_key();
  PosePacket p;
  p.buttons = 3;
  p.session = 0xfeedull;
  p.seq = 0x0102030405060708ull;
  p.device_ns = -42;
  p.tip = {1.5, -2.25, 1e5};
  p.q = {0.5, 0.5, 0.5, 0.5};
  std::vector<std::uint8_t> b = udp_pose_bytes(p, &key);
  REQUIRE(b.size() == st::rt::kPoseBytes);
  CHECK(std::string(b.begin(), b.begin() + 4) == "STHP");
  CHECK(b[4] == 2);
  CHECK(b[16] == 0x08);  // little-endian
  PosePacket out;
  REQUIRE(st::rt::decode_pose(b.data(), b.size(), 1e6, &key, out) == PoseReject::kOk);
  CHECK(out.version == 2);
  CHECK(out.buttons == 3);
  CHECK(out.session == 0xfeedull);
  CHECK(out.seq == p.seq);
  CHECK(out.device_ns == -42);
  CHECK(out.tip == p.tip);
  CHECK(out.q == p.q);

  // Authentication: any changed byte, another key, or no tag at all is refused.
  for (std::size_t i : {std::size_t(6), std::size_t(16), std::size_t(40), std::size_t(87), std::size_t(100)}) {
    std::vector<std::uint8_t> forged = b;
    forged[i] ^= 1;
    CAPTURE(i);
    CHECK(st::rt::decode_pose(forged.data(), forged.size(), 1e6, &key, out) == PoseReject::kAuth);
  }
  const BridgeKey other = udp_test_key(1);
  CHECK(st::rt::decode_pose(b.data(), b.size(), 1e6, &other, out) == PoseReject::kAuth);
  const std::vector<std::uint8_t> untagged = udp_pose_bytes(p, nullptr);
  CHECK(st::rt::decode_pose(untagged.data(), untagged.size(), 1e6, &key, out) == PoseReject::kAuth);
  // Without a key (auth = "none") the tag is not looked at.
  CHECK(st::rt::decode_pose(untagged.data(), untagged.size(), 1e6, nullptr, out) == PoseReject::kOk);

  // Version 1: 80 bytes, no session and no tag; refused where a key is required.
  PosePacket v1 = p;
  v1.version = 1;
  const std::vector<std::uint8_t> b1 = udp_pose_bytes(v1, &key);
  REQUIRE(b1.size() == st::rt::kPoseBytesV1);
  CHECK(st::rt::decode_pose(b1.data(), b1.size(), 1e6, &key, out) == PoseReject::kLegacy);
  REQUIRE(st::rt::decode_pose(b1.data(), b1.size(), 1e6, nullptr, out) == PoseReject::kOk);
  CHECK(out.version == 1);
  CHECK(out.session == 0);
  CHECK(out.seq == p.seq);
  CHECK(out.tip == p.tip);

  CHECK(st::rt::decode_pose(b.data(), 119, 1e6, &key, out) == PoseReject::kSize);
  CHECK(st::rt::decode_pose(b.data(), 3, 1e6, &key, out) == PoseReject::kSize);
  std::vector<std::uint8_t> longer = b;
  longer.push_back(0);
  CHECK(st::rt::decode_pose(longer.data(), longer.size(), 1e6, &key, out) == PoseReject::kSize);
  std::vector<std::uint8_t> bad = b;
  bad[3] = 'F';
  CHECK(st::rt::decode_pose(bad.data(), bad.size(), 1e6, &key, out) == PoseReject::kMagic);
  bad = b;
  bad[4] = 3;
  CHECK(st::rt::decode_pose(bad.data(), bad.size(), 1e6, &key, out) == PoseReject::kVersion);
  auto decode = [&](const PosePacket& pk) {
    const std::vector<std::uint8_t> e = udp_pose_bytes(pk, &key);
    return st::rt::decode_pose(e.data(), e.size(), 1e6, &key, out);
  };
  PosePacket q = p;
  q.tip[1] = std::nan("");
  CHECK(decode(q) == PoseReject::kNonFinite);
  q = p;
  q.q[2] = INFINITY;
  CHECK(decode(q) == PoseReject::kNonFinite);
  q = p;
  q.tip[0] = 2e6;
  CHECK(decode(q) == PoseReject::kRange);
  q = p;
  q.q = {1.01, 0, 0, 0};
  CHECK(decode(q) == PoseReject::kQuaternion);
  q.q = {0, 0, 0, 0};
  CHECK(decode(q) == PoseReject::kQuaternion);
  q.q = {1.0005, 0, 0, 0};  // within 1e-3: accepted and normalised
  REQUIRE(decode(q) == PoseReject::kOk);
  CHECK(out.q[0] == doctest::Approx(1.0).epsilon(1e-15));

  ForcePacket f;
  f.flags = st::rt::kForceFading;
  f.session = 0xfeedull;
  f.seq = 7;
  f.pose_seq = 9;
  f.pose_device_ns = 123456789;
  f.servo_ns = 987654321;
  f.force = {0.1, -0.2, 3.5};
  f.torque = {0.01, 0.02, -0.03};
  std::uint8_t fb[st::rt::kForceBytes];
  REQUIRE(st::rt::encode_force(f, &key, fb) == st::rt::kForceBytes);
  ForcePacket g;
  REQUIRE(st::rt::decode_force(fb, sizeof fb, &key, g));
  CHECK(g.version == 2);
  CHECK(g.flags == f.flags);
  CHECK(g.session == 0xfeedull);
  CHECK(g.seq == 7);
  CHECK(g.pose_seq == 9);
  CHECK(g.pose_device_ns == 123456789);
  CHECK(g.servo_ns == 987654321);
  CHECK(g.force == f.force);
  CHECK(g.torque == f.torque);
  CHECK_FALSE(st::rt::decode_force(fb, 127, &key, g));
  CHECK_FALSE(st::rt::decode_force(fb, sizeof fb, &other, g));  // a forged force never reaches the hand
  fb[50] ^= 4;
  CHECK_FALSE(st::rt::decode_force(fb, sizeof fb, &key, g));
  // Version 1 force: what a legacy driver gets (no torque).
  ForcePacket f1 = f;
  f1.version = 1;
  REQUIRE(st::rt::encode_force(f1, nullptr, fb) == st::rt::kForceBytesV1);
  REQUIRE(st::rt::decode_force(fb, st::rt::kForceBytesV1, nullptr, g));
  CHECK(g.version == 1);
  CHECK(g.force == f.force);
  CHECK(g.torque == std::array<double, 3>{0, 0, 0});
  CHECK(g.pose_device_ns == 123456789);
  CHECK(g.servo_ns == 987654321);

  std::uint8_t rb[st::rt::kRefusalBytes];
  st::rt::encode_refusal(st::rt::BridgeRefusal::kRefusedVersion, 0, rb);
  st::rt::BridgeRefusal why{};
  std::uint64_t session = 1;
  REQUIRE(st::rt::decode_refusal(rb, sizeof rb, why, session));
  CHECK(why == st::rt::BridgeRefusal::kRefusedVersion);
  CHECK(session == 0);
  CHECK(std::string(reinterpret_cast<const char*>(rb + 16)).find("version 1 refused") == 0);
  CHECK(st::rt::kRefusalBytes <= st::rt::kPoseBytesV1);  // never more than the datagram it answers
}

TEST_CASE("udp bridge keys: written 0600, read back; a bad key file is refused naming the file and what was expected") {
  const std::string dir = "/tmp/st_bridge_key_test_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/bridge.key";
  std::filesystem::remove(path);
  auto k = st::rt::random_bridge_key();
  REQUIRE(k);
  CHECK(k.value() != st::rt::random_bridge_key().value());
  REQUIRE(st::rt::write_bridge_key(path, k.value(), false));
  CHECK((std::filesystem::status(path).permissions() & std::filesystem::perms::all) ==
        (std::filesystem::perms::owner_read | std::filesystem::perms::owner_write));
  auto back = st::rt::read_bridge_key(path);
  REQUIRE(back);
  CHECK(back.value() == k.value());
  auto again = st::rt::write_bridge_key(path, k.value(), false);
  REQUIRE_FALSE(again);
  CHECK(again.error().find("already exists") != std::string::npos);
  const BridgeKey k2 = udp_test_key();
  REQUIRE(st::rt::write_bridge_key(path, k2, true));  // replace
  CHECK(st::rt::read_bridge_key(path).value() == k2);

  auto expect_refused = [&](const std::string& content, const char* what, unsigned mode = 0600) {
    std::filesystem::remove(path);
    { std::ofstream(path) << content; }
    std::filesystem::permissions(path, std::filesystem::perms(mode));
    auto r = st::rt::read_bridge_key(path);
    CAPTURE(content);
    REQUIRE_FALSE(r);
    CHECK(r.error().find(path) != std::string::npos);
    CHECK(r.error().find(what) != std::string::npos);
  };
  expect_refused("abc\n", "64 hexadecimal digits");
  expect_refused(std::string(64, 'g') + "\n", "64 hexadecimal digits");
  expect_refused(std::string(65, 'a') + "\n", "64 hexadecimal digits");
  expect_refused(std::string(64, 'a') + "\n", "group or others", 0644);
  expect_refused(std::string(5000, 'a'), "-byte limit for a bridge key");
  std::filesystem::remove(path);
  auto missing = st::rt::read_bridge_key(path);
  REQUIRE_FALSE(missing);
  CHECK(missing.error().find("cannot open") != std::string::npos);
  REQUIRE(::mkfifo(path.c_str(), 0600) == 0);  // a FIFO neither hangs nor is taken
  auto fifo = st::rt::read_bridge_key(path);
  REQUIRE_FALSE(fifo);
  CHECK(fifo.error().find("not a regular file") != std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST_CASE("udp bridge: bad settings are refused naming the field") {
  const Eigen::Isometry3d grip = Eigen::Isometry3d::Identity();
  st::rt::UdpDeviceConfig c;
  c.bind = "127.0.0.1";
  auto r = st::rt::UdpDevice::open(c, grip);
  REQUIRE_FALSE(r);
  CHECK(r.error().find("device.bind") != std::string::npos);
  CHECK(r.error().find("HOST:PORT") != std::string::npos);
  c.bind = "127.0.0.1:99999";
  r = st::rt::UdpDevice::open(c, grip);
  REQUIRE_FALSE(r);
  CHECK(r.error().find("port") != std::string::npos);
  c.bind = "127.0.0.1:0";
  c.peer = "nowhere";
  r = st::rt::UdpDevice::open(c, grip);
  REQUIRE_FALSE(r);
  CHECK(r.error().find("device.peer") != std::string::npos);
  // A port in use.
  c.peer = "";
  auto first = st::rt::UdpDevice::open(c, grip);
  REQUIRE(first);
  c.bind = first.value()->address();
  r = st::rt::UdpDevice::open(c, grip);
  REQUIRE_FALSE(r);
  CHECK(r.error().find("cannot bind") != std::string::npos);
}

TEST_CASE("udp bridge: poses become probe poses, forces come back echoing the pose, refusals are counted") {
  st::rt::UdpDeviceConfig c = udp_test_config();
  c.scale = 2;
  c.offset_mm = {10, 0, -5};
  c.max_force_N = 4;
  c.silence_ms = 1000;  // real time below: a loaded machine must not make the driver look silent
  c.session_timeout_ms = 1000;
  Eigen::Isometry3d grip = Eigen::Isometry3d::Identity();
  grip.translate(Eigen::Vector3d(0, 0, -3));  // the fingertip 3 mm above the probe's origin
  auto dev_r = st::rt::UdpDevice::open(c, grip);
  REQUIRE(dev_r);
  st::rt::UdpDevice& dev = *dev_r.value();
  CHECK(dev.max_force_N() == 4);
  UdpDriver drv(dev.address());

  Eigen::Isometry3d pose;
  CHECK_FALSE(dev.read_pose(st::rt::now_ns(), pose));             // no driver yet
  dev.command_force(st::rt::now_ns(), Eigen::Vector3d(1, 0, 0));  // nobody to send to
  CHECK(dev.stats().forces.load() == 0);

  // A 90° turn about z: the probe's origin (3 mm below the tip along the probe's z) goes with it.
  const double h = std::sqrt(0.5);
  drv.send_pose(1, {1, 2, 3}, {h, 0, 0, h});
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d(12, 4, 1 - 3), pose));
  CHECK((pose.linear() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm() < 1e-12);
  CHECK((pose * Eigen::Vector3d(0, 0, 3) - Eigen::Vector3d(12, 4, 1)).norm() < 1e-12);  // the tip

  // The force echoes the pose (it fades in from zero over fade_ms: timed in the next case).
  const std::int64_t t0 = st::rt::now_ns();
  dev.read_pose(t0, pose);
  dev.command_force(t0, Eigen::Vector3d(0, 0, 2));
  ForcePacket f;
  REQUIRE(drv.recv_force(f));
  CHECK(f.pose_seq == 1);
  CHECK(f.pose_device_ns == 1001);
  CHECK(f.seq == 1);
  CHECK(f.force[2] <= 2);
  for (int k = 1; k <= 10; ++k) {  // 10 ticks of 1 ms with fresh poses
    drv.send_pose(1 + k, {1, 2, 3});
    REQUIRE(udp_wait_count(dev.stats().poses, std::uint64_t(1 + k)));
  }
  double last = f.force[2];
  for (int k = 1; k <= 60; ++k) {  // simulated ticks, 1 ms apart, within silence_ms of the last pose
    const std::int64_t t = st::rt::now_ns();
    dev.read_pose(t, pose);
    dev.command_force(t, Eigen::Vector3d(0, 0, 2));
    REQUIRE(drv.recv_force(f));
    CHECK(f.force[2] >= last);  // never a step down while the driver talks
    CHECK(f.force[2] <= 2);
    last = f.force[2];
    std::this_thread::sleep_for(std::chrono::microseconds(200));
    drv.send_pose(20 + k, {1, 2, 3});
  }
  CHECK(f.pose_seq >= 11);
  REQUIRE(udp_wait_count(dev.stats().poses, 71));  // seq 1, 2-11, 21-80: every one arrived

  // Refusals: a stale sequence number, garbage, a NaN pose, a second driver.
  const std::uint64_t poses_before = dev.stats().poses.load();
  drv.send_pose(5, {0, 0, 0});
  REQUIRE(udp_wait_count(dev.stats().stale, 1));
  drv.send(std::vector<std::uint8_t>(17, 0xab));
  REQUIRE(udp_wait_count(dev.stats().malformed, 1));
  drv.send_pose(1000, {std::nan(""), 0, 0});
  REQUIRE(udp_wait_count(dev.stats().malformed, 2));
  CHECK(PoseReject(dev.stats().last_reject.load()) == PoseReject::kNonFinite);
  UdpDriver other(dev.address());  // another program with the key, while the driver's session is live
  other.session = 2;
  other.send_pose(2000, {50, 50, 50});
  REQUIRE(udp_wait_count(dev.stats().busy, 1));
  CHECK(dev.stats().poses.load() == poses_before);
  REQUIRE(dev.read_pose(st::rt::now_ns(), pose));
  CHECK((pose * Eigen::Vector3d(0, 0, 3) - Eigen::Vector3d(12, 4, 1)).norm() < 1e-12);  // still the last good pose
  CHECK(dev.summary().find("1 stale") != std::string::npos);
  CHECK(dev.summary().find("1 busy") != std::string::npos);
  CHECK(dev.summary().find("1 sessions") != std::string::npos);

  // A non-finite force is never passed on.
  dev.command_force(st::rt::now_ns(), Eigen::Vector3d(std::nan(""), 1, 0));
  REQUIRE(drv.recv_force(f));
  CHECK(std::isfinite(f.force[0]));
  CHECK(f.force[0] == 0);
}

TEST_CASE("udp bridge: a silent driver's force fades to zero and fades back in when it returns") {
  st::rt::UdpDeviceConfig c = udp_test_config();
  c.silence_ms = 200;  // long enough that a loaded machine's delay before t0 leaves it fresh at first
  c.fade_ms = 50;
  auto dev_r = st::rt::UdpDevice::open(c, Eigen::Isometry3d::Identity());
  REQUIRE(dev_r);
  st::rt::UdpDevice& dev = *dev_r.value();
  UdpDriver drv(dev.address());
  drv.send_pose(1, {0, 0, 0});
  Eigen::Isometry3d pose;
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d::Zero(), pose));
  // Simulated ticks from now: the pose stays fresh until 200 ms after its arrival, so the gain
  // climbs to 1 at 1/50 per ms, then falls 1/50 per ms once the driver has been silent 200 ms.
  const std::int64_t t0 = st::rt::now_ns();
  ForcePacket f;
  double prev = 0, peak = 0, at_end = -1;
  for (int ms = 0; ms <= 400; ++ms) {
    const std::int64_t t = t0 + std::int64_t(ms) * 1000000;
    REQUIRE(dev.read_pose(t, pose));  // the last pose is held
    dev.command_force(t, Eigen::Vector3d(1, 0, 0));
    REQUIRE(drv.recv_force(f));
    if (ms > 0) CHECK(std::abs(f.force[0] - prev) <= 1.0 / 50 + 1e-9);  // at most 1/fade_ms per ms: no step
    prev = f.force[0];
    peak = std::max(peak, prev);
    at_end = prev;
  }
  CHECK(peak == doctest::Approx(1.0));
  CHECK(at_end == 0);
  CHECK((f.flags & st::rt::kForceFading) != 0);
  CHECK(dev.stats().fades.load() == 1);
  // Back: the force rises again from zero, by at most 1/fade_ms per ms.
  drv.send_pose(2, {0, 0, 0});
  REQUIRE(udp_wait_count(dev.stats().poses, 2));
  const std::int64_t t1 = st::rt::now_ns();
  prev = 0;
  for (int ms = 0; ms <= 10; ++ms) {
    const std::int64_t t = t1 + std::int64_t(ms) * 1000000;
    dev.read_pose(t, pose);
    dev.command_force(t, Eigen::Vector3d(1, 0, 0));
    REQUIRE(drv.recv_force(f));
    if (ms > 0) CHECK(f.force[0] - prev <= 1.0 / 50 + 1e-9);
    if (ms == 0) CHECK(f.force[0] < 0.5);  // from zero: only the time since the last tick's step
    prev = f.force[0];
  }
  CHECK(prev > 0);
  CHECK(f.pose_seq == 2);
}

TEST_CASE("udp bridge: a flood of garbage is counted and the next valid pose still arrives") {
  st::rt::UdpDeviceConfig c = udp_test_config();
  auto dev_r = st::rt::UdpDevice::open(c, Eigen::Isometry3d::Identity());
  REQUIRE(dev_r);
  st::rt::UdpDevice& dev = *dev_r.value();
  UdpDriver drv(dev.address());
  std::vector<std::uint8_t> junk(80);
  for (int i = 0; i < 20000; ++i) {
    for (std::size_t k = 0; k < junk.size(); ++k) junk[k] = std::uint8_t(i * 31 + k * 7);
    drv.send(junk);
  }
  std::vector<std::uint8_t> big(1400, 0x55);
  for (int i = 0; i < 100; ++i) drv.send(big);
  REQUIRE(udp_wait_count(dev.stats().malformed, 1));
  // Wait until the receiver has drained the socket (the count stops growing), then drive.
  for (std::uint64_t seen = 0; seen != dev.stats().malformed.load();) {
    seen = dev.stats().malformed.load();
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  drv.send_pose(1, {4, 5, 6});
  Eigen::Isometry3d pose;
  CHECK(udp_wait_pose(dev, Eigen::Vector3d(4, 5, 6), pose));
  CHECK(dev.stats().poses.load() == 1);
  CHECK(dev.stats().malformed.load() >= 1);
}

TEST_CASE("udp bridge: a pinned peer is the only driver taken, even when another sends first") {
  UdpDriver probe_port("127.0.0.1:9");  // a bound socket, to learn a free port for the pinned driver
  sockaddr_in self{};
  self.sin_family = AF_INET;
  inet_pton(AF_INET, "127.0.0.1", &self.sin_addr);
  REQUIRE(::bind(probe_port.fd, reinterpret_cast<sockaddr*>(&self), sizeof self) == 0);
  socklen_t len = sizeof self;
  getsockname(probe_port.fd, reinterpret_cast<sockaddr*>(&self), &len);
  st::rt::UdpDeviceConfig c = udp_test_config();
  c.peer = "127.0.0.1:" + std::to_string(ntohs(self.sin_port));
  auto dev_r = st::rt::UdpDevice::open(c, Eigen::Isometry3d::Identity());
  REQUIRE(dev_r);
  st::rt::UdpDevice& dev = *dev_r.value();
  UdpDriver pinned(dev.address());
  std::swap(pinned.fd, probe_port.fd);  // the bound socket drives
  UdpDriver other(dev.address());
  other.send_pose(1, {7, 7, 7});
  REQUIRE(udp_wait_count(dev.stats().foreign, 1));
  pinned.send_pose(1, {1, 2, 3});
  Eigen::Isometry3d pose;
  CHECK(udp_wait_pose(dev, Eigen::Vector3d(1, 2, 3), pose));
  CHECK(dev.stats().poses.load() == 1);
}

TEST_CASE(
    "udp bridge: a forged, unsigned or version-1 datagram moves nothing and gets a refusal; a huge sequence number "
    "cannot lock the driver out") {
  st::rt::UdpDeviceConfig c = udp_test_config();
  c.silence_ms = 1000;
  c.session_timeout_ms = 1000;
  auto dev_r = st::rt::UdpDevice::open(c, Eigen::Isometry3d::Identity());
  REQUIRE(dev_r);
  st::rt::UdpDevice& dev = *dev_r.value();
  UdpDriver drv(dev.address());
  drv.send_pose(1, {0, 0, 10});
  Eigen::Isometry3d pose;
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d(0, 0, 10), pose));

  // From the driver's own socket (what a forged source address amounts to): a wrong key, no tag,
  // the legacy version. Each is counted, answered with a refusal, and the pose stays.
  auto refusal_of = [&](const UdpDriver& d) {
    for (int i = 0; i < 50; ++i) {
      const std::vector<std::uint8_t> b = d.recv(100);
      st::rt::BridgeRefusal why{};
      std::uint64_t session = 0;
      if (!b.empty() && st::rt::decode_refusal(b.data(), b.size(), why, session)) return why;
    }
    return st::rt::BridgeRefusal{};
  };
  UdpDriver forger(dev.address());
  std::swap(forger.fd, drv.fd);  // same address and port as the driver
  forger.key = udp_test_key(9);
  forger.send_pose(2, {0, 0, -40});
  REQUIRE(udp_wait_count(dev.stats().unauthenticated, 1));
  CHECK(refusal_of(forger) == st::rt::BridgeRefusal::kBadTag);
  std::this_thread::sleep_for(std::chrono::milliseconds(110));  // refusals: at most one per 100 ms
  forger.sign = false;
  forger.send_pose(3, {0, 0, -40});
  REQUIRE(udp_wait_count(dev.stats().unauthenticated, 2));
  CHECK(refusal_of(forger) == st::rt::BridgeRefusal::kBadTag);
  std::this_thread::sleep_for(std::chrono::milliseconds(110));
  forger.version = 1;
  forger.send_pose(4, {0, 0, -40});
  REQUIRE(udp_wait_count(dev.stats().old_version, 1));
  CHECK(refusal_of(forger) == st::rt::BridgeRefusal::kRefusedVersion);
  std::swap(forger.fd, drv.fd);
  REQUIRE(dev.read_pose(st::rt::now_ns(), pose));
  CHECK((pose.translation() - Eigen::Vector3d(0, 0, 10)).norm() < 1e-12);
  CHECK(dev.stats().poses.load() == 1);

  // A sequence number of 2^64 - 1 (even signed: a driver bug) is a jump, refused; the driver's
  // next real pose still counts.
  drv.send_pose(~std::uint64_t{0}, {0, 0, 9});
  REQUIRE(udp_wait_count(dev.stats().jumps, 1));
  drv.send_pose(2, {0, 0, 8});
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d(0, 0, 8), pose));
  drv.send_pose(2 + c.max_seq_jump, {0, 0, 7});  // the largest jump allowed
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d(0, 0, 7), pose));
  CHECK(dev.stats().jumps.load() == 1);
  CHECK(dev.stats().refusals_sent.load() >= 2);
}

TEST_CASE(
    "udp bridge: a restarted driver (a new session) is taken once the old one is silent; an old session never again") {
  st::rt::UdpDeviceConfig c = udp_test_config();
  c.silence_ms = 50;
  c.session_timeout_ms = 300;
  auto dev_r = st::rt::UdpDevice::open(c, Eigen::Isometry3d::Identity());
  REQUIRE(dev_r);
  st::rt::UdpDevice& dev = *dev_r.value();
  UdpDriver first(dev.address());
  first.session = 11;
  first.send_pose(1, {1, 0, 0});
  Eigen::Isometry3d pose;
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d(1, 0, 0), pose));
  // The driver restarts (a new socket, a new session, its count from 1) at once: busy.
  UdpDriver second(dev.address());
  second.session = 22;
  second.send_pose(1, {1, 1, 0});
  REQUIRE(udp_wait_count(dev.stats().busy, 1));
  std::vector<std::uint8_t> r = second.recv();
  st::rt::BridgeRefusal why{};
  std::uint64_t refused_session = 0;
  REQUIRE(st::rt::decode_refusal(r.data(), r.size(), why, refused_session));
  CHECK(why == st::rt::BridgeRefusal::kBusy);
  CHECK(refused_session == 22);
  // After session_timeout_ms of silence it is taken, and gets forces.
  std::this_thread::sleep_for(std::chrono::milliseconds(350));
  second.send_pose(2, {1, 1, 0});
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d(1, 1, 0), pose));
  CHECK(dev.stats().sessions.load() == 2);
  dev.command_force(st::rt::now_ns(), Eigen::Vector3d(0.1, 0, 0));
  ForcePacket f;
  REQUIRE(second.recv_force(f));
  CHECK(f.session == 22);
  CHECK(f.pose_seq == 2);
  // The first session's poses, replayed after the second went silent, are never taken again.
  std::this_thread::sleep_for(std::chrono::milliseconds(350));
  first.send_pose(500, {5, 5, 5});
  REQUIRE(udp_wait_count(dev.stats().stale, 1));
  REQUIRE(dev.read_pose(st::rt::now_ns(), pose));
  CHECK((pose.translation() - Eigen::Vector3d(1, 1, 0)).norm() < 1e-12);
}

TEST_CASE(
    "udp bridge: slew limits turn a pose jump, a turn and a force step into ramps; the torque is sent only by a 6-DOF "
    "device") {
  st::rt::UdpDeviceConfig c = udp_test_config();
  c.silence_ms = 10000;
  c.session_timeout_ms = 10000;
  c.fade_ms = 1e-6;  // the gain is 1 from the second tick on: the slew limit alone shapes the force
  c.max_pose_step_mm = 2;
  c.max_rotation_step_deg = 5;
  c.max_force_step_N = 0.5;
  c.max_torque_step_Nm = 0.05;
  c.max_torque_Nm = 1;
  auto dev_r = st::rt::UdpDevice::open(c, Eigen::Isometry3d::Identity());
  REQUIRE(dev_r);
  st::rt::UdpDevice& dev = *dev_r.value();
  CHECK(dev.max_torque_Nm() == 1);
  UdpDriver drv(dev.address());
  drv.send_pose(1, {0, 0, 0});
  Eigen::Isometry3d pose;
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d::Zero(), pose));  // the first pose is taken as it is
  // A 9 mm jump with a 20° turn about z: 2 mm and 5° a tick, then there.
  const double h = std::cos(10 * M_PI / 180), sz = std::sin(10 * M_PI / 180);
  drv.send_pose(2, {0, 0, -9}, {h, 0, 0, sz});
  REQUIRE(udp_wait_count(dev.stats().poses, 2));
  std::vector<double> z, turn;
  for (int k = 0; k < 6; ++k) {
    REQUIRE(dev.read_pose(st::rt::now_ns(), pose));
    z.push_back(pose.translation().z());
    turn.push_back(Eigen::AngleAxisd(pose.linear()).angle() * 180 / M_PI);
  }
  CHECK(z[0] == doctest::Approx(-2));
  CHECK(z[3] == doctest::Approx(-8));
  CHECK(z[4] == doctest::Approx(-9));
  CHECK(turn[0] == doctest::Approx(5));
  CHECK(turn[2] == doctest::Approx(15));
  CHECK(turn[4] == doctest::Approx(20));
  CHECK(dev.stats().pose_limited.load() == 4);  // ticks 0-3 (tick 4 arrives within one step)
  // A 2 N, 0.2 N·m step: 0.5 N and 0.05 N·m a tick.
  ForcePacket f;
  std::vector<double> fz, tz;
  for (int k = 0; k < 6; ++k) {
    dev.command_wrench(st::rt::now_ns(), Eigen::Vector3d(0, 0, 2), Eigen::Vector3d(0, 0.2, 0));
    REQUIRE(drv.recv_force(f));
    fz.push_back(f.force[2]);
    tz.push_back(f.torque[1]);
  }
  CHECK(fz[0] == doctest::Approx(0.5));
  CHECK(fz[2] == doctest::Approx(1.5));
  CHECK(fz[3] == doctest::Approx(2));
  CHECK(fz[5] == doctest::Approx(2));
  CHECK(tz[0] == doctest::Approx(0.05));
  CHECK(tz[3] == doctest::Approx(0.2));
  CHECK((f.flags & st::rt::kForceLimited) == 0);  // reached: no longer limited
  CHECK(dev.stats().force_limited.load() == 3);
  // A non-finite torque is never passed on; a 3-DOF bridge sends none.
  dev.command_wrench(st::rt::now_ns(), Eigen::Vector3d(0, 0, 2), Eigen::Vector3d(std::nan(""), 0, 0));
  REQUIRE(drv.recv_force(f));
  CHECK(std::isfinite(f.torque[0]));
  c.max_torque_Nm = 0;
  auto three = st::rt::UdpDevice::open(c, Eigen::Isometry3d::Identity());
  REQUIRE(three);
  UdpDriver drv3(three.value()->address());
  drv3.send_pose(1, {0, 0, 0});
  REQUIRE(udp_wait_pose(*three.value(), Eigen::Vector3d::Zero(), pose));
  // The pose may have arrived before the first tick (whose gain starts the fade at 0): one more.
  std::this_thread::sleep_for(std::chrono::milliseconds(1));
  REQUIRE(three.value()->read_pose(st::rt::now_ns(), pose));
  three.value()->command_wrench(st::rt::now_ns(), Eigen::Vector3d(0, 0, 0.1), Eigen::Vector3d(0, 0.04, 0));
  REQUIRE(drv3.recv_force(f));
  CHECK(f.force[2] == doctest::Approx(0.1));
  CHECK(f.torque == std::array<double, 3>{0, 0, 0});
}

TEST_CASE(
    "udp bridge, auth = none: a version-1 driver still works, but a forged pose from elsewhere or a sequence jump is "
    "refused") {
  st::rt::UdpDeviceConfig c = udp_test_config();
  c.auth = st::rt::BridgeAuth::kNone;
  c.silence_ms = 1000;
  c.session_timeout_ms = 1000;
  auto dev_r = st::rt::UdpDevice::open(c, Eigen::Isometry3d::Identity());
  REQUIRE(dev_r);
  st::rt::UdpDevice& dev = *dev_r.value();
  UdpDriver old(dev.address());
  old.version = 1;
  old.sign = false;
  old.send_pose(1, {3, 0, 0});
  Eigen::Isometry3d pose;
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d(3, 0, 0), pose));
  dev.command_wrench(st::rt::now_ns(), Eigen::Vector3d(0.01, 0, 0), Eigen::Vector3d::Zero());
  const std::vector<std::uint8_t> b = old.recv();
  REQUIRE(b.size() == st::rt::kForceBytesV1);  // it gets what it speaks
  ForcePacket f;
  REQUIRE(st::rt::decode_force(b.data(), b.size(), nullptr, f));
  CHECK(f.version == 1);
  CHECK(f.pose_seq == 1);
  // Another address while the driver is live: busy. The driver's address with 2^64 - 1: a jump.
  UdpDriver other(dev.address());
  other.version = 1;
  other.sign = false;
  other.send_pose(2, {-50, 0, 0});
  REQUIRE(udp_wait_count(dev.stats().busy, 1));
  UdpDriver spoof(dev.address());
  std::swap(spoof.fd, old.fd);
  spoof.version = 1;
  spoof.sign = false;
  spoof.send_pose(~std::uint64_t{0}, {-50, 0, 0});
  REQUIRE(udp_wait_count(dev.stats().jumps, 1));
  std::swap(spoof.fd, old.fd);
  old.send_pose(2, {3, 1, 0});
  REQUIRE(udp_wait_pose(dev, Eigen::Vector3d(3, 1, 0), pose));
  CHECK(dev.summary().find("NOT authenticated") != std::string::npos);
}
