// SPDX-License-Identifier: BSD-3-Clause
// Tests for `spheretouch query` and `spheretouch build` through the real binary: output format,
// the exact pair set against the library, --blocks equality, pose-file errors, the tree cache.
#include <filesystem>
#include <sstream>

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
  std::string endpoints;
  for (int i = 0; i < 2; ++i) {
    const std::string ep = "tcp://127.0.0.1:" + std::to_string(st::test::free_port());
    daemons.push_back(std::make_unique<st::test::Process>(
        std::vector<std::string>{st::test::worker_binary(), "--bind", ep, "--id", std::to_string(i)}, d.file("w.log")));
    endpoints += (i ? "," : "") + ep;
  }
  const auto r = run_command(base + " --connect " + endpoints);
  INFO(r.output.substr(0, 400));
  CHECK(r.exit_code == 0);
  CHECK(r.output == single.output);
}
