// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// UdpDevice: a Device fed by a real haptic device's driver program over UDP (the bridge). The
/// driver (a loop around OpenHaptics, Force Dimension's SDK, CHAI3D or libnifalcon; see
/// examples/udp_device_emulator.py) sends one pose datagram per servo tick of its own and reads
/// back the force datagrams the servo sends every tick.
//
// Wire format, version 1, little-endian, one message per datagram (docs/user-guide/devices.md, "A bridge for real
// devices"):
//
//   pose, driver -> spheretouch, 80 bytes        force, spheretouch -> driver, 64 bytes
//   0  u32 magic "STHP"                          0  u32 magic "STHF"
//   4  u16 version (1)                           4  u16 version (1)
//   6  u16 buttons (reported, not used)          6  u16 flags (kForceFading, kForceNoPose)
//   8  u64 seq (+1 per pose)                     8  u64 seq (+1 per force sent)
//   16 i64 device_ns (driver's clock at          16 u64 pose_seq (newest pose taken)
//          sampling)                             24 i64 pose_device_ns (its device_ns, echoed)
//   24 f64 x, y, z: tool tip, device mm          32 f64 fx, fy, fz: force, N, device axes
//   48 f64 qw, qx, qy, qz: orientation (unit)    56 i64 servo_ns (the servo's clock when sent)
//
// The tool tip maps to the object as tip_object = scale · tip_device + offset; the orientation
// turns the probe about its tip (identity: the probe as the scene holds it). Echoing device_ns
// lets the driver measure pose-to-force time on its own clock.
//
// What the bridge promises: poses are read and checked on a receiver thread; the haptic thread
// only takes the newest valid pose from a triple buffer (it never waits, never parses). A
// datagram of the wrong size, magic or version, with non-finite or out-of-range numbers, a
// quaternion off unit length by more than 1e-3, a sequence number not newer than the last, or
// from another address than the first valid driver (the peer is latched, or pinned by config)
// is counted and dropped. A driver that goes silent for silence_ms has its force faded to zero
// over fade_ms; when it comes back the force fades in again over fade_ms.
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

inline constexpr std::uint32_t kPoseMagic = 0x50485453u;   ///< "STHP" little-endian
inline constexpr std::uint32_t kForceMagic = 0x46485453u;  ///< "STHF" little-endian
inline constexpr std::uint16_t kBridgeVersion = 1;         ///< the wire format's version
///@{
inline constexpr std::size_t kPoseBytes = 80, kForceBytes = 64;  ///< datagram sizes, bytes
///@}
inline constexpr std::uint16_t kForceFading = 1;  ///< the force is being faded (driver silent or just back)
inline constexpr std::uint16_t kForceNoPose = 2;  ///< no valid pose yet: the force is zero

/// A pose datagram's fields.
struct PosePacket {
  std::uint16_t buttons = 0;            ///< reported, not used
  std::uint64_t seq = 0;                ///< +1 per pose
  std::int64_t device_ns = 0;           ///< the driver's clock at sampling
  std::array<double, 3> tip{};          ///< device mm
  std::array<double, 4> q{1, 0, 0, 0};  ///< w, x, y, z
};
/// A force datagram's fields.
struct ForcePacket {
  std::uint16_t flags = 0;  ///< kForceFading, kForceNoPose
  ///@{
  std::uint64_t seq = 0, pose_seq = 0;  ///< +1 per force sent; the newest pose taken
  ///@}
  ///@{
  std::int64_t pose_device_ns = 0, servo_ns = 0;  ///< that pose's device_ns (echoed); the servo's clock when sent
  ///@}
  std::array<double, 3> force{};  ///< N
};

/// Why a datagram was refused (kOk: accepted as a pose).
enum class PoseReject : std::uint8_t { kOk, kSize, kMagic, kVersion, kNonFinite, kRange, kQuaternion };
const char* to_string(PoseReject r);  ///< the reason in words, for messages

/// Encodes a pose (kPoseBytes bytes into out).
void encode_pose(const PosePacket& p, std::uint8_t* out);
/// Decodes and checks a pose datagram of `n` bytes: sizes, magic, version, finite numbers, |tip| <=
/// max_abs_mm, a unit quaternion within 1e-3 (returned normalised).
PoseReject decode_pose(const std::uint8_t* data, std::size_t n, double max_abs_mm, PosePacket& out);
/// Encodes a force (kForceBytes bytes into out).
void encode_force(const ForcePacket& f, std::uint8_t* out);
/// Decodes a force datagram; false unless it has the size, magic and version of one.
bool decode_force(const std::uint8_t* data, std::size_t n, ForcePacket& out);

/// Settings of `[device] kind = "udp"`.
struct UdpDeviceConfig {
  std::string bind = "127.0.0.1:7600";  ///< address:port to listen on (loopback by default; "[::1]:P" for IPv6)
  std::string peer;                     ///< "" = latch the first valid driver; else only this address:port
  double silence_ms = 20;               ///< no pose for this long: the force fades out
  double fade_ms = 50;                  ///< fade length, both ways
  double scale = 1;                     ///< device mm -> object mm
  std::array<double, 3> offset_mm{};    ///< object mm added after scaling
  double max_abs_mm = 1e6;              ///< a tip coordinate beyond this is refused
  double max_force_N = 10;              ///< the device's peak force
};
inline UdpDeviceConfig DefaultUdpDeviceConfig() { return {}; }  ///< loopback, latching the first driver

/// Counters (read while running, relaxed).
struct UdpDeviceStats {
  std::atomic<std::uint64_t> poses{0};      ///< valid poses taken by the receiver
  std::atomic<std::uint64_t> malformed{0};  ///< wrong size, magic, version, numbers or quaternion
  std::atomic<std::uint64_t> stale{0};      ///< sequence number not newer than the last
  std::atomic<std::uint64_t> foreign{0};    ///< from another address than the driver's
  std::atomic<std::uint64_t> gaps{0};    ///< sequence numbers the servo never saw (lost, or overtaken by a newer pose)
  std::atomic<std::uint64_t> forces{0};  ///< force datagrams sent
  std::atomic<std::uint64_t> send_errors{0};  ///< sendto failures (buffer full, peer gone)
  std::atomic<std::uint64_t> fades{0};        ///< times the force started fading out for silence
  std::atomic<std::uint16_t> last_reject{0};  ///< PoseReject of the last malformed datagram
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
  double max_force_N() const noexcept override { return config_.max_force_N; }

  const UdpDeviceStats& stats() const { return stats_; }  ///< counters, updated while running
  std::string address() const { return bound_; }          ///< the bound address:port (port resolved when 0)
  /// One line for the run's summary: poses, refusals by kind, forces, fades.
  std::string summary() const;

 private:
  struct Incoming {
    PosePacket p;
    std::int64_t arrival_ns = 0;
    sockaddr_storage from{};
    socklen_t from_len = 0;
  };
  UdpDevice(const UdpDeviceConfig& c, const Eigen::Isometry3d& grip, int fd, std::string bound,
            const sockaddr_storage& pinned, socklen_t pinned_len);
  void receive(sockaddr_storage peer, socklen_t peer_len) noexcept;  // the receiver thread (peer_len 0: latch)
  double gain(std::int64_t now_ns) noexcept;

  UdpDeviceConfig config_;
  Eigen::Isometry3d grip_;
  int fd_ = -1;
  std::string bound_;
  TripleBuffer<Incoming> in_;
  UdpDeviceStats stats_;
  std::atomic<bool> stop_{false};
  std::thread rx_;
  // Haptic thread only.
  Incoming cur_{};
  bool have_pose_ = false;
  std::uint64_t taken_seq_ = 0;
  double gain_ = 0;
  std::int64_t gain_ns_ = 0;
  bool fading_out_ = false;
  std::uint64_t force_seq_ = 0;
};

}  // namespace st::rt
