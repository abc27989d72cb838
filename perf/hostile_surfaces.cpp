// SPDX-License-Identifier: BSD-3-Clause
// The hostile bench's attacks on the run's other surfaces (hostile_surfaces.hpp): the UDP device
// bridge and the live view, each started in this process as a run starts them.
#include "hostile_surfaces.hpp"

#include <arpa/inet.h>
#include <civetweb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <thread>

#include "../tests/app/view_raw.hpp"
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/shm_status.hpp>
#include <spheretouch/rt/udp_device.hpp>
#include <spheretouch/view/view_server.hpp>

namespace st::bench {
namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

/// A UDP socket on loopback sending datagrams to `addr` ("127.0.0.1:PORT").
struct UdpSender {
  int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_in to{};
  explicit UdpSender(const std::string& addr) {
    const auto colon = addr.rfind(':');
    to.sin_family = AF_INET;
    to.sin_port = htons(std::uint16_t(std::stoi(addr.substr(colon + 1))));
    inet_pton(AF_INET, addr.substr(0, colon).c_str(), &to.sin_addr);
  }
  ~UdpSender() { ::close(fd); }
  UdpSender(const UdpSender&) = delete;
  UdpSender& operator=(const UdpSender&) = delete;
  void send(const rt::PosePacket& p, const rt::BridgeKey* key) const {
    std::uint8_t b[rt::kPoseBytes];
    const std::size_t n = rt::encode_pose(p, key, b);
    (void)::sendto(fd, b, n, 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  }
};

}  // namespace

SurfaceOutcome forged_udp(std::chrono::milliseconds window) {
  SurfaceOutcome out;
  rt::UdpDeviceConfig c;
  c.bind = "127.0.0.1:0";
  Result<rt::BridgeKey> key = rt::random_bridge_key();
  if (!key) return {false, "no key: " + key.error()};
  c.key = key.value();
  auto dev_r = rt::UdpDevice::open(c, Eigen::Isometry3d::Identity());
  if (!dev_r) return {false, "bridge: " + dev_r.error()};
  rt::UdpDevice& dev = *dev_r.value();
  // The driver: its own session, signed poses at 1 kHz, the tip at the origin. The attacker
  // sends from the driver's very socket (what a forged source address achieves): unsigned
  // version-1 poses, version-2 ones under a wrong key, and a sequence number of 2^64 - 1, all
  // putting the tip 50 mm away.
  UdpSender driver(dev.address());
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> forged{0};
  std::thread drive([&] {
    rt::PosePacket p;
    p.session = 0x5e55'1011'0000'0001ull;
    rt::BridgeKey wrong = c.key;
    wrong[0] ^= 1;
    for (std::uint64_t seq = 1; !stop.load(); ++seq) {
      p.version = rt::kBridgeVersion;
      p.seq = seq;
      p.device_ns = std::int64_t(seq) * 1'000'000;
      p.tip = {0, 0, 0};
      driver.send(p, &c.key);
      if (seq > 50 && seq % 4 == 0) {  // once the session is up: a forgery every 4 ms
        rt::PosePacket f = p;
        f.tip = {50, 0, 0};
        switch ((seq / 4) % 3) {
          case 0:
            f.version = 1;
            driver.send(f, nullptr);
            break;
          case 1:
            driver.send(f, &wrong);
            break;
          default:
            f.seq = ~std::uint64_t{0};
            driver.send(f, &wrong);
            break;
        }
        forged.fetch_add(1);
      }
      std::this_thread::sleep_for(1ms);
    }
  });
  // The servo: a pose a millisecond, the farthest the tip was ever handed from the origin.
  double farthest = 0;
  std::uint64_t ticks = 0, taken = 0;
  const auto until = Clock::now() + window;
  while (Clock::now() < until) {
    Eigen::Isometry3d pose;
    if (dev.read_pose(rt::now_ns(), pose)) {
      ++taken;
      farthest = std::max(farthest, pose.translation().norm());
    }
    ++ticks;
    std::this_thread::sleep_for(1ms);
  }
  stop = true;
  drive.join();
  const rt::UdpDeviceStats& s = dev.stats();
  const std::uint64_t refused = s.unauthenticated.load() + s.old_version.load() + s.malformed.load();
  out.refused = farthest < 1e-9 && refused >= forged.load() && taken * 2 > ticks;
  out.note = std::to_string(forged.load()) + " forged datagrams, " + std::to_string(refused) +
             " refused (unauthenticated " + std::to_string(s.unauthenticated.load()) + ", version 1 " +
             std::to_string(s.old_version.load()) + "); the tip handed to the servo stayed within " +
             std::to_string(farthest) + " mm of the driver's; " + std::to_string(s.poses.load()) + " driver poses taken";
  return out;
}

/// A live view served from this process, with frames of the largest size published at 60 Hz.
struct ViewFixture::Impl {
  geom::Mesh probe = geom::make_capsule(4, 10, 24), object = geom::make_icosphere(60, 30);  // 18,000 faces
  rt::ShmStatus status{};
  std::unique_ptr<view::ViewServer> server;
  std::thread publisher;
  std::atomic<bool> stop{false};
  int port = 0;
  std::string token;
};

ViewFixture::ViewFixture() : impl_(std::make_unique<Impl>()) {
  mg_init_library(0);
  Impl& v = *impl_;
  view::ViewServerConfig vc;
  vc.listen = "127.0.0.1:0";
  auto s = view::ViewServer::start(vc, v.probe, v.object, v.status.view, v.status, nullptr);
  if (!s) {
    error_ = "view: " + s.error();
    return;
  }
  v.server = std::move(s).value();
  // http://127.0.0.1:PORT/?t=TOKEN
  const std::string url = v.server->url();
  const auto colon = url.rfind(':'), slash = url.find('/', colon);
  v.port = std::stoi(url.substr(colon + 1, slash - colon - 1));
  v.token = url.substr(url.find("?t=") + 3);
  v.publisher = std::thread([&v] {
    auto f = std::make_unique<rt::ViewFrame>();
    f->flags = rt::ViewFrame::kInContact;
    f->n_probe = std::min<std::uint32_t>(rt::kViewMaxFaces, std::uint32_t(v.probe.faces.size()));
    f->n_object = rt::kViewMaxFaces;
    for (std::uint32_t i = 0; i < f->n_probe; ++i) f->faces[i] = i;
    for (std::uint32_t i = 0; i < f->n_object; ++i) f->faces[f->n_probe + i] = i;
    f->contacts = f->n_probe + f->n_object;
    for (std::uint64_t round = 1; !v.stop.load(); ++round) {
      f->round = round;
      v.status.view.store(*f, f->used_bytes());
      std::this_thread::sleep_for(16ms);
    }
  });
}

ViewFixture::~ViewFixture() {
  impl_->stop = true;
  if (impl_->publisher.joinable()) impl_->publisher.join();
  impl_->server.reset();
}

SurfaceOutcome ViewFixture::foreign_origin(std::chrono::milliseconds window) {
  if (!error_.empty()) return {false, error_};
  const Impl& v = *impl_;
  const std::string here = "127.0.0.1:" + std::to_string(v.port), q = "?t=" + v.token;
  const std::uint64_t before = v.server->stats().forbidden;
  // A page on another site (cross-site WebSocket hijacking), a rebound name (DNS rebinding), no
  // token, over and over for the window: each must get 403; then the view's own page gets 101.
  int foreign = 0, rebound = 0, tokenless = 0;
  std::uint64_t tries = 0, wrong = 0;
  for (const auto until = Clock::now() + window; Clock::now() < until; ++tries) {
    foreign = test::view_raw(v.port, test::view_upgrade(q, here, "http://evil.example"));
    rebound = test::view_raw(v.port, test::view_upgrade(q, "evil.example:" + std::to_string(v.port), ""));
    tokenless = test::view_raw(v.port, test::view_upgrade("", here, "http://" + here));
    wrong += (foreign != 403) + (rebound != 403) + (tokenless != 403);
  }
  const int own = test::view_raw(v.port, test::view_upgrade(q, here, "http://" + here));
  const std::uint64_t forbidden = v.server->stats().forbidden - before;
  SurfaceOutcome out;
  out.refused = wrong == 0 && tries > 0 && own == 101;
  out.note = std::to_string(3 * tries) + " handshakes, " + std::to_string(wrong) +
             " not refused (last: foreign Origin " + std::to_string(foreign) + ", foreign Host " +
             std::to_string(rebound) + ", no token " + std::to_string(tokenless) + "), the view's own page " +
             std::to_string(own) + "; " + std::to_string(forbidden) + " counted forbidden";
  return out;
}

namespace {
struct PageCount {
  std::atomic<std::uint64_t> frames{0};
};
int count_frames(mg_connection*, int bits, char*, std::size_t, void* user) {
  if ((bits & 0x0f) == MG_WEBSOCKET_OPCODE_BINARY) static_cast<PageCount*>(user)->frames.fetch_add(1);
  return 1;
}
}  // namespace

SurfaceOutcome ViewFixture::stalled_page(std::chrono::milliseconds window) {
  if (!error_.empty()) return {false, error_};
  const Impl& v = *impl_;
  const std::string here = "127.0.0.1:" + std::to_string(v.port);
  // The stalled page: a real handshake, then it never reads again (a 4 KiB receive buffer).
  int stalled = -1;
  const int code =
      test::view_raw(v.port, test::view_upgrade("?t=" + v.token, here, "http://" + here), &stalled, nullptr, 100);
  // The honest page: civetweb's client, counting the frames it gets.
  PageCount honest;
  char err[256] = "";
  const std::string path = "/ws?t=" + v.token;
  mg_connection* ws = mg_connect_websocket_client("127.0.0.1", v.port, 0, err, sizeof err, path.c_str(), nullptr,
                                                  count_frames, nullptr, &honest);
  SurfaceOutcome out;
  if (!ws) {
    if (stalled >= 0) ::close(stalled);
    return {false, std::string("honest page could not connect: ") + err};
  }
  std::this_thread::sleep_for(300ms);  // past the mesh message and the first frames
  const std::uint64_t f0 = honest.frames.load();
  const auto t0 = Clock::now();
  std::this_thread::sleep_for(window);
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  const double fps = double(honest.frames.load() - f0) / s;
  const view::ViewStats vs = v.server->stats();
  mg_close_connection(ws);
  if (stalled >= 0) ::close(stalled);
  out.refused = code == 101 && fps > 30;
  out.note = "stalled page handshake " + std::to_string(code) + "; the honest page drew " + std::to_string(fps) +
             " frames/s (60 published) while it stalled; " + std::to_string(vs.dropped) +
             " frames dropped for slow pages, " + std::to_string(vs.write_failures) + " writes failed";
  return out;
}

}  // namespace st::bench
