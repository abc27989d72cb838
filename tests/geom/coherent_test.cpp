// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/coherent.*: the coherent collider returns collide()'s pair set on
// every round of slides, jitter and jerks (real meshes, every ISA, far from the origin, tiny and
// huge scales, coplanar and degenerate faces), reuses its certificates where the motion allows,
// and falls back to collide() on jumps, budgets and a full pool.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include <spheretouch/geom/coherent.hpp>
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/simd.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include "test_models.hpp"
#include "test_util.hpp"

using namespace st::geom;

// Names of their own: the sanitizer builds compile the test files as one unit (unity).
namespace {

struct CoBody {
  Mesh mesh;
  SphereTree tree;
  explicit CoBody(Mesh m) : mesh(std::move(m)), tree(SphereTree::build(mesh, DefaultTreeConfig()).value()) {}
};

constexpr double kPiCoherent = 3.14159265358979323846;

// The path chosen by the motion alone (no timing against collide()), so the counters below are
// the same on every machine.
CoherentConfig fixed() {
  CoherentConfig c;
  c.arbitrate = false;
  return c;
}

// A pose of the probe pressed 3 mm into the object at a random vertex (random turn, seeded) with
// at least 50 pairs; `plain` holds collide()'s answer there.
Pose pressed_start(const CoBody& probe, const CoBody& object, std::uint64_t seed, CollideScratch& scratch,
                   CollideResult& plain) {
  const auto normals = st::test::vertex_normals(object.mesh);
  std::mt19937_64 rng(seed);
  Pose start;
  do {
    std::uniform_int_distribution<std::uint32_t> vo(0, object.mesh.num_vertices() - 1);
    const std::uint32_t o = vo(rng);
    start = st::test::pose_near(probe.mesh, 0, object.mesh, o, normals[o], 3.0, st::test::random_rotation(rng));
    collide(probe.mesh, probe.tree, object.mesh, object.tree, start, {}, scratch, plain);
  } while (plain.pairs.size() < 50);
  return start;
}

// A pose moved from `start` by `along` (object frame) and turned by `deg` about `axis` through `pivot`.
Pose moved(const Pose& start, const Vec3& pivot, const Vec3& dir, double along, const Vec3& axis, double deg) {
  Pose p = Pose::Identity();
  p.linear() = Eigen::AngleAxisd(deg * kPiCoherent / 180, axis).toRotationMatrix();
  p.translation() = pivot - p.linear() * pivot + along * dir;
  return p * start;
}

// Runs both paths at each pose and compares them; returns the rounds compared.
struct CoherentCompare {
  CollideScratch scratch;
  CollideResult plain, coh;
  int rounds = 0;
  void at(CoherentCollider& cc, const CoBody& probe, const CoBody& object, const Pose& pose, CollideConfig opt = {}) {
    opt.sort_pairs = true;
    collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, opt, scratch, plain);
    cc.collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, opt, coh);
    CAPTURE(rounds);
    REQUIRE(coh.pairs == plain.pairs);
    CHECK(coh.probe_faces == plain.probe_faces);
    CHECK(coh.object_faces == plain.object_faces);
    CHECK(coh.stats.pair_limit_hit == plain.stats.pair_limit_hit);
    ++rounds;
  }
};

// The hand_L2 probe pressed into the elephant (pressed_start, seeded) and the comparison of the
// two paths, for the tests that start from one such pose.
struct HandOnElephant {
  CoBody probe{*st::test::model_mesh("hand_L2.off")};
  CoBody object{*st::test::model_mesh("elephant.off")};
  CoherentCompare cmp;
  Pose start;
  explicit HandOnElephant(std::uint64_t seed) : start(pressed_start(probe, object, seed, cmp.scratch, cmp.plain)) {}
};

// The pivot and slide direction at a pose in contact: the touched object faces' centre and a
// direction in their mean plane.
void slide_frame(const Mesh& object, const std::vector<FacePair>& pairs, Vec3& pivot, Vec3& dir, Vec3& axis) {
  REQUIRE(!pairs.empty());
  Vec3 c = Vec3::Zero(), n = Vec3::Zero();
  for (const FacePair& fp : pairs) {
    const auto& t = object.faces[fp.object];
    const Vec3 a = object.vertex(t[0]), b = object.vertex(t[1]), d = object.vertex(t[2]);
    c += (a + b + d) / 3;
    n += (b - a).cross(d - a);
  }
  pivot = c / double(pairs.size());
  n.normalize();
  dir = n.cross(Vec3::UnitX());
  if (dir.norm() < 0.1) dir = n.cross(Vec3::UnitY());
  dir.normalize();
  axis = (n + n.cross(dir)).normalized();
}

}  // namespace

TEST_CASE(
    "the coherent collider gives collide()'s pairs on every round of slides, jitter and a jerk (hand_L2 x elephant)") {
  const CoBody probe(*st::test::model_mesh("hand_L2.off"));
  const CoBody object(*st::test::model_mesh("elephant.off"));
  const auto normals = st::test::vertex_normals(object.mesh);
  std::mt19937_64 rng(20261127);
  CoherentCompare cmp;
  const int starts = st::test::kSanitizerBuild ? 1 : 3;
  const int per_series = st::test::kSanitizerBuild ? 30 : 80;
  std::uint64_t reused = 0, refreshes = 0, retested = 0;
  int found = 0;
  for (int attempt = 0; attempt < 200 && found < starts; ++attempt) {
    std::uniform_int_distribution<std::uint32_t> vo(0, object.mesh.num_vertices() - 1),
        vp(0, probe.mesh.num_vertices() - 1);
    const std::uint32_t o = vo(rng);
    const Pose start =
        st::test::pose_near(probe.mesh, vp(rng), object.mesh, o, normals[o], 1.5, st::test::random_rotation(rng));
    collide(probe.mesh, probe.tree, object.mesh, object.tree, start, {}, cmp.scratch, cmp.plain);
    if (cmp.plain.pairs.size() < 20) continue;
    ++found;
    CAPTURE(attempt);
    Vec3 pivot, dir, axis;
    slide_frame(object.mesh, cmp.plain.pairs, pivot, dir, axis);
    for (const double step : {0.001, 0.01, 0.03}) {
      CAPTURE(step);
      CoherentCollider cc(fixed());
      for (int k = 0; k < per_series; ++k) {  // forth, then back over the same poses
        const int s = k < per_series / 2 ? k : per_series - k;
        cmp.at(cc, probe, object, moved(start, pivot, dir, s * step, axis, s * 0.01));
      }
      reused += cc.stats().reused, refreshes += cc.stats().refreshes, retested += cc.stats().retested;
      CHECK(cc.stats().rounds == std::uint64_t(per_series));
      CHECK(cc.stats().peak_bytes > 0);
      CHECK(cc.stats().peak_bytes <= cc.config().max_bytes);
    }
    {  // jitter between three poses: certificates are checked against their own pose, so no refresh wears out
      CoherentCollider cc(fixed());
      for (int k = 0; k < per_series; ++k)
        cmp.at(cc, probe, object, moved(start, pivot, dir, 0.01 * (k % 3), axis, 0.0));
      const std::uint64_t before = cc.stats().refreshes;
      for (int k = 0; k < per_series; ++k)
        cmp.at(cc, probe, object, moved(start, pivot, dir, 0.01 * (k % 3), axis, 0.0));
      CHECK(cc.stats().refreshes == before);
      CHECK(cc.stats().plain_rounds == 0);
    }
    {  // a long jitter within a small reach: every visit that tests some candidates again charges
       // the motion to its entry's level (FrontEntry::level), which is folded back into the
       // margins once past 16 reaches (hundreds of times here): answers stay exact throughout
      CoherentConfig small = fixed();
      small.reach = 0.01;
      CoherentCollider cc(small);
      const int rounds = st::test::kSanitizerBuild ? 200 : 600;
      for (int k = 0; k < rounds; ++k)
        cmp.at(cc, probe, object, moved(start, pivot, dir, 0.002 * (k % 3), axis, 0.002 * (k % 2)));
      CHECK(cc.stats().plain_rounds == 0);
      CHECK(cc.stats().retested > 0);
    }
    {  // a long creep (0.0005 mm a round): candidates carried through many refreshes outlive the
       // poses kept (CoherentCollider::kPoses) and must then be tested again, not trusted
      CoherentCollider cc(fixed());
      const int rounds = st::test::kSanitizerBuild ? 300 : 600;
      for (int k = 0; k < rounds; ++k) cmp.at(cc, probe, object, moved(start, pivot, dir, 0.0005 * k, axis, 0.0));
      CHECK(cc.stats().plain_rounds == 0);
      CHECK(cc.stats().reused > 0);
    }
    {  // a jerk of 1 mm + 1 degree: the front rebuilt in the jerk's round, every round exact
      CoherentCollider cc(fixed());
      for (int k = 0; k < 40; ++k)
        cmp.at(cc, probe, object, moved(start, pivot, dir, 0.005 * k + (k >= 20 ? 1.0 : 0.0), axis, k >= 20 ? 1.0 : 0.0));
      CHECK(cc.stats().plain_rounds == 0);
      CHECK(cc.stats().rebuilds == 2);
    }
  }
  REQUIRE(found == starts);
  // The certificates did their job: most answers came from them, a few were tested again (about
  // one in ten here: a leaf pair's visit that tests some again moves its anchor, so the way back
  // of a slide finds the others' margins spent where a certificate per candidate pose would not).
  CHECK(reused > 8 * retested);
  CHECK(refreshes > 0);
}

TEST_CASE("the coherent collider is exact on every ISA, far from the origin, at tiny and huge scales") {
  using simd::Isa;
  const Isa before = simd::active_isa();
  const Mesh& hand = *st::test::model_mesh("hand.off");
  const Mesh& bunny = *st::test::model_mesh("bunny.off");
  const auto normals = st::test::vertex_normals(bunny);
  for (const double scale : {1e-3, 1.0, 1e4}) {
    for (const double offset : {0.0, 1e6}) {
      CAPTURE(scale);
      CAPTURE(offset);
      Mesh p = hand, o = bunny;
      for (Mesh* m : {&p, &o}) {
        for (Vec3& v : m->local) v *= scale;
        m->origin = m->origin * scale + Vec3(offset, -offset, 0.5 * offset);
      }
      const CoBody probe(p), object(o);
      std::mt19937_64 rng(7);
      const Pose start =
          st::test::pose_near(probe.mesh, 0, object.mesh, 10, normals[10], 2.0 * scale, st::test::random_rotation(rng));
      for (int i = 0; i <= static_cast<int>(simd::best_isa()); ++i) {
        REQUIRE(simd::set_isa(static_cast<Isa>(i)));
        const std::string isa = simd::isa_name(static_cast<Isa>(i));
        CAPTURE(isa);
        CoherentCollider cc(fixed());
        CoherentCompare cmp;
        for (int k = 0; k < 24; ++k)
          cmp.at(cc, probe, object,
                 moved(start, object.mesh.vertex(10), Vec3::UnitX(), 0.004 * scale * (k % 12), Vec3::UnitZ(),
                       0.02 * (k % 12)));
        CHECK(cc.stats().plain_rounds < cc.stats().rounds);  // the scale-free defaults kept it coherent
      }
    }
  }
  REQUIRE(simd::set_isa(before));
}

TEST_CASE("the coherent collider is exact on coplanar, touching and degenerate faces sliding over each other") {
  // Two grids in one plane (every face pair coplanar), one turned a hair: the filter decides
  // none of the touching pairs, so the exact test and margin 0 carry them.
  Mesh floor = st::test::grid(12), tile = st::test::grid(4);
  tile.faces.push_back({0, 0, 1});  // a degenerate face (a segment)
  const CoBody object(floor), probe(tile);
  CoherentCollider cc(fixed());
  CoherentCompare cmp;
  for (int k = 0; k < 60; ++k) {
    Pose pose = Pose::Identity();
    pose.translation() = Vec3(2.0 + 0.01 * k, 2.0 + 0.003 * k, (k % 5 == 0) ? 1e-12 : 0.0);
    pose.linear() = Eigen::AngleAxisd(1e-7 * (k % 3), Vec3::UnitZ()).toRotationMatrix();
    cmp.at(cc, probe, object, pose);
  }
  CHECK(!cmp.plain.pairs.empty());
}

TEST_CASE("a rebuild walks what collide() walks: the sphere pairs that meet, no leaf pair gathered") {
  const CoBody probe(*st::test::model_mesh("hand_L2.off"));
  const CoBody object(*st::test::model_mesh("elephant.off"));
  CoherentCompare cmp;
  const std::vector<std::uint64_t> seeds =
      st::test::kSanitizerBuild ? std::vector<std::uint64_t>{5} : std::vector<std::uint64_t>{5, 6, 7};
  for (const std::uint64_t seed : seeds) {
    CAPTURE(seed);
    const Pose start = pressed_start(probe, object, seed, cmp.scratch, cmp.plain);
    Vec3 pivot, dir, axis;
    slide_frame(object.mesh, cmp.plain.pairs, pivot, dir, axis);
    CoherentCollider cc(fixed());
    // A slide (the reach grows with the motion), then a jerk of 1 mm + 1°: its round rebuilds the
    // front, with the reach of the slide (the jerk's own step does not set it).
    for (int k = 0; k < 20; ++k) cmp.at(cc, probe, object, moved(start, pivot, dir, 0.01 * k, axis, 0.01 * k));
    const double reach = cc.reach();
    REQUIRE(reach > 0.02);
    const std::uint64_t rebuilds = cc.stats().rebuilds, reused = cc.stats().reused;
    cmp.at(cc, probe, object, moved(start, pivot, dir, 1.2, axis, 1.2));
    REQUIRE(cc.stats().rebuilds == rebuilds + 1);
    CHECK(cc.stats().plain_rounds == 0);
    CHECK(cc.reach() == reach);
    // Sphere pairs apart by less than the reach are recorded as groups, not descended, and no
    // leaf pair is gathered with widened boxes (the counts may differ by a pair whose float gap
    // and float sphere test disagree at 0).
    CHECK(cmp.coh.stats.node_pairs <= cmp.plain.stats.node_pairs + cmp.plain.stats.node_pairs / 100);
    CHECK(cmp.coh.stats.tri_pairs <= cmp.plain.stats.tri_pairs + cmp.plain.stats.tri_pairs / 100);
    CHECK(cc.stats().reused == reused);
    // The next rounds expand those groups as the probe moves and build the leaf pairs: exact.
    const std::uint64_t expansions = cc.stats().expansions;
    for (int k = 1; k < 30; ++k)
      cmp.at(cc, probe, object, moved(start, pivot, dir, 1.2 + 0.01 * k, axis, 1.2 + 0.01 * k));
    CHECK(cc.stats().reused > reused);
    CHECK(cc.stats().expansions > expansions);
  }
}

TEST_CASE("a probe withdrawn: the front is walked from the roots again and becomes as coarse as the contact") {
  const CoBody probe(*st::test::model_mesh("hand_L2.off"));
  const CoBody object(*st::test::model_mesh("elephant.off"));
  CoherentCompare cmp;
  const Pose pressed = pressed_start(probe, object, 11, cmp.scratch, cmp.plain);
  Vec3 pivot, dir, axis, out = Vec3::Zero();
  slide_frame(object.mesh, cmp.plain.pairs, pivot, dir, axis);
  for (const FacePair& fp : cmp.plain.pairs) {  // the touched faces' mean normal
    const auto& t = object.mesh.faces[fp.object];
    const Vec3 a = object.mesh.vertex(t[0]);
    out += (object.mesh.vertex(t[1]) - a).cross(object.mesh.vertex(t[2]) - a);
  }
  out.normalize();
  // The way along it, and the distance, at which the contact ends (1 mm steps); the test starts
  // 1 mm before, in light contact.
  auto pairs_at = [&](const Vec3& way, double d) {
    collide(probe.mesh, probe.tree, object.mesh, object.tree, moved(pressed, pivot, way, d, axis, 0.0), {}, cmp.scratch,
            cmp.plain);
    return cmp.plain.pairs.size();
  };
  Vec3 away = out;
  double gone = 1;
  for (; gone < 200; ++gone) {
    if (pairs_at(out, gone) == 0) break;
    if (pairs_at(-out, gone) == 0) {
      away = -out;
      break;
    }
  }
  REQUIRE(gone < 200);
  const Pose start = moved(pressed, pivot, away, gone - 1, axis, 0.0);
  CoherentCollider cc(fixed());
  int k = 0;
  for (; k < 40; ++k) cmp.at(cc, probe, object, moved(start, pivot, dir, 0.0, axis, 0.002 * k));  // turning in contact
  REQUIRE(!cmp.plain.pairs.empty());
  const std::size_t in_contact = cc.stats().entries;
  // Withdrawn 0.02 mm a round until 70 rounds out of contact: more than the rounds between two
  // checks for a walk from the roots (CoherentCollider::kRerootEvery).
  for (int left = 0; k < 400 && left < 70; ++k) {
    cmp.at(cc, probe, object, moved(start, pivot, away, 0.02 * (k - 39), axis, 0.002 * 39));
    left = cmp.plain.pairs.empty() ? left + 1 : 0;
  }
  REQUIRE(cmp.plain.pairs.empty());
  CHECK(cc.stats().plain_rounds == 0);
  // Without contact the walk from the roots is a rebuild (no leaf pair worth keeping): the first
  // round's and at least that one. It stops nearer the roots than the front of the contact.
  CHECK(cc.stats().rebuilds >= 2);
  CHECK(cc.stats().entries < in_contact);  // 396 of 724 (before: 773 of 724, never walked again)
}

TEST_CASE("a probe clear of the object: one sphere test a round, the front dropped, exact when it comes back") {
  HandOnElephant scene(5);
  auto& [probe, object, cmp, start] = scene;
  const Vec3 x = Vec3::UnitX();
  // No step is a jump (max_step): what ends the front here is the probe being clear.
  CoherentConfig cfg = fixed();
  cfg.max_step = 1e9;
  CoherentCollider cc(cfg);
  for (int k = 0; k < 5; ++k) cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.001 * k, x, 0.0));
  REQUIRE(cc.stats().entries > 0);
  // Far off (the probe's and the object's bounding spheres apart by a metre, on either side): no
  // pair, after one sphere test, as collide() answers; nothing of the contact's front is kept.
  const double far = 2 * (double(probe.tree.nodes[0].radius) + double(object.tree.nodes[0].radius)) + 1000;
  for (const double way : {far, -far, far + 1}) {
    const std::uint64_t plain = cc.stats().plain_rounds;
    cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, way, x, 0.0));
    CHECK(cmp.coh.pairs.empty());
    CHECK(cmp.coh.stats.node_pairs == 1);
    CHECK(cmp.plain.stats.node_pairs == 1);
    CHECK(cc.stats().plain_rounds == plain + 1);
    CHECK(cc.stats().entries == 0);
  }
  // Back in contact: a rebuild, then certificates again, every round collide()'s pairs.
  const std::uint64_t rebuilds = cc.stats().rebuilds;
  for (int k = 0; k < 5; ++k) cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.001 * k, x, 0.0));
  CHECK(cc.stats().rebuilds == rebuilds + 1);
  CHECK(cc.stats().reused > 0);
  // Object roots restricted (a worker's blocks): apart only when every root is.
  CollideConfig blocks;
  blocks.restrict_object = true;
  std::vector<std::uint32_t> roots;
  for (std::uint32_t c = 0; c < object.tree.nodes[0].count; ++c) roots.push_back(object.tree.nodes[0].first + c);
  blocks.object_roots = roots;
  for (int k = 0; k < 3; ++k) cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.001 * k, x, 0.0), blocks);
  CHECK(!cmp.coh.pairs.empty());
  cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, far, x, 0.0), blocks);
  CHECK(cmp.coh.pairs.empty());
  CHECK(cmp.coh.stats.node_pairs == roots.size());
  CHECK(cc.stats().entries == 0);
}

TEST_CASE("the coherent collider keeps collide()'s limits and falls back on jumps, a full pool and non-finite poses") {
  HandOnElephant scene(3);
  auto& [probe, object, cmp, start] = scene;
  const Vec3 x = Vec3::UnitX();

  SUBCASE("max_pairs stops it as it stops collide(); max_work bounds its own work; both drop the cache") {
    CoherentCollider cc(fixed());
    CollideConfig capped;
    capped.max_pairs = 10;
    CollideConfig budget;
    budget.max_work = 200;
    CollideConfig sorted;
    sorted.sort_pairs = true;
    for (int k = 0; k < 6; ++k) {
      const Pose pose = moved(start, Vec3::Zero(), x, 0.001 * k, x, 0.0);
      cmp.at(cc, probe, object, pose);
      CollideResult a, b, full;
      const std::uint64_t rebuilds = cc.stats().rebuilds;
      cc.collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, capped, a);
      collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, capped, cmp.scratch, b);
      CHECK(a.stats.pair_limit_hit);
      CHECK(b.stats.pair_limit_hit);
      CHECK(a.pairs.size() <= capped.max_pairs + kMaxLeafFaces * kMaxLeafFaces);
      // The budget counts the work a round does: a round from certificates may finish within it
      // (then it is complete and exact); one that runs out says so and drops the cache.
      cc.collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, budget, a);
      collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, sorted, cmp.scratch, full);
      if (!a.stats.work_limit_hit) {
        std::sort(a.pairs.begin(), a.pairs.end());
        CHECK(a.pairs == full.pairs);
      }
      cc.collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, budget, a);  // from the roots: cut short
      CHECK(a.stats.work_limit_hit);
      CHECK(cc.stats().rebuilds > rebuilds);
    }
  }
  SUBCASE("a pool over max_bytes runs collide() (the pairs are the same) and says so") {
    CoherentConfig tiny = fixed();
    tiny.max_bytes = 4096;
    CoherentCollider cc(tiny);
    for (int k = 0; k < 10; ++k) cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.001 * k, x, 0.0));
    CHECK(cc.stats().overflows == 1);  // then 63 rounds of collide() before it tries again
    CHECK(cc.stats().plain_rounds == 10);
    CHECK(cc.bytes() < 64 * 1024 * 1024);
  }
  SUBCASE("a jerk rebuilds the front at once; a jump after a jump runs collide(); a non-finite pose gives nothing") {
    CoherentCollider cc(fixed());
    cmp.at(cc, probe, object, start);
    cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.001, x, 0.0));
    CHECK(cc.stats().rebuilds == 1);
    cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 5.0, x, 0.0));  // a jerk: rebuilt there
    CHECK(cc.stats().rebuilds == 2);
    CHECK(cc.stats().plain_rounds == 0);
    const CoherentStats jerk = cc.stats();
    for (int k = 1; k <= 6; ++k)  // answered from that front
      cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 5.0 + 0.001 * k, x, 0.0));
    CHECK(cc.stats().rebuilds == 2);
    CHECK(cc.stats().plain_rounds == 0);
    CHECK(cc.stats().reused > jerk.reused);
    // Fast motion: the first jump rebuilds, the next ones run collide() (the cache dropped).
    for (int k = 1; k <= 3; ++k) cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 5.006 - 1.5 * k, x, 0.0));
    CHECK(cc.stats().rebuilds == 3);
    CHECK(cc.stats().plain_rounds == 2);
    cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.507, x, 0.0));  // slow again: rebuilt
    CHECK(cc.stats().rebuilds == 4);
    CHECK(cc.stats().plain_rounds == 2);
    Pose bad = start;
    bad(0, 3) = std::nan("");
    CollideResult r;
    cc.collide(probe.mesh, probe.tree, object.mesh, object.tree, bad, {}, r);
    CHECK(r.pairs.empty());
    cmp.at(cc, probe, object, start);
  }
  SUBCASE("object roots (a worker's blocks): the same pairs as collide() with them; new roots asked twice start over") {
    CoherentCollider cc(fixed());
    std::vector<std::uint32_t> roots;
    for (std::uint32_t i = 0; i < object.tree.num_nodes(); ++i)
      if (object.tree.nodes[i].depth == 2) roots.push_back(i);
    REQUIRE(roots.size() >= 2);
    CollideConfig opt;
    opt.restrict_object = true;
    opt.object_roots = roots;
    for (int k = 0; k < 8; ++k) cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.002 * k, x, 0.0), opt);
    const CoherentStats before = cc.stats();
    CHECK(before.reused > 0);
    // Other roots once (a round that skips a block): collide() answers, the front is kept.
    CollideConfig fewer = opt;
    fewer.object_roots = std::span<const std::uint32_t>(roots).subspan(1);
    cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.016, x, 0.0), fewer);
    CHECK(cc.stats().plain_rounds == before.plain_rounds + 1);
    CHECK(cc.stats().rebuilds == before.rebuilds);
    // Back to the front's roots: answered from it (reused answers, no rebuild).
    cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.018, x, 0.0), opt);
    CHECK(cc.stats().rebuilds == before.rebuilds);
    CHECK(cc.stats().reused > before.reused);
    // Alternating roots round by round: every round exact, never a rebuild.
    for (int k = 0; k < 10; ++k)
      cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.02 + 0.002 * k, x, 0.0), k % 2 ? opt : fewer);
    CHECK(cc.stats().rebuilds == before.rebuilds);
    CHECK(cc.stats().plain_rounds == before.plain_rounds + 6);
    // The other roots asked twice in a row: the front starts over for them.
    cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.04, x, 0.0), fewer);
    CHECK(cc.stats().rebuilds == before.rebuilds);
    cmp.at(cc, probe, object, moved(start, Vec3::Zero(), x, 0.042, x, 0.0), fewer);
    CHECK(cc.stats().rebuilds == before.rebuilds + 1);
  }
}

TEST_CASE("arbitration against collide()'s time changes the path, never the pairs") {
  // Light contact (a small probe grazing a grid), where collide() takes microseconds: whichever
  // path the timing picks, round by round, the pairs are collide()'s.
  const CoBody object(st::test::grid(40)), probe(st::test::grid(3));
  CoherentCollider cc;  // arbitrate: the default
  REQUIRE(cc.config().arbitrate);
  CoherentCompare cmp;
  for (int k = 0; k < 700; ++k) {
    Pose pose = Pose::Identity();
    pose.translation() = Vec3(10.0 + 0.002 * (k % 200), 10.0, 0.0);
    pose.linear() = Eigen::AngleAxisd(0.3, Vec3::UnitX()).toRotationMatrix();
    cmp.at(cc, probe, object, pose);
  }
  CHECK(!cmp.plain.pairs.empty());
  CHECK(cc.stats().rounds == 700);
  // Each jump back (every 200 rounds) rebuilds the front or, in a spell of plain rounds (the
  // collider gave way), is one of them; the first round is either too. Timed plain rounds come on
  // top (from round 127, unless the collider clearly wins: settled(), the machine's timing).
  CHECK(cc.stats().plain_rounds + cc.stats().rebuilds >= 4);
}

TEST_CASE("node work: collide() and the coherent collider charge the triangle tests they make to the object's leaves") {
  const CoBody probe(*st::test::model_mesh("hand_L2.off"));
  const CoBody object(*st::test::model_mesh("elephant.off"));
  CollideScratch scratch;
  CollideResult plain;
  const Pose start = pressed_start(probe, object, 11, scratch, plain);
  // The object leaf of each face (the leaf whose face range holds it).
  std::vector<std::uint32_t> leaf_of(object.mesh.faces.size(), ~0u);
  for (std::uint32_t i = 0; i < object.tree.num_nodes(); ++i)
    if (object.tree.nodes[i].leaf)
      for (std::uint32_t k = 0; k < object.tree.nodes[i].count; ++k)
        leaf_of[object.tree.face_order[object.tree.nodes[i].first + k]] = i;
  NodeWork work;
  work.work.assign(object.tree.num_nodes(), 0);
  // What a query charged: only leaves, each listed once, in all its triangle tests plus at most
  // one per leaf pair that had any (so between tri_pairs and 2 x tri_pairs).
  const auto charged = [&](const CollideResult& r) {
    std::vector<std::uint32_t> t = work.touched;
    std::sort(t.begin(), t.end());
    CHECK(std::adjacent_find(t.begin(), t.end()) == t.end());
    std::uint64_t sum = 0;
    for (std::uint32_t n = 0; n < work.work.size(); ++n) {
      CHECK((work.work[n] > 0) == std::binary_search(t.begin(), t.end(), n));
      if (work.work[n] > 0) CHECK(object.tree.nodes[n].leaf);
      sum += work.work[n];
    }
    CHECK(sum >= r.stats.tri_pairs);
    CHECK(sum <= 2 * r.stats.tri_pairs);
    return sum;
  };
  CollideConfig counted;
  counted.node_work = &work;
  CollideResult r;
  for (bool filter : {true, false}) {
    counted.tri_filter = filter;
    collide(probe.mesh, probe.tree, object.mesh, object.tree, start, counted, scratch, r);
    CHECK(r.pairs.size() == plain.pairs.size());
    CHECK(charged(r) > 0);
    for (const FacePair& fp : r.pairs) CHECK(work.work[leaf_of[fp.object]] > 0);  // every hit was tested
    work.clear();
    CHECK(std::all_of(work.work.begin(), work.work.end(), [](std::uint32_t w) { return w == 0; }));
  }
  // The coherent collider along a slide: the same pairs, and once its certificates hold, fewer
  // tests charged than collide() makes at the same pose.
  CoherentCollider cc(fixed());
  counted.tri_filter = true;
  std::uint64_t last_coherent = 0;
  for (int k = 0; k < 40; ++k) {
    const Pose pose = moved(start, Vec3::Zero(), Vec3::UnitX(), 0.01 * k, Vec3::UnitZ(), 0.01 * k);
    cc.collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, counted, r);
    collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, {}, scratch, plain);
    std::sort(r.pairs.begin(), r.pairs.end());
    std::sort(plain.pairs.begin(), plain.pairs.end());
    REQUIRE(r.pairs == plain.pairs);
    last_coherent = charged(r);
    work.clear();
  }
  CHECK(cc.stats().reused > 0);
  CHECK(last_coherent < plain.stats.tri_pairs);
}
