// SPDX-License-Identifier: BSD-3-Clause
// A device of your own, run in-process by the installed run engine:
//   c++ -std=c++20 custom_device.cpp $(pkg-config --cflags --libs spheretouch-engine) -o custom_device
//   ./custom_device configs/small.toml [--seconds 5] [--compare] [--json]
//
// Vendor SDKs (OpenHaptics' hdScheduleAsynchronous, Force Dimension's dhd loop, libnifalcon, CHAI3D's
// device layer) run their own 1 kHz servo thread and call the program back once a period; inside
// the callback the program reads the handle's pose and sets the force the SDK sends to the motors.
// `VendorSdk` below stands in for such an SDK (its own thread and clock, a handle that replays the
// scene's press-and-slide trajectory); `VendorDevice` is the st::rt::Device spheretouch talks to;
// the callback calls RunEngine::tick(), which turns the pose just read into a force in the same call.
// With a real SDK, replace VendorSdk by the SDK's calls: nothing else changes.
//
// Prints the run's ticks, misses and pose-to-force time (SDK pose sample -> force handed back);
// --compare then runs the same scene with the engine's own simulated device (the miss rates of the
// two runs are comparable); --json prints the figures as one JSON object (perf/device_bench.sh).
#include <pthread.h>
#include <time.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <spheretouch/engine/run_engine.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/device.hpp>
#include <spheretouch/rt/histogram.hpp>

namespace {

/// A stand-in for a vendor SDK: a servo thread at `rate_hz` on its own absolute-deadline clock
/// that calls the user's callback each period with the handle's pose sampled just before.
class VendorSdk {
 public:
  using Callback = void (*)(void* user);
  explicit VendorSdk(double rate_hz) : period_ns_(std::int64_t(1e9 / rate_hz)) {}
  ~VendorSdk() { stop(); }
  /// The handle's motion (here: a recording it replays); before start().
  void set_handle_path(st::rt::Trajectory path) { path_ = std::move(path); }

  void start(Callback cb, void* user) {
    thread_ = std::thread([this, cb, user] {
      std::int64_t deadline = st::rt::now_ns();
      const std::int64_t t0 = deadline;
      while (!stop_.load(std::memory_order_relaxed)) {
        deadline += period_ns_;
        const timespec ts = st::rt::to_timespec(deadline);
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {}
        // The SDK samples the encoders, then runs the callback.
        sample_ns_ = st::rt::now_ns();
        const double t = double(sample_ns_ - t0) * 1e-9;
        handle_ = path_.at(std::fmod(t, path_.duration_s()));  // the recorded motion, replayed
        cb(user);
        motor_force_ = pending_force_;  // "sent to the motors" at the end of the tick
      }
    });
  }
  void stop() {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
    stop_.store(false);
  }
  // What the SDK offers inside the callback.
  const Eigen::Isometry3d& handle_pose() const { return handle_; }
  std::int64_t sample_ns() const { return sample_ns_; }
  void set_force(const Eigen::Vector3d& f) { pending_force_ = f; }
  double max_force_N() const { return 3.3; }  // a desktop device's peak force

 private:
  st::rt::Trajectory path_;
  std::int64_t period_ns_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  Eigen::Isometry3d handle_ = Eigen::Isometry3d::Identity();
  std::int64_t sample_ns_ = 0;
  Eigen::Vector3d pending_force_ = Eigen::Vector3d::Zero(), motor_force_ = Eigen::Vector3d::Zero();
};

/// The device spheretouch sees. Its calls run inside the SDK's callback (RunEngine::tick), so
/// they only read and write the SDK's state: no lock, no allocation, no blocking.
class VendorDevice final : public st::rt::Device {
 public:
  explicit VendorDevice(VendorSdk& sdk) : sdk_(sdk) {}
  bool read_pose(std::int64_t, Eigen::Isometry3d& pose) noexcept override {
    pose = sdk_.handle_pose();
    return true;
  }
  void command_force(std::int64_t, const Eigen::Vector3d& force_N) noexcept override {
    sdk_.set_force(force_N);
    pose_to_force_.record(st::rt::now_ns() - sdk_.sample_ns());
  }
  double max_force_N() const noexcept override { return sdk_.max_force_N(); }
  const st::rt::LatencyHistogram& pose_to_force() const { return pose_to_force_; }

 private:
  VendorSdk& sdk_;
  st::rt::LatencyHistogram pose_to_force_;
};

struct RunFigures {
  std::uint64_t ticks = 0, misses = 0;
  double peak_force_N = 0;
};

/// Runs the scene for its duration; `sdk` null = the scene's own device. Prints the summary.
bool run(const st::engine::Scene& scene, VendorSdk* sdk, VendorDevice* device, RunFigures& fig) {
  st::engine::RunOptions options;
  options.device = device;
  options.device_clocked = device != nullptr;
  st::Result<std::unique_ptr<st::engine::RunEngine>> prepared = st::engine::RunEngine::prepare(scene, options);
  if (!prepared) {
    std::fprintf(stderr, "custom_device: %s\n", prepared.error().c_str());
    return false;
  }
  st::engine::RunEngine& engine = *prepared.value();
  if (sdk) sdk->set_handle_path(engine.trajectory());  // the scene's press-and-slide, replayed
  if (st::Status s = engine.start(); !s) {
    std::fprintf(stderr, "custom_device: %s\n", s.error().c_str());
    return false;
  }
  // The SDK's callback: one servo tick of the engine per period.
  if (sdk) sdk->start([](void* e) { static_cast<st::engine::RunEngine*>(e)->tick(st::rt::now_ns()); }, &engine);
  std::vector<std::string> notes;
  while (engine.poll(false, notes)) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const st::engine::RunStatus status = engine.status();
  if (sdk) sdk->stop();
  st::engine::RunReport report = engine.finish(0);
  engine.save(report);
  std::fputs(report.summary.c_str(), stderr);
  fig.ticks = status.ticks;
  fig.misses = status.misses;
  return report.failures.empty();
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_path;
  double seconds = 5;
  bool compare = false, json = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--seconds") && i + 1 < argc)
      seconds = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--compare"))
      compare = true;
    else if (!std::strcmp(argv[i], "--json"))
      json = true;
    else if (argv[i][0] != '-' && scene_path.empty())
      scene_path = argv[i];
    else {
      std::fprintf(stderr, "usage: custom_device SCENE.toml [--seconds S] [--compare] [--json]\n");
      return 2;
    }
  }
  if (scene_path.empty() || !(seconds > 0)) {
    std::fprintf(stderr, "usage: custom_device SCENE.toml [--seconds S] [--compare] [--json]\n");
    return 2;
  }
  st::Result<st::engine::Scene> loaded = st::engine::load_scene(scene_path);
  if (!loaded) {
    std::fprintf(stderr, "custom_device: %s\n", loaded.error().c_str());
    return 2;
  }
  st::engine::Scene scene = loaded.value();
  scene.duration_s = seconds;
  scene.write_trace = scene.write_perfetto = scene.write_ply = false;  // the summary is enough here
  const std::string out =
      (std::filesystem::temp_directory_path() / ("custom_device-" + std::to_string(getpid()))).string();
  scene.out_dir = out + "/vendor";

  VendorSdk sdk(scene.haptic.rate_hz);
  VendorDevice device(sdk);
  RunFigures vendor, builtin;
  bool ok = run(scene, &sdk, &device, vendor);
  if (ok && compare) {
    scene.out_dir = out + "/builtin";
    ok = run(scene, nullptr, nullptr, builtin);
  }
  std::filesystem::remove_all(out);
  const st::rt::LatencyHistogram& h = device.pose_to_force();
  const double p50 = double(h.percentile_ns(0.5)) / 1e3, p99 = double(h.percentile_ns(0.99)) / 1e3,
               mx = double(h.max_ns()) / 1e3;
  if (json) {
    std::printf(
        "{\"seconds\": %.1f, \"vendor_ticks\": %llu, \"vendor_misses\": %llu, \"pose_to_force_us_p50\": %.2f, "
        "\"pose_to_force_us_p99\": %.2f, \"pose_to_force_us_max\": %.2f, \"forces\": %llu",
        seconds, (unsigned long long)vendor.ticks, (unsigned long long)vendor.misses, p50, p99, mx,
        (unsigned long long)h.count());
    if (compare)
      std::printf(", \"builtin_ticks\": %llu, \"builtin_misses\": %llu", (unsigned long long)builtin.ticks,
                  (unsigned long long)builtin.misses);
    std::printf("}\n");
  } else {
    std::printf(
        "vendor callback device: %llu ticks, %llu misses; pose-to-force p50 %.1f us, p99 %.1f us, max %.1f us\n",
        (unsigned long long)vendor.ticks, (unsigned long long)vendor.misses, p50, p99, mx);
    if (compare)
      std::printf("built-in simulated device: %llu ticks, %llu misses\n", (unsigned long long)builtin.ticks,
                  (unsigned long long)builtin.misses);
  }
  // The run worked when the callback ticked the servo (about one force a period).
  return ok && h.count() > 0 && vendor.ticks > 0 ? 0 : 1;
}
