// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// <spheretouch/engine/run_engine.hpp>: RunEngine, the main job of `spheretouch run` as a library
/// (pkg-config `spheretouch-engine`, CMake `spheretouch::engine`). A probe touches an object with
/// force at 1 kHz: the haptic side (the servo: HapticLoop + HapticServo, or the servo as its own
/// process) never waits; the collision thread (CollisionLoop) answers poses with contact models,
/// colliding in its own thread or through a fleet of workers (scatter-gather); the triple buffers
/// live in a named shared-memory segment that `spheretouch monitor` can watch; telemetry goes to
/// a run directory.
///
/// The command line (src/app/cmd_run.cpp) owns what is about the terminal: arguments, signals,
/// the status line and where the summary is printed. A program drives the same engine:
///
///     auto e = RunEngine::prepare(scene, options);   // bodies, trees, script, backend, outputs
///     e->start();                                    // servo and collision thread running
///     while (e->poll(stop_requested, notes)) sleep 20 ms;  // until the duration or a stop
///     RunReport r = e->finish(0);                    // stopped; outputs written; the summary
///     e->save(r);                                    // summary.txt (and trace cleanup)
///
/// **Your own device** (a vendor SDK's: OpenHaptics, Force Dimension's dhd, libnifalcon, CHAI3D's
/// device layer): implement rt::Device (the rules are in <spheretouch/rt/device.hpp>) and set
/// RunOptions::device. Two ways to clock the servo:
///  * the engine's haptic thread ticks at the scene's `[haptic] rate_hz` and calls your device
///    (read_pose(), then command_force()): for a device whose driver keeps its newest pose in
///    memory (RunOptions::device_clocked = false, the default);
///  * your device's own servo callback (hdScheduleAsynchronous, a dhd loop) calls tick() once a
///    period and the engine starts no haptic thread (device_clocked = true): the pose the
///    callback just read becomes a force in the same call, with no wait for another thread's
///    tick. examples/custom_device.cpp does this.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <spheretouch/engine/distributed.hpp>
#include <spheretouch/engine/scene.hpp>
#include <spheretouch/rt/shm_status.hpp>
#include <spheretouch/geom/result.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {
class Device;
class PoseFeedDevice;
}  // namespace st::rt

namespace st::inline SPHERETOUCH_ABI::engine {

/// What the caller adds to a scene.
struct RunOptions {
  /// The servo as its own process (`spheretouch servo`, re-executed from /proc/self/exe: only
  /// the spheretouch executable can do this). Needs `scene_path`.
  bool split = false;
  std::string scene_path;  ///< the scene file (the split servo reads its settings from it)
  std::string shm_name;    ///< shared-memory segment ("" = /spheretouch-PID-RANDOM: this process, 16 random hex digits)
  ClientCurve curve;       ///< CURVE keys for worker daemons (empty: plain)
  /// Progress notes during prepare() and start() ("loading probe and object ..."); may be empty.
  std::function<void(const std::string&)> note;
  /// Set (to a signal number) to abandon start()'s wait for the split servo; may be null.
  const std::atomic<int>* stop = nullptr;
  /// A device of the caller's, used instead of the scene's `[device]` (its kind, UDP and script
  /// settings are not used; trajectory() is the scene's script, for a device that replays it).
  /// Not owned: it must outlive the engine. Not with `split`. Its max_force_N() lowers the
  /// scene's saturation peak when below it.
  rt::Device* device = nullptr;
  /// With `device`: the device's own periodic callback clocks the servo by calling tick(), and
  /// the engine starts no haptic thread. False: the engine's haptic thread polls the device.
  bool device_clocked = false;
};

/// A snapshot for a status line, read while the run goes on.
struct RunStatus {
  double elapsed_s = 0;               ///< since start()
  bool have_servo = false;            ///< the servo has published a status (the fields below)
  std::uint64_t ticks = 0;            ///< haptic ticks so far
  std::uint64_t misses = 0;           ///< haptic deadline misses so far
  double force_N = 0;                 ///< |force| commanded at the last tick
  std::uint64_t rounds = 0;           ///< collision rounds so far
  double round_ms = 0;                ///< the last round's latency
  std::uint32_t contacts = 0;         ///< the last round's contacts
  std::uint32_t workers_replied = 0;  ///< fleet only: workers that answered the newest round
  std::uint32_t workers_asked = 0;    ///< and workers asked
};

/// The end of a run: the summary (always complete, whatever happened to the files) and every
/// output that could not be written whole (the run then failed: exit status 1 in the CLI).
struct RunReport {
  std::string summary;                ///< the summary printed and saved (summary.txt)
  std::vector<std::string> failures;  ///< outputs not written whole, one message each
};

/// One run of a scene: prepare(), start(), poll() until it is over, finish(), save().
class RunEngine {
 public:
  /// Loads the bodies the scene names, their trees (from the cache when valid), the script;
  /// starts the fleet (when the scene has workers) and creates the run directory, the segment,
  /// the servo (in-process) and the collision loop. Nothing runs yet. Errors name the scene
  /// field, file or flag at fault.
  static Result<std::unique_ptr<RunEngine>> prepare(const Scene& scene, const RunOptions& options);
  ~RunEngine();
  RunEngine(const RunEngine&) = delete;
  RunEngine& operator=(const RunEngine&) = delete;

  /// Starts the servo (thread or process) and the collision thread; the run's clock starts here.
  Status start();
  /// One step of the run's watcher, to be called every ~20 ms: samples memory, watches the split
  /// servo and the collision side's silence (`notes` gets a line per event). False when the run
  /// is over: its duration passed, `stop_requested`, or (split) the servo process ended.
  bool poll(bool stop_requested, std::vector<std::string>& notes);
  /// The run so far.
  RunStatus status() const;
  /// Stops everything, writes the run's outputs (trace.json, contact.ply) and returns the
  /// summary. `signal`: the signal that stopped the run (0: it ran its course).
  RunReport finish(int signal);
  /// Writes the summary to summary.txt and removes the temporary per-tick files when the scene
  /// asked for no trace; failures are added to `report`.
  void save(RunReport& report);

  /// One servo tick at `now_ns` (CLOCK_MONOTONIC, rt::now_ns()), for RunOptions::device_clocked:
  /// call it from your device's servo callback once a period, after the device has its newest
  /// pose; the servo reads it (Device::read_pose), computes the force and commands it
  /// (Device::command_force) before tick() returns. Takes no lock, allocates nothing, never
  /// waits; one caller thread at a time. Calls before start() or after finish() (or without
  /// device_clocked) do nothing, so a callback may keep running around them. A gap of k periods
  /// between two calls counts k - 1 misses.
  void tick(std::int64_t now_ns) noexcept;
  /// The scene's trajectory (the built-in press-and-slide script or its `[device] script` file),
  /// probe pose in the object frame over time: what the simulated device plays, and what a
  /// caller's device may replay.
  const rt::Trajectory& trajectory() const;

  /// [device] kind = "browser": the device the live view's page drives (null otherwise).
  rt::PoseFeedDevice* pose_feed() const;
  const geom::Mesh& probe() const;   ///< the probe as loaded
  const geom::Mesh& object() const;  ///< the object as loaded (of several: the first)
  /// Every object as loaded with its placement (object file coordinates → world), scene order.
  std::vector<std::pair<const geom::Mesh*, geom::Pose>> placed_objects() const;
  /// The run's status area: servo and collision status, the scene reference and the view frames.
  const rt::ShmStatus& shm_status() const;
  const Scene& scene() const;              ///< the scene run
  std::string split() const;               ///< how the object was dealt to workers and why ("" without workers)
  const std::string& backend() const;      ///< "in the collision thread", "2 in-process workers", ...
  const std::string& servo_where() const;  ///< "servo thread" or "servo process pid N"
  const std::string& run_dir() const;      ///< the run directory
  const std::string& shm_name() const;     ///< the segment's name
  bool has_fleet() const;                  ///< collisions go through workers

 private:
  struct State;
  explicit RunEngine(std::unique_ptr<State> s);
  std::unique_ptr<State> s_;
};

}  // namespace st::engine
