// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/contact_depth.*: one side's depth search on a round of the patch model set up
// step by step (pairs, pose, records): a ball pressed into a box's face (the ball's depth along +z
// is the press depth, the box has no vertex inside), into its corner (the corner's depth along −n
// is the press depth), a search from the last round's memory, and the max_inside_vertices cap.
#include <spheretouch/geom/contact_depth.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include <spheretouch/geom/contact_patch.hpp>
#include <spheretouch/geom/primitives.hpp>
#include "analytic_shapes.hpp"
#include "test_models.hpp"

namespace st::inline SPHERETOUCH_ABI::geom {
/// The patch model's parts, for the tests (a friend of ContactBuilder).
struct PatchTestAccess {
  using Patch = ContactBuilder::Patch;
};
}  // namespace st::geom

using namespace st::geom;
using Patch = PatchTestAccess::Patch;

namespace {

using st::test::ball10;
using st::test::box40;
using st::test::kDepthTol;

using st::test::pose_at;

/// A round of the patch model up to its depth search (Patch::build()'s steps before PD).
void set_up_round(Patch& patch, const Mesh& probe, const Mesh& object, const Pose& pose) {
  const std::vector<FacePair> pairs = st::test::brute_force(probe, object, pose);
  REQUIRE(!pairs.empty());
  patch.prepare(probe, object);
  patch.next_epoch();
  ContactModel m;
  patch.take_pairs(probe, object, patch.in_order(pairs), m);
  patch.set_pose(probe, object, pose);
  patch.make_records(m);
}

}  // namespace

TEST_CASE("contact depth: a ball pressed into a box's face: its depth along +z is the press depth") {
  for (double d : {0.5, 2.0, 5.0}) {
    CAPTURE(d);
    Patch patch(DefaultContactConfig());
    set_up_round(patch, ball10(), box40(), pose_at(Vec3(1.3, -2.1, 30.0 - d)));
    const Deepest dp = DepthSearch(patch, true, Vec3::UnitZ()).run();
    CHECK(std::abs(dp.depth - d) <= kDepthTol);
    CHECK(dp.depth <= d + 1e-9);  // the ball's vertices lie on the sphere
    CHECK(dp.inside > 0);
    CHECK_FALSE(dp.capped);
    REQUIRE(dp.face < box40().faces.size());
    CHECK(std::abs(dp.point.z() + dp.depth - 20) < 1e-9);  // it leaves through the top face
    if (dp.vertex != UINT32_MAX) CHECK((dp.point - patch.probe_point(dp.vertex, ball10())).norm() == 0);
    // The box has no vertex inside the ball.
    const Deepest dobj = DepthSearch(patch, false, -Vec3::UnitZ()).run();
    CHECK(dobj.inside == 0);
    CHECK(dobj.vertex == UINT32_MAX);
    CHECK(dobj.depth <= dp.depth);
  }
}

TEST_CASE("contact depth: a ball pressed onto a box's corner: the corner's depth along −n is the press depth") {
  const Vec3 n = Vec3(1, 1, 1).normalized();
  const Vec3 corner(20, 20, 20);
  for (double d : {1.0, 3.0}) {
    CAPTURE(d);
    Patch patch(DefaultContactConfig());
    set_up_round(patch, ball10(), box40(), pose_at(corner + (10 - d) * n));
    // The corner leaves the ball along −n after d (the ball's centre is on its diagonal).
    const Deepest dobj = DepthSearch(patch, false, -n).run();
    CHECK(std::abs(dobj.depth - d) <= kDepthTol);
    CHECK(dobj.depth <= d + 1e-9);
    CHECK(dobj.inside == 1);
    REQUIRE(dobj.vertex < box40().local.size());
    CHECK((box40().local[dobj.vertex] - corner).norm() == 0);
    CHECK(dobj.face < ball10().faces.size());
    // No ball point is deeper along +n than the corner.
    const Deepest dp = DepthSearch(patch, true, n).run();
    CHECK(dp.depth <= d + 1e-9);
  }
}

TEST_CASE("contact depth: the next round climbs from the memory to the same depth") {
  Patch patch(DefaultContactConfig());
  const Pose p = pose_at(Vec3(1.3, -2.1, 28.0));
  set_up_round(patch, ball10(), box40(), p);
  const Deepest first = DepthSearch(patch, true, Vec3::UnitZ()).run();
  REQUIRE(first.depth > 0);
  const DepthMemory& memory = patch.probe_s.memory;
  CHECK(memory.vertex[0] < ball10().local.size());
  CHECK(memory.face[0] < box40().faces.size());
  for (int round = 0; round < 5; ++round) {  // the same pose: rounds with and without a search for new regions
    CAPTURE(round);
    set_up_round(patch, ball10(), box40(), p);
    const Deepest again = DepthSearch(patch, true, Vec3::UnitZ()).run();
    CHECK(again.depth == first.depth);
    CHECK(again.face == first.face);
    CHECK(again.vertex == first.vertex);
  }
}

TEST_CASE("contact depth: the search stops at max_inside_vertices") {
  ContactConfig config = DefaultContactConfig();
  config.max_inside_vertices = 3;
  Patch patch(config);
  set_up_round(patch, ball10(), box40(), pose_at(Vec3(1.3, -2.1, 25.0)));
  const Deepest dp = DepthSearch(patch, true, Vec3::UnitZ()).run();
  CHECK(dp.capped);
  CHECK(dp.inside <= 3);
  CHECK(dp.depth <= 5 + 1e-9);
}
