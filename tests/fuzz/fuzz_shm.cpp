// SPDX-License-Identifier: BSD-3-Clause
// libFuzzer target: the shared-memory segment as its readers see it (rt/shm_segment.hpp). The
// input becomes the contents of a real POSIX shared-memory segment, any size; its creator pid
// and start time are set to this process (a live creator, as an attacker writing into a live
// run's segment has). Then the monitor's read-only attach reads the header and status (with the
// scene reference and the view frame, which a view checks before sending), and a read-write
// attach runs the haptic servo for a few ticks on the segment's pose and contact-model buffers
// (indices, flags, model contents all fuzzed).
// Properties, beyond "no crash, leak, UB or hang":
//  * every commanded force is finite and within the device limit;
//  * a view frame that passes rt::sanitize_view_frame has its counts within the frame, its face
//    ids within the meshes and finite numbers;
//  * a refused attach says why.
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "fuzz_check.hpp"
#include <spheretouch/rt/haptic_servo.hpp>
#include <spheretouch/rt/shm_segment.hpp>
#include <spheretouch/rt/simulated_device.hpp>

namespace {

using namespace st::rt;

Trajectory still_script() {
  Trajectory t;
  TimedPose a;
  a.t_s = 0;
  TimedPose b;
  b.t_s = 1;
  b.pose.translation() = Eigen::Vector3d(0.5, 0, -0.2);
  t.keys = {a, b};
  return t;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string name = "/spheretouch-fuzz-shm-" + std::to_string(::getpid());
  static const std::uint64_t my_ticks = process_start_ticks(::getpid());
  std::vector<std::uint8_t> b(data, data + size);
  if (b.size() >= sizeof(ShmHeader)) {
    const std::int32_t pid = ::getpid();
    std::memcpy(b.data() + offsetof(ShmHeader, creator_pid), &pid, sizeof pid);
    std::memcpy(b.data() + offsetof(ShmHeader, creator_start_ticks), &my_ticks, sizeof my_ticks);
  }
  const int fd = ::shm_open(name.c_str(), O_CREAT | O_RDWR | O_TRUNC, 0600);
  ST_FUZZ_CHECK(fd >= 0, "shm_open for the harness");
  ST_FUZZ_CHECK(::ftruncate(fd, static_cast<off_t>(b.size())) == 0, "ftruncate for the harness");
  if (!b.empty()) ST_FUZZ_CHECK(::pwrite(fd, b.data(), b.size(), 0) == static_cast<ssize_t>(b.size()), "pwrite");
  ::close(fd);

  // The monitor's view.
  auto ro = ShmSegment::attach_read_only(name);
  if (ro) {
    ServoStatus s;
    CollisionStatus c;
    (void)ro.value()->status().servo.load(s);
    (void)ro.value()->status().collision.load(c);
    SceneRef ref;
    (void)ro.value()->status().scene.load(ref);
    static auto frame = std::make_unique<ViewFrame>();
    constexpr std::uint32_t kFaces = 1000;  // the meshes a view would draw
    if (ro.value()->status().view.load(*frame, 8) && sanitize_view_frame(*frame, kFaces, kFaces)) {
      ST_FUZZ_CHECK(frame->n_probe <= kViewMaxFaces && frame->n_object <= kViewMaxFaces, "counts within the frame");
      for (std::uint32_t i = 0; i < frame->n_probe + frame->n_object; ++i)
        ST_FUZZ_CHECK(frame->faces[i] < kFaces, "face ids within the meshes");
      for (double v : frame->pose) ST_FUZZ_CHECK(std::isfinite(v), "pose finite");
      ST_FUZZ_CHECK(std::isfinite(frame->penetration_mm) && std::isfinite(frame->round_ms), "figures finite");
    }
    (void)ro.value()->creator_alive();
  } else {
    ST_FUZZ_CHECK(!ro.error().empty(), "a refused attach says why");
  }
  // The split servo's view: a few ticks on the segment's buffers.
  auto rw = ShmSegment::attach(name);
  if (rw) {
    ShmSegment& seg = *rw.value();
    SimulatedDevice dev(still_script(), VirtualUser{}, 64);
    HapticServo servo(dev, seg.poses(), seg.models(), ForceLaw{}, DefaultInterpolatorConfig(),
                      DefaultSaturationConfig(), nullptr, DefaultPassivityConfig(), 1e-3);
    for (int k = 0; k < 12; ++k) {
      TickInfo info;
      info.tick = info.deadline_index = std::uint64_t(k);
      info.deadline_ns = info.woke_ns = 1'000'000'000 + std::int64_t(k) * 1'000'000;
      info.period_ns = 1'000'000;
      servo.tick(info);
      PoseSample p;
      (void)seg.poses().read(p);  // the collision side's read
    }
    for (const ForceRecord& r : dev.records()) {
      ST_FUZZ_CHECK(r.force_N.allFinite(), "commanded force finite");
      ST_FUZZ_CHECK(r.force_N.norm() <= dev.max_force_N() * (1 + 1e-12), "commanded force within the device limit");
    }
  } else {
    ST_FUZZ_CHECK(!rw.error().empty(), "a refused attach says why");
  }
  ::shm_unlink(name.c_str());
  return 0;
}
