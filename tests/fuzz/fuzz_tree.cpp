// SPDX-License-Identifier: BSD-3-Clause
// libFuzzer target: the sphere-tree cache reader (geom/tree_io.hpp). An attacker who can write
// the cache file can make its checksum and mesh hash match (neither is cryptographic), so the
// harness does that for every input (seal_tree_bytes) and the structure check is what stands.
// Properties, beyond "no crash, leak, UB, hang or unbounded allocation":
//  * a refused file says why;
//  * a tree the reader accepts gives collide() exactly the reference pair set (every pair of
//    overlapping triangles, net/reference_backend.hpp) at several poses: an accepted tree may be
//    shaped differently from the one we build, but never wrong; and so does the coherent
//    collider sliding a little forth and back from each.
#include <algorithm>
#include <cstdint>
#include <vector>

#include "fuzz_check.hpp"
#include <spheretouch/geom/coherent.hpp>
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/tree_io.hpp>
#include <spheretouch/net/reference_backend.hpp>

namespace {

using namespace st::geom;

struct Fixture {
  Mesh object = make_icosphere(10.0, 2);  // 320 faces
  Mesh probe = make_box(Vec3(6, 6, 6));
  TreeConfig params = [] {
    TreeConfig p = DefaultTreeConfig();
    p.leaf_faces = 4;  // several levels over 320 faces
    return p;
  }();
  SphereTree probe_tree = SphereTree::build(probe, params).value();
  std::vector<Pose> poses = [] {
    std::vector<Pose> v;
    for (int i = 0; i < 4; ++i) {
      Pose p = Pose::Identity();
      p.linear() = Eigen::AngleAxisd(0.4 * i, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
      const Vec3 dir = Vec3(std::cos(1.3 * i), std::sin(1.3 * i), 0.3 * i - 0.5).normalized();
      p.translation() = dir * (10.0 - i);  // straddling the surface, a little deeper each time
      v.push_back(p);
    }
    return v;
  }();
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const Fixture fx;
  std::vector<std::uint8_t> bytes(data, data + size);
  seal_tree_bytes(bytes, fx.object, fx.params);
  st::Result<SphereTree> t = parse_tree(bytes, "fuzz.tree", fx.object, fx.params);
  if (!t) {
    ST_FUZZ_CHECK(!t.error().empty(), "a refusal says why");
    return 0;
  }
  CollideScratch scratch;
  CollideResult result;
  for (const Pose& pose : fx.poses) {
    collide(fx.probe, fx.probe_tree, fx.object, t.value(), pose, DefaultCollideConfig(), scratch, result);
    std::vector<FacePair> got = result.pairs;
    std::sort(got.begin(), got.end());
    std::vector<st::net::FacePair> ref = st::net::reference_collide(fx.probe, fx.object, pose);
    std::sort(ref.begin(), ref.end());
    ST_FUZZ_CHECK(got.size() == ref.size(), "an accepted tree gives the reference pair count");
    ST_FUZZ_CHECK(got == ref, "an accepted tree gives the reference pairs");
  }
  // The coherent collider sliding a little from each pose, forth and back (certificates made at
  // one pose are used at the next): the reference pairs every round.
  CoherentConfig fixed;
  fixed.arbitrate = false;
  CoherentCollider coherent(fixed);
  for (const Pose& start : fx.poses)
    for (int k = 0; k < 8; ++k) {  // 0.004 a round along x, forth then back, from each pose
      Pose pose = start;
      pose.translation().x() += 0.004 * (k < 4 ? k : 8 - k);
      coherent.collide(fx.probe, fx.probe_tree, fx.object, t.value(), pose, DefaultCollideConfig(), result);
      std::vector<FacePair> got = result.pairs;
      std::sort(got.begin(), got.end());
      std::vector<st::net::FacePair> ref = st::net::reference_collide(fx.probe, fx.object, pose);
      std::sort(ref.begin(), ref.end());
      ST_FUZZ_CHECK(got == ref, "an accepted tree gives the coherent collider the reference pairs");
    }
  return 0;
}
