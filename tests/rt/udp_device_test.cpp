// SPDX-License-Identifier: BSD-3-Clause
// The UDP device bridge: the wire format (every refusal), and a live UdpDevice on loopback fed by
// a driver socket: poses taken, forces echoed, the peer latched, stale/malformed/foreign datagrams
// counted and dropped, silence faded out and back in without a step, floods survived.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <thread>
#include <vector>

#include "doctest/doctest.h"
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/udp_device.hpp>

namespace {

using st::rt::ForcePacket;
using st::rt::PosePacket;
using st::rt::PoseReject;

std::vector<std::uint8_t> udp_pose_bytes(const PosePacket& p) {
  std::vector<std::uint8_t> b(st::rt::kPoseBytes);
  st::rt::encode_pose(p, b.data());
  return b;
}

/// A driver's socket on loopback, sending to the device's port.
struct UdpDriver {
  int fd = -1;
  sockaddr_in to{};
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
    p.seq = seq;
    p.device_ns = std::int64_t(1000 + seq);
    p.tip = tip;
    p.q = q;
    send(udp_pose_bytes(p));
  }
  /// The next force datagram within timeout_ms; false if none.
  bool recv_force(ForcePacket& f, int timeout_ms = 2000) const {
    pollfd pf{fd, POLLIN, 0};
    if (::poll(&pf, 1, timeout_ms) <= 0) return false;
    std::uint8_t b[256];
    const ssize_t n = ::recv(fd, b, sizeof b, 0);
    return n > 0 && st::rt::decode_force(b, std::size_t(n), f);
  }
};

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
  PosePacket p;
  p.buttons = 3;
  p.seq = 0x0102030405060708ull;
  p.device_ns = -42;
  p.tip = {1.5, -2.25, 1e5};
  p.q = {0.5, 0.5, 0.5, 0.5};
  std::vector<std::uint8_t> b = udp_pose_bytes(p);
  CHECK(b[0] == 'S');
  CHECK(b[1] == 'T');
  CHECK(b[2] == 'H');
  CHECK(b[3] == 'P');
  CHECK(b[8] == 0x08);  // little-endian
  PosePacket out;
  REQUIRE(st::rt::decode_pose(b.data(), b.size(), 1e6, out) == PoseReject::kOk);
  CHECK(out.buttons == 3);
  CHECK(out.seq == p.seq);
  CHECK(out.device_ns == -42);
  CHECK(out.tip == p.tip);
  CHECK(out.q == p.q);

  CHECK(st::rt::decode_pose(b.data(), 79, 1e6, out) == PoseReject::kSize);
  std::vector<std::uint8_t> longer = b;
  longer.push_back(0);
  CHECK(st::rt::decode_pose(longer.data(), longer.size(), 1e6, out) == PoseReject::kSize);
  std::vector<std::uint8_t> bad = b;
  bad[3] = 'F';
  CHECK(st::rt::decode_pose(bad.data(), bad.size(), 1e6, out) == PoseReject::kMagic);
  bad = b;
  bad[4] = 2;
  CHECK(st::rt::decode_pose(bad.data(), bad.size(), 1e6, out) == PoseReject::kVersion);
  PosePacket q = p;
  q.tip[1] = std::nan("");
  CHECK(st::rt::decode_pose(udp_pose_bytes(q).data(), 80, 1e6, out) == PoseReject::kNonFinite);
  q = p;
  q.q[2] = INFINITY;
  CHECK(st::rt::decode_pose(udp_pose_bytes(q).data(), 80, 1e6, out) == PoseReject::kNonFinite);
  q = p;
  q.tip[0] = 2e6;
  CHECK(st::rt::decode_pose(udp_pose_bytes(q).data(), 80, 1e6, out) == PoseReject::kRange);
  q = p;
  q.q = {1.01, 0, 0, 0};
  CHECK(st::rt::decode_pose(udp_pose_bytes(q).data(), 80, 1e6, out) == PoseReject::kQuaternion);
  q.q = {0, 0, 0, 0};
  CHECK(st::rt::decode_pose(udp_pose_bytes(q).data(), 80, 1e6, out) == PoseReject::kQuaternion);
  q.q = {1.0005, 0, 0, 0};  // within 1e-3: accepted and normalised
  REQUIRE(st::rt::decode_pose(udp_pose_bytes(q).data(), 80, 1e6, out) == PoseReject::kOk);
  CHECK(out.q[0] == doctest::Approx(1.0).epsilon(1e-15));

  ForcePacket f;
  f.flags = st::rt::kForceFading;
  f.seq = 7;
  f.pose_seq = 9;
  f.pose_device_ns = 123456789;
  f.servo_ns = 987654321;
  f.force = {0.1, -0.2, 3.5};
  std::uint8_t fb[st::rt::kForceBytes];
  st::rt::encode_force(f, fb);
  ForcePacket g;
  REQUIRE(st::rt::decode_force(fb, sizeof fb, g));
  CHECK(g.flags == f.flags);
  CHECK(g.seq == 7);
  CHECK(g.pose_seq == 9);
  CHECK(g.pose_device_ns == 123456789);
  CHECK(g.servo_ns == 987654321);
  CHECK(g.force == f.force);
  CHECK_FALSE(st::rt::decode_force(fb, 63, g));
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
  st::rt::UdpDeviceConfig c;
  c.bind = "127.0.0.1:0";
  c.scale = 2;
  c.offset_mm = {10, 0, -5};
  c.max_force_N = 4;
  c.silence_ms = 1000;  // real time below: a loaded machine must not make the driver look silent
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
  UdpDriver other(dev.address());
  other.send_pose(2000, {50, 50, 50});
  REQUIRE(udp_wait_count(dev.stats().foreign, 1));
  CHECK(dev.stats().poses.load() == poses_before);
  REQUIRE(dev.read_pose(st::rt::now_ns(), pose));
  CHECK((pose * Eigen::Vector3d(0, 0, 3) - Eigen::Vector3d(12, 4, 1)).norm() < 1e-12);  // still the last good pose
  CHECK(dev.summary().find("1 stale") != std::string::npos);
  CHECK(dev.summary().find("1 foreign") != std::string::npos);

  // A non-finite force is never passed on.
  dev.command_force(st::rt::now_ns(), Eigen::Vector3d(std::nan(""), 1, 0));
  REQUIRE(drv.recv_force(f));
  CHECK(std::isfinite(f.force[0]));
  CHECK(f.force[0] == 0);
}

TEST_CASE("udp bridge: a silent driver's force fades to zero and fades back in when it returns") {
  st::rt::UdpDeviceConfig c;
  c.bind = "127.0.0.1:0";
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
  st::rt::UdpDeviceConfig c;
  c.bind = "127.0.0.1:0";
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
  st::rt::UdpDeviceConfig c;
  c.bind = "127.0.0.1:0";
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
