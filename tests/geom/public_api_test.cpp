// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/collide.*: the public API gives exactly geom::collide()'s pairs (and the
// brute-force reference's), frames compose as documented, the first-pair and capped requests
// return pairs of the full set with consistent counters, and bad bodies and requests are refused
// with a message.
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdlib>
#include <limits>
#include <random>

#include <spheretouch/geom/pose_io.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/collide.hpp>
#include <spheretouch/contact.hpp>
#include <spheretouch/load_mesh.hpp>
#include "test_models.hpp"
#include "test_util.hpp"

namespace {

st::Body api_body(st::geom::Mesh mesh) {
  st::Result<st::Body> b = st::Body::make(std::move(mesh));
  REQUIRE_MESSAGE(b.ok(), b.error());
  return std::move(b).value();
}

std::vector<st::FacePair> api_inner_pairs(const st::Body& probe, const st::Body& object, const st::Pose& pose) {
  st::geom::CollideScratch scratch;
  st::geom::CollideResult res;
  st::geom::CollideConfig opt = st::geom::DefaultCollideConfig();
  opt.sort_pairs = true;
  st::geom::collide(probe.mesh(), probe.tree(), object.mesh(), object.tree(), pose, opt, scratch, res);
  return res.pairs;
}

bool api_is_subset(const std::vector<st::FacePair>& part, const std::vector<st::FacePair>& all) {
  return std::all_of(part.begin(), part.end(),
                     [&](const st::FacePair& p) { return std::binary_search(all.begin(), all.end(), p); });
}

}  // namespace

TEST_CASE("the public API returns exactly the inner collide()'s pairs and the brute-force set") {
  const st::Body probe = api_body(st::geom::make_capsule(4, 12, 10));
  const st::Body object = api_body(st::geom::make_icosphere(20, 6));
  st::ComputeCollision pair(probe, object);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-26, 26);
  int touching = 0;
  st::CollisionResult r;
  for (int i = 0; i < 40; ++i) {
    st::Pose pose = st::Pose::Identity();
    pose.linear() = st::test::random_rotation(rng);
    pose.translation() = st::Vec3(u(rng), u(rng), u(rng));
    pair.at_relative(pose, st::CollisionRequest::all_pairs(), r);
    CHECK(r.complete);
    CHECK(r.pairs == api_inner_pairs(probe, object, pose));
    std::vector<st::FacePair> brute = st::test::brute_force(probe.mesh(), object.mesh(), pose);
    std::sort(brute.begin(), brute.end());
    CHECK(r.pairs == brute);
    std::vector<std::uint32_t> scratch;
    const st::geom::FaceCounts c = st::geom::count_faces(r.pairs, scratch);
    CHECK(r.probe_faces == c.probe_faces);
    CHECK(r.object_faces == c.object_faces);
    CHECK(r.colliding() == !r.pairs.empty());
    touching += r.colliding() ? 1 : 0;
  }
  CHECK(touching >= 5);  // the poses exercise contact, not only misses
}

TEST_CASE("world frames compose as object.frame()^-1 * probe.frame()") {
  st::Body probe = api_body(st::geom::make_box({10, 10, 10}));
  st::Body object = api_body(st::geom::make_icosphere(15, 5));
  std::mt19937_64 rng(11);
  st::Pose world = st::Pose::Identity();
  world.linear() = st::test::random_rotation(rng);
  world.translation() = st::Vec3(1e5, -2e5, 3e4);  // far from the world origin
  st::Pose rel = st::Pose::Identity();
  rel.linear() = st::test::random_rotation(rng);
  rel.translation() = st::Vec3(14, 3, -2);  // the box's corner region inside the sphere's surface
  object.set_frame(world);
  probe.set_frame(world * rel);
  const st::Pose composed = st::relative_pose(probe, object);
  CHECK((composed.matrix() - rel.matrix()).cwiseAbs().maxCoeff() < 1e-9);
  st::ComputeCollision pair(probe, object);
  st::CollisionResult at_frames, at_given, at_rel;
  pair(st::CollisionRequest::all_pairs(), at_frames);
  pair(probe.frame(), object.frame(), st::CollisionRequest::all_pairs(), at_given);
  pair.at_relative(composed, st::CollisionRequest::all_pairs(), at_rel);
  REQUIRE(at_frames.colliding());
  CHECK(at_frames.pairs == at_rel.pairs);
  CHECK(at_given.pairs == at_rel.pairs);
  st::CollisionResult once;
  st::collide(probe, object, st::CollisionRequest::all_pairs(), once);
  CHECK(once.pairs == at_rel.pairs);
}

TEST_CASE("first-pair and capped requests return pairs of the full set, with counters of what they return") {
  const st::Body probe = api_body(*st::test::model_mesh("hand_L2.off"));
  const st::Body object = api_body(*st::test::model_mesh("elephant.off"));
  const char* root = std::getenv("ST_SOURCE_ROOT");
  st::Result<std::vector<st::Pose>> poses =
      st::geom::read_poses(std::string(root ? root : ".") + "/perf/poses/hand_elephant.txt");
  REQUIRE_MESSAGE(poses.ok(), poses.error());
  std::vector<st::Pose> all_poses = poses.value();
  // And the hand's vertices placed at random elephant vertices, 0-4 mm deep.
  std::mt19937_64 rng(5);
  const auto normals = st::test::vertex_normals(object.mesh());
  std::uniform_int_distribution<std::uint32_t> vo(0, static_cast<std::uint32_t>(object.mesh().num_vertices() - 1));
  std::uniform_int_distribution<std::uint32_t> vp(0, static_cast<std::uint32_t>(probe.mesh().num_vertices() - 1));
  std::uniform_real_distribution<double> depth(0.0, 4.0);
  for (int i = 0; i < 12; ++i) {
    const std::uint32_t o = vo(rng);
    all_poses.push_back(st::test::pose_near(probe.mesh(), vp(rng), object.mesh(), o, normals[o], depth(rng),
                                            st::test::random_rotation(rng)));
  }
  st::ComputeCollision pair(probe, object);
  st::CollisionResult all, first, capped;
  int checked = 0;
  for (const st::Pose& pose : all_poses) {
    pair.at_relative(pose, st::CollisionRequest::all_pairs(), all);
    CHECK(all.pairs == api_inner_pairs(probe, object, pose));
    pair.at_relative(pose, st::CollisionRequest::first_pair(), first);
    pair.at_relative(pose, st::CollisionRequest::capped(50), capped);
    if (!all.colliding()) {
      CHECK_FALSE(first.colliding());
      CHECK(first.complete);
      continue;
    }
    ++checked;
    REQUIRE(first.pairs.size() == 1);
    CHECK(first.contacts() == 2);
    CHECK(api_is_subset(first.pairs, all.pairs));
    CHECK(first.stats.tri_pairs <= all.stats.tri_pairs);  // it stopped early
    CHECK(capped.pairs.size() == std::min<std::size_t>(50, all.pairs.size()));
    CHECK(api_is_subset(capped.pairs, all.pairs));
    CHECK(std::is_sorted(capped.pairs.begin(), capped.pairs.end()));
    std::vector<std::uint32_t> scratch;
    const st::geom::FaceCounts c = st::geom::count_faces(capped.pairs, scratch);
    CHECK(capped.probe_faces == c.probe_faces);
    CHECK(capped.object_faces == c.object_faces);
    if (all.pairs.size() > 50) CHECK_FALSE(capped.complete);
    // A service's limit of 50: a full answer up to 50, else 51 pairs and not complete.
    pair.at_relative(pose, st::CollisionRequest::past_limit(50), capped);
    CHECK(capped.complete == (all.pairs.size() <= 50));
    CHECK(capped.pairs.size() == std::min<std::size_t>(51, all.pairs.size()));
  }
  CHECK(checked >= 8);
  CHECK(st::CollisionRequest::past_limit(SIZE_MAX).max_pairs == SIZE_MAX);
}

TEST_CASE("approximate requests report a superset of the exact pairs") {
  const st::Body probe = api_body(st::geom::make_capsule(3, 10, 8));
  const st::Body object = api_body(st::geom::make_icosphere(12, 5));
  st::ComputeCollision pair(probe, object);
  st::Pose pose = st::Pose::Identity();
  pose.translation() = st::Vec3(12, 1, 0.5);
  st::CollisionResult exact, approx;
  pair.at_relative(pose, st::CollisionRequest::all_pairs(), exact);
  pair.at_relative(pose, st::CollisionRequest::approximate(st::geom::kLeafSpheres), approx);
  REQUIRE(exact.colliding());
  CHECK(approx.pairs.size() >= exact.pairs.size());
  CHECK(api_is_subset(exact.pairs, approx.pairs));
}

TEST_CASE("the object-block restriction, the contact patch and load_mesh through the public API") {
  const st::Body hand = api_body(*st::test::model_mesh("hand_L2.off"));
  const st::Body ele = api_body(*st::test::model_mesh("elephant.off"));
  st::ComputeCollision pair(hand, ele);
  const char* root_dir = std::getenv("ST_SOURCE_ROOT");
  const st::Result<std::vector<st::Pose>> poses =
      st::geom::read_poses(std::string(root_dir ? root_dir : ".") + "/perf/results/poses/hand_elephant.txt");
  REQUIRE(poses.ok());
  const st::Pose pose = poses.value().at(5);  // ~1,000 contacts
  st::CollisionResult all, part, none;
  pair.at_relative(pose, st::CollisionRequest::all_pairs(), all);
  REQUIRE(all.colliding());
  // The root's children split in two halves: the two restricted queries' pairs are the whole set.
  const st::geom::SphereNode& root = ele.tree().nodes[0];
  REQUIRE(root.count >= 2);
  std::vector<std::uint32_t> first, second;
  for (std::uint32_t k = 0; k < root.count; ++k) (k < root.count / 2 ? first : second).push_back(root.first + k);
  std::vector<st::FacePair> merged;
  for (const auto* roots : {&first, &second}) {
    st::CollisionRequest r = st::CollisionRequest::all_pairs();
    r.restrict_object = true;
    r.object_roots = *roots;
    pair.at_relative(pose, r, part);
    merged.insert(merged.end(), part.pairs.begin(), part.pairs.end());
  }
  std::sort(merged.begin(), merged.end());
  CHECK(merged == all.pairs);
  st::CollisionRequest empty = st::CollisionRequest::all_pairs();
  empty.restrict_object = true;
  pair.at_relative(pose, empty, none);
  CHECK_FALSE(none.colliding());
  st::CollisionRequest unfiltered = st::CollisionRequest::all_pairs();
  unfiltered.tri_filter = false;
  pair.at_relative(pose, unfiltered, part);
  CHECK(part.pairs == all.pairs);
  CHECK(part.stats.tri_exact == part.stats.tri_pairs);

  // The contact model of what the query found, as the builder gives it directly.
  st::ComputeContactPatch patch;
  const st::ContactModel m = patch(pair, pose, all);
  st::geom::ContactBuilder direct;
  const st::ContactModel d = direct.build(hand.mesh(), ele.mesh(), pose, all.pairs);
  CHECK(m.in_contact());
  CHECK(m.penetration_mm == d.penetration_mm);
  CHECK((st::geom::to_eigen(m.force_dir) - st::geom::to_eigen(d.force_dir)).norm() == 0.0);

  // st::load_mesh: the mesh geom::load_mesh reads, or its error.
  const st::Result<st::Mesh> loaded = st::load_mesh(st::test::model("hand_L2.off"));
  REQUIRE(loaded.ok());
  CHECK(loaded.value().num_faces() == hand.mesh().num_faces());
  const st::Result<st::Mesh> missing = st::load_mesh("/nonexistent/hand.off");
  CHECK_FALSE(missing.ok());
  CHECK(st::test::contains(missing.error(), "/nonexistent/hand.off"));
}

TEST_CASE("one probe against object blocks in turn: grouped trees and set_object, as the workers use them") {
  const st::Body probe = api_body(st::geom::make_capsule(4, 12, 10));
  const st::Body whole = api_body(st::geom::make_icosphere(20, 6));
  // Two blocks of the object's faces (even and odd indices: interleaved, as block-cyclic shares
  // are), each its own body; and one body over both blocks whose tree keeps them in separate
  // subtrees (SphereTree::build's groups).
  const st::geom::Mesh& m = whole.mesh();
  std::vector<std::vector<std::uint32_t>> ids(2);
  for (std::uint32_t f = 0; f < m.num_faces(); ++f) ids[f % 2].push_back(f);
  auto part_of = [&](const std::vector<std::uint32_t>& faces) {
    st::geom::Mesh part;
    part.name = "block";
    part.origin = m.origin;
    part.local = m.local;  // every vertex: the faces keep their vertex indices
    for (std::uint32_t f : faces) part.faces.push_back(m.faces[f]);
    return part;
  };
  st::geom::Mesh grouped = part_of(ids[0]);
  for (std::uint32_t f : ids[1]) grouped.faces.push_back(m.faces[f]);
  const std::vector<std::uint32_t> groups = {std::uint32_t(ids[0].size()), std::uint32_t(ids[1].size())};
  const std::uint32_t split = groups[0];  // grouped faces below it are block 0's
  auto gmesh = std::make_shared<const st::geom::Mesh>(grouped);
  st::Result<st::geom::SphereTree> gt = st::geom::SphereTree::build(*gmesh, st::geom::DefaultTreeConfig(), groups);
  REQUIRE(gt.ok());
  auto gtree = std::make_shared<const st::geom::SphereTree>(std::move(gt).value());
  // The grouped tree's hash includes the groups: without them the body is refused, with them made.
  CHECK_FALSE(st::Body::make(gmesh, gtree).ok());
  st::Result<st::Body> gbody = st::Body::make(gmesh, gtree, st::Pose::Identity(), groups);
  REQUIRE_MESSAGE(gbody.ok(), gbody.error());
  const std::vector<std::vector<std::uint32_t>> roots = st::geom::group_roots(*gtree, m.num_faces(), groups);
  REQUIRE(roots.size() == 2);

  const st::Body block0 = api_body(part_of(ids[0])), block1 = api_body(part_of(ids[1]));
  st::ComputeCollision whole_pair(probe, whole), grouped_pair(probe, gbody.value()), blocks(probe, block0);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-24, 24);
  int touching = 0;
  st::CollisionResult all, r;
  for (int i = 0; i < 30; ++i) {
    st::Pose pose = st::Pose::Identity();
    pose.linear() = st::test::random_rotation(rng);
    pose.translation() = st::Vec3(u(rng), u(rng), u(rng));
    whole_pair.at_relative(pose, st::CollisionRequest::all_pairs(), all);
    touching += all.colliding() ? 1 : 0;
    std::vector<st::FacePair> by_blocks, by_groups;
    for (int b = 0; b < 2; ++b) {
      // The block bodies in turn through one collider (set_object keeps the probe's caches).
      blocks.set_object(b == 0 ? block0 : block1);
      blocks.at_relative(pose, st::CollisionRequest::all_pairs(), r);
      for (const st::FacePair& p : r.pairs) by_blocks.push_back({p.probe, ids[b][p.object]});
      // The grouped body restricted to one group's subtrees (a worker skipping the other block).
      st::CollisionRequest only = st::CollisionRequest::all_pairs();
      only.restrict_object = true;
      only.object_roots = roots[b];
      grouped_pair.at_relative(pose, only, r);
      for (const st::FacePair& p : r.pairs) {
        CHECK((p.object < split) == (b == 0));  // only the asked group's faces
        by_groups.push_back({p.probe, p.object < split ? ids[0][p.object] : ids[1][p.object - split]});
      }
    }
    std::sort(by_blocks.begin(), by_blocks.end());
    std::sort(by_groups.begin(), by_groups.end());
    CHECK(by_blocks == all.pairs);
    CHECK(by_groups == all.pairs);
  }
  CHECK(touching >= 5);
}

TEST_CASE("bad bodies and requests are refused with a message") {
  st::geom::Mesh bad = st::geom::make_box({1, 1, 1});
  bad.name = "broken-box";
  bad.faces[3][1] = 999;
  st::Result<st::Body> b = st::Body::make(bad);
  REQUIRE_FALSE(b.ok());
  CHECK(st::test::contains(b.error(), "broken-box"));
  // value() on an error throws the error's message (not std::bad_variant_access, message lost).
  bool threw = false;
  try {
    (void)b.value();
  } catch (const st::BadResultAccess& e) {
    threw = true;
    CHECK(std::string(e.what()) == b.error());
  }
  CHECK(threw);
  CHECK_THROWS_AS((void)std::move(b).value(), st::BadResultAccess);
  const st::Result<int> fine = 3;
  CHECK(fine.error().empty());  // no error: an empty message, not a throw

  // A tree built for another mesh.
  auto box = std::make_shared<const st::geom::Mesh>(st::geom::make_box({1, 1, 1}));
  auto ball = st::geom::make_icosphere(1, 2);
  auto ball_tree = std::make_shared<const st::SphereTree>(st::SphereTree::build(ball).value());
  st::Result<st::Body> mismatched = st::Body::make(box, ball_tree);
  REQUIRE_FALSE(mismatched.ok());
  CHECK(st::test::contains(mismatched.error(), "another mesh"));

  st::CollisionRequest zero = st::DefaultCollisionRequest();
  zero.max_pairs = 0;
  CHECK(st::test::contains(st::check(zero), "max_pairs"));
  const st::Body one = api_body(st::geom::make_box({2, 2, 2}));
  st::ComputeCollision pair(one, one);
  st::CollisionResult r;
  pair.at_relative(st::Pose::Identity(), zero, r);
  CHECK(r.bad_request);
  CHECK_FALSE(r.colliding());
  st::Pose nan = st::Pose::Identity();
  nan.translation().x() = std::numeric_limits<double>::quiet_NaN();
  pair.at_relative(nan, st::CollisionRequest::all_pairs(), r);  // never crashes; nothing found
  CHECK_FALSE(r.colliding());
}
