// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/sphere_tree.* and src/spheretouch/geom/tree_io.*: structure, enclosure (exact, with the
// float padding), balanced leaves, layers, tightness, persistence errors.
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <random>

#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/geom/tree_io.hpp>
#include "test_models.hpp"

using namespace st::geom;

namespace {

// `groups`: the runs of faces the tree was built with (empty: one run of all faces).
void check_tree(const Mesh& m, const SphereTree& t, std::vector<std::uint32_t> groups = {}) {
  const std::uint32_t F = static_cast<std::uint32_t>(m.num_faces());
  REQUIRE(t.num_faces() == F);
  REQUIRE(t.cold.size() == t.nodes.size());
  // Every face in exactly one leaf, and leaves balanced within their run: floor(n/M) or ceil(n/M)
  // faces, M = ceil(n/leaf_faces), <= leaf_faces; no leaf holds faces of two runs.
  const std::uint32_t L = t.params.leaf_faces;
  if (groups.empty()) groups.push_back(F);
  std::vector<std::uint32_t> run_end;  // exclusive end face of each run
  std::uint32_t M = 0;
  for (std::uint32_t at = 0; std::uint32_t n : groups) {
    run_end.push_back(at += n);
    M += (n + L - 1) / L;
  }
  REQUIRE(run_end.back() == F);
  const auto run_of = [&](std::uint32_t f) {
    return std::size_t(std::upper_bound(run_end.begin(), run_end.end(), f) - run_end.begin());
  };
  std::vector<int> seen(F, 0);
  std::uint32_t leaves = 0;
  for (std::uint32_t i = 0; i < t.num_nodes(); ++i) {
    const SphereNode& h = t.nodes[i];
    const SphereNodeCold& c = t.cold[i];
    if (h.leaf) {
      ++leaves;
      REQUIRE(h.count >= 1);
      const std::size_t g = run_of(t.face_order[h.first]);
      const std::uint32_t n = groups[g], Mg = (n + L - 1) / L;
      CHECK(h.count >= n / Mg);
      CHECK(h.count <= (n + Mg - 1) / Mg);
      CHECK(h.count <= L);
      for (std::uint32_t s = h.first; s < h.first + h.count; ++s) CHECK(run_of(t.face_order[s]) == g);
      CHECK(h.first == c.face_begin);
      for (std::uint32_t s = h.first; s < h.first + h.count; ++s) ++seen[t.face_order[s]];
    } else {
      // Children contiguous, their face ranges tile the parent's, one layer deeper.
      REQUIRE(h.count >= 1);
      REQUIRE(h.count <= kMaxChildren);
      std::uint32_t at = c.face_begin;
      for (std::uint32_t k = 0; k < h.count; ++k) {
        const std::uint32_t ch = h.first + k;
        CHECK(t.cold[ch].face_begin == at);
        CHECK(t.cold[ch].parent == i);
        CHECK(t.nodes[ch].depth == h.depth + 1);
        at = t.cold[ch].face_end;
      }
      CHECK(at == c.face_end);
      CHECK(c.desc_end > h.first);
    }
    // Enclosure, exact in double: every vertex of every face below is inside the padded float sphere.
    const Vec3 ctr(h.centre[0], h.centre[1], h.centre[2]);
    const double r = h.radius;
    bool inside = true;
    for (std::uint32_t s = c.face_begin; s < c.face_end; ++s)
      for (auto v : m.faces[t.face_order[s]]) inside &= (m.local[v] - ctr).norm() <= r;
    CHECK(inside);
    // Tight: the padded float radius is the Welzl radius up to float rounding, and never worse than
    // the box's circumscribed sphere.
    Box bx;
    for (std::uint32_t s = c.face_begin; s < c.face_end; ++s)
      for (auto v : m.faces[t.face_order[s]]) bx.grow(m.local[v]);
    CHECK(c.radius <= 0.5 * bx.diagonal() * (1 + 1e-12) + 1e-12);
    CHECK(r <= c.radius * (1 + 1e-5) + 1e-5 * (std::abs(c.centre[0]) + std::abs(c.centre[1]) + std::abs(c.centre[2]) + 1));
  }
  CHECK(leaves == M);
  for (std::uint32_t f = 0; f < F; ++f) CHECK_MESSAGE(seen[f] == 1, "face ", f);
  CHECK(t.nodes[0].depth == 0);
  // Layers cover every face exactly once, in depth-first order.
  for (std::uint32_t n = 0; n <= t.num_depths; ++n) {  // includes one past the deepest
    std::vector<int> cover(F, 0);
    for (std::uint32_t i : t.layer(n)) {
      CHECK((t.nodes[i].depth == n || (t.nodes[i].leaf && t.nodes[i].depth < n)));
      for (const std::uint32_t* f = t.faces_begin(i); f != t.faces_end(i); ++f) ++cover[*f];
    }
    CHECK(std::all_of(cover.begin(), cover.end(), [](int c) { return c == 1; }));
  }
}

}  // namespace

TEST_CASE("min_sphere is the minimal enclosing sphere on known sets") {
  std::vector<Vec3> two{{-1, 0, 0}, {3, 0, 0}};
  Vec3 c;
  double r;
  min_sphere(two, c, r);
  CHECK(r == doctest::Approx(2.0).epsilon(1e-12));
  CHECK(c.x() == doctest::Approx(1.0).epsilon(1e-12));
  // Points on a sphere of radius 5 around (1,2,3), plus inner points: radius 5.
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g;
  std::vector<Vec3> pts;
  for (int i = 0; i < 500; ++i) {
    Vec3 d(g(rng), g(rng), g(rng));
    pts.push_back(Vec3(1, 2, 3) + 5 * d.normalized() * (i % 3 == 0 ? 0.5 : 1.0));
  }
  min_sphere(pts, c, r);
  CHECK(r == doctest::Approx(5.0).epsilon(1e-3));
  CHECK(r <= 5.0 * (1 + 1e-9));
  // Regular tetrahedron: circumradius.
  std::vector<Vec3> tet{{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}};
  min_sphere(tet, c, r);
  CHECK(r == doctest::Approx(std::sqrt(3.0)).epsilon(1e-12));
  // Obtuse triangle: the MES is the diameter of the longest side, not the circumcircle.
  std::vector<Vec3> obtuse{{-1, 0, 0}, {1, 0, 0}, {0, 0.1, 0}};
  min_sphere(obtuse, c, r);
  CHECK(r == doctest::Approx(1.0).epsilon(1e-12));
}

TEST_CASE("SphereTree invariants on generated meshes") {
  for (std::uint32_t L : {1u, 3u, 8u, 16u, 64u}) {
    CAPTURE(L);
    check_tree(make_box({2, 3, 4}), SphereTree::build(make_box({2, 3, 4}), {L}).value());
    const Mesh ico = make_icosphere(50, 9);
    check_tree(ico, SphereTree::build(ico, {L}).value());
    const Mesh cap = make_capsule(8, 30, 24);
    check_tree(cap, SphereTree::build(cap, {L}).value());
  }
  // Far from the file origin: local coordinates stay small.
  Mesh far = make_icosphere(10, 5);
  far.origin += Vec3(1e6, -2e6, 3e6);
  check_tree(far, SphereTree::build(far).value());
}

TEST_CASE("SphereTree invariants on real meshes") {
  for (const char* name : {"hand.off", "hand_L2.off", "elephant.off"}) {
    const Mesh* m = st::test::model_mesh(name);
    CAPTURE(name);
    for (std::uint32_t L : {4u, 8u, 20u}) {
      CAPTURE(L);
      auto t = SphereTree::build(*m, {L});
      REQUIRE(t.ok());
      check_tree(*m, t.value());
    }
  }
}

TEST_CASE("SphereTree grouped build: each run of faces its own subtrees, invariants hold") {
  // Three icospheres far apart, faces in runs of unequal sizes; and the elephant's faces reordered
  // by the blocks of one worker's block-cyclic share (layer 3 of its own tree, every 3rd block).
  Mesh three = make_icosphere(10, 6);
  const std::size_t per = three.faces.size();
  for (const Vec3& shift : {Vec3(100, 0, 0), Vec3(0, -80, 30)}) {
    const Mesh more = make_icosphere(shift.x() > 0 ? 20 : 5, shift.x() > 0 ? 9 : 3);
    const auto base = static_cast<std::uint32_t>(three.local.size());
    for (const Vec3& v : more.local) three.local.push_back(v + more.origin - three.origin + shift);
    for (const Tri& f : more.faces) three.faces.push_back({f[0] + base, f[1] + base, f[2] + base});
  }
  const std::uint32_t big = static_cast<std::uint32_t>(make_icosphere(20, 9).faces.size());
  const std::vector<std::uint32_t> runs{static_cast<std::uint32_t>(per), big,
                                        static_cast<std::uint32_t>(three.faces.size() - per - big)};
  for (std::uint32_t L : {1u, 5u, 24u, 64u}) {
    CAPTURE(L);
    check_tree(three, SphereTree::build(three, {L}, runs).value(), runs);
  }
  // Empty runs are skipped; one non-empty run is the plain build.
  const std::vector<std::uint32_t> with_empty{0, static_cast<std::uint32_t>(per), 0, big, runs[2], 0};
  check_tree(three, SphereTree::build(three, {8}, with_empty).value(), runs);
  const SphereTree one =
      SphereTree::build(three, {8}, std::vector<std::uint32_t>{0, std::uint32_t(three.faces.size())}).value();
  const SphereTree plain = SphereTree::build(three, {8}).value();
  CHECK(one.face_order == plain.face_order);

  const Mesh* el = st::test::model_mesh("elephant.off");
  const SphereTree et = SphereTree::build(*el).value();
  const std::vector<std::uint32_t> blocks = et.layer(3);
  Mesh share;
  share.origin = el->origin;
  share.local = el->local;
  std::vector<std::uint32_t> share_runs;
  for (std::size_t b = 0; b < blocks.size(); b += 3) {
    share_runs.push_back(std::uint32_t(et.faces_end(blocks[b]) - et.faces_begin(blocks[b])));
    for (const std::uint32_t* f = et.faces_begin(blocks[b]); f != et.faces_end(blocks[b]); ++f)
      share.faces.push_back(el->faces[*f]);
  }
  REQUIRE(share_runs.size() > 8);
  const SphereTree grouped = SphereTree::build(share, {}, share_runs).value();
  check_tree(share, grouped, share_runs);
  // Apart blocks kept apart: every leaf lies within its block, so its sphere is no larger than
  // the block's sphere in the elephant's own tree (the points of a subset; float padding aside).
  std::vector<double> block_r;
  for (std::size_t b = 0; b < blocks.size(); b += 3) block_r.push_back(et.nodes[blocks[b]].radius);
  std::vector<std::uint32_t> block_end;
  for (std::uint32_t at = 0; std::uint32_t n : share_runs) block_end.push_back(at += n);
  for (const SphereNode& n : grouped.nodes)
    if (n.leaf) {
      const std::uint32_t f = grouped.face_order[n.first];
      const std::size_t b = std::size_t(std::upper_bound(block_end.begin(), block_end.end(), f) - block_end.begin());
      CHECK(n.radius <= block_r[b] * (1 + 1e-5));
    }
  // Runs that do not cover the faces are refused.
  auto bad = SphereTree::build(three, {8}, std::vector<std::uint32_t>{runs[0], runs[1]});
  REQUIRE(!bad.ok());
  CHECK(bad.error().find("face groups cover") != std::string::npos);
}

TEST_CASE("SphereTree::build rejects bad input") {
  const Mesh box = make_box({1, 1, 1});
  CHECK(!SphereTree::build(box, {0}).ok());
  CHECK(!SphereTree::build(box, {kMaxLeafFaces + 1}).ok());
  Mesh empty;
  CHECK(!SphereTree::build(empty).ok());
  Mesh bad = box;
  bad.faces[3][1] = 999;
  auto r = SphereTree::build(bad);
  REQUIRE(!r.ok());
  CHECK(r.error().find("face 3") != std::string::npos);
}

TEST_CASE("tree files round-trip and tell stale from corrupt") {
  const Mesh m = make_icosphere(20, 8);
  const SphereTree t = SphereTree::build(m).value();
  const std::string path = (std::filesystem::temp_directory_path() / "st_tree_test.sttree").string();
  REQUIRE(write_tree(t, path).ok());
  auto back = read_tree(path, m);
  REQUIRE(back.ok());
  const SphereTree& u = back.value();
  CHECK(u.mesh_hash == t.mesh_hash);
  CHECK(u.num_depths == t.num_depths);
  CHECK(std::memcmp(u.nodes.data(), t.nodes.data(), t.nodes.size() * sizeof(SphereNode)) == 0);
  CHECK(u.face_order == t.face_order);

  // Stale: other parameters, or a moved vertex.
  auto s1 = read_tree(path, m, {4});
  REQUIRE(!s1.ok());
  CHECK(s1.error().find("stale") != std::string::npos);
  Mesh moved = m;
  moved.local[5].x() += 1e-9;
  auto s2 = read_tree(path, moved);
  REQUIRE(!s2.ok());
  CHECK(s2.error().find("stale") != std::string::npos);

  auto corrupt_with = [&](auto&& edit) {
    std::ifstream in(path, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), {});
    edit(bytes);
    const std::string p2 = path + ".bad";
    std::ofstream(p2, std::ios::binary) << bytes;
    auto r = read_tree(p2, m);
    std::remove(p2.c_str());
    return r.ok() ? std::string("ok") : r.error();
  };
  CHECK(corrupt_with([](std::string& b) { b[0] = 'X'; }).find("corrupt: bad magic") != std::string::npos);
  CHECK(corrupt_with([](std::string& b) { b[8] = 9; }).find("corrupt: format version") != std::string::npos);
  CHECK(corrupt_with([](std::string& b) { b.resize(b.size() - 4); }).find("corrupt: sizes") != std::string::npos);
  CHECK(corrupt_with([](std::string& b) { b[200] ^= 0x10; }).find("corrupt: payload checksum") != std::string::npos);
  CHECK(corrupt_with([](std::string& b) { b.resize(10); }).find("corrupt") != std::string::npos);
  CHECK(read_tree(path + ".missing", m).error().find("cannot open") != std::string::npos);
  std::remove(path.c_str());
}
