// SPDX-License-Identifier: BSD-3-Clause
// UdpDevice: see udp_device.hpp for the wire format and what the bridge promises.
#include <spheretouch/rt/udp_device.hpp>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <poll.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>

#ifdef ST_HAVE_SODIUM
#include <sodium.h>
#endif

#include <spheretouch/geom/text_file.hpp>
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

/// The HMAC-SHA256 tag of data[0, n) under key; false in a build without libsodium.
bool tag_of(const BridgeKey& key, const std::uint8_t* data, std::size_t n, std::uint8_t* tag) {
#ifdef ST_HAVE_SODIUM
  static_assert(crypto_auth_hmacsha256_KEYBYTES == kBridgeKeyBytes && crypto_auth_hmacsha256_BYTES == kBridgeTagBytes);
  return crypto_auth_hmacsha256(tag, data, n, key.data()) == 0;
#else
  (void)key, (void)data, (void)n, (void)tag;
  return false;
#endif
}

/// Does data[n, n + 32) hold the tag of data[0, n) under key (in constant time)?
bool tag_verifies(const BridgeKey& key, const std::uint8_t* data, std::size_t n) {
#ifdef ST_HAVE_SODIUM
  return crypto_auth_hmacsha256_verify(data + n, data, n, key.data()) == 0;
#else
  (void)key, (void)data, (void)n;
  return false;
#endif
}

/// Writes the tag of out[0, n) at out + n (zeros without a key).
void put_tag(const BridgeKey* key, std::uint8_t* out, std::size_t n) {
  if (!key || !tag_of(*key, out, n, out + n)) std::memset(out + n, 0, kBridgeTagBytes);
}

/// Closes a descriptor on scope exit.
struct FdCloser {
  int fd = -1;
  ~FdCloser() {
    if (fd >= 0) ::close(fd);
  }
};

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
    case PoseReject::kAuth:
      return "tag does not verify (wrong key)";
    case PoseReject::kLegacy:
      return "version 1 (unauthenticated) refused";
  }
  return "?";
}

const char* to_string(BridgeRefusal r) {
  switch (r) {
    case BridgeRefusal::kRefusedVersion:
      return "version 1 refused: this bridge needs version 2 with HMAC";
    case BridgeRefusal::kBadTag:
      return "the HMAC tag does not verify: wrong key";
    case BridgeRefusal::kBusy:
      return "another session holds the device; retry when it is silent";
    case BridgeRefusal::kSessionUsed:
      return "this session id was served before: pick a new random one";
  }
  return "?";
}

std::size_t encode_pose(const PosePacket& p, const BridgeKey* key, std::uint8_t* out) {
  put32(out, kPoseMagic);
  put16(out + 4, p.version);
  put16(out + 6, p.buttons);
  if (p.version == kBridgeLegacyVersion) {
    put64(out + 8, p.seq);
    put64(out + 16, std::uint64_t(p.device_ns));
    for (int i = 0; i < 3; ++i) putf(out + 24 + 8 * i, p.tip[i]);
    for (int i = 0; i < 4; ++i) putf(out + 48 + 8 * i, p.q[i]);
    return kPoseBytesV1;
  }
  put64(out + 8, p.session);
  put64(out + 16, p.seq);
  put64(out + 24, std::uint64_t(p.device_ns));
  for (int i = 0; i < 3; ++i) putf(out + 32 + 8 * i, p.tip[i]);
  for (int i = 0; i < 4; ++i) putf(out + 56 + 8 * i, p.q[i]);
  put_tag(key, out, kPoseBytes - kBridgeTagBytes);
  return kPoseBytes;
}

PoseReject decode_pose(const std::uint8_t* data, std::size_t n, double max_abs_mm, const BridgeKey* key, PosePacket& out) {
  if (n < 8) return PoseReject::kSize;
  if (get32(data) != kPoseMagic) return PoseReject::kMagic;
  PosePacket p;
  p.version = get16(data + 4);
  p.buttons = get16(data + 6);
  const std::uint8_t* at = nullptr;  // tip and quaternion
  if (p.version == kBridgeVersion) {
    if (n != kPoseBytes) return PoseReject::kSize;
    if (key && !tag_verifies(*key, data, kPoseBytes - kBridgeTagBytes)) return PoseReject::kAuth;
    p.session = get64(data + 8);
    p.seq = get64(data + 16);
    p.device_ns = std::int64_t(get64(data + 24));
    at = data + 32;
  } else if (p.version == kBridgeLegacyVersion) {
    if (n != kPoseBytesV1) return PoseReject::kSize;
    if (key) return PoseReject::kLegacy;
    p.seq = get64(data + 8);
    p.device_ns = std::int64_t(get64(data + 16));
    at = data + 24;
  } else {
    return PoseReject::kVersion;
  }
  for (int i = 0; i < 3; ++i) p.tip[i] = getf(at + 8 * i);
  for (int i = 0; i < 4; ++i) p.q[i] = getf(at + 24 + 8 * i);
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

std::size_t encode_force(const ForcePacket& f, const BridgeKey* key, std::uint8_t* out) {
  put32(out, kForceMagic);
  put16(out + 4, f.version);
  put16(out + 6, f.flags);
  if (f.version == kBridgeLegacyVersion) {
    put64(out + 8, f.seq);
    put64(out + 16, f.pose_seq);
    put64(out + 24, std::uint64_t(f.pose_device_ns));
    for (int i = 0; i < 3; ++i) putf(out + 32 + 8 * i, f.force[i]);
    put64(out + 56, std::uint64_t(f.servo_ns));
    return kForceBytesV1;
  }
  put64(out + 8, f.session);
  put64(out + 16, f.seq);
  put64(out + 24, f.pose_seq);
  put64(out + 32, std::uint64_t(f.pose_device_ns));
  for (int i = 0; i < 3; ++i) putf(out + 40 + 8 * i, f.force[i]);
  for (int i = 0; i < 3; ++i) putf(out + 64 + 8 * i, f.torque[i]);
  put64(out + 88, std::uint64_t(f.servo_ns));
  put_tag(key, out, kForceBytes - kBridgeTagBytes);
  return kForceBytes;
}

bool decode_force(const std::uint8_t* data, std::size_t n, const BridgeKey* key, ForcePacket& out) {
  if (n < 8 || get32(data) != kForceMagic) return false;
  const std::uint16_t version = get16(data + 4);
  if (version == kBridgeLegacyVersion && n == kForceBytesV1) {
    out = ForcePacket{};
    out.version = version;
    out.flags = get16(data + 6);
    out.seq = get64(data + 8);
    out.pose_seq = get64(data + 16);
    out.pose_device_ns = std::int64_t(get64(data + 24));
    for (int i = 0; i < 3; ++i) out.force[i] = getf(data + 32 + 8 * i);
    out.servo_ns = std::int64_t(get64(data + 56));
    return true;
  }
  if (version != kBridgeVersion || n != kForceBytes) return false;
  if (key && !tag_verifies(*key, data, kForceBytes - kBridgeTagBytes)) return false;
  out.version = version;
  out.flags = get16(data + 6);
  out.session = get64(data + 8);
  out.seq = get64(data + 16);
  out.pose_seq = get64(data + 24);
  out.pose_device_ns = std::int64_t(get64(data + 32));
  for (int i = 0; i < 3; ++i) out.force[i] = getf(data + 40 + 8 * i);
  for (int i = 0; i < 3; ++i) out.torque[i] = getf(data + 64 + 8 * i);
  out.servo_ns = std::int64_t(get64(data + 88));
  return true;
}

void encode_refusal(BridgeRefusal why, std::uint64_t session, std::uint8_t* out) {
  std::memset(out, 0, kRefusalBytes);
  put32(out, kRefusalMagic);
  put16(out + 4, kBridgeVersion);
  put16(out + 6, std::uint16_t(why));
  put64(out + 8, session);
  const char* text = to_string(why);
  std::memcpy(out + 16, text, std::min<std::size_t>(std::strlen(text), kRefusalBytes - 17));
}

bool decode_refusal(const std::uint8_t* data, std::size_t n, BridgeRefusal& why, std::uint64_t& session) {
  if (n != kRefusalBytes || get32(data) != kRefusalMagic || get16(data + 4) != kBridgeVersion) return false;
  why = BridgeRefusal(get16(data + 6));
  session = get64(data + 8);
  return true;
}

bool bridge_auth_available() {
#ifdef ST_HAVE_SODIUM
  return true;
#else
  return false;
#endif
}

Result<BridgeKey> random_bridge_key() {
#ifdef ST_HAVE_SODIUM
  if (sodium_init() < 0) return fail("libsodium failed to initialise: no random key");
  BridgeKey k;
  randombytes_buf(k.data(), k.size());
  return k;
#else
  return fail(
      "this build has no libsodium: it cannot make or check bridge keys (build with libsodium-dev, or set [device] "
      "auth = \"none\")");
#endif
}

Result<BridgeKey> read_bridge_key(const std::string& path) {
  Result<std::string> text = geom::read_text_file(path, 4096, "bridge key", /*owner_only=*/true);
  if (!text) return Error{text.error()};
  std::string& buf = text.value();
  const std::size_t n = buf.size();
  std::size_t end = 0;
  while (end < n && buf[end] != '\n') ++end;
  while (end > 0 && std::isspace(static_cast<unsigned char>(buf[end - 1]))) --end;
  BridgeKey k{};
  bool ok = end == 2 * kBridgeKeyBytes;
  for (std::size_t i = 0; ok && i < end; ++i) {
    const int c = std::tolower(static_cast<unsigned char>(buf[i]));
    const int v = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
    if (v < 0)
      ok = false;
    else
      k[i / 2] = std::uint8_t(k[i / 2] << 4 | v);
  }
  std::memset(buf.data(), 0, buf.size());  // no copy of the key left behind
  if (!ok) {
    k.fill(0);
    return fail(path,
                ": first line: expected the bridge key as 64 hexadecimal digits (spheretouch keygen --bridge --out "
                "FILE makes one)");
  }
  return k;
}

Status write_bridge_key(const std::string& path, const BridgeKey& key, bool replace) {
  char line[2 * kBridgeKeyBytes + 2];
  for (std::size_t i = 0; i < key.size(); ++i) std::snprintf(line + 2 * i, 3, "%02x", key[i]);
  line[2 * kBridgeKeyBytes] = '\n';
  // Replacing: a new 0600 file beside it, renamed over it (never a write through a planted symlink).
  std::string tmp = replace ? path + ".tmp-XXXXXX" : path;
  FdCloser f{replace ? ::mkostemp(tmp.data(), O_CLOEXEC)
                     : ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC | O_NOCTTY, 0600)};
  if (f.fd < 0) {
    const int e = errno;
    std::memset(line, 0, sizeof line);
    if (e == EEXIST) return fail(path, ": already exists; refusing to overwrite a key file (--force replaces it)");
    return fail(path, ": cannot create the bridge key: ", std::strerror(e));
  }
  bool ok = ::fchmod(f.fd, 0600) == 0;
  for (std::size_t off = 0; ok && off < 2 * kBridgeKeyBytes + 1;) {
    const ssize_t w = ::write(f.fd, line + off, 2 * kBridgeKeyBytes + 1 - off);
    if (w < 0 && errno == EINTR) continue;
    ok = w > 0;
    if (ok) off += std::size_t(w);
  }
  ok = ok && ::fsync(f.fd) == 0;
  const int e = errno;
  std::memset(line, 0, sizeof line);
  if (ok && replace && ::rename(tmp.c_str(), path.c_str()) != 0) ok = false;
  if (!ok) {
    ::unlink(tmp.c_str());
    return fail(path, ": cannot write the bridge key: ", std::strerror(e ? e : errno));
  }
  return Ok{};
}

std::string check(const UdpDeviceConfig& c) {
  if (!(c.silence_ms > 0) || !(c.fade_ms > 0)) return "silence_ms and fade_ms must be > 0";
  if (!(c.scale > 0) || !std::isfinite(c.scale)) return "scale must be a finite number > 0";
  if (!(c.max_force_N > 0)) return "max_force_N must be > 0";
  if (!(c.max_torque_Nm >= 0) || !std::isfinite(c.max_torque_Nm)) return "max_torque_Nm must be a finite number >= 0";
  if (!(c.session_timeout_ms >= c.silence_ms) || !std::isfinite(c.session_timeout_ms))
    return "session_timeout_ms must be finite and >= silence_ms (a session is never replaced while its force is still "
           "on)";
  if (c.max_seq_jump < 1) return "max_seq_jump must be >= 1";
  if (!(c.max_pose_step_mm > 0) || !(c.max_rotation_step_deg > 0) || !(c.max_force_step_N > 0) ||
      !(c.max_torque_step_Nm > 0))
    return "max_pose_step_mm, max_rotation_step_deg, max_force_step_N and max_torque_step_Nm must be > 0";
  if (c.auth == BridgeAuth::kHmac && !bridge_auth_available())
    return "auth = \"hmac\": this build has no libsodium (build with libsodium-dev, or set auth = \"none\" on a "
           "trusted link)";
  return "";
}

Result<std::unique_ptr<UdpDevice>> UdpDevice::open(const UdpDeviceConfig& c, const Eigen::Isometry3d& grip) {
  if (std::string why = check(c); !why.empty()) return fail("device: ", why);
#ifdef ST_HAVE_SODIUM
  if (sodium_init() < 0) return fail("device: libsodium failed to initialise");
#endif
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

void UdpDevice::refuse(BridgeRefusal why, std::uint64_t session, const sockaddr_storage& to, socklen_t to_len) noexcept {
  // At most 10 a second, each no bigger than the datagram it answers: a forged source gets no
  // amplification and no flood out of the bridge.
  const std::int64_t t = now_ns();
  if (last_refusal_ns_ && t - last_refusal_ns_ < 100'000'000) return;
  last_refusal_ns_ = t;
  std::uint8_t buf[kRefusalBytes];
  encode_refusal(why, session, buf);
  if (::sendto(fd_, buf, sizeof buf, MSG_DONTWAIT | MSG_NOSIGNAL, reinterpret_cast<const sockaddr*>(&to), to_len) ==
      ssize_t(sizeof buf))
    stats_.refusals_sent.fetch_add(1, std::memory_order_relaxed);
}

void UdpDevice::receive(sockaddr_storage pinned, socklen_t pinned_len) noexcept {
  // One session at a time: its id (version 2; 0 for version 1), version, address, last sequence
  // number and arrival. Sessions served before are remembered (a ring) and never taken again.
  const BridgeKey* key = config_.auth == BridgeAuth::kHmac ? &config_.key : nullptr;
  const std::int64_t timeout_ns = std::int64_t(config_.session_timeout_ms * 1e6);
  struct Session {
    bool live = false;
    std::uint64_t id = 0, last_seq = 0, number = 0;
    std::uint16_t version = 0;
    sockaddr_storage peer{};
    socklen_t peer_len = 0;
    std::int64_t last_ns = 0;
  } cur;
  std::array<std::uint64_t, 16> served{};  // ids of ended sessions (version 2, authenticated)
  std::size_t served_next = 0;
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
      if (pinned_len > 0 && !same_peer(in.from, in.from_len, pinned, pinned_len)) {
        stats_.foreign.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      const PoseReject why = decode_pose(buf, std::size_t(n), config_.max_abs_mm, key, in.p);
      if (why == PoseReject::kAuth || why == PoseReject::kLegacy) {
        (why == PoseReject::kAuth ? stats_.unauthenticated : stats_.old_version).fetch_add(1, std::memory_order_relaxed);
        refuse(why == PoseReject::kAuth ? BridgeRefusal::kBadTag : BridgeRefusal::kRefusedVersion,
               why == PoseReject::kAuth ? get64(buf + 8) : 0, in.from, in.from_len);
        continue;
      }
      if (why != PoseReject::kOk) {
        stats_.malformed.fetch_add(1, std::memory_order_relaxed);
        stats_.last_reject.store(std::uint16_t(why), std::memory_order_relaxed);
        continue;
      }
      // Authenticated, a session is its id and the address follows it (a forged source gains
      // nothing); unauthenticated, the address is part of the session.
      const bool silent = !cur.live || in.arrival_ns - cur.last_ns >= timeout_ns;
      const bool same = cur.live && in.p.session == cur.id && in.p.version == cur.version &&
                        (key || same_peer(in.from, in.from_len, cur.peer, cur.peer_len));
      bool start = !same;
      if (same) {
        if (in.p.seq <= cur.last_seq) {
          if (!silent || key) {  // authenticated: an old pose of this session is a replay, silent or not
            stats_.stale.fetch_add(1, std::memory_order_relaxed);
            continue;
          }
          start = true;  // unauthenticated and silent: the same address restarted its count
        } else if (in.p.seq - cur.last_seq > config_.max_seq_jump && !silent) {
          stats_.jumps.fetch_add(1, std::memory_order_relaxed);
          continue;
        }
      }
      if (start) {
        if (!silent) {
          stats_.busy.fetch_add(1, std::memory_order_relaxed);
          refuse(BridgeRefusal::kBusy, in.p.session, in.from, in.from_len);
          continue;
        }
        if (key && std::find(served.begin(), served.end(), in.p.session) != served.end()) {
          stats_.stale.fetch_add(1, std::memory_order_relaxed);
          refuse(BridgeRefusal::kSessionUsed, in.p.session, in.from, in.from_len);
          continue;
        }
        if (cur.live && key && cur.id != in.p.session) {
          served[served_next] = cur.id;
          served_next = (served_next + 1) % served.size();
        }
        cur.live = true;
        cur.id = in.p.session;
        cur.version = in.p.version;
        ++cur.number;
        stats_.sessions.fetch_add(1, std::memory_order_relaxed);
      }
      cur.peer = in.from;
      cur.peer_len = in.from_len;
      cur.last_seq = in.p.seq;
      cur.last_ns = in.arrival_ns;
      in.session_no = cur.number;
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
    if (have_pose_ && in.session_no == cur_.session_no && in.p.seq > taken_seq_ + 1)
      stats_.gaps.fetch_add(in.p.seq - taken_seq_ - 1, std::memory_order_relaxed);
    if (!have_pose_) {  // the very first pose is taken as it is; after it, every change is a ramp
      shown_tip_ = Eigen::Vector3d(in.p.tip[0], in.p.tip[1], in.p.tip[2]);
      shown_q_ = Eigen::Quaterniond(in.p.q[0], in.p.q[1], in.p.q[2], in.p.q[3]);
    }
    cur_ = in;
    taken_seq_ = in.p.seq;
    have_pose_ = true;
  }
  (void)gain(now_ns);
  if (!have_pose_) return false;
  // Slew limits: toward the newest pose by at most max_pose_step_mm and max_rotation_step_deg.
  const auto& p = cur_.p;
  const Eigen::Vector3d tip(p.tip[0], p.tip[1], p.tip[2]);
  const Eigen::Quaterniond q(p.q[0], p.q[1], p.q[2], p.q[3]);
  bool limited = false;
  const Eigen::Vector3d d = tip - shown_tip_;
  if (const double len = d.norm(); len > config_.max_pose_step_mm) {
    shown_tip_ += d * (config_.max_pose_step_mm / len);
    limited = true;
  } else {
    shown_tip_ = tip;
  }
  const double max_turn = config_.max_rotation_step_deg * M_PI / 180;
  if (const double turn = shown_q_.angularDistance(q); turn > max_turn) {
    shown_q_ = shown_q_.slerp(max_turn / turn, q).normalized();
    limited = true;
  } else {
    shown_q_ = q;
  }
  if (limited) stats_.pose_limited.fetch_add(1, std::memory_order_relaxed);
  const Eigen::Vector3d off(config_.offset_mm[0], config_.offset_mm[1], config_.offset_mm[2]);
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translate(config_.scale * shown_tip_ + off);
  t.rotate(shown_q_);
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
  command_wrench(now_ns, force_N, Eigen::Vector3d::Zero());
}

namespace {

/// `sent` moved toward `target` by at most `step`; true when the limit acted.
bool slew(Eigen::Vector3d& sent, const Eigen::Vector3d& target, double step) {
  const Eigen::Vector3d d = target - sent;
  const double len = d.norm();
  if (len <= step) {
    sent = target;
    return false;
  }
  sent += d * (step / len);
  return true;
}

}  // namespace

void UdpDevice::command_wrench(std::int64_t now_ns, const Eigen::Vector3d& force_N, const Eigen::Vector3d& torque_Nm) noexcept {
  if (!have_pose_) return;  // no driver yet: nobody to send to
  ForcePacket f;
  f.version = cur_.p.version;  // a legacy driver gets what it speaks
  f.session = cur_.p.session;
  f.seq = ++force_seq_;
  f.pose_seq = cur_.p.seq;
  f.pose_device_ns = cur_.p.device_ns;
  f.servo_ns = now_ns;
  const double g = gain_;
  if (g < 1) f.flags |= kForceFading;
  // The servo sends finite values; never pass on anything else. A 3-DOF device sends no torque.
  const Eigen::Vector3d force = force_N.allFinite() ? Eigen::Vector3d(g * force_N) : Eigen::Vector3d::Zero();
  const Eigen::Vector3d torque =
      config_.max_torque_Nm > 0 && torque_Nm.allFinite() ? Eigen::Vector3d(g * torque_Nm) : Eigen::Vector3d::Zero();
  const bool lf = slew(sent_force_, force, config_.max_force_step_N);
  const bool lt = slew(sent_torque_, torque, config_.max_torque_step_Nm);
  if (lf || lt) {
    f.flags |= kForceLimited;
    stats_.force_limited.fetch_add(1, std::memory_order_relaxed);
  }
  for (int i = 0; i < 3; ++i) {
    f.force[i] = sent_force_[i];
    f.torque[i] = sent_torque_[i];
  }
  std::uint8_t buf[kForceBytes];
  const std::size_t n = encode_force(f, config_.auth == BridgeAuth::kHmac ? &config_.key : nullptr, buf);
  if (::sendto(fd_, buf, n, MSG_DONTWAIT | MSG_NOSIGNAL, reinterpret_cast<const sockaddr*>(&cur_.from), cur_.from_len) ==
      ssize_t(n))
    stats_.forces.fetch_add(1, std::memory_order_relaxed);
  else
    stats_.send_errors.fetch_add(1, std::memory_order_relaxed);
}

std::string UdpDevice::summary() const {
  auto n = [](const std::atomic<std::uint64_t>& a) { return std::to_string(a.load(std::memory_order_relaxed)); };
  std::string s = "udp " + bound_ + ": " + n(stats_.poses) + " poses, " + n(stats_.gaps) + " seq gaps, " +
                  n(stats_.forces) + " forces sent (" + n(stats_.send_errors) + " failed), " + n(stats_.fades) +
                  " fade-outs; refused: " + n(stats_.malformed) + " malformed, " + n(stats_.stale) + " stale, " +
                  n(stats_.foreign) + " foreign, " + n(stats_.unauthenticated) + " unauthenticated, " +
                  n(stats_.old_version) + " old-version, " + n(stats_.jumps) + " seq jumps, " + n(stats_.busy) +
                  " busy; " + n(stats_.sessions) + " sessions; slew-limited ticks: " + n(stats_.pose_limited) +
                  " pose, " + n(stats_.force_limited) + " force";
  if (stats_.malformed.load(std::memory_order_relaxed))
    s += std::string(" (last malformed: ") + to_string(PoseReject(stats_.last_reject.load(std::memory_order_relaxed))) +
         ")";
  s += config_.auth == BridgeAuth::kHmac ? "; authenticated (HMAC-SHA256)" : "; NOT authenticated (auth = none)";
  return s;
}

}  // namespace st::rt
