// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// UdpDevice: a Device fed by a real haptic device's driver program over UDP (the bridge). The
/// driver (a loop around OpenHaptics, Force Dimension's SDK, CHAI3D or libnifalcon; see
/// examples/udp_device_emulator.py) sends one pose datagram per servo tick of its own and reads
/// back the force datagrams the servo sends every tick.
//
// Wire format, version 2 (and the legacy version 1), little-endian, one message per datagram
// (docs/user-guide/devices.md, "A bridge for real devices"):
//
//   pose, driver -> spheretouch, 120 bytes        force, spheretouch -> driver, 128 bytes
//   0  u32 magic "STHP"                           0  u32 magic "STHF"
//   4  u16 version (2)                            4  u16 version (2)
//   6  u16 buttons (reported, not used)           6  u16 flags (kForceFading, kForceNoPose, kForceLimited)
//   8  u64 session (the driver's, random, != 0)   8  u64 session (echoed)
//   16 u64 seq (+1 per pose)                      16 u64 seq (+1 per force sent)
//   24 i64 device_ns (driver's clock at           24 u64 pose_seq (newest pose taken)
//          sampling)                              32 i64 pose_device_ns (its device_ns, echoed)
//   32 f64 x, y, z: tool tip, device mm           40 f64 fx, fy, fz: force, N, device axes
//   56 f64 qw, qx, qy, qz: orientation (unit)     64 f64 tx, ty, tz: torque about the tool centre point, N·m
//   88 u8[32] tag: HMAC-SHA256(key, bytes 0-87)   88 i64 servo_ns (the servo's clock when sent)
//                                                 96 u8[32] tag: HMAC-SHA256(key, bytes 0-95)
//
//   refusal, spheretouch -> a refused sender, 80 bytes (never more than the datagram it answers):
//   0 u32 magic "STHR", 4 u16 version (2), 6 u16 reason (BridgeRefusal), 8 u64 session (echoed,
//   0 for version 1), 16 char[64] the reason in words, NUL-padded. Not authenticated: a driver
//   reports it and never acts on it.
//
// Version 1 (80-byte pose, 64-byte force: the same fields without session, torque and tag, in
// that order) is spoken only to a scene that turns authentication off (`[device] auth = "none"`);
// otherwise a version-1 pose gets a refusal (kRefusedVersion) and is counted.
//
// The tool tip maps to the object as tip_object = scale · tip_device + offset; the orientation
// turns the probe about its tip (identity: the probe as the scene holds it). Echoing device_ns
// lets the driver measure pose-to-force time on its own clock.
//
// What the bridge promises: poses are read, authenticated and checked on a receiver thread; the
// haptic thread only takes the newest valid pose from a triple buffer (it never waits, never
// parses). Authentication (auth = "hmac", the default): every pose and force carries an
// HMAC-SHA256 tag under a 32-byte key the run and the driver share (a key file, or one the run
// makes for itself); a datagram whose tag does not verify is counted and dropped, so a forged
// source address gains nothing. Sessions: the driver picks a random session id when it starts;
// the bridge serves one session at a time and takes a new one (a restarted driver, another
// program) only once the current one has been silent for session_timeout_ms, never one it served
// before. Within a session a sequence number must be newer than the last and at most
// max_seq_jump ahead of it. A datagram of the wrong size, magic or version, with non-finite or
// out-of-range numbers, a quaternion off unit length by more than 1e-3, or from another address
// than a pinned peer is counted and dropped. Per tick, the pose handed to the servo moves at most
// max_pose_step_mm and max_rotation_step_deg toward the newest pose, and the force (torque) sent
// changes by at most max_force_step_N (max_torque_step_Nm): one bad pose or a glitch is a ramp,
// never a step. A driver that goes silent for silence_ms has its force faded to zero over fade_ms;
// when it comes back the force fades in again over fade_ms.
#pragma once
#include <spheretouch/abi.hpp>
#include <netinet/in.h>
#include <sys/socket.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/device.hpp>
#include <spheretouch/rt/triple_buffer.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

inline constexpr std::uint32_t kPoseMagic = 0x50485453u;     ///< "STHP" little-endian
inline constexpr std::uint32_t kForceMagic = 0x46485453u;    ///< "STHF" little-endian
inline constexpr std::uint32_t kRefusalMagic = 0x52485453u;  ///< "STHR" little-endian
inline constexpr std::uint16_t kBridgeVersion = 2;           ///< the wire format's version
inline constexpr std::uint16_t kBridgeLegacyVersion = 1;     ///< spoken only with auth = "none"
///@{
inline constexpr std::size_t kPoseBytes = 120, kForceBytes = 128, kRefusalBytes = 80;  ///< version-2 sizes, bytes
inline constexpr std::size_t kPoseBytesV1 = 80, kForceBytesV1 = 64;                    ///< version-1 sizes, bytes
///@}
inline constexpr std::size_t kBridgeKeyBytes = 32;  ///< HMAC-SHA256 key
inline constexpr std::size_t kBridgeTagBytes = 32;  ///< HMAC-SHA256 tag
inline constexpr std::uint16_t kForceFading = 1;    ///< the force is being faded (driver silent or just back)
inline constexpr std::uint16_t kForceNoPose = 2;    ///< no valid pose yet: the force is zero
inline constexpr std::uint16_t kForceLimited = 4;   ///< the force or torque was slew-limited this tick

/// The shared secret of an authenticated bridge.
using BridgeKey = std::array<std::uint8_t, kBridgeKeyBytes>;

/// A pose datagram's fields.
struct PosePacket {
  std::uint16_t version = kBridgeVersion;  ///< 2, or 1 (legacy: no session, no tag)
  std::uint16_t buttons = 0;               ///< reported, not used
  std::uint64_t session = 0;               ///< the driver's random session id (version 2)
  std::uint64_t seq = 0;                   ///< +1 per pose
  std::int64_t device_ns = 0;              ///< the driver's clock at sampling
  std::array<double, 3> tip{};             ///< device mm
  std::array<double, 4> q{1, 0, 0, 0};     ///< w, x, y, z
};
/// A force datagram's fields.
struct ForcePacket {
  std::uint16_t version = kBridgeVersion;  ///< 2, or 1 (to a legacy driver: no session, torque, tag)
  std::uint16_t flags = 0;                 ///< kForceFading, kForceNoPose, kForceLimited
  std::uint64_t session = 0;               ///< the pose's session, echoed (version 2)
  ///@{
  std::uint64_t seq = 0, pose_seq = 0;  ///< +1 per force sent; the newest pose taken
  ///@}
  ///@{
  std::int64_t pose_device_ns = 0, servo_ns = 0;  ///< that pose's device_ns (echoed); the servo's clock when sent
  ///@}
  std::array<double, 3> force{};   ///< N
  std::array<double, 3> torque{};  ///< N·m about the tool centre point (zero for a 3-DOF device; version 2)
};

/// Why a datagram was refused (kOk: accepted as a pose).
enum class PoseReject : std::uint8_t {
  kOk,
  kSize,
  kMagic,
  kVersion,
  kNonFinite,
  kRange,
  kQuaternion,
  kAuth,    ///< the tag does not verify under the key
  kLegacy,  ///< a version-1 pose where authentication is required
};
const char* to_string(PoseReject r);  ///< the reason in words, for messages

/// Why a refusal datagram was sent.
enum class BridgeRefusal : std::uint16_t {
  kRefusedVersion = 1,  ///< version 1 (unauthenticated) to a bridge that authenticates
  kBadTag = 2,          ///< the tag did not verify (wrong key)
  kBusy = 3,            ///< another session holds the device (retry after session_timeout_ms of its silence)
  kSessionUsed = 4,     ///< a session id the bridge served before (pick a new random one)
};
const char* to_string(BridgeRefusal r);  ///< the reason in words (at most 63 characters)

/// Encodes a pose; returns its size (kPoseBytes, or kPoseBytesV1 for p.version 1). A version-2
/// pose is tagged with `key` (all-zero tag when key is null: an unauthenticated bridge ignores it).
std::size_t encode_pose(const PosePacket& p, const BridgeKey* key, std::uint8_t* out);
/// Decodes and checks a pose datagram of `n` bytes: size, magic, version, the tag under `key`
/// (null: not checked, and version 1 accepted; else version 1 is kLegacy), finite numbers, |tip|
/// <= max_abs_mm, a unit quaternion within 1e-3 (returned normalised).
PoseReject decode_pose(const std::uint8_t* data, std::size_t n, double max_abs_mm, const BridgeKey* key, PosePacket& out);
/// Encodes a force; returns its size (kForceBytes, or kForceBytesV1 for f.version 1; tagged as encode_pose()).
std::size_t encode_force(const ForcePacket& f, const BridgeKey* key, std::uint8_t* out);
/// Decodes a force datagram; false unless it has the size, magic and version of one and (with a
/// key, version 2) a tag that verifies.
bool decode_force(const std::uint8_t* data, std::size_t n, const BridgeKey* key, ForcePacket& out);
/// Encodes a refusal (kRefusalBytes bytes into out).
void encode_refusal(BridgeRefusal why, std::uint64_t session, std::uint8_t* out);
/// Decodes a refusal; false unless it has the size, magic and version of one.
bool decode_refusal(const std::uint8_t* data, std::size_t n, BridgeRefusal& why, std::uint64_t& session);

/// True when this build can authenticate (it was built with libsodium).
bool bridge_auth_available();
/// A fresh random key (libsodium's CSPRNG); an error in a build without libsodium.
Result<BridgeKey> random_bridge_key();
/// Reads a key file: 64 hexadecimal digits on the first line, a regular file of at most 4 KiB
/// that group and others cannot access. Errors name the file and what was expected.
Result<BridgeKey> read_bridge_key(const std::string& path);
/// Writes a key file (mode 0600 from its creation; never follows a symlink, never replaces a
/// file unless `replace`).
Status write_bridge_key(const std::string& path, const BridgeKey& key, bool replace);

/// How the bridge authenticates.
enum class BridgeAuth : std::uint8_t {
  kHmac,  ///< version 2 with HMAC-SHA256 tags (the default)
  kNone,  ///< no authentication: version 2 with any tag, and version 1, are taken (a trusted link only)
};

/// Settings of `[device] kind = "udp"`.
struct UdpDeviceConfig {
  std::string bind = "127.0.0.1:7600";  ///< address:port to listen on (loopback by default; "[::1]:P" for IPv6)
  std::string peer;                     ///< "" = any address (the session decides); else only this address:port
  double silence_ms = 20;               ///< no pose for this long: the force fades out
  double fade_ms = 50;                  ///< fade length, both ways
  double scale = 1;                     ///< device mm -> object mm
  std::array<double, 3> offset_mm{};    ///< object mm added after scaling
  double max_abs_mm = 1e6;              ///< a tip coordinate beyond this is refused
  double max_force_N = 10;              ///< the device's peak force
  double max_torque_Nm = 0;             ///< the device's peak torque (0: a 3-DOF device, torque sent as zero)
  BridgeAuth auth = BridgeAuth::kHmac;  ///< authentication of poses and forces
  BridgeKey key{};                      ///< the shared key (auth = kHmac)
  double session_timeout_ms = 500;      ///< a new session is taken only after the current one is silent this long
  std::uint64_t max_seq_jump = 1000;    ///< a pose more than this many sequence numbers ahead is refused
  double max_pose_step_mm = 2;          ///< per tick: the tip handed to the servo moves at most this, device mm
  double max_rotation_step_deg = 5;     ///< per tick: the orientation turns at most this
  double max_force_step_N = 0.5;        ///< per tick: the force sent changes at most this
  double max_torque_step_Nm = 0.05;     ///< per tick: the torque sent changes at most this
};
inline UdpDeviceConfig DefaultUdpDeviceConfig() { return {}; }  ///< loopback, authenticated, any driver address
/// Checks a configuration's numbers; "" when fine, else the field and the reason.
std::string check(const UdpDeviceConfig& c);

/// Counters (read while running, relaxed).
struct UdpDeviceStats {
  std::atomic<std::uint64_t> poses{0};            ///< valid poses taken by the receiver
  std::atomic<std::uint64_t> malformed{0};        ///< wrong size, magic, version, numbers or quaternion
  std::atomic<std::uint64_t> unauthenticated{0};  ///< the tag did not verify
  std::atomic<std::uint64_t> old_version{0};      ///< version-1 poses refused (authentication required)
  std::atomic<std::uint64_t> stale{0};          ///< sequence number not newer than the last, or a session served before
  std::atomic<std::uint64_t> jumps{0};          ///< sequence number more than max_seq_jump ahead
  std::atomic<std::uint64_t> busy{0};           ///< another session's poses while the current one is live
  std::atomic<std::uint64_t> foreign{0};        ///< from another address than a pinned peer
  std::atomic<std::uint64_t> sessions{0};       ///< sessions started (a driver, a restarted driver)
  std::atomic<std::uint64_t> refusals_sent{0};  ///< refusal datagrams sent (at most 10 a second)
  std::atomic<std::uint64_t> gaps{0};  ///< sequence numbers the servo never saw (lost, or overtaken by a newer pose)
  std::atomic<std::uint64_t> pose_limited{0};   ///< ticks whose pose was slew-limited
  std::atomic<std::uint64_t> force_limited{0};  ///< ticks whose force or torque was slew-limited
  std::atomic<std::uint64_t> forces{0};         ///< force datagrams sent
  std::atomic<std::uint64_t> send_errors{0};    ///< sendto failures (buffer full, peer gone)
  std::atomic<std::uint64_t> fades{0};          ///< times the force started fading out for silence
  std::atomic<std::uint16_t> last_reject{0};    ///< PoseReject of the last malformed datagram
};

/// A Device fed over UDP by a real haptic device's driver program (the bridge).
class UdpDevice final : public Device {
 public:
  /// Opens and binds the socket and starts the receiver thread. `grip` maps probe file
  /// coordinates to the tool frame (tip at the origin, the scene's probe orientation), so
  /// pose = Trans(scale·tip + offset) · Rot(q) · grip.
  static Result<std::unique_ptr<UdpDevice>> open(const UdpDeviceConfig& config, const Eigen::Isometry3d& grip);
  ~UdpDevice() override;
  UdpDevice(const UdpDevice&) = delete;
  UdpDevice& operator=(const UdpDevice&) = delete;

  bool read_pose(std::int64_t now_ns, Eigen::Isometry3d& pose) noexcept override;
  void command_force(std::int64_t now_ns, const Eigen::Vector3d& force_N) noexcept override;
  /// Sends force and torque (version 2; a version-1 driver gets the force alone).
  void command_wrench(std::int64_t now_ns, const Eigen::Vector3d& force_N, const Eigen::Vector3d& torque_Nm) noexcept override;
  double max_force_N() const noexcept override { return config_.max_force_N; }
  double max_torque_Nm() const noexcept override { return config_.max_torque_Nm; }

  const UdpDeviceStats& stats() const { return stats_; }  ///< counters, updated while running
  std::string address() const { return bound_; }          ///< the bound address:port (port resolved when 0)
  /// One line for the run's summary: poses, refusals by kind, sessions, slew limits, forces, fades.
  std::string summary() const;

 private:
  struct Incoming {
    PosePacket p;
    std::int64_t arrival_ns = 0;
    std::uint64_t session_no = 0;  // +1 per session the receiver started
    sockaddr_storage from{};
    socklen_t from_len = 0;
  };
  UdpDevice(const UdpDeviceConfig& c, const Eigen::Isometry3d& grip, int fd, std::string bound,
            const sockaddr_storage& pinned, socklen_t pinned_len);
  void receive(sockaddr_storage pinned, socklen_t pinned_len) noexcept;  // the receiver thread (pinned_len 0: any)
  void refuse(BridgeRefusal why, std::uint64_t session, const sockaddr_storage& to, socklen_t to_len) noexcept;
  double gain(std::int64_t now_ns) noexcept;

  UdpDeviceConfig config_;
  Eigen::Isometry3d grip_;
  int fd_ = -1;
  std::string bound_;
  TripleBuffer<Incoming> in_;
  UdpDeviceStats stats_;
  std::atomic<bool> stop_{false};
  std::thread rx_;
  std::int64_t last_refusal_ns_ = 0;  // receiver thread: refusals are rate-limited
  // Haptic thread only.
  Incoming cur_{};
  bool have_pose_ = false;
  std::uint64_t taken_seq_ = 0;
  Eigen::Vector3d shown_tip_ = Eigen::Vector3d::Zero();          // the slew-limited tip, device mm
  Eigen::Quaterniond shown_q_ = Eigen::Quaterniond::Identity();  // and orientation
  Eigen::Vector3d sent_force_ = Eigen::Vector3d::Zero();         // what the last datagram carried
  Eigen::Vector3d sent_torque_ = Eigen::Vector3d::Zero();
  double gain_ = 0;
  std::int64_t gain_ns_ = 0;
  bool fading_out_ = false;
  std::uint64_t force_seq_ = 0;
};

}  // namespace st::rt
