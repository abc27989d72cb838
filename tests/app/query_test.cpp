// SPDX-License-Identifier: BSD-3-Clause
// Tests for `spheretouch query` and `spheretouch build` through the real binary: output format,
// the exact pair set against the library, --blocks equality, pose-file errors, the tree cache.
#include <filesystem>
#include <sstream>

#include <spheretouch/engine/scene.hpp>
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/pose_io.hpp>
#include <spheretouch/geom/primitives.hpp>
#include "app/query_meshes.hpp"
#include "net/process_util.hpp"
#include "test_util.hpp"

using namespace st;
using st::test::contains;
using st::test::run_command;
using st::test::spheretouch_exe;

namespace {

struct Fixture : st::test::QueryMeshes {
  std::string query(const std::string& extra) const {
    return spheretouch_exe() + " query " + probe + " " + object + " --poses " + poses + " --tree-cache " +
           dir.file("trees") + " " + extra;
  }
};

/// The expected output computed through the library (same meshes as read from the files).
std::string expected_output(const Fixture& f) {
  const geom::Mesh p = geom::load_mesh(f.probe).value().mesh, o = geom::load_mesh(f.object).value().mesh;
  const geom::SphereTree pt = geom::SphereTree::build(p).value(), ot = geom::SphereTree::build(o).value();
  std::ostringstream out;
  geom::CollideScratch scratch;
  geom::CollideResult r;
  geom::CollideConfig opt = geom::DefaultCollideConfig();
  opt.sort_pairs = true;
  const auto poses = geom::read_poses(f.poses).value();
  for (std::size_t i = 0; i < poses.size(); ++i) {
    geom::collide(p, pt, o, ot, poses[i], opt, scratch, r);
    out << "pose " << i << " pairs " << r.pairs.size() << " contacts " << r.contacts() << "\n";
    for (const auto& fp : r.pairs) out << fp.probe << " " << fp.object << "\n";
  }
  return out.str();
}
/// `n` real worker daemons on free loopback ports (kept in `keep`); their endpoints, comma-separated.
std::string start_daemons(const st::test::TempDir& d, int n, std::vector<std::unique_ptr<st::test::Process>>& keep) {
  std::string endpoints;
  for (int i = 0; i < n; ++i) {
    const std::string ep = "tcp://127.0.0.1:" + std::to_string(st::test::free_port());
    keep.push_back(std::make_unique<st::test::Process>(
        std::vector<std::string>{st::test::worker_binary(), "--bind", ep, "--id", std::to_string(i)}, d.file("w.log")));
    endpoints += (i ? "," : "") + ep;
  }
  return endpoints;
}
}  // namespace

TEST_CASE("query prints the sorted exact pair set per pose") {
  Fixture f;
  const auto r = run_command(f.query(""));
  REQUIRE(r.exit_code == 0);
  CHECK(r.output == expected_output(f));
  CHECK(contains(r.output, "pose 0 pairs 0 contacts 0\n"));
  CHECK_FALSE(contains(r.output, "pose 1 pairs 0 "));  // pressed in: there are pairs
}

TEST_CASE("query --blocks W gives the same output as the single query, for W = 1..6") {
  Fixture f;
  const std::string base = run_command(f.query("")).output;
  for (int w = 1; w <= 6; ++w)
    for (const char* layout : {"--layer 1 --block-size 1", "--layer 2 --block-size 3"}) {
      const auto r = run_command(f.query("--blocks " + std::to_string(w) + " " + layout));
      INFO("W=" << w << " " << layout);
      CHECK(r.exit_code == 0);
      CHECK(r.output == base);
    }
}

TEST_CASE("query --count-only and --stats") {
  Fixture f;
  const auto r = run_command(f.query("--count-only --stats --repeat 3 2>/dev/null"));
  std::istringstream in(r.output);
  int lines = 0;
  for (std::string l; std::getline(in, l); ++lines) CHECK(l.rfind("pose ", 0) == 0);
  CHECK(lines == 3);
  const auto s = run_command(f.query("--count-only --stats >/dev/null"));
  CHECK(contains(s.output, "stats pose 1 query_us "));
  CHECK(contains(s.output, " node_pairs "));
  CHECK(contains(s.output, " tri_tests "));
}

TEST_CASE("query --approx-layer reports a superset of the exact pairs") {
  Fixture f;
  const auto exact = run_command(f.query("--count-only")),
             approx = run_command(f.query("--count-only --approx-layer -1"));
  REQUIRE(exact.exit_code == 0);
  REQUIRE(approx.exit_code == 0);
  auto pairs_of = [](const std::string& out, int pose) {
    const std::string key = "pose " + std::to_string(pose) + " pairs ";
    return std::stoul(out.substr(out.find(key) + key.size()));
  };
  for (int i = 0; i < 3; ++i) CHECK(pairs_of(approx.output, i) >= pairs_of(exact.output, i));
}

TEST_CASE("query: pose-file errors name the line and what is wrong") {
  Fixture f;
  const std::pair<const char*, const char*> cases[] = {
      {"1 0 0 0 0 1 0 0 0 0 1 0 0 0 0\n", ":1:"},        {"1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 1\n", ":1:"},
      {"# c\n1 0 0 0 0 1 x 0 0 0 1 0 0 0 0 1\n", ":2:"}, {"2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n", ":1:"},
      {"1 0 0 nan 0 1 0 0 0 0 1 0 0 0 0 1\n", ":1:"},
  };
  for (const auto& item : cases) {
    const auto& text = item.first;  // not a structured binding: INFO captures it (clang < 16)
    const auto& where = item.second;
    st::test::write_file(f.poses, text);
    const auto r = run_command(f.query(""));
    INFO(text << " -> " << r.output);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.output, "poses.txt" + std::string(where)));
  }
}

TEST_CASE("build writes a tree file; a stale or corrupt cache file is rebuilt, never trusted") {
  Fixture f;
  const std::string trees = f.dir.file("trees");
  auto r = run_command(spheretouch_exe() + " build " + f.object + " -o " + f.dir.file("o.stree"));
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  CHECK(contains(r.output, "bytes/face"));
  CHECK(std::filesystem::file_size(f.dir.file("o.stree")) > 0);

  const std::string good = run_command(f.query("")).output;  // fills the cache
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(trees)) files.push_back(e.path());
  REQUIRE(files.size() == 2);
  // Corrupt one file (flip a byte in the payload) and swap in the other body's tree as stale.
  {
    std::fstream io(files[0], std::ios::in | std::ios::out | std::ios::binary);
    io.seekp(200);
    io.put('\x5a');
  }
  r = run_command(f.query(""));
  CHECK(r.exit_code == 0);
  CHECK(contains(r.output, "tree cache: "));
  CHECK(contains(r.output, ": corrupt: "));
  std::filesystem::copy_file(files[1], files[0], std::filesystem::copy_options::overwrite_existing);
  r = run_command(f.query(""));
  CHECK(contains(r.output, ": stale: "));
  // After rebuilding, the output is the same and the cache is silent again.
  r = run_command(f.query(""));
  CHECK(r.output == good);
}

TEST_CASE("query over in-process workers and over worker daemons gives the single-process output (real meshes)") {
  const std::string root = std::getenv("ST_SOURCE_ROOT") ? std::getenv("ST_SOURCE_ROOT") : ".";
  const std::string base = spheretouch_exe() + " query " + st::test::model("hand_L2.off") + " " +
                           st::test::model("elephant.off") + " --poses " + root +
                           "/perf/poses/hand_elephant.txt --no-cache";
  const auto single = run_command(base);
  REQUIRE(single.exit_code == 0);
  CHECK(contains(single.output, "pose 2 pairs "));
  CHECK_FALSE(contains(single.output, "pose 2 pairs 0 "));
  for (int w : {1, 2, 4, 8}) {
    const auto r = run_command(base + " --workers " + std::to_string(w));
    INFO("workers " << w);
    CHECK(r.exit_code == 0);
    CHECK(r.output == single.output);
  }
  // Two real daemons on loopback.
  st::test::TempDir d;
  std::vector<std::unique_ptr<st::test::Process>> daemons;
  const auto r = run_command(base + " --connect " + start_daemons(d, 2, daemons));
  INFO(r.output.substr(0, 400));
  CHECK(r.exit_code == 0);
  CHECK(r.output == single.output);
}

TEST_CASE(
    "query --scene: each object's pairs equal a single-object query at its relative poses, in one process, over "
    "in-process workers and over worker daemons") {
  const std::string root = std::getenv("ST_SOURCE_ROOT") ? std::getenv("ST_SOURCE_ROOT") : ".";
  st::test::TempDir d;
  // The elephant at the origin (the perf poses press the hand into it) and the bunny placed, turned,
  // overlapping it: most poses touch both.
  const std::string scene = d.file("two.toml");
  st::test::write_file(scene, "[probe]\nmesh = \"" + st::test::model("hand_L2.off") +
                                  "\"\n[[object]]\nname = \"elephant\"\nmesh = \"" + st::test::model("elephant.off") +
                                  "\"\n[[object]]\nname = \"bunny\"\nmesh = \"" + st::test::model("bunny.off") +
                                  "\"\nposition_mm = [5.0, -3.0, 2.0]\nrotation_deg = [10.0, 20.0, 30.0]\n");
  const std::string world_poses = root + "/perf/poses/hand_elephant.txt";
  const auto poses = geom::read_poses(world_poses).value();
  REQUIRE(poses.size() >= 3);
  const auto parsed = st::engine::load_scene(scene);
  REQUIRE_MESSAGE(parsed.ok(), parsed.error());
  const std::vector<st::engine::ObjectSpec> objects = st::engine::scene_objects(parsed.value());
  REQUIRE(objects.size() == 2);

  // The single-object answers: each object alone at P_k^-1 · pose, as its own query.
  std::vector<std::vector<std::string>> single(objects.size());  // [object][pose]: its pair lines
  for (std::size_t k = 0; k < objects.size(); ++k) {
    const std::string rel = d.file("rel" + std::to_string(k) + ".txt");
    std::ostringstream text;
    text.precision(17);
    for (const geom::Pose& p : poses) {
      const Eigen::Matrix4d m = (objects[k].placement.pose().inverse() * p).matrix();
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) text << m(r, c) << (r == 3 && c == 3 ? "\n" : " ");
    }
    st::test::write_file(rel, text.str());
    const auto r = run_command(spheretouch_exe() + " query " + st::test::model("hand_L2.off") + " " +
                               objects[k].body.mesh + " --poses " + rel + " --no-cache");
    REQUIRE(r.exit_code == 0);
    std::istringstream in(r.output);
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("pose ", 0) == 0)
        single[k].push_back("");
      else
        single[k].back() += line + "\n";
    }
    REQUIRE(single[k].size() == poses.size());
  }
  // A scene query's output split into [object][pose] pair lines, checking the counts and totals.
  auto split = [&](const std::string& output) {
    std::vector<std::vector<std::string>> got(objects.size(), std::vector<std::string>(poses.size()));
    std::istringstream in(output);
    std::string line;
    long pose = -1, object = -1;
    std::size_t total = 0, sum = 0;
    while (std::getline(in, line)) {
      std::size_t n = 0, c = 0;
      if (std::sscanf(line.c_str(), "pose %ld pairs %zu contacts %zu", &pose, &total, &c) == 3) {
        object = -1;
        sum = 0;
      } else if (std::sscanf(line.c_str(), "object %ld pairs %zu contacts %zu", &object, &n, &c) == 3) {
        sum += n;
        if (object == long(objects.size()) - 1) CHECK(sum == total);
      } else {
        REQUIRE(object >= 0);
        got[std::size_t(object)][std::size_t(pose)] += line + "\n";
      }
    }
    return got;
  };
  const std::string base = spheretouch_exe() + " query --scene " + scene + " --poses " + world_poses + " --no-cache";
  auto check_same = [&](const std::string& how, const std::string& extra) {
    const auto r = run_command(base + extra);
    INFO(how);
    INFO(r.output.substr(0, 300));
    REQUIRE(r.exit_code == 0);
    const auto got = split(r.output);
    int both = 0;
    for (std::size_t i = 0; i < poses.size(); ++i) {
      for (std::size_t k = 0; k < objects.size(); ++k) CHECK(got[k][i] == single[k][i]);
      both += !got[0][i].empty() && !got[1][i].empty();
    }
    CHECK(both >= 2);  // the poses touch both objects at once
  };
  check_same("one process", "");
  check_same("2 in-process workers", " --workers 2");
  std::vector<std::unique_ptr<st::test::Process>> daemons;
  check_same("2 worker daemons", " --connect " + start_daemons(d, 2, daemons));
  // PROBE OBJECT and --scene together, or neither: a clear error.
  const auto both =
      run_command(base + " " + st::test::model("hand_L2.off") + " " + st::test::model("bunny.off") + " 2>&1");
  CHECK(both.exit_code == 2);
  CHECK(contains(both.output, "--scene names the probe and the objects"));
  const auto none = run_command(spheretouch_exe() + " query --poses " + world_poses + " 2>&1");
  CHECK(none.exit_code == 2);
  CHECK(contains(none.output, "give PROBE and OBJECT mesh files, or --scene SCENE"));
}
