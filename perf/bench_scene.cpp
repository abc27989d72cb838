// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench scene: what a collision round costs against the number of objects in a scene
// (issue #28): 1, 10 and 100 copies of the object placed on a grid, the probe touching none of
// them, or touching one (object 0, at the perf poses' contact counts). Rounds run through the real
// collision loop (engine::CollisionLoop: the top-level cull, one collider and contact builder per
// object, the ContactSet) in the collision thread, fed one pose at a time; a round's time is the
// loop's own (pose taken to set published). The phases alternate in blocks so drift hits them
// alike; the figures are medians, and the touched object's pairs are compared with the
// single-object scene's at every pose.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <thread>

#include <spheretouch/collide.hpp>
#include <spheretouch/engine/collision_loop.hpp>
#include <spheretouch/rt/triple_buffer.hpp>

#include "bench.hpp"
#include "bench_json.hpp"
#include "bench_tables_common.hpp"

namespace st::bench {
namespace {

struct SceneArgs {
  std::string probe = ".cache/models/hand_L2.off";
  std::string object = ".cache/models/elephant.off";
  std::string poses = "perf/poses/hand_elephant.txt";
  std::vector<int> counts{1, 10, 100};
  int rounds = 60;  ///< rounds per phase and block
  int blocks = 8;   ///< blocks of every phase, interleaved
  bool json = false;
};

/// One phase of a scene: a pose the probe holds, the rounds' times and the pairs they gave.
struct Phase {
  std::string name;
  geom::Pose pose;
  std::uint32_t target = 0;          ///< the pose file's contact target (0: touching none)
  std::vector<double> us;            ///< round times
  std::vector<std::uint32_t> pairs;  ///< pairs per round (every object summed)
};

/// `n` objects: object 0 at the origin (the poses touch it), the others on a square grid around it,
/// `spacing` apart (each object's bounding sphere clear of the others' and of the probe near object 0).
std::vector<engine::WorldObject> grid(const st::Body& object, int n, double spacing) {
  std::vector<engine::WorldObject> w;
  const BoundingSphere bound = object.bounding_sphere();
  w.push_back({&object.mesh(), geom::Pose::Identity(), bound});
  int side = 1;
  while (side * side < n) side += 2;  // odd: object 0 sits in the middle cell
  for (int cell = 0; cell < side * side && int(w.size()) < n; ++cell) {
    const int i = cell % side - side / 2, j = cell / side - side / 2;
    if (i == 0 && j == 0) continue;  // object 0's
    geom::Pose p = geom::Pose::Identity();
    p.translate(geom::Vec3(spacing * i, spacing * j, 0));
    w.push_back({&object.mesh(), p, bound});
  }
  return w;
}

void run_scene(const SceneArgs& a) {
  const Body probe_b = load_body(a.probe), object_b = load_body(a.object);
  auto body = [](const Body& b) {
    Result<st::Body> r =
        st::Body::make(std::make_shared<const geom::Mesh>(b.mesh), std::make_shared<const geom::SphereTree>(b.tree));
    if (!r) {
      std::fprintf(stderr, "spheretouch-bench scene: %s\n", r.error().c_str());
      std::exit(1);
    }
    return std::move(r).value();
  };
  const st::Body probe = body(probe_b), object = body(object_b);
  const std::vector<TaggedPose> tagged = read_tagged_poses(a.poses);
  if (tagged.empty()) {
    std::fprintf(stderr, "spheretouch-bench scene: %s has no poses\n", a.poses.c_str());
    std::exit(2);
  }
  const BoundingSphere probe_bound = probe.bounding_sphere();
  const double r_obj = object.bounding_sphere().radius, r_probe = probe_bound.radius;
  const double spacing = 2 * r_obj + 2 * r_probe + 10;  // probe at object 0 reaches no other
  // The phases: the probe far above every object (touching none), then at each contact pose.
  std::vector<Phase> proto;
  {
    geom::Pose far = tagged.front().pose;
    far.pretranslate(geom::Vec3(0, 0, 4 * spacing));
    proto.push_back({"none", far, 0, {}, {}});
    for (const TaggedPose& t : tagged)
      if (t.target >= 500)  // ~500, ~1000, ~1500 contacts: the collide bench's buckets
        proto.push_back({"touch " + std::to_string(t.target), t.pose, t.target, {}, {}});
  }
  CollisionRequest request;
  request.sort_pairs = true;

  Json out = Json::object();
  out["probe"] = probe_b.label;
  out["object"] = object_b.label;
  out["object_faces"] = object.mesh().num_faces();
  out["spacing_mm"] = round_to(spacing, 1);
  Json scenes = Json::array();
  // One collision loop per object count, all alive at once; blocks of every (count, phase) pair
  // alternate, so drift (a VM neighbour, the CPU clock) hits every figure alike. The first block
  // warms the caches and is not counted.
  struct Scene {
    int n;
    std::vector<Phase> phases;
    std::unique_ptr<rt::TripleBuffer<rt::PoseSample>> poses = std::make_unique<rt::TripleBuffer<rt::PoseSample>>();
    std::unique_ptr<rt::TripleBuffer<geom::ContactSet>> sets = std::make_unique<rt::TripleBuffer<geom::ContactSet>>();
    std::vector<std::optional<ComputeCollision>> colliders;
    CollisionResult result;
    std::unique_ptr<engine::CollisionLoop> loop;
    std::uint64_t seq = 0;
    std::vector<std::pair<std::uint64_t, std::size_t>> seq_phase;  // counted pose seq → phase
  };
  std::vector<std::unique_ptr<Scene>> runs;
  for (const int n : a.counts) {
    auto sc = std::make_unique<Scene>();
    Scene& r = *sc;
    r.n = n;
    r.phases = proto;
    r.colliders.resize(std::size_t(n));
    engine::CollideFn fn = [&r, &probe, &object, &request](std::uint64_t, std::uint32_t k, const geom::Pose& pose,
                                                           engine::RoundOutput& o) {
      if (!r.colliders[k]) r.colliders[k].emplace(probe, object);
      r.colliders[k]->at_relative(pose, request, r.result);
      o.pairs.assign(r.result.pairs.begin(), r.result.pairs.end());
    };
    const std::size_t total = std::size_t(a.blocks + 1) * proto.size() * std::size_t(a.rounds) + 16;
    r.loop = std::make_unique<engine::CollisionLoop>(probe.mesh(), probe_bound, grid(object, n, spacing), *r.poses,
                                                     *r.sets, fn, 0, total);
    r.loop->start();
    runs.push_back(std::move(sc));
  }
  for (int b = 0; b <= a.blocks; ++b)
    for (auto& sc : runs)
      for (std::size_t p = 0; p < proto.size(); ++p)
        for (int i = 0; i < a.rounds; ++i) {
          Scene& r = *sc;
          rt::PoseSample& s = r.poses->input();
          s.seq = ++r.seq;
          s.sampled_ns = rt::now_ns();
          s.pose = geom::to_pod(r.phases[p].pose);
          r.poses->publish();
          while (true) {  // the loop answers every pose; wait for this one's set
            r.sets->update();
            if (r.sets->output().pose_seq == r.seq) break;
            std::this_thread::yield();
          }
          if (b > 0 && i > 0) r.seq_phase.push_back({r.seq, p});  // not the warm-up block, not a switch's first round
        }
  std::vector<std::vector<Phase>> results;
  for (auto& sc : runs) {
    Scene& r = *sc;
    r.loop->stop();
    for (const engine::RoundRecord& rec : r.loop->records()) {
      const auto it =
          std::lower_bound(r.seq_phase.begin(), r.seq_phase.end(), std::make_pair(rec.pose_seq, std::size_t(0)));
      if (it == r.seq_phase.end() || it->first != rec.pose_seq) continue;
      r.phases[it->second].us.push_back(double(rec.end_ns - rec.start_ns) * 1e-3);
      r.phases[it->second].pairs.push_back(rec.pairs);
    }
    results.push_back(std::move(r.phases));
  }
  // Ratios against the single-object scene at the same phase, medians.
  std::vector<double> base;
  for (Phase& p : results.front()) base.push_back(quantile(p.us, 0.5));
  if (!a.json)
    std::printf("%-8s %-12s %10s %10s %8s %8s %s\n", "objects", "phase", "median_us", "p90_us", "ratio", "pairs",
                "pairs = 1-object");
  for (std::size_t c = 0; c < results.size(); ++c) {
    Json rows = Json::array();
    for (std::size_t p = 0; p < results[c].size(); ++p) {
      Phase& ph = results[c][p];
      std::vector<double> us = ph.us;
      const double med = quantile(us, 0.5), p90 = quantile(us, 0.9);
      const bool same = ph.pairs == results.front()[p].pairs;
      const std::uint32_t pairs = ph.pairs.empty() ? 0 : ph.pairs.front();
      const double ratio = base[p] > 0 ? med / base[p] : 0.0;
      if (!a.json)
        std::printf("%-8d %-12s %10.1f %10.1f %8.3f %8u %s\n", a.counts[c], ph.name.c_str(), med, p90, ratio, pairs,
                    same ? "yes" : "NO");
      rows.push_back({{"phase", ph.name},
                      {"target_contacts", ph.target},
                      {"rounds", ph.us.size()},
                      {"median_us", round_to(med, 1)},
                      {"p90_us", round_to(p90, 1)},
                      {"ratio_vs_one_object", round_to(ratio, 3)},
                      {"pairs", pairs},
                      {"pairs_equal_one_object", same}});
    }
    scenes.push_back({{"objects", a.counts[c]}, {"phases", rows}});
  }
  out["scenes"] = scenes;
  if (a.json) print_json(out);
}

}  // namespace

void add_scene(CLI::App& app) {
  auto a = std::make_shared<SceneArgs>();
  CLI::App* c = app.add_subcommand(
      "scene",
      "A collision round's cost against the number of objects (1, 10, 100 copies on a grid): the probe touching "
      "none, or one of them at the pose file's ~500/1000/1500-contact poses; ratios against the 1-object scene in "
      "the same run, pairs compared");
  c->add_option("--probe", a->probe, "probe mesh")->capture_default_str();
  c->add_option("--object", a->object, "object mesh (copied on the grid)")->capture_default_str();
  c->add_option("--poses", a->poses, "pose file with '# contacts N (target T)' tags (the collide bench's)")->capture_default_str();
  c->add_option("--counts", a->counts, "object counts; the first is the baseline")->capture_default_str();
  c->add_option("--rounds", a->rounds, "rounds per phase and block")->capture_default_str()->check(CLI::Range(5, 100000));
  c->add_option("--blocks", a->blocks, "blocks of every phase, interleaved")->capture_default_str()->check(CLI::Range(1, 1000));
  c->add_flag("--json", a->json, "one JSON object on stdout");
  c->callback([a] { run_scene(*a); });
}

}  // namespace st::bench
