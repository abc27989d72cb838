// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/reference_backend.*: the SAT triangle test on the cases that matter (closed
// sets: touching collides), and the grid backend against all-pairs brute force.
#include <doctest/doctest.h>

#include <spheretouch/net/reference_backend.hpp>
#include "net_test_util.hpp"

using namespace st;
using namespace st::net;
using geom::Vec3;

TEST_CASE("sat_tri_overlap: crossing, separated, touching at a vertex and an edge, coplanar") {
  const Vec3 a0(0, 0, 0), a1(1, 0, 0), a2(0, 1, 0);
  CHECK(sat_tri_overlap(a0, a1, a2, Vec3(0.2, 0.2, -1), Vec3(0.2, 0.2, 1), Vec3(0.3, 0.4, 1)));  // pierces
  CHECK_FALSE(sat_tri_overlap(a0, a1, a2, Vec3(0, 0, 0.1), Vec3(1, 0, 0.1), Vec3(0, 1, 0.1)));   // parallel above
  CHECK(sat_tri_overlap(a0, a1, a2, Vec3(1, 0, 0), Vec3(2, 0, 1), Vec3(2, 1, 1)));               // shares a vertex
  CHECK(sat_tri_overlap(a0, a1, a2, Vec3(0.5, 0.5, 0), Vec3(1, 1, 1), Vec3(1, 1, -1)));     // touches the hypotenuse
  CHECK(sat_tri_overlap(a0, a1, a2, Vec3(0.1, 0.1, 0), Vec3(2, 0.1, 0), Vec3(0.1, 2, 0)));  // coplanar overlap
  CHECK_FALSE(sat_tri_overlap(a0, a1, a2, Vec3(0.6, 0.6, 0), Vec3(2, 0.6, 0), Vec3(0.6, 2, 0)));  // coplanar apart
  CHECK(sat_tri_overlap(a0, a1, a2, Vec3(0.5, 0.5, 0), Vec3(2, 0.5, 0), Vec3(0.5, 2, 0)));        // coplanar, touching
}

TEST_CASE("the grid backend finds exactly the pairs of all-pairs brute force") {
  const test::NetScene s = test::small_scene(6);
  for (const geom::Pose& pose : test::contact_poses(s, 6)) {
    std::vector<FacePair> brute;
    const geom::Pose rel = Eigen::Translation3d(-s.object.origin) * pose * Eigen::Translation3d(s.probe.origin);
    for (std::uint32_t p = 0; p < s.probe.faces.size(); ++p)
      for (std::uint32_t o = 0; o < s.object.faces.size(); ++o) {
        const auto& a = s.probe.faces[p];
        const auto& b = s.object.faces[o];
        if (sat_tri_overlap(rel * s.probe.local[a[0]], rel * s.probe.local[a[1]], rel * s.probe.local[a[2]],
                            s.object.local[b[0]], s.object.local[b[1]], s.object.local[b[2]]))
          brute.push_back({p, o});
      }
    CHECK(reference_collide(s.probe, s.object, pose) == brute);
  }
}

TEST_CASE("the union of the shares' pairs equals the whole object's, for any number of shares") {
  const test::NetScene s = test::small_scene(8, 16);
  const auto poses = test::contact_poses(s, 8);
  std::size_t total = 0;
  for (std::uint32_t w : {1u, 3u, 8u}) {
    const auto share = block_cyclic(static_cast<std::uint32_t>(s.blocks.size()), w);
    std::vector<std::unique_ptr<CollisionBackend>> bk;
    for (std::uint32_t i = 0; i < w; ++i) {
      bk.push_back(make_reference_backend());
      REQUIRE(bk.back()->load(make_block_set(s.probe, s.object, s.blocks, share[i], 8).value()).ok());
    }
    for (const geom::Pose& pose : poses) {
      std::vector<FacePair> u;
      for (auto& b : bk) b->query(pose, {}, u, {});
      std::sort(u.begin(), u.end());
      CHECK(u == reference_collide(s.probe, s.object, pose));
      total += u.size();
    }
  }
  CHECK(total > 0);
}
