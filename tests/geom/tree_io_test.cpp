// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/tree_io.* against forged tree files: the checksum and the mesh hash are not
// cryptographic, so an attacker who can write the cache can make them pass (here: edit the tree,
// then write_tree() computes a fresh checksum and keeps the mesh hash). Each forgery that once
// crashed collide() (stack sized from num_depths) or made it run forever (shared children), or
// that would hide collisions (spheres that do not hold their faces), must be refused with a
// message naming what is wrong. And collide() itself never overflows its stack on a tree that
// lies about its depth. (The round trip and stale/corrupt headers: sphere_tree_test.cpp.)
#include <spheretouch/geom/tree_io.hpp>

#include <doctest/doctest.h>

#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <string>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/primitives.hpp>
#include "test_util.hpp"

using namespace st::geom;

namespace {
// Writes an edited copy of `t` (valid checksum, the real mesh hash) and reads it back for `m`.
std::string forge(const Mesh& m, const SphereTree& t, const std::function<void(SphereTree&)>& edit) {
  SphereTree f = t;
  edit(f);
  const std::string path = (std::filesystem::temp_directory_path() / "st_tree_forged.sttree").string();
  REQUIRE(write_tree(f, path).ok());
  auto r = read_tree(path, m);
  std::remove(path.c_str());
  return r.ok() ? std::string("accepted") : r.error();
}
// The first inner node with at least two inner children, and those two children.
bool two_inner_siblings(const SphereTree& t, std::uint32_t& parent, std::uint32_t& a, std::uint32_t& b) {
  for (std::uint32_t i = 0; i < t.num_nodes(); ++i) {
    const SphereNode& h = t.nodes[i];
    if (h.leaf) continue;
    std::uint32_t found = 0;
    for (std::uint32_t k = h.first; k < h.first + h.count; ++k)
      if (!t.nodes[k].leaf) (found++ == 0 ? a : b) = k;
    if (found >= 2) {
      parent = i;
      return true;
    }
  }
  return false;
}
std::uint32_t first_leaf(const SphereTree& t) {
  for (std::uint32_t i = 0; i < t.num_nodes(); ++i)
    if (t.nodes[i].leaf) return i;
  return 0;
}
}  // namespace

TEST_CASE("tree files: forged structures are refused, each with what is wrong") {
  const Mesh m = make_icosphere(20, 12);  // 2,880 faces: several layers of inner nodes
  const SphereTree t = SphereTree::build(m).value();
  REQUIRE(t.num_depths >= 3);
  CHECK(forge(m, t, [](SphereTree&) {}) == "accepted");  // the forger's own round trip is fine

  std::uint32_t parent = 0, a = 0, b = 0;
  REQUIRE(two_inner_siblings(t, parent, a, b));
  const std::uint32_t leaf = first_leaf(t);

  struct Case {
    const char* what;
    std::function<void(SphereTree&)> edit;
    const char* expect;
  };
  const Case cases[] = {
      // The crash: collide() sized its stack from num_depths.
      {"num_depths huge", [](SphereTree& f) { f.num_depths = 1u << 30; }, "num_depths"},
      {"num_depths smaller than the tree", [](SphereTree& f) { f.num_depths = 1; }, "deepest node"},
      {"a node deeper than its parent + 1", [&](SphereTree& f) { f.nodes[leaf].depth = 200; }, "depth"},
      // The hang: two inner nodes sharing their children (a DAG: exponential descent).
      {"two parents",
       [&](SphereTree& f) {
         f.nodes[b].first = f.nodes[a].first;
         f.nodes[b].count = f.nodes[a].count;
       },
       "two parents"},
      {"a cycle back to the root", [&](SphereTree& f) { f.nodes[a].first = 0; }, "child range"},
      {"unreachable nodes", [](SphereTree& f) { f.nodes[0].count = 1; }, "cover"},
      {"a child's faces outside its parent's", [&](SphereTree& f) { f.cold[f.nodes[a].first].face_begin += 1; },
       "face range"},
      {"a leaf's face range past the end", [&](SphereTree& f) { f.cold[leaf].face_end = f.num_faces() + 5; }, "cover"},
      {"a leaf with more faces than the limit", [&](SphereTree& f) { f.nodes[leaf].count = 65; }, "leaf"},
      {"a wrong parent field", [&](SphereTree& f) { f.cold[a].parent = b; }, "parent"},
      {"a wrong descendant range", [&](SphereTree& f) { f.cold[a].desc_end += 1; }, "descendant range"},
      {"face_order not a permutation", [](SphereTree& f) { f.face_order[1] = f.face_order[0]; }, "permutation"},
      {"a NaN sphere", [&](SphereTree& f) { f.nodes[a].radius = std::nanf(""); }, "not finite"},
      // Would hide collisions rather than crash: a sphere or a face box that misses its faces.
      {"a leaf sphere too small", [&](SphereTree& f) { f.nodes[leaf].radius *= 0.5f; }, "sphere does not hold face"},
      {"a face box too small", [](SphereTree& f) { f.face_boxes[3].hi[0] = f.face_boxes[3].lo[0]; }, "face box"},
      // Would turn every query into brute force: spheres and boxes that hold everything.
      {"a huge root sphere", [](SphereTree& f) { f.nodes[0].radius = 1e30f; },
       "node 0 sphere (radius 1.0000000150474662e+30) is not tight"},
      {"a huge leaf sphere", [&](SphereTree& f) { f.nodes[leaf].radius *= 3.0f; }, "is not tight"},
      {"an infinite face box",
       [](SphereTree& f) {
         f.face_boxes[3].lo[1] = -std::numeric_limits<float>::infinity();
         f.face_boxes[3].hi[2] = std::numeric_limits<float>::infinity();
       },
       "face box of face"},
      {"a face box 1 mm too wide", [](SphereTree& f) { f.face_boxes[5].hi[0] += 1.0f; }, "is not tight"},
  };
  for (const Case& c : cases) {
    const std::string what = c.what;
    CAPTURE(what);
    const std::string e = forge(m, t, c.edit);
    CAPTURE(e);
    CHECK(e != "accepted");
    CHECK(st::test::contains(e, "corrupt"));
    CHECK(st::test::contains(e, c.expect));
  }
}

TEST_CASE("collide: a tree lying about its depth stops the traversal instead of overflowing the stack") {
  const Mesh probe = make_icosphere(10, 6), object = make_icosphere(20, 12);
  const SphereTree pt = SphereTree::build(probe).value();
  SphereTree pt_lie = pt, ot = SphereTree::build(object).value();
  Pose pose = Pose::Identity();
  pose.translation() = Vec3(0, 0, 27);
  CollideScratch sc;
  CollideResult honest, lying, huge;
  collide(probe, pt, object, ot, pose, {}, sc, honest);
  REQUIRE(!honest.pairs.empty());
  CHECK(honest.stats.truncated == 0);
  ot.num_depths = 0;  // the stack is sized for trees of no layers: 8 entries
  pt_lie.num_depths = 0;
  CollideScratch sc2;
  collide(probe, pt_lie, object, ot, pose, {}, sc2, lying);
  CHECK(lying.stats.truncated > 0);
  ot.num_depths = 1u << 30;  // would size a multi-gigabyte stack (or wrap the size to nothing)
  CollideScratch sc3;
  collide(probe, pt, object, ot, pose, {}, sc3, huge);
  CHECK(huge.stats.truncated == 1);
  CHECK(huge.pairs.empty());
}

TEST_CASE("write_tree: a full disk is an error naming the file, and leaves no temporary behind") {
  const Mesh m = make_icosphere(20, 6);
  const SphereTree t = SphereTree::build(m).value();
  const std::string path = (std::filesystem::temp_directory_path() / "st_tree_full.sttree").string();
  std::filesystem::remove(path);
  std::filesystem::remove(path + ".tmp");
  std::filesystem::create_symlink("/dev/full", path + ".tmp");  // the temporary lands on a full "disk"
  const st::Status s = write_tree(t, path);
  REQUIRE_FALSE(s.ok());
  CHECK(st::test::contains(s.error(), path));
  CHECK(st::test::contains(s.error(), "No space left on device"));
  CHECK_FALSE(std::filesystem::exists(std::filesystem::symlink_status(path + ".tmp")));
  CHECK_FALSE(std::filesystem::exists(path));
}
