// SPDX-License-Identifier: BSD-3-Clause
// UdpDevice: see udp_device.hpp for the wire format and what the bridge promises.
#include <spheretouch/rt/udp_device.hpp>

#include <arpa/inet.h>
#include <netdb.h>
#include <poll.h>
#include <unistd.h>

#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>

#include <spheretouch/rt/clock.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

namespace {

void put16(std::uint8_t* p, std::uint16_t v) {
  for (int i = 0; i < 2; ++i) p[i] = std::uint8_t(v >> (8 * i));
}
void put32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = std::uint8_t(v >> (8 * i));
}
void put64(std::uint8_t* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = std::uint8_t(v >> (8 * i));
}
void putf(std::uint8_t* p, double v) { put64(p, std::bit_cast<std::uint64_t>(v)); }
std::uint16_t get16(const std::uint8_t* p) { return std::uint16_t(p[0] | (p[1] << 8)); }
std::uint32_t get32(const std::uint8_t* p) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
std::uint64_t get64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
double getf(const std::uint8_t* p) { return std::bit_cast<double>(get64(p)); }

/// Same address and port.
bool same_peer(const sockaddr_storage& a, socklen_t al, const sockaddr_storage& b, socklen_t bl) {
  if (a.ss_family != b.ss_family) return false;
  if (a.ss_family == AF_INET) {
    const auto& x = reinterpret_cast<const sockaddr_in&>(a);
    const auto& y = reinterpret_cast<const sockaddr_in&>(b);
    return x.sin_port == y.sin_port && x.sin_addr.s_addr == y.sin_addr.s_addr;
  }
  if (a.ss_family == AF_INET6) {
    const auto& x = reinterpret_cast<const sockaddr_in6&>(a);
    const auto& y = reinterpret_cast<const sockaddr_in6&>(b);
    return x.sin6_port == y.sin6_port && std::memcmp(&x.sin6_addr, &y.sin6_addr, sizeof x.sin6_addr) == 0;
  }
  return al == bl && std::memcmp(&a, &b, al) == 0;
}

/// "host:port" or "[v6]:port" resolved (numeric port); the field name goes into errors.
Result<addrinfo*> resolve(const std::string& where, const std::string& field, bool passive) {
  std::string host, port;
  if (!where.empty() && where.front() == '[') {
    const auto close = where.find("]:");
    if (close == std::string::npos) return fail(field, ": '", where, "': expected [IPv6]:PORT");
    host = where.substr(1, close - 1);
    port = where.substr(close + 2);
  } else {
    const auto colon = where.rfind(':');
    if (colon == std::string::npos || where.find(':') != colon)
      return fail(field, ": '", where, "': expected HOST:PORT (IPv6 as [ADDR]:PORT)");
    host = where.substr(0, colon);
    port = where.substr(colon + 1);
  }
  if (port.empty() || port.size() > 5 || port.find_first_not_of("0123456789") != std::string::npos || std::stoi(port) > 65535)
    return fail(field, ": '", where, "': the port must be a number 0-65535");
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  hints.ai_flags = AI_NUMERICSERV | (passive ? AI_PASSIVE : 0);
  addrinfo* res = nullptr;
  if (int rc = getaddrinfo(host.c_str(), port.c_str(), &hints, &res); rc != 0 || !res)
    return fail(field, ": '", where, "': ", gai_strerror(rc));
  return res;
}

std::string to_text(const sockaddr_storage& a) {
  char host[INET6_ADDRSTRLEN] = "?";
  if (a.ss_family == AF_INET) {
    const auto& x = reinterpret_cast<const sockaddr_in&>(a);
    inet_ntop(AF_INET, &x.sin_addr, host, sizeof host);
    return std::string(host) + ":" + std::to_string(ntohs(x.sin_port));
  }
  if (a.ss_family == AF_INET6) {
    const auto& x = reinterpret_cast<const sockaddr_in6&>(a);
    inet_ntop(AF_INET6, &x.sin6_addr, host, sizeof host);
    std::string text = "[";  // appended, not operator+: GCC 12 warns falsely on "[" + std::string (bug 105329)
    text += host;
    text += "]:";
    text += std::to_string(ntohs(x.sin6_port));
    return text;
  }
  return "?";
}

}  // namespace

const char* to_string(PoseReject r) {
  switch (r) {
    case PoseReject::kOk:
      return "ok";
    case PoseReject::kSize:
      return "wrong size";
    case PoseReject::kMagic:
      return "not a pose (magic)";
    case PoseReject::kVersion:
      return "unknown version";
    case PoseReject::kNonFinite:
      return "NaN or infinite number";
    case PoseReject::kRange:
      return "tip out of range";
    case PoseReject::kQuaternion:
      return "quaternion not unit";
  }
  return "?";
}

void encode_pose(const PosePacket& p, std::uint8_t* out) {
  put32(out, kPoseMagic);
  put16(out + 4, kBridgeVersion);
  put16(out + 6, p.buttons);
  put64(out + 8, p.seq);
  put64(out + 16, std::uint64_t(p.device_ns));
  for (int i = 0; i < 3; ++i) putf(out + 24 + 8 * i, p.tip[i]);
  for (int i = 0; i < 4; ++i) putf(out + 48 + 8 * i, p.q[i]);
}

PoseReject decode_pose(const std::uint8_t* data, std::size_t n, double max_abs_mm, PosePacket& out) {
  if (n != kPoseBytes) return PoseReject::kSize;
  if (get32(data) != kPoseMagic) return PoseReject::kMagic;
  if (get16(data + 4) != kBridgeVersion) return PoseReject::kVersion;
  PosePacket p;
  p.buttons = get16(data + 6);
  p.seq = get64(data + 8);
  p.device_ns = std::int64_t(get64(data + 16));
  for (int i = 0; i < 3; ++i) p.tip[i] = getf(data + 24 + 8 * i);
  for (int i = 0; i < 4; ++i) p.q[i] = getf(data + 48 + 8 * i);
  double q2 = 0;
  for (double v : p.tip)
    if (!std::isfinite(v)) return PoseReject::kNonFinite;
  for (double v : p.q) {
    if (!std::isfinite(v)) return PoseReject::kNonFinite;
    q2 += v * v;
  }
  for (double v : p.tip)
    if (!(std::abs(v) <= max_abs_mm)) return PoseReject::kRange;
  if (!(std::abs(std::sqrt(q2) - 1) <= 1e-3)) return PoseReject::kQuaternion;
  const double inv = 1 / std::sqrt(q2);
  for (double& v : p.q) v *= inv;
  out = p;
  return PoseReject::kOk;
}

void encode_force(const ForcePacket& f, std::uint8_t* out) {
  put32(out, kForceMagic);
  put16(out + 4, kBridgeVersion);
  put16(out + 6, f.flags);
  put64(out + 8, f.seq);
  put64(out + 16, f.pose_seq);
  put64(out + 24, std::uint64_t(f.pose_device_ns));
  for (int i = 0; i < 3; ++i) putf(out + 32 + 8 * i, f.force[i]);
  put64(out + 56, std::uint64_t(f.servo_ns));
}

bool decode_force(const std::uint8_t* data, std::size_t n, ForcePacket& out) {
  if (n != kForceBytes || get32(data) != kForceMagic || get16(data + 4) != kBridgeVersion) return false;
  out.flags = get16(data + 6);
  out.seq = get64(data + 8);
  out.pose_seq = get64(data + 16);
  out.pose_device_ns = std::int64_t(get64(data + 24));
  for (int i = 0; i < 3; ++i) out.force[i] = getf(data + 32 + 8 * i);
  out.servo_ns = std::int64_t(get64(data + 56));
  return true;
}

Result<std::unique_ptr<UdpDevice>> UdpDevice::open(const UdpDeviceConfig& c, const Eigen::Isometry3d& grip) {
  if (!(c.silence_ms > 0) || !(c.fade_ms > 0)) return fail("device: silence_ms and fade_ms must be > 0");
  if (!(c.scale > 0) || !std::isfinite(c.scale)) return fail("device: scale must be a finite number > 0");
  if (!(c.max_force_N > 0)) return fail("device: max_force_N must be > 0");
  sockaddr_storage pinned{};  // the pinned driver, resolved once (the receiver thread compares)
  socklen_t pinned_len = 0;
  if (!c.peer.empty()) {
    Result<addrinfo*> p = resolve(c.peer, "device.peer", false);
    if (!p) return Error{p.error()};
    std::memcpy(&pinned, p.value()->ai_addr, p.value()->ai_addrlen);
    pinned_len = p.value()->ai_addrlen;
    freeaddrinfo(p.value());
  }
  Result<addrinfo*> r = resolve(c.bind, "device.bind", true);
  if (!r) return Error{r.error()};
  addrinfo* ai = r.value();
  const int fd = ::socket(ai->ai_family, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    freeaddrinfo(ai);
    return fail("device.bind: ", c.bind, ": socket: ", std::strerror(errno));
  }
  if (::bind(fd, ai->ai_addr, ai->ai_addrlen) != 0) {
    const int e = errno;
    freeaddrinfo(ai);
    ::close(fd);
    return fail("device.bind: ", c.bind, ": cannot bind (", std::strerror(e), ")");
  }
  freeaddrinfo(ai);
  sockaddr_storage self{};
  socklen_t len = sizeof self;
  getsockname(fd, reinterpret_cast<sockaddr*>(&self), &len);
  return std::unique_ptr<UdpDevice>(new UdpDevice(c, grip, fd, to_text(self), pinned, pinned_len));
}

UdpDevice::UdpDevice(const UdpDeviceConfig& c, const Eigen::Isometry3d& grip, int fd, std::string bound,
                     const sockaddr_storage& pinned, socklen_t pinned_len)
    : config_(c), grip_(grip), fd_(fd), bound_(std::move(bound)) {
  rx_ = std::thread([this, pinned, pinned_len] { receive(pinned, pinned_len); });
}

UdpDevice::~UdpDevice() {
  stop_.store(true);
  if (rx_.joinable()) rx_.join();
  ::close(fd_);
}

void UdpDevice::receive(sockaddr_storage peer, socklen_t peer_len) noexcept {
  // The peer: pinned by config (peer_len > 0), or the first sender of a valid pose.
  bool have_peer = peer_len > 0;
  std::uint64_t last_seq = 0;
  bool any = false;
  std::uint8_t buf[256];
  while (!stop_.load(std::memory_order_relaxed)) {
    pollfd pf{fd_, POLLIN, 0};
    if (::poll(&pf, 1, 20) <= 0) continue;  // 20 ms: how long a stop waits for this thread
    // Drain what is queued; only the newest valid pose is published.
    bool publish = false;
    for (;;) {
      Incoming in;
      in.from_len = sizeof in.from;
      const ssize_t n =
          ::recvfrom(fd_, buf, sizeof buf, MSG_DONTWAIT | MSG_TRUNC, reinterpret_cast<sockaddr*>(&in.from), &in.from_len);
      if (n < 0) break;  // EAGAIN: drained (or an error: poll again)
      in.arrival_ns = now_ns();
      if (have_peer && !same_peer(in.from, in.from_len, peer, peer_len)) {
        stats_.foreign.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      const PoseReject why = decode_pose(buf, std::size_t(n), config_.max_abs_mm, in.p);
      if (why != PoseReject::kOk) {
        stats_.malformed.fetch_add(1, std::memory_order_relaxed);
        stats_.last_reject.store(std::uint16_t(why), std::memory_order_relaxed);
        continue;
      }
      if (any && in.p.seq <= last_seq) {
        stats_.stale.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      if (!have_peer) {
        peer = in.from;
        peer_len = in.from_len;
        have_peer = true;
      }
      any = true;
      last_seq = in.p.seq;
      stats_.poses.fetch_add(1, std::memory_order_relaxed);
      in_.input() = in;
      publish = true;
    }
    if (publish) in_.publish();
  }
}

bool UdpDevice::read_pose(std::int64_t now_ns, Eigen::Isometry3d& pose) noexcept {
  if (in_.update()) {
    const Incoming& in = in_.output();
    if (have_pose_ && in.p.seq > taken_seq_ + 1)
      stats_.gaps.fetch_add(in.p.seq - taken_seq_ - 1, std::memory_order_relaxed);
    cur_ = in;
    taken_seq_ = in.p.seq;
    have_pose_ = true;
  }
  (void)gain(now_ns);
  if (!have_pose_) return false;
  const auto& p = cur_.p;
  const Eigen::Vector3d tip(p.tip[0], p.tip[1], p.tip[2]);
  const Eigen::Vector3d off(config_.offset_mm[0], config_.offset_mm[1], config_.offset_mm[2]);
  const Eigen::Quaterniond q(p.q[0], p.q[1], p.q[2], p.q[3]);
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translate(config_.scale * tip + off);
  t.rotate(q);
  pose = t * grip_;
  return true;
}

double UdpDevice::gain(std::int64_t now_ns) noexcept {
  // Moves toward 1 while poses are fresh and toward 0 once the driver has been silent for
  // silence_ms, by 1 per fade_ms: the force never steps when a driver stops or comes back.
  const bool fresh = have_pose_ && now_ns - cur_.arrival_ns <= std::int64_t(config_.silence_ms * 1e6);
  if (have_pose_ && !fresh && !fading_out_) stats_.fades.fetch_add(1, std::memory_order_relaxed);
  fading_out_ = have_pose_ && !fresh;
  const double dt = gain_ns_ ? double(std::max<std::int64_t>(0, now_ns - gain_ns_)) : 0.0;
  gain_ns_ = now_ns;
  const double step = dt / (config_.fade_ms * 1e6);
  gain_ = fresh ? std::min(1.0, gain_ + step) : std::max(0.0, gain_ - step);
  return gain_;
}

void UdpDevice::command_force(std::int64_t now_ns, const Eigen::Vector3d& force_N) noexcept {
  if (!have_pose_) return;  // no driver yet: nobody to send to
  ForcePacket f;
  f.seq = ++force_seq_;
  f.pose_seq = cur_.p.seq;
  f.pose_device_ns = cur_.p.device_ns;
  f.servo_ns = now_ns;
  const double g = gain_;
  if (g < 1) f.flags |= kForceFading;
  for (int i = 0; i < 3; ++i) {
    const double v = g * force_N[i];
    f.force[i] = std::isfinite(v) ? v : 0.0;  // the servo sends finite forces; never pass on anything else
  }
  std::uint8_t buf[kForceBytes];
  encode_force(f, buf);
  if (::sendto(fd_, buf, sizeof buf, MSG_DONTWAIT | MSG_NOSIGNAL, reinterpret_cast<const sockaddr*>(&cur_.from),
               cur_.from_len) == ssize_t(sizeof buf))
    stats_.forces.fetch_add(1, std::memory_order_relaxed);
  else
    stats_.send_errors.fetch_add(1, std::memory_order_relaxed);
}

std::string UdpDevice::summary() const {
  auto n = [](const std::atomic<std::uint64_t>& a) { return std::to_string(a.load(std::memory_order_relaxed)); };
  std::string s = "udp " + bound_ + ": " + n(stats_.poses) + " poses, " + n(stats_.gaps) + " seq gaps, " +
                  n(stats_.forces) + " forces sent (" + n(stats_.send_errors) + " failed), " + n(stats_.fades) +
                  " fade-outs; refused: " + n(stats_.malformed) + " malformed, " + n(stats_.stale) + " stale, " +
                  n(stats_.foreign) + " foreign";
  if (stats_.malformed.load(std::memory_order_relaxed))
    s += std::string(" (last: ") + to_string(PoseReject(stats_.last_reject.load(std::memory_order_relaxed))) + ")";
  return s;
}

}  // namespace st::rt
