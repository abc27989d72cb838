// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/engine/run_engine.*: the main job driven as a library, without the command line —
// what a program or a benchmark does with it.
#include <doctest/doctest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>

#include <spheretouch/engine/run_engine.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/device.hpp>
#include <spheretouch/rt/view_frame.hpp>
#include "test_util.hpp"

namespace {

std::string engine_scene_text(const std::string& extra) {
  return "[probe]\nbuiltin = \"capsule\"\nradius_mm = 6.0\nlength_mm = 30.0\n"
         "[object]\nbuiltin = \"icosphere\"\nradius_mm = 40.0\nfrequency = 12\n"
         "[tree]\ncache = false\n" +
         extra;
}

/// A run engine prepared from scene `text`, its progress notes into `notes`.
std::unique_ptr<st::engine::RunEngine> engine_prepare(const std::string& text, std::vector<std::string>& notes) {
  auto scene = st::engine::parse_scene(text, "e.toml", ".");
  REQUIRE_MESSAGE(scene.ok(), scene.error());
  st::engine::RunOptions opt;
  opt.note = [&notes](const std::string& m) { notes.push_back(m); };
  auto made = st::engine::RunEngine::prepare(scene.value(), opt);
  REQUIRE_MESSAGE(made.ok(), made.error());
  return std::move(made).value();
}

std::string engine_read(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

TEST_CASE("run engine: prepare, start, poll, finish and save without the command line") {
  st::test::TempDir dir;
  const std::string out = dir.file("run");
  std::vector<std::string> notes;
  const auto made = engine_prepare(
      engine_scene_text("[workers]\ncount = 0\n[run]\nduration_s = 2.5\n[output]\ndir = \"" + out + "\"\nstatus = \"off\"\n"),
      notes);
  st::engine::RunEngine& run = *made;
  CHECK(run.run_dir() == out);
  CHECK(run.backend() == "in the collision thread");
  CHECK_FALSE(run.has_fleet());
  CHECK_FALSE(notes.empty());  // "loading probe and object ...", face counts
  REQUIRE(run.start().ok());

  std::vector<std::string> events;
  int polls = 0;
  while (run.poll(false, events)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    REQUIRE(++polls < 2000);  // the run ends at its duration (2.5 s), not never
  }
  const st::engine::RunStatus st = run.status();
  CHECK(st.elapsed_s >= 2.5);
  CHECK(st.have_servo);
  CHECK(st.ticks > 1000);  // counts, not timing: a 1 kHz loop for 2.5 s on any host
  CHECK(st.rounds > 10);   // the collision thread answered poses
  CHECK(st.force_N >= 0);

  st::engine::RunReport report = run.finish(0);
  CHECK(report.failures.empty());
  // Every run published view frames of its meshes and its scene reference (no scene file here).
  auto frame = std::make_unique<st::rt::ViewFrame>();
  REQUIRE(run.shm_status().view.load(*frame));
  CHECK(frame->round > 0);
  CHECK(st::rt::sanitize_view_frame(*frame, std::uint32_t(run.probe().num_faces()),
                                    std::uint32_t(run.object().num_faces())));
  st::rt::SceneRef ref;
  REQUIRE(run.shm_status().scene.load(ref));
  CHECK(std::string(ref.scene_path).empty());
  CHECK(ref.object_faces == run.object().num_faces());
  CHECK(st::engine::compare_scene_ref(ref, run.probe(), run.object()).empty());
  CHECK(report.summary.rfind("summary\n", 0) == 0);
  CHECK(report.summary.find("in the collision thread") != std::string::npos);
  CHECK(report.summary.find("outputs         " + out + "/") != std::string::npos);
  run.save(report);
  CHECK(report.failures.empty());
  CHECK(engine_read(out + "/summary.txt") == report.summary);
  // The built-in script presses the capsule into the ball: contact reached the trace and the PLY.
  CHECK(std::ifstream(out + "/contact.ply").good());
  CHECK(std::ifstream(out + "/trace.json").good());
}

TEST_CASE("run engine: with workers the split is chosen automatically and said in the summary; a pinned one is kept") {
  st::test::TempDir dir;
  // The scene text ends in [tree]: these keys land there.
  for (const std::string& tree : {std::string(), std::string("layer = 1\nblock_size = 2\nmapping = \"random\"\n")}) {
    CAPTURE(tree);
    auto scene = st::engine::parse_scene(
        engine_scene_text(tree + "[workers]\ncount = 3\n[run]\nduration_s = 0.3\n[output]\ndir = \"" +
                          dir.file(tree.empty() ? "auto" : "pinned") + "\"\nstatus = \"off\"\n"),
        "e.toml", ".");
    REQUIRE_MESSAGE(scene.ok(), scene.error());
    auto made = st::engine::RunEngine::prepare(scene.value(), {});
    REQUIRE_MESSAGE(made.ok(), made.error());
    st::engine::RunEngine& run = *made.value();
    const std::string split = run.split();
    INFO(split);
    if (tree.empty()) {
      CHECK(split.find("(automatic;") != std::string::npos);
      CHECK(split.find("block-cyclic over 3 workers") != std::string::npos);
    } else {
      CHECK(split.rfind("layer 1, block size 2: ", 0) == 0);
      CHECK(split.find("random over 3 workers (set in the scene)") != std::string::npos);
    }
    REQUIRE(run.start().ok());
    std::vector<std::string> events;
    while (run.poll(false, events)) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    st::engine::RunReport report = run.finish(0);
    CHECK(report.summary.find("  split           " + split) != std::string::npos);
  }
}

TEST_CASE("run engine: prepare fails with an error naming the field; nothing is left running") {
  st::test::TempDir dir;
  auto scene =
      st::engine::parse_scene(engine_scene_text("[output]\ndir = \"" + dir.file("run") + "\"\n"), "e.toml", ".");
  REQUIRE(scene.ok());
  st::engine::Scene s = scene.value();
  s.object.builtin.clear();
  s.object.mesh = dir.file("missing.off");
  auto bad = st::engine::RunEngine::prepare(s, {});
  REQUIRE_FALSE(bad.ok());
  CHECK(bad.error().find("e.toml: ") == 0);
  CHECK(bad.error().find("missing.off") != std::string::npos);

  st::engine::RunOptions split;
  split.split = true;  // the split servo re-reads the scene file: it must be named
  auto no_file = st::engine::RunEngine::prepare(scene.value(), split);
  REQUIRE_FALSE(no_file.ok());
  CHECK(no_file.error().find("scene_path") != std::string::npos);
}

TEST_CASE("scene reference: records the path and the meshes; tells other meshes apart") {
  const st::geom::Mesh probe = st::geom::make_capsule(6, 30, 24);
  st::geom::Mesh object = st::geom::make_icosphere(40, 12);
  const st::rt::SceneRef ref = st::engine::scene_ref("/some/scene.toml", probe, object);
  CHECK(std::string(ref.scene_path) == "/some/scene.toml");
  CHECK(ref.probe_faces == probe.num_faces());
  CHECK(ref.object_vertices == object.num_vertices());
  CHECK(st::engine::compare_scene_ref(ref, probe, object).empty());
  CHECK(st::engine::compare_scene_ref(ref, probe, st::geom::make_icosphere(40, 13)).find("the object has ") == 0);
  object.local[17].x() += 1e-9;  // one coordinate, one ulp-ish: another mesh
  CHECK(st::engine::compare_scene_ref(ref, probe, object).find("other coordinates") != std::string::npos);
  CHECK(st::engine::compare_scene_ref(ref, object, object).find("the probe has ") == 0);
  const std::string long_path(st::rt::SceneRef::kMaxPath, 'x');  // too long to record: none
  CHECK(std::string(st::engine::scene_ref(long_path, probe, object).scene_path).empty());
}

namespace {

/// A device of the caller's: replays the engine's trajectory by the time it is asked at, counts
/// its calls and the forces it was given.
class ReplayDevice final : public st::rt::Device {
 public:
  const st::rt::Trajectory* path = nullptr;
  std::int64_t t0 = 0;
  std::atomic<std::uint64_t> reads{0}, forces{0};
  double peak_N = 0;
  bool read_pose(std::int64_t now_ns, Eigen::Isometry3d& pose) noexcept override {
    if (!path) return false;
    if (t0 == 0) t0 = now_ns;
    pose = path->at(double(now_ns - t0) * 1e-9);
    reads.fetch_add(1, std::memory_order_relaxed);
    return true;
  }
  void command_force(std::int64_t, const Eigen::Vector3d& f) noexcept override {
    forces.fetch_add(1, std::memory_order_relaxed);
    peak_N = std::max(peak_N, f.norm());
  }
  double max_force_N() const noexcept override { return 2.0; }
};

}  // namespace

TEST_CASE("run engine: a caller's device, polled by the haptic thread or ticked from its own callback") {
  st::test::TempDir dir;
  for (const bool clocked : {false, true}) {
    CAPTURE(clocked);
    auto scene = st::engine::parse_scene(
        engine_scene_text("[workers]\ncount = 0\n[run]\nduration_s = 2.5\n[output]\ndir = \"" +
                          dir.file(clocked ? "clocked" : "polled") + "\"\nstatus = \"off\"\ntrace = false\n"),
        "e.toml", ".");
    REQUIRE_MESSAGE(scene.ok(), scene.error());
    ReplayDevice device;
    st::engine::RunOptions opt;
    opt.device = &device;
    opt.device_clocked = clocked;
    auto made = st::engine::RunEngine::prepare(scene.value(), opt);
    REQUIRE_MESSAGE(made.ok(), made.error());
    st::engine::RunEngine& run = *made.value();
    device.path = &run.trajectory();
    REQUIRE(run.trajectory().duration_s() > 2.0);  // the built-in press and slide
    run.tick(st::rt::now_ns());                    // before start(): nothing happens
    CHECK(device.reads.load() == 0);
    REQUIRE(run.start().ok());
    std::atomic<bool> stop{false};
    std::thread callback;
    if (clocked)  // the device's own 1 kHz servo callback
      callback = std::thread([&] {
        for (std::int64_t next = st::rt::now_ns(); !stop.load(); next += 1'000'000) {
          while (st::rt::now_ns() < next) std::this_thread::sleep_for(std::chrono::microseconds(100));
          run.tick(st::rt::now_ns());
        }
      });
    std::vector<std::string> events;
    while (run.poll(false, events)) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    st::engine::RunReport report = run.finish(0);
    const std::uint64_t reads_at_finish = device.reads.load();
    if (clocked) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the callback keeps calling after finish()
      CHECK(device.reads.load() == reads_at_finish);               // ... and nothing happens
      stop.store(true);
      callback.join();
      CHECK(st::test::contains(report.summary, "the device's own callback"));
    } else {
      CHECK(st::test::contains(report.summary, "servo thread"));
    }
    CHECK(report.failures.empty());
    // About one pose read and one force per millisecond, from whichever clock ticked.
    CHECK(reads_at_finish > 1500);
    CHECK(device.forces.load() == reads_at_finish);
    // The probe pressed into the object: the device felt it, within its own limit.
    CHECK(device.peak_N > 0.2);
    CHECK(device.peak_N <= 2.0 + 1e-9);
  }
}

TEST_CASE("run engine: a caller's device is refused with the split servo, and device_clocked without a device") {
  auto scene = st::engine::parse_scene(engine_scene_text("[workers]\ncount = 0\n"), "e.toml", ".");
  REQUIRE(scene.ok());
  ReplayDevice device;
  st::engine::RunOptions split;
  split.device = &device;
  split.split = true;
  split.scene_path = "e.toml";
  auto a = st::engine::RunEngine::prepare(scene.value(), split);
  REQUIRE_FALSE(a.ok());
  CHECK(st::test::contains(a.error(), "RunOptions::device"));
  st::engine::RunOptions clocked;
  clocked.device_clocked = true;
  auto b = st::engine::RunEngine::prepare(scene.value(), clocked);
  REQUIRE_FALSE(b.ok());
  CHECK(st::test::contains(b.error(), "device_clocked"));
}

TEST_CASE("scene: [device] dof, torque_limit_nm and tcp_mm; the tool point defaults to the probe's tip") {
  auto six = st::engine::parse_scene(
      engine_scene_text("[device]\ndof = 6\ntorque_limit_nm = 0.05\ntcp_mm = [0.0, 0.0, 12.5]\n"), "w.toml", ".");
  REQUIRE_MESSAGE(six.ok(), six.error());
  CHECK(six.value().device.wrench.dof == 6);
  CHECK(six.value().device.wrench.torque_limit_Nm == 0.05);
  CHECK_FALSE(six.value().device.tcp_auto);
  const st::geom::Mesh capsule = st::geom::make_capsule(6, 30, 24);
  CHECK(st::engine::tool_point(six.value(), capsule) == st::geom::Vec3(0, 0, 12.5));
  // Default: 3-DOF, the tool point at the probe's tip (its lowest vertex along the approach).
  auto dflt = st::engine::parse_scene(engine_scene_text(""), "d.toml", ".");
  REQUIRE(dflt.ok());
  CHECK(dflt.value().device.wrench.dof == 3);
  CHECK(dflt.value().device.tcp_auto);
  CHECK(st::engine::tool_point(dflt.value(), capsule).z() == doctest::Approx(-(15.0 + 6.0)));
  for (const auto& [text, field] : {std::pair<std::string, std::string>{"dof = 5\n", "dof"},
                                    {"dof = 6\n", "torque_limit_nm"},
                                    {"torque_limit_nm = -1.0\n", "torque_limit_nm"},
                                    {"tcp_mm = [1.0, 2.0]\n", "tcp_mm"}}) {
    CAPTURE(text);
    auto bad = st::engine::parse_scene(engine_scene_text("[device]\n" + text), "bad.toml", ".");
    REQUIRE_FALSE(bad.ok());
    CHECK(st::test::contains(bad.error(), field));
    CHECK(st::test::contains(bad.error(), "bad.toml"));
  }
}

TEST_CASE("run engine: a scene of two objects; the probe presses on both at once, in the thread and over workers") {
  // Two boxes side by side along y with a 1 mm gap; the capsule presses down over the gap and
  // slides along it (x), touching both the whole time.
  for (const int workers : {0, 2}) {
    CAPTURE(workers);
    st::test::TempDir dir;
    const std::string out = dir.file("run");
    std::vector<std::string> notes;
    const auto made = engine_prepare(
        "[probe]\nbuiltin = \"capsule\"\nradius_mm = 6.0\nlength_mm = 30.0\n"
        "[[object]]\nname = \"left\"\nbuiltin = \"box\"\nsize_mm = 40\nposition_mm = [0, -20.5, 0]\n"
        "[[object]]\nname = \"right\"\nbuiltin = \"box\"\nsize_mm = 40\nposition_mm = [0, 20.5, 0]\n"
        "[[object]]\nname = \"far\"\nbuiltin = \"icosphere\"\nradius_mm = 10\nposition_mm = [0, 0, -500]\n"
        "[object.material]\nstatic_friction = 0.4\ndynamic_friction = 0.3\n"
        // leaf_faces = 2: the 12-face boxes have 6 leaves, so 2 workers get blocks of them.
        "[device]\ntarget = [-10, 0, 20]\nslide_mm = 20\n[tree]\ncache = false\nleaf_faces = 2\n[workers]\ncount = " +
            std::to_string(workers) + "\n[run]\nduration_s = 4.5\n[output]\ndir = \"" + out + "\"\nstatus = \"off\"\n",
        notes);
    st::engine::RunEngine& run = *made;
    CHECK(std::any_of(notes.begin(), notes.end(),
                      [](const std::string& n) { return n.find("3 objects") != std::string::npos; }));
    REQUIRE(run.start().ok());
    std::vector<std::string> events;
    while (run.poll(false, events)) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    st::engine::RunReport report = run.finish(0);
    INFO(report.summary);
    CHECK(report.failures.empty());
    // Per object: rounds the top level let the probe reach it, rounds it was touched.
    auto object_line = [&](const std::string& name, unsigned long long& reached, unsigned long long& touching) {
      const std::size_t at = report.summary.find("    " + name + " ");
      REQUIRE(at != std::string::npos);
      const std::string line = report.summary.substr(at, report.summary.find('\n', at) - at);
      std::size_t faces = 0;
      REQUIRE(std::sscanf(line.c_str() + 4 + name.size(), " %zu faces, %llu / %llu rounds", &faces, &reached, &touching) ==
              3);
      CHECK(faces > 0);
    };
    unsigned long long lr = 0, lt = 0, rr = 0, rt = 0, fr = 1, ft = 1;
    object_line("left", lr, lt);
    object_line("right", rr, rt);
    object_line("far", fr, ft);
    CHECK(lt > 10);  // both touched, for many rounds
    CHECK(rt > 10);
    CHECK(fr == 0);  // the far sphere never reached: the top level kept it out of every round
    unsigned long long both = 0;
    const std::size_t ob = report.summary.find("  objects         3; ");
    REQUIRE(ob != std::string::npos);
    REQUIRE(std::sscanf(report.summary.c_str() + ob, "  objects         3; %llu rounds touched", &both) == 1);
    CHECK(both > 10);  // pressed on both boxes at once
    CHECK(ft == 0);
    CHECK(st::test::contains(report.summary, " 0 incomplete"));
    // The two boxes' forces add: the peak is well above zero and within the limit.
    double peak = 0, limit = 0;
    const std::size_t f = report.summary.find("force           peak ");
    REQUIRE(f != std::string::npos);
    REQUIRE(std::sscanf(report.summary.c_str() + f, "force           peak %lf N (limit %lf N)", &peak, &limit) == 2);
    CHECK(peak > 0.1);
    CHECK(peak <= limit + 1e-9);
    CHECK(st::test::contains(report.summary, "friction        per object's material"));
    if (workers > 0) {  // every object dealt over the workers, none left to the collision thread
      CHECK(st::test::contains(report.summary, "3 objects"));
      CHECK_FALSE(st::test::contains(report.summary, "too small to split"));
    }
  }
}
