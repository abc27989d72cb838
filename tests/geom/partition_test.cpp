// Tests src/geom/partition.*: blocks cover every face once; the union over workers of collide
// restricted to each worker's roots equals the unrestricted result, for W = 1..16.
#include <doctest/doctest.h>

#include "geom/collide.hpp"
#include "geom/partition.hpp"
#include "geom/primitives.hpp"
#include "test_models.hpp"

using namespace st::geom;

TEST_CASE("block-cyclic partition: cover and union over workers") {
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
      for (std::uint32_t W = 1; W <= 16; ++W) {
        CAPTURE(layer);
        CAPTURE(B);
        CAPTURE(W);
        const Partition p = make_partition(et, layer, W, B).value();
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
