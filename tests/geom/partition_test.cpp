// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/partition.*: blocks cover every face once; the union over workers of collide
// restricted to each worker's roots equals the unrestricted result, for W = 1..16 and every
// mapping (block-cyclic, contiguous, random); the automatic split never yields an empty or
// out-of-range block and gives every worker a block, for any worker count it accepts.
#include <doctest/doctest.h>

#include <algorithm>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/partition.hpp>
#include <spheretouch/geom/primitives.hpp>
#include "test_models.hpp"

using namespace st::geom;
using st::Result;

TEST_CASE("partition, every mapping: cover and union over workers") {
  const Mesh* hp = st::test::model_mesh("hand_L2.off");
  const Mesh* ep = st::test::model_mesh("elephant.off");
  const Mesh hand = hp ? *hp : make_capsule(6, 20, 32);
  const Mesh ele = ep ? *ep : make_icosphere(30, 20);
  const SphereTree ht = SphereTree::build(hand).value();
  const SphereTree et = SphereTree::build(ele).value();
  // A pose with contacts: hand vertex 0 pushed 3 mm into the object near its vertex 0.
  const auto normals = st::test::vertex_normals(ele);
  const Pose pose = st::test::pose_near(hand, 0, ele, 0, normals[0], 3.0, Eigen::Matrix3d::Identity());
  CollideScratch scratch;
  CollideResult full, part;
  CollideConfig opt;
  opt.sort_pairs = true;
  collide(hand, ht, ele, et, pose, opt, scratch, full);
  REQUIRE(!full.pairs.empty());
  MESSAGE("partition pose: ", full.contacts(), " contacts");
  for (std::uint32_t layer : {0u, 1u, 2u, 3u, et.num_depths}) {
    for (std::uint32_t B : {1u, 3u, 16u}) {
      for (std::uint32_t i = 0; i < 3 * 16; ++i) {
        const Mapping m = static_cast<Mapping>(i / 16);
        const std::uint32_t W = i % 16 + 1;
        if (m != Mapping::block_cyclic && W % 3 != 1 && W != 16) continue;  // 1, 4, 7, 10, 13, 16
        CAPTURE(layer);
        CAPTURE(B);
        CAPTURE(W);
        CAPTURE(to_string(m));
        const Partition p = make_partition(et, layer, W, B, m, 7).value();
        REQUIRE(p.owners.size() == p.num_blocks());
        for (std::uint32_t k = 0; k < p.num_blocks(); ++k) CHECK(p.owner(k) < W);
        if (m == Mapping::block_cyclic)
          for (std::uint32_t k = 0; k < p.num_blocks(); ++k) CHECK(p.owner(k) == k % W);
        if (m == Mapping::contiguous)
          for (std::uint32_t k = 1; k < p.num_blocks(); ++k) CHECK(p.owner(k) >= p.owner(k - 1));
        std::vector<int> cover(ele.num_faces(), 0);
        std::vector<FacePair> uni;
        for (std::uint32_t w = 0; w < W; ++w) {
          const std::vector<std::uint32_t> roots = p.worker_roots(w);
          for (std::uint32_t r : roots)
            for (const std::uint32_t* f = et.faces_begin(r); f != et.faces_end(r); ++f) ++cover[*f];
          CollideConfig o;
          o.object_roots = roots;
          o.restrict_object = true;
          collide(hand, ht, ele, et, pose, o, scratch, part);
          uni.insert(uni.end(), part.pairs.begin(), part.pairs.end());
        }
        CHECK(std::all_of(cover.begin(), cover.end(), [](int c) { return c == 1; }));
        std::sort(uni.begin(), uni.end());
        CHECK(uni == full.pairs);
      }
    }
  }
  CHECK(!make_partition(et, 1, 0, 4).ok());
  CHECK(!make_partition(et, 1, 4, 0).ok());
  // Subtree extents are contiguous ranges of the flat arrays.
  for (std::uint32_t r : et.layer(2)) {
    const SubtreeExtent e = subtree_extent(et, r);
    CHECK(e.face_end - e.face_begin == et.cold[r].face_end - et.cold[r].face_begin);
    for (std::uint32_t d = e.desc_begin; d < e.desc_end; ++d) {
      CHECK(et.cold[d].face_begin >= e.face_begin);
      CHECK(et.cold[d].face_end <= e.face_end);
    }
  }
}

TEST_CASE("automatic split: in range, no empty block, every worker served; pinned knobs are kept") {
  const Mesh* ep = st::test::model_mesh("elephant.off");
  const Mesh ele = ep ? *ep : make_icosphere(30, 20);
  std::vector<Mesh> meshes{ele, make_icosphere(10, 2), make_capsule(3, 8, 6)};
  for (const Mesh& mesh : meshes) {
    const SphereTree t = SphereTree::build(mesh).value();
    CAPTURE(mesh.num_faces());
    for (Mapping m : {Mapping::block_cyclic, Mapping::contiguous, Mapping::random}) {
      for (std::uint32_t W : {1u, 2u, 3u, 4u, 7u, 8u, 16u, 33u, 64u, 200u}) {
        CAPTURE(W);
        const std::string mapping = to_string(m);
        CAPTURE(mapping);
        SplitModelConfig cfg;
        cfg.contact_radius = 5;
        Result<SplitChoice> c = choose_split(t, W, m, cfg);
        if (!c) {
          // Refused only when no layer has enough blocks for W workers (or, for a random deal,
          // when every deal leaves some worker without a block).
          CHECK((m == Mapping::random || t.layer(t.num_depths).size() < W));
          continue;
        }
        const SplitChoice& s = c.value();
        CHECK(s.layer < t.num_depths);
        CHECK(s.block_size >= 1);
        const Partition p = make_partition(t, s.layer, W, s.block_size, m).value();
        CHECK(p.num_blocks() == s.blocks);
        CHECK(p.num_blocks() >= W);
        std::vector<std::uint32_t> held(W, 0);
        for (std::uint32_t k = 0; k < p.num_blocks(); ++k) {
          REQUIRE(p.owner(k) < W);
          ++held[p.owner(k)];
          const auto b = p.block(k);
          REQUIRE(!b.empty());
          std::size_t faces = 0;
          for (std::uint32_t n : b) {
            REQUIRE(n < t.num_nodes());
            faces += t.cold[n].face_end - t.cold[n].face_begin;
          }
          CHECK(faces > 0);
        }
        CHECK(*std::min_element(held.begin(), held.end()) >= 1);
        CHECK(s.imbalance() >= 1.0 - 1e-9);
        CHECK(!s.why.empty());
      }
    }
    // A pinned layer or block size is kept; the other knob is chosen.
    if (t.num_depths > 2) {
      Result<SplitChoice> pinned = choose_split(t, 2, Mapping::block_cyclic, {}, 1, 0);
      if (pinned) CHECK(pinned.value().layer == 1);
      Result<SplitChoice> sized = choose_split(t, 1, Mapping::block_cyclic, {}, kFree, 3);
      REQUIRE(sized.ok());
      CHECK(sized.value().block_size == 3);
    }
  }
  const SphereTree et = SphereTree::build(ele).value();
  CHECK(!choose_split(et, 0, Mapping::block_cyclic).ok());
  // More workers than leaves: a clear refusal, never an empty worker.
  const Result<SplitChoice> too_many = choose_split(et, 1u << 30, Mapping::block_cyclic);
  REQUIRE(!too_many.ok());
  CHECK(too_many.error().find("workers a block each") != std::string::npos);
}

namespace {

// The elephant's tree (an icosphere's where the model set is absent), the splits' test object.
SphereTree elephant_tree() {
  const Mesh* ep = st::test::model_mesh("elephant.off");
  return SphereTree::build(ep ? *ep : make_icosphere(30, 20)).value();
}

}  // namespace

TEST_CASE("automatic split: by its own model, the pick is no worse than the paper's layer 2, block size 1") {
  const SphereTree t = elephant_tree();
  SplitModelConfig cfg;
  cfg.contact_radius = 12;
  for (std::uint32_t W : {2u, 8u}) {
    const SplitChoice c = choose_split(t, W, Mapping::block_cyclic, cfg).value();
    MESSAGE("W=", W, ": ", c.why);
    CHECK(c.blocks >= W);
    // The chosen split is no worse, by the model, than the paper's fixed layer 2, block size 1.
    const Result<SplitChoice> fixed = choose_split(t, W, Mapping::block_cyclic, cfg, 2, 1);
    if (fixed)
      CHECK(c.predicted_max <= fixed.value().predicted_max * (1 + cfg.tie) * (1 + cfg.smaller_blocks_tie) + 1e-9);
  }
}

TEST_CASE("automatic split: a smaller block size at the pick's layer wins within smaller_blocks_tie") {
  const SphereTree t = elephant_tree();
  SplitModelConfig strict;
  strict.contact_radius = 12;
  strict.smaller_blocks_tie = 0;
  SplitModelConfig cfg = strict;
  cfg.smaller_blocks_tie = 0.05;
  for (std::uint32_t W : {2u, 4u, 8u}) {
    CAPTURE(W);
    const SplitChoice cheapest = choose_split(t, W, Mapping::block_cyclic, strict).value();
    const SplitChoice c = choose_split(t, W, Mapping::block_cyclic, cfg).value();
    MESSAGE("W=", W, ": cheapest ", cheapest.why, "; picked ", c.why);
    CHECK(c.layer == cheapest.layer);
    CHECK(c.block_size <= cheapest.block_size);
    CHECK(c.predicted_max <= cheapest.predicted_max * 1.05 + 1e-9);
    // The pick is the smallest block size within the tie: every smaller one costs more than it allows.
    for (std::uint32_t B = 1; B < c.block_size; ++B) {
      const Result<SplitChoice> smaller = choose_split(t, W, Mapping::block_cyclic, strict, c.layer, B);
      if (smaller) CHECK(smaller.value().predicted_max > cheapest.predicted_max * 1.05);
    }
    // And what it gave up for it, the cheapest's model cost, is where it says.
    const Result<SplitChoice> same = choose_split(t, W, Mapping::block_cyclic, strict, c.layer, c.block_size);
    REQUIRE(same.ok());
    CHECK(same.value().predicted_max == doctest::Approx(c.predicted_max));
  }
}
