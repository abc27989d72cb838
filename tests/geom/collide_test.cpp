// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/collide.*: the exact pair set equals a brute-force reference on real and
// generated meshes (far, near, deep, barely touching, far from the origin), approximate mode is a
// superset, scratch reuse does not allocate, bad poses are harmless.
#include <doctest/doctest.h>

#include <random>
#include <set>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/simd.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include "test_models.hpp"
#include "test_util.hpp"

using namespace st::geom;
using st::test::brute_force;

namespace {

struct Body {
  Mesh mesh;
  SphereTree tree;
  explicit Body(Mesh m, TreeConfig p = DefaultTreeConfig())
      : mesh(std::move(m)), tree(SphereTree::build(mesh, p).value()) {}
};

std::vector<FacePair> run(const Body& probe, const Body& object, const Pose& pose, CollideConfig opt = {}) {
  static CollideScratch scratch;
  CollideResult res;
  opt.sort_pairs = true;
  collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, opt, scratch, res);
  // Counters agree with the pairs: contacts = distinct faces on each side.
  std::set<std::uint32_t> pf, of;
  for (auto& p : res.pairs) {
    pf.insert(p.probe);
    of.insert(p.object);
  }
  CHECK(res.probe_faces == pf.size());
  CHECK(res.object_faces == of.size());
  CHECK(std::adjacent_find(res.pairs.begin(), res.pairs.end()) == res.pairs.end());
  return res.pairs;
}

// Poses of probe against object: far, random near-surface, deep, exact vertex touches.
std::vector<std::pair<std::string, Pose>> poses_for(const Mesh& probe, const Mesh& object, int near_count,
                                                    std::uint64_t seed) {
  std::vector<std::pair<std::string, Pose>> out;
  std::mt19937_64 rng(seed);
  Pose far = Pose::Identity();
  far.translation() = object.origin - probe.origin + Vec3(1000, 0, 0);
  out.emplace_back("far", far);
  const auto normals = st::test::vertex_normals(object);
  std::uniform_int_distribution<std::uint32_t> vo(0, static_cast<std::uint32_t>(object.num_vertices() - 1));
  std::uniform_int_distribution<std::uint32_t> vp(0, static_cast<std::uint32_t>(probe.num_vertices() - 1));
  std::uniform_real_distribution<double> depth(-1.0, 6.0);
  for (int i = 0; i < near_count; ++i) {
    const std::uint32_t o = vo(rng);
    out.emplace_back("near " + std::to_string(i), st::test::pose_near(probe, vp(rng), object, o, normals[o], depth(rng),
                                                                      st::test::random_rotation(rng)));
  }
  Pose deep = Pose::Identity();
  deep.linear() = st::test::random_rotation(rng);
  deep.translation() = object.origin - deep.linear() * probe.origin;
  out.emplace_back("deep", deep);
  // Barely touching: probe's extreme vertex along -d onto object's extreme vertex along +d, R = I,
  // kept only when the transformed vertex lands exactly on the object vertex.
  int touches = 0;
  for (int axis = 0; axis < 3; ++axis)
    for (double sgn : {1.0, -1.0}) {
      std::uint32_t io = 0, ip = 0;
      for (std::uint32_t v = 0; v < object.num_vertices(); ++v)
        if (sgn * object.local[v][axis] > sgn * object.local[io][axis]) io = v;
      for (std::uint32_t v = 0; v < probe.num_vertices(); ++v)
        if (sgn * probe.local[v][axis] < sgn * probe.local[ip][axis]) ip = v;
      Pose p = Pose::Identity();
      p.translation() = object.vertex(io) - probe.vertex(ip);
      const RelTransform rt = transform_to_object(p, probe, object);
      if (apply(rt, probe.local[ip]) != object.local[io]) continue;
      ++touches;
      out.emplace_back("touch axis " + std::to_string(axis) + (sgn > 0 ? "+" : "-"), p);
    }
  MESSAGE(touches, " exact vertex-vertex touches constructed");
  return out;
}

void compare_at(const Body& probe, const Body& object, const std::vector<std::pair<std::string, Pose>>& poses,
                bool all_pairs = false) {
  for (const auto& named : poses) {
    // Not a structured binding: CAPTURE's lambda cannot capture one before clang 16.
    const std::string& name = named.first;
    const Pose& pose = named.second;
    CAPTURE(name);
    const auto got = run(probe, object, pose);
    const auto want = brute_force(probe.mesh, object.mesh, pose, all_pairs);
    CHECK(got.size() == want.size());
    CHECK(got == want);
    if (name == "far") CHECK(got.empty());
    if (name.rfind("touch", 0) == 0) CHECK(!got.empty());
  }
}

Mesh shifted(Mesh m, const Vec3& d) {
  m.origin += d;
  return m;
}

}  // namespace

TEST_CASE("a grouped object tree (a worker's share of apart blocks) gives exactly the brute-force pairs") {
  const Mesh ico = make_icosphere(40, 12);
  const SphereTree whole = SphereTree::build(ico, {8}).value();
  Mesh share;
  share.origin = ico.origin;
  share.local = ico.local;
  std::vector<std::uint32_t> runs;
  const std::vector<std::uint32_t> blocks = whole.layer(2);
  for (std::size_t b = 0; b < blocks.size(); b += 2) {
    runs.push_back(std::uint32_t(whole.faces_end(blocks[b]) - whole.faces_begin(blocks[b])));
    for (const std::uint32_t* f = whole.faces_begin(blocks[b]); f != whole.faces_end(blocks[b]); ++f)
      share.faces.push_back(ico.faces[*f]);
  }
  REQUIRE(runs.size() > 4);
  // Only the vertices the share uses (a touch pose needs its extreme vertex on a face).
  std::vector<std::uint32_t> remap(share.local.size(), ~0u);
  std::vector<Vec3> used;
  for (Tri& f : share.faces)
    for (std::uint32_t& v : f) {
      if (remap[v] == ~0u) remap[v] = std::uint32_t(used.size()), used.push_back(share.local[v]);
      v = remap[v];
    }
  share.local = used;
  Body object(share);
  object.tree = SphereTree::build(share, {8}, runs).value();
  const Body probe(make_capsule(6, 25, 10));
  compare_at(probe, object, poses_for(probe.mesh, object.mesh, 12, 91));

  // Each run has one root whose faces are exactly the run's; colliding from the roots of every
  // other run gives exactly the pairs outside the left-out runs (a worker's Query skip list).
  const auto roots = group_roots(object.tree, share.faces.size(), runs);
  REQUIRE(roots.size() == runs.size());
  std::vector<std::uint32_t> run_of;
  for (std::uint32_t g = 0; g < runs.size(); ++g) run_of.insert(run_of.end(), runs[g], g);
  for (std::uint32_t g = 0; g < runs.size(); ++g) {
    REQUIRE(roots[g].size() == 1);
    const std::uint32_t r = roots[g][0];
    std::vector<std::uint32_t> faces(object.tree.faces_begin(r), object.tree.faces_end(r));
    std::sort(faces.begin(), faces.end());
    REQUIRE(faces.size() == runs[g]);
    CHECK(faces.front() == std::uint32_t(std::find(run_of.begin(), run_of.end(), g) - run_of.begin()));
    CHECK(std::all_of(faces.begin(), faces.end(), [&](std::uint32_t f) { return run_of[f] == g; }));
  }
  int compared = 0;
  for (const auto& [label, pose] : poses_for(probe.mesh, object.mesh, 12, 93)) {
    CAPTURE(label);
    const std::vector<FacePair> all = brute_force(probe.mesh, object.mesh, pose);
    std::vector<std::uint32_t> kept;
    for (std::uint32_t g = 0; g < runs.size(); ++g)
      if (g % 3 != 1) kept.push_back(roots[g][0]);
    CollideConfig opt;
    opt.restrict_object = true;
    opt.object_roots = kept;
    std::vector<FacePair> expect;
    for (const FacePair& fp : all)
      if (run_of[fp.object] % 3 != 1) expect.push_back(fp);
    CHECK(run(probe, object, pose, opt) == expect);
    compared += !expect.empty() && expect.size() < all.size();
  }
  CHECK(compared > 0);
  // A tree built without the runs mixes them in its leaves: no roots to collide them apart.
  const Body ungrouped(share, {8});
  CHECK(group_roots(ungrouped.tree, share.faces.size(), runs).empty());
  // Runs that do not add up to the faces: refused.
  CHECK(group_roots(object.tree, share.faces.size() + 1, runs).empty());
}

TEST_CASE("one scratch alternating between object trees gives each query the result of a fresh scratch") {
  const Body probe(make_capsule(6, 25, 10));
  const Body a(make_icosphere(30, 6)), b(make_icosphere(22, 9));
  const auto pa = poses_for(probe.mesh, a.mesh, 6, 5), pb = poses_for(probe.mesh, b.mesh, 6, 6);
  CollideScratch shared;
  for (std::size_t i = 0; i < pa.size(); ++i)
    for (int k = 0; k < 2; ++k) {
      const Body& o = k ? b : a;
      const Pose& pose = k ? pb[i].second : pa[i].second;
      CollideScratch fresh;
      CollideResult r1, r2;
      collide(probe.mesh, probe.tree, o.mesh, o.tree, pose, {}, shared, r1);
      collide(probe.mesh, probe.tree, o.mesh, o.tree, pose, {}, fresh, r2);
      CHECK(r1.pairs == r2.pairs);
      CHECK(r1.stats.node_pairs == r2.stats.node_pairs);
      CHECK(r1.stats.tri_pairs == r2.stats.tri_pairs);
    }
}

TEST_CASE("transform_to_object: t is accurate with origins at 1e6 mm") {
  Mesh a = make_box({1, 1, 1}), b = make_box({1, 1, 1});
  a.origin = Vec3(1e6 + 0.25, -3e6, 7e6);
  b.origin = Vec3(-1e6, 2e6 + 0.5, 7e6);
  Pose pose = Pose::Identity();
  pose.linear() = Eigen::AngleAxisd(0.3, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  pose.translation() = Vec3(0.1, 0.2, 0.3);
  const RelTransform rt = transform_to_object(pose, a, b);
  // Reference in long double (64-bit mantissa) is far more accurate than one double rounding.
  for (int i = 0; i < 3; ++i) {
    long double t = pose.translation()[i];
    for (int j = 0; j < 3; ++j) t += static_cast<long double>(rt.R(i, j)) * a.origin[j];
    t -= b.origin[i];
    CHECK(std::abs(static_cast<long double>(rt.t[i]) - t) <= 1e-9L);
  }
}

TEST_CASE("collide equals brute force: generated meshes, touching cases") {
  Body a(make_box({2, 2, 2}));
  Body b(make_box({2, 2, 2}));
  auto at = [](Vec3 t) {
    Pose p = Pose::Identity();
    p.translation() = t;
    return p;
  };
  // Face-face, edge-edge (collinear), vertex-vertex, just apart, overlapping.
  for (const Vec3& t : {Vec3(2, 0, 0), Vec3(2, 2, 0), Vec3(2, 2, 2), Vec3(2.0000001, 0, 0), Vec3(1, 0.5, 0.25)}) {
    CAPTURE(t.transpose());
    const Pose p = at(t);
    const auto got = run(a, b, p);
    CHECK(got == brute_force(a.mesh, b.mesh, p, true));
    CHECK(got.empty() == (t.x() > 2));
  }
  // Crossing edges: probe rotated 90 degrees about x (exact: entries 0, 1, -1).
  Pose r = Pose::Identity();
  r.linear() << 1, 0, 0, 0, 0, -1, 0, 1, 0;
  r.translation() = Vec3(0, 2, 2);
  CHECK(run(a, b, r) == brute_force(a.mesh, b.mesh, r, true));
  // Spheres and capsules at random poses, several leaf sizes.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-25, 25);
  for (std::uint32_t L : {1u, 5u, 8u, 32u}) {
    Body s(make_icosphere(20, 8), {L});
    Body c(make_capsule(6, 20, 20), {L});
    for (int i = 0; i < (st::test::kSanitizerBuild ? 4 : 10); ++i) {
      Pose p = Pose::Identity();
      p.linear() = st::test::random_rotation(rng);
      p.translation() = Vec3(u(rng), u(rng), u(rng));
      CAPTURE(L);
      CAPTURE(i);
      CHECK(run(c, s, p) == brute_force(c.mesh, s.mesh, p, true));
    }
  }
}

TEST_CASE("collide equals brute force: hand x hand (literal all pairs)") {
  // The literal loop over every face pair (no culling at all) checks the grid-accelerated
  // reference used below; hand x hand keeps it at 5.7e6 exact tests per pose (sanitizer builds).
  const Mesh* hand = st::test::model_mesh("hand.off");
  Body probe(*hand), object(*hand);
  auto poses = poses_for(*hand, *hand, 4, 1);
  poses.resize(4);                                              // far and three near poses
  if (st::test::kSanitizerBuild) poses = {poses[1], poses[2]};  // two near poses
  compare_at(probe, object, poses, true);
}

TEST_CASE("collide equals brute force: hand and hand_L2 x elephant at >= 20 poses") {
  const Mesh* ele = st::test::model_mesh("elephant.off");
  Body object(*ele);
  for (const char* hn : {"hand.off", "hand_L2.off"}) {
    const Mesh* hand = st::test::model_mesh(hn);
    CAPTURE(hn);
    Body probe(*hand);
    const auto poses = poses_for(*hand, *ele, st::test::kSanitizerBuild ? 6 : 18, 2);
    CHECK(poses.size() >= (st::test::kSanitizerBuild ? 8u : 20u));
    compare_at(probe, object, poses);
    // Both bodies 1e6 mm from the origin, pose composed so the scene is the same.
    const Vec3 dp(1e6, -1e6, 2e6), dob(1e6 + 3, -1e6, 2e6 - 5);
    Body fprobe(shifted(*hand, dp)), fobject(shifted(*ele, dob));
    std::vector<std::pair<std::string, Pose>> far_poses;
    for (const auto& [name, pose] : poses) {
      Pose q = Eigen::Translation3d(dob) * pose * Eigen::Translation3d(-dp);
      far_poses.emplace_back(name + " @1e6", q);
    }
    far_poses.erase(
        std::remove_if(far_poses.begin(), far_poses.end(), [](auto& p) { return p.first.rfind("touch", 0) == 0; }),
        far_poses.end());
    compare_at(fprobe, fobject, far_poses);
  }
}

TEST_CASE("every SIMD instruction set gives the same pairs and counters (run-time dispatch)") {
  using simd::Isa;
  const Isa best = simd::best_isa(), before = simd::active_isa();
  // The names round-trip, and an ISA above what the CPU and build have is refused, changing nothing.
  for (const Isa isa : {Isa::scalar, Isa::sse2, Isa::avx2}) {
    Isa back = Isa::scalar;
    CHECK(simd::parse_isa(simd::isa_name(isa), back));
    CHECK(back == isa);
  }
  Isa unused = Isa::scalar;
  CHECK_FALSE(simd::parse_isa("avx9", unused));
  if (best < Isa::avx2) {
    CHECK_FALSE(simd::set_isa(Isa::avx2));
    CHECK(simd::active_isa() == before);
  }
  MESSAGE("best ISA on this machine: " << std::string(simd::isa_name(best)));

  const Mesh* hand = st::test::model_mesh("hand_L2.off");
  const Mesh* ele = st::test::model_mesh("elephant.off");
  Body probe(*hand), object(*ele);
  const auto poses = poses_for(*hand, *ele, st::test::kSanitizerBuild ? 4 : 10, 7);
  CollideScratch scratch;
  std::size_t touching = 0;
  for (const auto& [name, pose] : poses) {
    CAPTURE(name);
    CollideResult ref;
    std::vector<Isa> isas;
    for (int i = 0; i <= static_cast<int>(best); ++i) isas.push_back(static_cast<Isa>(i));
    for (const Isa isa : isas) {
      const std::string isa_name = simd::isa_name(isa);
      CAPTURE(isa_name);
      REQUIRE(simd::set_isa(isa));
      CHECK(simd::active_isa() == isa);
      CollideResult res;
      CollideConfig opt;
      opt.sort_pairs = true;
      collide(probe.mesh, probe.tree, object.mesh, object.tree, pose, opt, scratch, res);
      if (isa == Isa::scalar) {
        ref = res;
        touching += !res.pairs.empty();
        // A leaf's faces are boxed once a query: never more leaves than the probe has, some
        // whenever a pair was found (its probe face's leaf), none without a leaf pair.
        CHECK(res.stats.probe_leaves <= probe.tree.num_leaves());
        CHECK(res.stats.probe_leaves <= res.stats.leaf_pairs);
        if (!res.pairs.empty()) CHECK(res.stats.probe_leaves > 0);
        continue;
      }
      CHECK(res.pairs == ref.pairs);
      CHECK(res.stats.node_pairs == ref.stats.node_pairs);
      CHECK(res.stats.leaf_pairs == ref.stats.leaf_pairs);
      CHECK(res.stats.tri_pairs == ref.stats.tri_pairs);
      CHECK(res.stats.probe_leaves == ref.stats.probe_leaves);
    }
  }
  CHECK(touching >= poses.size() / 2);  // the poses exercise the leaf stage, not only far misses
  REQUIRE(simd::set_isa(before));
}

// A pair of one-triangle-per-cell meshes: cell c holds probe triangle c and object triangle c,
// cells 10 x scale apart, so the candidate pairs are exactly the same-cell pairs.
struct CellPairs {
  std::vector<Vec3> pv, ov;
  void add(const std::array<Vec3, 3>& p, const std::array<Vec3, 3>& o, double scale) {
    const double cell = 10 * scale;
    const Vec3 at(cell * static_cast<double>(pv.size() / 3), 0, 0);
    for (const Vec3& v : p) pv.push_back(v + at);
    for (const Vec3& v : o) ov.push_back(v + at);
  }
  static Mesh mesh(const char* name, const std::vector<Vec3>& v) {
    std::vector<Tri> f;
    for (std::uint32_t i = 0; i + 2 < v.size(); i += 3) f.push_back({i, i + 1, i + 2});
    return make_mesh(name, v, f);
  }
};

TEST_CASE("the certified triangle filter decides as the exact test does, at every scale and ISA") {
  using simd::Isa;
  std::mt19937_64 rng(20261126);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const auto tri = [&](double scale) {
    return std::array<Vec3, 3>{Vec3(unit(rng), unit(rng), unit(rng)) * scale, Vec3(unit(rng), unit(rng), unit(rng)) * scale,
                               Vec3(unit(rng), unit(rng), unit(rng)) * scale};
  };
  const Isa before = simd::active_isa();
  for (const double scale : {1e-6, 1e-3, 1.0, 1e3, 1e6}) {
    CAPTURE(scale);
    CellPairs generic, hard;
    for (int c = 0; c < 150; ++c) generic.add(tri(scale), tri(scale), scale);  // random: apart or deep
    for (int c = 0; c < 40; ++c) {
      const auto o = tri(scale);
      const Vec3 n = (o[1] - o[0]).cross(o[2] - o[0]).normalized();
      const Vec3 inside = (o[0] + o[1] + o[2]) / 3;
      auto p = tri(scale);
      // Touching at a shared vertex, exactly.
      hard.add({o[1], p[1], p[2]}, o, scale);
      // A vertex on the face (barycentric point, rounded), the rest above or below.
      hard.add({inside, inside + n * scale, inside + (p[2] - p[1]) * 0.5 + n * scale}, o, scale);
      // Coplanar and overlapping; coplanar and apart; parallel 1e-9 x scale above.
      hard.add({o[0] * 0.5 + inside * 0.5, o[1] * 0.5 + inside * 0.5, o[2] * 0.5 + inside * 0.5}, o, scale);
      hard.add({o[0] * 2.0 - inside, o[1] * 2.0 - inside - (o[1] - o[0]) * 1.5, o[2] * 2.0 - inside}, o, scale);
      hard.add({o[0] + n * 1e-9 * scale, o[1] + n * 1e-9 * scale, o[2] + n * 1e-9 * scale}, o, scale);
      // Degenerate: a segment through the face, a point on it; an edge nearly parallel to one of O's.
      hard.add({inside - n * scale, inside + n * scale, inside}, o, scale);
      hard.add({inside, inside, inside}, o, scale);
      const Vec3 e = (o[1] - o[0]) + n.cross(o[1] - o[0]) * 1e-7;
      hard.add({o[0] + n * 1e-7 * scale, o[0] + n * 1e-7 * scale + e, inside - n * 0.3 * scale}, o, scale);
    }
    for (CellPairs* cells : {&generic, &hard}) {
      const bool is_generic = cells == &generic;
      CAPTURE(is_generic);
      Body probe(CellPairs::mesh("probe", cells->pv)), object(CellPairs::mesh("object", cells->ov));
      const Pose id = Pose::Identity();
      std::vector<FacePair> ref = brute_force(probe.mesh, object.mesh, id);
      std::sort(ref.begin(), ref.end());
      for (int i = 0; i <= static_cast<int>(simd::best_isa()); ++i) {
        const std::string isa_name = simd::isa_name(static_cast<Isa>(i));
        CAPTURE(isa_name);
        REQUIRE(simd::set_isa(static_cast<Isa>(i)));
        CollideScratch scratch;
        CollideConfig opt;
        opt.sort_pairs = true;
        CollideResult with, without;
        collide(probe.mesh, probe.tree, object.mesh, object.tree, id, opt, scratch, with);
        opt.tri_filter = false;
        collide(probe.mesh, probe.tree, object.mesh, object.tree, id, opt, scratch, without);
        CHECK(with.pairs == ref);
        CHECK(without.pairs == ref);
        CHECK(with.stats.tri_pairs == without.stats.tri_pairs);
        CHECK(without.stats.tri_exact == without.stats.tri_pairs);  // off: every candidate exact
        CHECK(with.stats.tri_exact <= with.stats.tri_pairs);
        if (is_generic) {
          // Random triangles in the same box: apart or deeply crossing, well conditioned; the filter
          // must decide nearly all of them (it is the point), and the set must not be trivial.
          CHECK(with.stats.tri_pairs >= 100);
          CHECK(!ref.empty());
          CHECK(with.stats.tri_exact * 20 <= with.stats.tri_pairs);
        }
      }
    }
  }
  REQUIRE(simd::set_isa(before));
}

TEST_CASE("approximate mode is a superset of exact") {
  const Mesh* hand = st::test::model_mesh("hand.off");
  const Mesh* ele = st::test::model_mesh("elephant.off");
  Body probe(*hand), object(*ele);
  // Three near poses: the approximate lists run to millions of pairs (0.3–5 M here), so more
  // poses cost seconds (more under the sanitizers) without reaching other code.
  const auto poses = poses_for(*hand, *ele, 3, 3);
  for (int stop : {kLeafSpheres, static_cast<int>(object.tree.num_depths) - 2}) {
    for (const auto& named : poses) {
      const std::string& name = named.first;  // not a structured binding: CAPTURE captures it
      const Pose& pose = named.second;
      // The hand buried in the elephant at the coarse layer adds millions more pairs, nothing new.
      if (name == "deep" && stop != kLeafSpheres) continue;
      CAPTURE(name);
      CAPTURE(stop);
      const auto exact = run(probe, object, pose);
      CollideConfig o;
      o.stop_layer = stop;
      const auto approx = run(probe, object, pose, o);
      CHECK(std::includes(approx.begin(), approx.end(), exact.begin(), exact.end()));
    }
  }
}

TEST_CASE("scratch reuse: no reallocation once warm; non-finite pose gives nothing") {
  Body s(make_icosphere(20, 8)), c(make_capsule(6, 20, 20));
  Pose p = Pose::Identity();
  p.translation() = Vec3(0, 0, 15);
  CollideScratch scratch;
  CollideResult res;
  collide(c.mesh, c.tree, s.mesh, s.tree, p, {}, scratch, res);
  REQUIRE(!res.pairs.empty());
  const auto* data = res.pairs.data();
  const auto n = res.pairs.size();
  CHECK(res.stats.node_pairs > 0);
  CHECK(res.stats.tri_pairs >= n);
  for (int i = 0; i < 5; ++i) {
    collide(c.mesh, c.tree, s.mesh, s.tree, p, {}, scratch, res);
    CHECK(res.pairs.data() == data);
    CHECK(res.pairs.size() == n);
  }
  p.translation().x() = std::nan("");
  collide(c.mesh, c.tree, s.mesh, s.tree, p, {}, scratch, res);
  CHECK(res.pairs.empty());
}

TEST_CASE("SortedRuns merges sorted runs (and unsorted ones it sorts) into what std::sort gives, for 0 to 65 runs") {
  std::mt19937_64 rng(5);
  st::geom::SortedRuns runs;
  std::vector<FacePair> pairs;
  // Both of its ways, by the non-empty runs: small ids (15 bits of key: 2 radix passes, so from 5
  // runs on it radix-sorts; many repeats), ids up to 2^20 (40 bits: 4 passes, from 17 runs on)
  // and ids over all 32 bits (64 bits: 6 passes, it merges up to 64 runs, radix-sorts 65: no
  // empty run there).
  for (const std::uint32_t range : {400u, 1u << 20, 0u})
    for (std::size_t k : {0, 1, 2, 3, 4, 5, 7, 8, 16, 17, 33, 64, 65})
      for (int unsorted : {0, 1}) {
        pairs.clear();
        runs.clear();
        const auto id = [&](std::uint32_t small) {  // a probe's ids below 40 with the small range
          return range == 0 ? std::uint32_t(rng()) : std::uint32_t(rng() % (range == 400 ? small : range));
        };
        for (std::size_t r = 0; r < k; ++r) {
          runs.begin(pairs.size());
          const std::size_t n = range == 0 ? 1 + rng() % 49 : rng() % 50;  // empty runs too
          for (std::size_t i = 0; i < n; ++i) pairs.push_back({id(40), id(range)});
          // A worker's run is sorted; the last one (the assist's, or a worker that did not sort) may not be.
          if (!(unsorted && r + 1 == k)) std::sort(pairs.end() - std::ptrdiff_t(n), pairs.end());
          runs.end(pairs);
        }
        std::vector<FacePair> expect = pairs;
        std::sort(expect.begin(), expect.end());
        runs.merge(pairs);
        CAPTURE(range);
        CAPTURE(k);
        CAPTURE(unsorted);
        CHECK(pairs == expect);
      }
}

TEST_CASE("sort_distinct_ids and count_faces give std::sort + std::unique's ids, at every size and id range") {
  std::mt19937_64 rng(12);
  std::vector<std::uint32_t> scratch, scratch2;
  for (std::uint32_t range : {0u, 1u, 7u, 2048u, 70000u, 1u << 24, 0xffffffffu})
    for (std::size_t n : {0, 1, 63, 64, 255, 256, 257, 1000, 20000}) {  // both sides of the radix's threshold
      std::vector<std::uint32_t> ids(n);
      std::vector<FacePair> pairs(n);
      for (std::size_t i = 0; i < n; ++i) {
        ids[i] = std::uint32_t(rng() % (std::uint64_t(range) + 1));
        pairs[i] = {std::uint32_t(rng() % (std::uint64_t(range) + 1)), ids[i]};
      }
      std::vector<std::uint32_t> expect = ids, probes;
      std::sort(expect.begin(), expect.end());
      expect.erase(std::unique(expect.begin(), expect.end()), expect.end());
      for (const FacePair& p : pairs) probes.push_back(p.probe);
      std::sort(probes.begin(), probes.end());
      const auto distinct_probes = std::size_t(std::unique(probes.begin(), probes.end()) - probes.begin());
      st::geom::sort_distinct_ids(ids, scratch);
      const st::geom::FaceCounts counts = st::geom::count_faces(pairs, scratch2);
      CAPTURE(range);
      CAPTURE(n);
      CHECK(ids == expect);
      CHECK(counts.object_faces == expect.size());
      CHECK(counts.probe_faces == distinct_probes);
    }
}

TEST_CASE("sort_face_pairs orders pairs as std::sort does, at every size and index range") {
  std::mt19937_64 rng(11);
  std::vector<std::uint64_t> scratch;
  for (std::uint32_t range : {1u, 7u, 2048u, 70000u, 1u << 24, 0xffffffffu})
    for (std::size_t n : {0, 1, 63, 64, 65, 1000, 20000}) {
      std::vector<FacePair> pairs(n);
      for (FacePair& p : pairs) {
        p.probe = std::uint32_t(rng() % (std::uint64_t(range) + 1));
        p.object = std::uint32_t(rng() % (std::uint64_t(range) + 1));
      }
      std::vector<FacePair> expect = pairs;
      std::sort(expect.begin(), expect.end());
      st::geom::sort_face_pairs(pairs, scratch);
      CAPTURE(range);
      CAPTURE(n);
      CHECK(pairs == expect);
    }
}
