// SPDX-License-Identifier: BSD-3-Clause
// The run engine (run_engine.hpp).
#include <spheretouch/engine/run_engine.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <memory>
#include <optional>
#include <thread>
#include <tuple>

#include <spheretouch/collide.hpp>
#include <spheretouch/engine/collision_loop.hpp>
#include <spheretouch/engine/run_outputs.hpp>
#include <spheretouch/engine/servo_process.hpp>
#include <spheretouch/engine/text.hpp>
#include <spheretouch/engine/tree_cache.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/haptic_loop.hpp>
#include <spheretouch/rt/haptic_servo.hpp>
#include <spheretouch/rt/pose_feed_device.hpp>
#include <spheretouch/rt/shm_segment.hpp>
#include <spheretouch/rt/telemetry.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

namespace {

std::string new_run_dir(const std::string& wanted) {
  if (!wanted.empty()) return wanted;
  char stamp[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::localtime(&now));
  std::string dir = std::string("runs/") + stamp;
  for (int i = 2; std::filesystem::exists(dir); ++i) dir = std::string("runs/") + stamp + "-" + std::to_string(i);
  return dir;
}

}  // namespace

/// Everything a run holds, in construction order (the collision loop refers to the meshes, the
/// segment's buffers and the collide function; members are destroyed in reverse).
struct RunEngine::State {
  Scene s;
  RunOptions opt;
  // The meshes and their trees, loaded once and shared (the collider, the fleet's set-up, the
  // collision loop and the outputs use them).
  std::optional<Body> probe_body;
  std::vector<ObjectSpec> specs;    // the scene's objects (scene_objects)
  std::vector<Body> object_bodies;  // their meshes and trees, in the same order
  const geom::Mesh& probe() const { return probe_body->mesh(); }
  const geom::Mesh& object() const { return object_bodies.front().mesh(); }
  rt::Trajectory script;
  // Collision backend: a ComputeCollision in the collision thread, or a fleet of workers.
  std::vector<std::optional<ComputeCollision>> colliders;  // per object, made in the collision thread
  CollisionRequest request;
  CollisionResult result;
  std::string backend = "in the collision thread";
  std::unique_ptr<Fleet> fleet;
  net::RoundResult round;
  std::atomic<std::uint32_t> replied{0}, asked{0};  // newest round, for the status line
  CollideFn collide_fn;
  // Outputs and the real-time side.
  std::string dir, csv, rounds_csv;
  std::unique_ptr<rt::ForceLaw> law;
  std::unique_ptr<rt::ShmSegment> shm;
  bool truncated_noted = false;              // the segment was truncated under us (said once; the run stops)
  std::unique_ptr<rt::SimulatedDevice> sim;  // in-process servo (no split): device, telemetry, servo
  std::unique_ptr<rt::UdpDevice> udp;        // [device] kind = "udp" (instead of sim)
  std::unique_ptr<rt::PoseFeedDevice> feed;  // [device] kind = "browser": poses from the live view's page
  std::unique_ptr<rt::Telemetry> telemetry;
  std::unique_ptr<rt::HapticServo> servo;
  std::unique_ptr<rt::HapticLoop> loop;
  std::unique_ptr<CollisionLoop> collision;
  std::unique_ptr<ViewFeed> view;  // frames for a live viewer, into the segment's status area
  std::string script_file;         // split: the trajectory as a file for the servo process
  // Running.
  bool started = false, finished = false;
  pid_t servo_pid = 0;
  std::string servo_where = "servo thread";
  // A caller's device clocked by its own callback (RunOptions::device_clocked): tick() runs the
  // servo. `accepting` opens at start() and closes at finish(), which then waits for a tick in
  // progress (in_tick) to end; both sides use sequentially consistent stores and loads.
  std::atomic<bool> accepting{false}, in_tick{false};
  std::uint64_t ext_ticks = 0, ext_misses = 0;
  std::int64_t ext_last_ns = 0;
  bool device_clocked() const { return opt.device != nullptr && opt.device_clocked; }
  std::int64_t t_start = 0, t_end = 0;
  int servo_exit = -1;     // split: the servo process's exit code once it ended
  bool forwarded = false;  // split: a stop was passed on to the servo
  std::int64_t forwarded_ns = 0;
  std::unique_ptr<SilenceWatch> silence;
  // Resident memory after one second of running (trees, buffers and connections in place) and at
  // the end: a long run must not grow (the soak test's target is < 1 MB).
  std::uint64_t rss_start = 0, rss_end = 0;

  void note(const std::string& m) const {
    if (opt.note) opt.note(m);
  }
  Status prepare();
  void stop_all();
  std::vector<const geom::Mesh*> object_meshes() const {
    std::vector<const geom::Mesh*> m;
    for (const Body& b : object_bodies) m.push_back(&b.mesh());
    return m;
  }
  /// The collision loop's world: every object with its placement and bounding sphere.
  std::vector<WorldObject> world() const {
    std::vector<WorldObject> w;
    for (std::size_t k = 0; k < object_bodies.size(); ++k)
      w.push_back({&object_bodies[k].mesh(), specs[k].placement.pose(), object_bodies[k].bounding_sphere()});
    return w;
  }
};

Status RunEngine::State::prepare() {
  // Before any thread exists (ours, libzmq's): lock_memory keeps every thread's stack resident whole.
  if (s.thread_stack_bytes)
    if (Status st = rt::set_default_thread_stack(s.thread_stack_bytes); !st)
      return fail(s.file, ": haptic.thread_stack_kb: ", st.error());
  if (opt.split && opt.scene_path.empty()) return fail("run: the split servo needs the scene file (scene_path)");
  if (opt.device && opt.split)
    return fail("run: a caller's device (RunOptions::device) drives the in-process servo: not with the split servo");
  if (opt.device_clocked && !opt.device) return fail("run: RunOptions::device_clocked needs RunOptions::device");

  // Only the bodies the scene names are loaded; trees come from the cache when valid.
  specs = scene_objects(s);
  note(specs.size() == 1 ? "loading probe and object ..."
                         : "loading probe and " + std::to_string(specs.size()) + " objects ...");
  Result<geom::Mesh> pm = load_body(s.probe, "probe");
  if (!pm) return fail(s.file, ": ", pm.error());
  const std::string cache = s.tree_cache ? default_tree_cache_dir() : "";
  bool cached = true;
  std::size_t object_faces = 0;
  auto make_body = [&](Result<geom::Mesh>& mesh, const std::string& field) -> Result<Body> {
    Result<CachedTree> t = tree_for(mesh.value(), s.tree, cache);
    if (!t) return Error{t.error()};
    if (!t.value().note.empty()) note("tree cache: " + t.value().note);
    if (&mesh != &pm) cached = cached && t.value().source == TreeSource::cached;
    Result<Body> b = Body::make(std::make_shared<const geom::Mesh>(std::move(mesh).value()),
                                std::make_shared<const geom::SphereTree>(std::move(t.value().tree)));
    if (!b) return fail(s.file, ": ", field, ": ", b.error());
    return b;
  };
  {
    Result<Body> b = make_body(pm, "probe");
    if (!b) return Error{b.error()};
    probe_body.emplace(std::move(b).value());
  }
  for (std::size_t k = 0; k < specs.size(); ++k) {
    const std::string field = s.objects.empty() ? "object" : "object[" + std::to_string(k + 1) + "]";
    Result<geom::Mesh> om = load_body(specs[k].body, field);
    if (!om) return fail(s.file, ": ", om.error());
    Result<Body> b = make_body(om, field);
    if (!b) return Error{b.error()};
    object_faces += b.value().mesh().num_faces();
    object_bodies.push_back(std::move(b).value());
  }
  colliders.resize(specs.size());
  {
    char line[200];
    if (specs.size() == 1)
      std::snprintf(line, sizeof line, "probe %zu faces, object %zu faces; trees %s", probe().num_faces(),
                    object().num_faces(), cached ? "from the cache" : "built");
    else
      std::snprintf(line, sizeof line, "probe %zu faces, %zu objects of %zu faces in all; trees %s",
                    probe().num_faces(), specs.size(), object_faces, cached ? "from the cache" : "built");
    note(line);
  }

  if (s.device.kind == "browser" && opt.split)
    return fail(s.file, ": device.kind = \"browser\" drives the run's own servo thread (not --split)");
  if (!opt.device && (s.device.kind == "udp" || s.device.kind == "browser")) {
    // A device drives the probe; the script is the grip (for the split servo, as a one-pose trajectory).
    script.keys = {rt::TimedPose{0.0, probe_grip(s, probe())}};
  } else if (s.device.script == "builtin") {
    script = builtin_script(s, probe(), object_meshes());
  } else {
    Result<rt::Trajectory> t = rt::load_trajectory(s.device.script);
    if (!t) return Error{t.error()};
    script = std::move(t).value();
  }

  // Collision backend. Workers and daemons plug in here (scatter-gather); 0 = this thread.
  request.approximate_layer = s.approx_layer;
  // Pairs in (probe, object) order, as the workers' merge gives them: the contact model is then
  // the same at every worker count, and the builder need not sort them.
  request.sort_pairs = true;
  collide_fn = [this](std::uint64_t, std::uint32_t k, const geom::Pose& pose, RoundOutput& out) {
    std::optional<ComputeCollision>& collider = colliders[k];
    if (!collider) {  // in the collision thread: its caches
      collider.emplace(*probe_body, object_bodies[k]);
      collider->set_coherent(s.coherent);
    }
    collider->at_relative(pose, request, result);
    out.pairs.assign(result.pairs.begin(), result.pairs.end());
  };
  if (!s.endpoints.empty() || s.workers > 0) {
    if (s.approx_layer != geom::kExact)
      return fail(s.file, ": collision.mode = \"approximate\" runs without workers (set workers.count = 0)");
    FleetSpec spec;
    spec.workers = s.workers;
    spec.endpoints = s.endpoints;
    spec.layer = s.layer;
    spec.block_size = s.block_size;
    spec.mapping = s.mapping;
    // A contact region for the automatic split: a quarter of the probe's bounding sphere (the
    // patch a hand or tool presses into a surface), in object millimetres.
    spec.contact_radius = 0.25 * probe_body->bounding_sphere().radius;
    spec.leaf_faces = s.tree.leaf_faces;
    spec.miss_limit = std::uint32_t(s.down_after);
    // "auto": daemons run on other machines, whose collision thread waits idle for their replies;
    // in-process workers share this machine's cores with it.
    spec.assist_blocks =
        s.assist_blocks >= 0 ? std::uint32_t(s.assist_blocks) : (spec.endpoints.empty() ? 0u : kAutoAssistBlocks);
    spec.coherent = s.coherent;
    spec.replicas = s.replicas;
    spec.distinct_faces = false;  // the contact model counts the contacts: the pairs are all it needs
    spec.curve = opt.curve;
    spec.note = opt.note;
    note("starting workers and loading their blocks ...");
    std::vector<FleetObject> fobjects;
    for (const Body& b : object_bodies) fobjects.push_back({&b.mesh(), &b.tree()});
    Result<std::unique_ptr<Fleet>> f = start_fleet(spec, probe(), fobjects);
    if (!f) return Error{f.error()};
    fleet = std::move(f).value();
    backend = fleet->description;
    const auto deadline = std::chrono::microseconds(std::int64_t(s.deadline_ms * 1000));
    collide_fn = [this, deadline, local = collide_fn](std::uint64_t seq, std::uint32_t k, const geom::Pose& pose,
                                                      RoundOutput& out) {
      if (!fleet->clients[k]) return local(seq, k, pose, out);  // too small to deal: this thread answers it
      fleet->clients[k]->round(seq, pose, net::Clock::now() + deadline, round);
      out.pairs.resize(round.pairs.size());
      for (std::size_t i = 0; i < round.pairs.size(); ++i) out.pairs[i] = {round.pairs[i].probe, round.pairs[i].object};
      out.complete = round.complete;
      replied.store(round.workers_replied, std::memory_order_relaxed);
      asked.store(round.workers_asked, std::memory_order_relaxed);
    };
  }

  dir = new_run_dir(s.out_dir);
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  // Run outputs (poses, forces, the contact state) are the user's: the directory is private.
  if (!ec)
    std::filesystem::permissions(dir, std::filesystem::perms::owner_all, std::filesystem::perm_options::replace, ec);
  if (ec) return fail(dir, ": cannot create the run directory (", ec.message(), ")");
  // The UDP bridge's key, made here for this run unless the scene names one: the split servo
  // reads it from the run directory.
  rt::UdpDeviceConfig udp_config;
  if (!opt.device && s.device.kind == "udp") {
    Result<rt::UdpDeviceConfig> uc = udp_device_config(s, dir, true);
    if (!uc) return Error{uc.error()};
    udp_config = uc.value();
    if (udp_config.auth == rt::BridgeAuth::kNone)
      note("udp device: auth = \"none\": datagrams are not authenticated; anyone who can send to " + udp_config.bind +
           " from the driver's address can move the probe (a trusted link only)");
    else if (s.device.key_file.empty())
      note("udp device: this run's key is in " + bridge_key_path(dir) + " (give it to the driver: --key)");
  }

  Result<rt::ForceLaw> made = rt::ForceLaw::make(s.law);
  if (!made) return fail(s.file, ": ", made.error());
  law = std::make_unique<rt::ForceLaw>(made.value());

  // The triple buffers live in a named shared-memory segment in both modes, so `spheretouch
  // monitor` can watch any run; with a split servo the servo process attaches to it. The run
  // says at once which scene and meshes it loaded (monitor --view loads the same).
  const auto ref = std::make_unique<rt::SceneRef>(
      scene_ref(opt.scene_path.empty() ? "" : std::filesystem::absolute(opt.scene_path).string(), probe(), object()));
  // The default name has a random part: another user cannot create it first (squat) or guess it.
  const std::string shm_name =
      opt.shm_name.empty() ? "/spheretouch-" + std::to_string(getpid()) + "-" + random_hex(8) : opt.shm_name;
  Result<std::unique_ptr<rt::ShmSegment>> segr = rt::ShmSegment::create(shm_name);
  if (!segr) return Error{segr.error()};
  shm = std::move(segr).value();
  shm->guard_truncation();  // another process truncating it must not kill the run
  rt::ShmStatus& status = shm->status();
  status.scene.store(*ref);

  csv = dir + "/ticks.csv";
  rounds_csv = dir + "/rounds.csv";
  loop = std::make_unique<rt::HapticLoop>(s.haptic);
  if (!opt.split) {
    // Commanded forces go to the per-tick trace, not into device records: memory stays flat however long the run.
    rt::Device* device = nullptr;
    if (opt.device) {
      device = opt.device;  // the caller's: the scene's [device] kind is not used
    } else if (s.device.kind == "udp") {
      Result<std::unique_ptr<rt::UdpDevice>> u = rt::UdpDevice::open(udp_config, script.keys.front().pose);
      if (!u) return fail(s.file, ": ", u.error());
      udp = std::move(u).value();
      device = udp.get();
      note("udp device: listening on " + udp->address() + " (pose datagrams in, force datagrams out)");
    } else if (s.device.kind == "browser") {
      // The page starts the tip where the built-in script starts: above the target, off the surface.
      const geom::Pose grip = script.keys.front().pose;
      const geom::Vec3 home =
          (builtin_script(s, probe(), object_meshes()).keys.front().pose * grip.inverse()).translation();
      feed = std::make_unique<rt::PoseFeedDevice>(grip, home, s.saturation.peak_N);
      device = feed.get();
    } else {
      sim = std::make_unique<rt::SimulatedDevice>(script, s.device.user, 0, s.saturation.peak_N);
      sim->set_repeat(s.device.repeat);
      device = sim.get();
    }
    if (s.write_trace || s.write_perfetto) {
      Result<std::unique_ptr<rt::Telemetry>> t = rt::Telemetry::open(csv);
      if (!t) return Error{t.error()};
      telemetry = std::move(t).value();
    }
    servo = std::make_unique<rt::HapticServo>(*device, shm->poses(), shm->models(), *law, s.interp, s.saturation,
                                              telemetry.get(), s.passivity, 1.0 / s.haptic.rate_hz);
    servo->publish_status_to(&status.servo);
    rt::WrenchConfig wrench = s.device.wrench;
    wrench.tcp_mm = tool_point(s, probe());
    servo->set_wrench(wrench);
    if (Status m = set_servo_materials(*servo, s); !m) return m;
  } else {
    // The servo gets the trajectory as a file (it loads no meshes) and the scene for its settings.
    script_file = dir + "/script.txt";
    if (Status w = write_trajectory(script_file, script); !w) return w;
  }
  collision = std::make_unique<CollisionLoop>(probe(), probe_body->bounding_sphere(), world(), shm->poses(),
                                              shm->models(), collide_fn, s.collision_rate_hz, 0, s.contact);
  collision->publish_status_to(&status.collision);
  // Every run publishes view frames, so that a live view (run --view, or monitor --view
  // attached at any time) can show it.
  view = std::make_unique<ViewFeed>(status.view);
  collision->show_to(view.get());
  if (s.write_trace || s.write_perfetto)
    if (Status st = collision->write_rounds_csv(rounds_csv); !st) return st;
  silence = std::make_unique<SilenceWatch>(s.interp.stale_timeout_ns);
  return Ok{};
}

Result<std::unique_ptr<RunEngine>> RunEngine::prepare(const Scene& scene, const RunOptions& options) {
  auto st = std::make_unique<State>();
  st->s = scene;
  st->opt = options;
  if (Status p = st->prepare(); !p) return Error{p.error()};
  return std::unique_ptr<RunEngine>(new RunEngine(std::move(st)));
}

RunEngine::RunEngine(std::unique_ptr<State> s) : s_(std::move(s)) {}

RunEngine::~RunEngine() {
  if (s_->started && !s_->finished) {
    s_->stop_all();
    if (s_->servo_pid > 0) {  // never leave a servo process behind
      kill(s_->servo_pid, SIGKILL);
      int ws = 0;
      waitpid(s_->servo_pid, &ws, 0);
    }
  }
}

Status RunEngine::start() {
  State& e = *s_;
  rt::ShmStatus& status = e.shm->status();
  if (e.opt.split) {
    ServoArgs sa;
    sa.shm = e.shm->name();
    sa.scene = std::filesystem::absolute(e.opt.scene_path).string();
    sa.script = std::filesystem::absolute(e.script_file).string();
    sa.out = std::filesystem::absolute(e.dir).string();
    sa.duration_s = e.s.duration_s;
    sa.parent = getpid();
    sa.tcp_mm = tool_point(e.s, e.probe());
    Result<pid_t> sp = spawn_servo(sa);
    if (!sp) return Error{sp.error()};
    e.servo_pid = sp.value();
    // Wait until the servo ticks (or fails to start): its status says so.
    for (int i = 0; status.servo_state.load(std::memory_order_acquire) < std::uint32_t(rt::ServoState::running); ++i) {
      int ws = 0;
      if (waitpid(e.servo_pid, &ws, WNOHANG) == e.servo_pid) {
        e.servo_pid = 0;
        return fail("servo process (pid ", sp.value(), ") failed to start (exit ",
                    WIFEXITED(ws) ? WEXITSTATUS(ws) : 128 + WTERMSIG(ws), ")");
      }
      if (i > 1000 || (e.opt.stop && e.opt.stop->load())) {  // 10 s
        kill(e.servo_pid, SIGKILL);
        waitpid(e.servo_pid, &ws, 0);
        e.servo_pid = 0;
        return fail("servo process (pid ", sp.value(), ") did not start ticking within 10 s");
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    e.servo_where = "servo process pid " + std::to_string(e.servo_pid);
    e.collision->start();
  } else if (e.device_clocked()) {
    // The caller's callback ticks the servo (tick()); no haptic thread of ours.
    status.servo_start_ticks.store(rt::process_start_ticks(getpid()), std::memory_order_relaxed);
    status.servo_pid.store(getpid(), std::memory_order_relaxed);
    e.collision->start();
    e.servo_where = "the device's own callback";
    e.accepting.store(true);
    status.servo_state.store(std::uint32_t(rt::ServoState::running), std::memory_order_release);
  } else {
    status.servo_start_ticks.store(rt::process_start_ticks(getpid()), std::memory_order_relaxed);
    status.servo_pid.store(getpid(), std::memory_order_relaxed);
    status.servo_state.store(std::uint32_t(rt::ServoState::starting), std::memory_order_release);
    e.collision->start();
    Result<rt::RtReport> rep = e.loop->start(*e.servo);
    if (!rep) {
      e.collision->stop();
      return fail("haptic loop: ", rep.error());
    }
    if (!rep.value().all_applied() || rep.value().fifo.requested || rep.value().mlock.requested)
      e.note("real-time: " + rep.value().describe());
    status.servo_state.store(std::uint32_t(rt::ServoState::running), std::memory_order_release);
  }
  e.started = true;
  e.t_start = rt::now_ns();
  return Ok{};
}

bool RunEngine::poll(bool stop_requested, std::vector<std::string>& notes) {
  State& e = *s_;
  const std::int64_t now = rt::now_ns();
  if (rt::ShmSegment::truncated() && !e.truncated_noted) {
    e.truncated_noted = true;
    notes.push_back("the shared-memory segment " + e.shm->name() +
                    " was truncated by another process: its data is gone (zero force); stopping the run");
  }
  stop_requested = stop_requested || rt::ShmSegment::truncated();
  const double elapsed = double(now - e.t_start) * 1e-9;
  if (e.rss_start == 0 && elapsed >= std::min(1.0, e.s.duration_s / 2)) e.rss_start = rt::resident_bytes();
  if (e.opt.split) {
    // The servo ends the run (its duration, or a stop we forward); never wait forever.
    int ws = 0;
    if (waitpid(e.servo_pid, &ws, WNOHANG) == e.servo_pid) {
      e.servo_exit = WIFEXITED(ws) ? WEXITSTATUS(ws) : 128 + WTERMSIG(ws);
      return false;
    }
    if ((stop_requested || elapsed > e.s.duration_s + 10) && !e.forwarded) {
      kill(e.servo_pid, SIGTERM);  // it stops ticking, writes its outputs and exits
      e.forwarded = true;
      e.forwarded_ns = now;
    } else if (e.forwarded && now - e.forwarded_ns > 5'000'000'000) {
      kill(e.servo_pid, SIGKILL);  // unresponsive for 5 s: do not hang the run
    }
  } else {
    if (stop_requested || elapsed >= e.s.duration_s) return false;
    rt::ServoStatus ss;
    if (e.shm->status().servo.load(ss)) {
      const std::string msg = e.silence->poll(ss, now);
      if (!msg.empty()) notes.push_back(msg);
    }
  }
  return true;
}

RunStatus RunEngine::status() const {
  const State& e = *s_;
  RunStatus r;
  r.elapsed_s = e.started ? double(rt::now_ns() - e.t_start) * 1e-9 : 0.0;
  rt::ServoStatus ss;
  r.have_servo = e.shm->status().servo.load(ss);
  if (r.have_servo) {
    r.ticks = ss.ticks;
    r.misses = ss.misses;
    r.force_N = std::sqrt(ss.force_N[0] * ss.force_N[0] + ss.force_N[1] * ss.force_N[1] + ss.force_N[2] * ss.force_N[2]);
  }
  r.rounds = e.collision->rounds();
  r.round_ms = double(e.collision->last_latency_ns()) * 1e-6;
  r.contacts = e.collision->last_contacts();
  r.workers_replied = e.replied.load(std::memory_order_relaxed);
  r.workers_asked = e.asked.load(std::memory_order_relaxed);
  return r;
}

void RunEngine::tick(std::int64_t now_ns) noexcept {
  State& e = *s_;
  e.in_tick.store(true);
  if (!e.accepting.load() || !e.device_clocked()) {  // before start(), after finish(), or not ours to call
    e.in_tick.store(false);
    return;
  }
  // Misses are periods without a call: a gap of k periods (rounded) after the previous tick
  // misses k - 1 of them. Measured from gaps, not from the first tick's phase, so a device
  // clock running a little fast or slow against [haptic] rate_hz does not count as misses.
  const std::int64_t period = e.loop->period_ns();
  rt::TickInfo info;
  info.tick = e.ext_ticks;
  if (e.ext_ticks > 0 && now_ns > e.ext_last_ns) {
    const std::int64_t periods = std::max<std::int64_t>(1, (now_ns - e.ext_last_ns + period / 2) / period);
    e.ext_misses += std::uint64_t(periods - 1);
  }
  info.deadline_index = e.ext_ticks + e.ext_misses;
  info.deadline_ns = now_ns;
  info.woke_ns = now_ns;
  info.period_ns = period;
  e.servo->tick(info);
  ++e.ext_ticks;
  e.ext_last_ns = now_ns;
  e.in_tick.store(false);
}

void RunEngine::State::stop_all() {
  if (device_clocked()) {
    accepting.store(false);
    while (in_tick.load()) std::this_thread::sleep_for(std::chrono::microseconds(20));  // one tick: ~tens of us
    shm->status().servo_state.store(std::uint32_t(rt::ServoState::finished), std::memory_order_release);
  } else if (!opt.split) {
    loop->stop();
    shm->status().servo_state.store(std::uint32_t(rt::ServoState::finished), std::memory_order_release);
  }
  collision->stop();
  if (telemetry) telemetry->close();
}

RunReport RunEngine::finish(int signal) {
  State& e = *s_;
  const Scene& s = e.s;
  e.t_end = rt::now_ns();
  e.rss_end = rt::resident_bytes();
  e.stop_all();
  e.finished = true;
  (void)signal;

  const double secs = double(e.t_end - e.t_start) * 1e-9;
  // Every failure to write an output is collected and reported with the summary, which is always
  // complete; the run has then failed (a full disk must not look like a good run).
  RunReport report;
  std::vector<std::string>& failures = report.failures;
  if (rt::ShmSegment::truncated())
    failures.push_back("the shared-memory segment " + e.shm->name() + " was truncated by another process");
  ServoResults sres;
  bool servo_lost = false;  // --split: the servo process's figures could not be read (never printed as zeros)
  if (e.opt.split) {
    // The summary is complete even when the servo's results cannot be read (its process failed, or
    // the disk was full when it wrote servo.txt): with the collision side's figures and a note.
    if (e.servo_exit != 0)
      failures.push_back("servo process (pid " + std::to_string(e.servo_pid) + ") ended with exit " +
                         std::to_string(e.servo_exit));
    Result<ServoResults> r = read_servo_results(e.dir + "/servo.txt");
    if (r) {
      sres = r.value();
    } else {
      failures.push_back(r.error() + " (the servo's figures are lost)");
      servo_lost = true;
    }
  } else {
    sres.seconds = secs;
    if (e.device_clocked()) {  // the device's callback was the clock: no wake-ups of ours
      sres.ticks = e.ext_ticks;
      sres.misses = e.ext_misses;
    } else {
      const rt::LoopStats& ls = e.loop->stats();
      sres.ticks = ls.ticks;
      sres.misses = ls.misses;
      sres.overruns = ls.overruns;
      sres.wake_p99_us = double(ls.wake_latency.percentile_ns(0.99)) / 1000.0;
    }
    sres.peak_force_N = e.servo->peak_force_N();
    sres.models = e.servo->stats().models;
    if (e.telemetry) {
      sres.telemetry_pushed = e.telemetry->stats().pushed;
      sres.telemetry_dropped = e.telemetry->stats().dropped;
    }
    if (e.sim) sres.device_dropped = e.sim->dropped_records();
    if (e.telemetry && !e.telemetry->error().empty()) failures.push_back(e.telemetry->error());
    sres.silences = e.silence->episodes();
    sres.longest_silence_ms = e.silence->longest_ms();
  }

  const CollisionLoop& collision = *e.collision;
  const rt::LatencyHistogram& lat = collision.latency();
  std::string& summary = report.summary;
  const double servo_secs = sres.seconds > 0 ? sres.seconds : secs;
  appendf(summary, "summary\n");
  appendf(summary, "  duration        %.2f s\n", secs);
  if (servo_lost) {
    // Its last published status is all there is: say so, never zeros as if measured.
    rt::ServoStatus sv{};
    const bool have = e.shm->status().servo.load(sv);
    if (have)
      appendf(summary,
              "  haptic          figures lost (the servo process's servo.txt); its last status: %llu ticks, %llu "
              "misses, peak force %.3f N; %s\n",
              static_cast<unsigned long long>(sv.ticks), static_cast<unsigned long long>(sv.misses), sv.peak_force_N,
              e.servo_where.c_str());
    else
      appendf(summary, "  haptic          figures lost (the servo process's servo.txt), and no status; %s\n",
              e.servo_where.c_str());
  } else if (e.device_clocked())  // the device's callback wakes the servo: its wake-ups are not ours to time
    appendf(summary, "  haptic          %llu ticks (%.1f Hz), %llu misses (gaps between the callback's calls); %s\n",
            static_cast<unsigned long long>(sres.ticks), double(sres.ticks) / servo_secs,
            static_cast<unsigned long long>(sres.misses), e.servo_where.c_str());
  else
    appendf(summary, "  haptic          %llu ticks (%.1f Hz), %llu misses, %llu overruns, wake-up p99 %.1f us; %s\n",
            static_cast<unsigned long long>(sres.ticks), double(sres.ticks) / servo_secs,
            static_cast<unsigned long long>(sres.misses), static_cast<unsigned long long>(sres.overruns),
            sres.wake_p99_us, e.servo_where.c_str());
  appendf(summary, "  collision       %llu rounds (%.1f Hz), latency p50 %.3f ms, p99 %.3f ms, %llu incomplete; %s\n",
          static_cast<unsigned long long>(collision.rounds()), double(collision.rounds()) / secs,
          double(lat.percentile_ns(0.5)) * 1e-6, double(lat.percentile_ns(0.99)) * 1e-6,
          static_cast<unsigned long long>(collision.incomplete()), e.backend.c_str());
  if (const rt::LatencyHistogram& cl = collision.contact_latency(); cl.count() > 0)
    appendf(summary, "  in contact      %llu rounds with pairs, latency p50 %.3f ms, p99 %.3f ms\n",
            static_cast<unsigned long long>(cl.count()), double(cl.percentile_ns(0.5)) * 1e-6,
            double(cl.percentile_ns(0.99)) * 1e-6);
  {  // the collision thread's coherent colliders (after the run: that thread has ended)
    geom::CoherentStats cs;
    for (const std::optional<ComputeCollision>& c : e.colliders)
      if (c && c->coherent()) {
        const geom::CoherentStats& k = c->coherent()->stats();
        cs.rounds += k.rounds, cs.plain_rounds += k.plain_rounds, cs.rebuilds += k.rebuilds;
        cs.reused += k.reused, cs.retested += k.retested, cs.peak_bytes = std::max(cs.peak_bytes, k.peak_bytes);
      }
    if (cs.rounds > 0)
      appendf(summary,
              "  coherent        %llu of %llu rounds from certificates (%llu plain: a jump or no contact near; %llu "
              "rebuilds), %llu answers reused, %llu tested again, cache peak %.1f MB\n",
              static_cast<unsigned long long>(cs.rounds - cs.plain_rounds), static_cast<unsigned long long>(cs.rounds),
              static_cast<unsigned long long>(cs.plain_rounds), static_cast<unsigned long long>(cs.rebuilds),
              static_cast<unsigned long long>(cs.reused), static_cast<unsigned long long>(cs.retested),
              double(cs.peak_bytes) / 1e6);
  }
  if (e.fleet) appendf(summary, "  split           %s\n", e.fleet->split.c_str());
  if (sres.silences)
    appendf(summary,
            "  silences        %llu: no contact model for the stale timeout, force faded to zero (longest %.0f ms)\n",
            static_cast<unsigned long long>(sres.silences), sres.longest_silence_ms);
  if (servo_lost)
    appendf(summary, "  force           (servo figures lost) limit %.2f N, peak penetration %.3f mm\n",
            s.saturation.peak_N, std::max(0.0, collision.peak_penetration_mm()));
  else
    appendf(summary, "  force           peak %.3f N (limit %.2f N), peak penetration %.3f mm\n", sres.peak_force_N,
            s.saturation.peak_N, std::max(0.0, collision.peak_penetration_mm()));
  {
    std::string guard = s.passivity.enabled ? "passivity guard on" : "passivity guard off";
    if (s.passivity.enabled && !e.opt.split)
      appendf(guard, " (controller acted on %llu ticks)",
              static_cast<unsigned long long>(e.servo->passivity_active_ticks()));
    appendf(summary, "  contact         model %s, interpolation %s, %s\n", geom::to_string(s.contact.model),
            rt::to_string(s.interp.mode), guard.c_str());
  }
  {
    bool any_friction = false;
    for (const ObjectSpec& o : e.specs)
      any_friction = any_friction || o.material.friction.static_mu > 0 || o.material.friction.dynamic_mu > 0;
    if (any_friction) {
      std::string counts = " (the servo process counts)";
      if (!e.opt.split && e.servo) {
        const rt::FrictionStats fs = e.servo->friction_stats();
        counts = "";
        if (e.specs.size() == 1) appendf(counts, ", stick spring %.3f N/mm", e.servo->friction().stiffness_N_per_mm());
        appendf(counts, ": %llu ticks stuck, %llu sliding, %llu break-aways",
                static_cast<unsigned long long>(fs.stuck_ticks), static_cast<unsigned long long>(fs.sliding_ticks),
                static_cast<unsigned long long>(fs.breakaways));
      }
      if (e.specs.size() == 1)
        appendf(summary, "  friction        static %.3g, dynamic %.3g%s\n", s.friction.static_mu, s.friction.dynamic_mu,
                counts.c_str());
      else
        appendf(summary, "  friction        per object's material (below)%s\n", counts.c_str());
    }
  }
  if (e.specs.size() > 1) {
    // Per object: how often the top level let the probe reach it, how often it was touched, and how deep.
    const std::vector<ObjectRoundStats>& os = collision.object_stats();
    appendf(summary,
            "  objects         %zu; %llu rounds touched two or more at once; per object: rounds reached (collided) / "
            "touching, peak pairs, peak PD\n",
            e.specs.size(), static_cast<unsigned long long>(collision.multi_touch_rounds()));
    for (std::size_t k = 0; k < e.specs.size() && k < os.size(); ++k) {
      const ObjectSpec& o = e.specs[k];
      appendf(summary, "    %-14s %zu faces, %llu / %llu rounds, %u pairs, %.3f mm; mu %.3g/%.3g\n", o.name.c_str(),
              e.object_bodies[k].mesh().num_faces(), static_cast<unsigned long long>(os[k].reached),
              static_cast<unsigned long long>(os[k].touching), os[k].peak_pairs, os[k].peak_penetration_mm,
              o.material.friction.static_mu, o.material.friction.dynamic_mu);
    }
    if (collision.overflow_rounds())
      appendf(summary, "    %llu rounds touched more than %u objects at once (the deepest %u rendered)\n",
              static_cast<unsigned long long>(collision.overflow_rounds()), geom::kMaxContactObjects,
              geom::kMaxContactObjects);
  }
  if (servo_lost)
    appendf(summary, "  telemetry       (servo figures lost)\n");
  else
    appendf(summary, "  telemetry       %llu samples, %llu dropped\n",
            static_cast<unsigned long long>(sres.telemetry_pushed),
            static_cast<unsigned long long>(sres.telemetry_dropped));
  if (sres.device_dropped)
    appendf(summary, "  device records  %llu dropped\n", static_cast<unsigned long long>(sres.device_dropped));
  if (e.udp)
    appendf(summary, "  device          %s; %llu ticks without a pose\n", e.udp->summary().c_str(),
            static_cast<unsigned long long>(e.servo->stats().pose_failures));
  if (e.rss_start && e.rss_end)
    appendf(summary, "  memory          RSS %.1f MB after %.1f s, %.1f MB at the end (%+.2f MB)\n",
            double(e.rss_start) / 1e6, std::min(1.0, s.duration_s / 2), double(e.rss_end) / 1e6,
            (double(e.rss_end) - double(e.rss_start)) / 1e6);
  appendf(summary, "  outputs         %s/\n", e.dir.c_str());
  if (!collision.rounds_csv_error().empty()) failures.push_back(collision.rounds_csv_error());
  // ticks.csv is whole when its writer saw no error (in this process, or the servo process's exit).
  const bool ticks_whole = (e.telemetry ? e.telemetry->error().empty() : !(e.opt.split && e.servo_exit != 0)) &&
                           collision.rounds_csv_error().empty();
  const bool have_csv = (s.write_trace || s.write_perfetto) && std::filesystem::exists(e.csv);
  if (s.write_perfetto && have_csv && !ticks_whole) {
    appendf(summary, "    trace.json    not written: ticks.csv or rounds.csv is incomplete\n");
  } else if (s.write_perfetto && have_csv) {
    if (Status st = write_trace_json(e.dir + "/trace.json", e.csv, e.rounds_csv); !st) {
      appendf(summary, "  trace.json: %s\n", st.error().c_str());
      failures.push_back(st.error());
    } else
      appendf(summary,
              "    trace.json    haptic ticks and collision rounds (open in ui.perfetto.dev or chrome://tracing)\n");
  }
  if (s.write_trace)
    appendf(summary, "    ticks.csv     one line per haptic tick; rounds.csv one line per collision round\n");
  if (e.opt.split) appendf(summary, "    servo.txt     the servo process's counters; script.txt its trajectory\n");
  if (s.write_ply) {
    if (collision.peak_pairs().empty()) {
      appendf(summary, "    contact.ply   not written: the probe never touched the object\n");
    } else if (Status st =
                   write_contact_ply(e.dir + "/contact.ply", e.probe(), e.object_bodies[collision.peak_object()].mesh(),
                                     collision.peak_pose(), collision.peak_pairs());
               !st) {
      appendf(summary, "    contact.ply: %s\n", st.error().c_str());
      failures.push_back(st.error());
    } else {
      appendf(summary, "    contact.ply   contact state at peak penetration, colliding faces red (MeshLab, Blender)\n");
    }
  }
  if (!failures.empty())
    appendf(summary, "  FAILED          %zu output(s) not written whole; first: %s\n", failures.size(),
            failures[0].c_str());
  return report;
}

void RunEngine::save(RunReport& report) {
  const State& e = *s_;
  const std::string summary_path = e.dir + "/summary.txt";
  if (std::FILE* f = std::fopen(summary_path.c_str(), "w")) {
    const bool wrote = std::fputs(report.summary.c_str(), f) >= 0 && std::fflush(f) == 0;
    const int err = errno;
    if ((std::fclose(f) != 0 || !wrote))
      report.failures.push_back(summary_path + ": write failed: " + std::strerror(wrote ? errno : err));
  } else {
    report.failures.push_back(summary_path + ": cannot create: " + std::strerror(errno));
  }
  const bool have_csv = (e.s.write_trace || e.s.write_perfetto) && std::filesystem::exists(e.csv);
  if (!e.s.write_trace && have_csv && std::filesystem::is_regular_file(e.csv)) {
    std::error_code ec;
    std::filesystem::remove(e.csv, ec);
    std::filesystem::remove(e.rounds_csv, ec);
  }
}

rt::PoseFeedDevice* RunEngine::pose_feed() const { return s_->feed.get(); }
const rt::Trajectory& RunEngine::trajectory() const { return s_->script; }
const geom::Mesh& RunEngine::probe() const { return s_->probe(); }
const geom::Mesh& RunEngine::object() const { return s_->object(); }
std::vector<std::pair<const geom::Mesh*, geom::Pose>> RunEngine::placed_objects() const {
  std::vector<std::pair<const geom::Mesh*, geom::Pose>> out;
  for (std::size_t k = 0; k < s_->object_bodies.size(); ++k)
    out.emplace_back(&s_->object_bodies[k].mesh(), s_->specs[k].placement.pose());
  return out;
}
const rt::ShmStatus& RunEngine::shm_status() const { return s_->shm->status(); }
const Scene& RunEngine::scene() const { return s_->s; }
const std::string& RunEngine::backend() const { return s_->backend; }
std::string RunEngine::split() const { return s_->fleet ? s_->fleet->split : std::string(); }
const std::string& RunEngine::servo_where() const { return s_->servo_where; }
const std::string& RunEngine::run_dir() const { return s_->dir; }
const std::string& RunEngine::shm_name() const { return s_->shm->name(); }
bool RunEngine::has_fleet() const { return s_->fleet != nullptr; }

}  // namespace st::engine
