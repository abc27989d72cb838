// SPDX-License-Identifier: BSD-3-Clause
// spheretouch query PROBE OBJECT --poses FILE: every colliding (probe face, object face) pair per
// pose, exactly. Output, per pose:
//   pose <i> pairs <n> contacts <c>
//   <probe_face> <object_face>        (n lines, sorted by probe face then object face)
// spheretouch query --scene SCENE --poses FILE: the scene's probe against every one of its objects
// (placed; poses in the world frame). Per pose the totals, then for each object in scene order
//   pose <i> pairs <n> contacts <c>
//   object <k> pairs <n> contacts <c> <name>
//   <probe_face> <object_face>        (that object's pairs, sorted, faces in its own file's order)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>

#include "app/commands.hpp"
#include <spheretouch/engine/distributed.hpp>
#include <spheretouch/engine/scene.hpp>
#include "app/mesh_options.hpp"
#include <spheretouch/engine/tree_cache.hpp>
#include <spheretouch/collide.hpp>
#include <spheretouch/geom/partition.hpp>
#include <spheretouch/geom/pose_io.hpp>

namespace st::app {

using engine::CachedTree;
using engine::ClientCurve;
using engine::default_tree_cache_dir;
using engine::Fleet;
using engine::FleetSpec;
using engine::load_client_curve;
using engine::start_fleet;
using engine::tree_for;
namespace {

struct QueryArgs {
  std::string probe, object, poses, cache_dir = default_tree_cache_dir();
  std::string scene;  ///< --scene: the probe and the objects from a scene file
  geom::LoadConfig load;
  std::uint32_t leaf_faces = geom::DefaultTreeConfig().leaf_faces;
  std::uint32_t blocks = 0, layer = 2, block_size = 1;
  int repeat = 1;
  int workers = 0;
  std::string connect;
  std::string server_key, client_key;  ///< CURVE key files for --connect
  int approx_layer = geom::kExact;
  bool count_only = false, stats = false, no_cache = false;
};

/// A body: the mesh with its tree through the cache, reporting a rejected cache file on stderr.
Body body_or_exit(geom::Mesh mesh, const geom::TreeConfig& params, const std::string& dir) {
  Result<CachedTree> r = tree_for(mesh, params, dir);
  if (!r) {
    std::fprintf(stderr, "spheretouch: %s\n", r.error().c_str());
    throw CLI::RuntimeError(2);
  }
  if (!r.value().note.empty()) std::fprintf(stderr, "spheretouch: tree cache: %s\n", r.value().note.c_str());
  Result<Body> body = Body::make(std::make_shared<const geom::Mesh>(std::move(mesh)),
                                 std::make_shared<const geom::SphereTree>(std::move(r.value().tree)));
  if (!body) {
    std::fprintf(stderr, "spheretouch: %s\n", body.error().c_str());
    throw CLI::RuntimeError(2);
  }
  return std::move(body).value();
}

/// --workers N / --connect EP,... as a fleet: the split knobs and CURVE keys of the query.
FleetSpec fleet_spec(const QueryArgs& a, const ClientCurve& curve) {
  FleetSpec spec;
  spec.workers = a.workers;
  for (std::string rest = a.connect; !rest.empty();) {
    const auto comma = rest.find(',');
    spec.endpoints.push_back(rest.substr(0, comma));
    rest = comma == std::string::npos ? "" : rest.substr(comma + 1);
  }
  spec.layer = a.layer;
  spec.block_size = a.block_size;
  spec.leaf_faces = a.leaf_faces;
  spec.curve = curve;
  spec.note = [](const std::string& m) { std::fprintf(stderr, "spheretouch: %s\n", m.c_str()); };
  return spec;
}

/// One object of a --scene query: its body, placement and (with workers) its client.
struct SceneObject {
  std::string name;
  Body body;
  geom::Pose placement, to_object;
  BoundingSphere bound;  ///< placed in the world
};

[[noreturn]] void query_die(int code, const std::string& msg) {
  std::fprintf(stderr, "spheretouch: %s\n", msg.c_str());
  throw CLI::RuntimeError(code);
}

/// query --scene: every object of the scene, each pose in the world frame.
void run_scene_query(const QueryArgs& a, const ClientCurve& curve) {
  Result<engine::Scene> scene = engine::load_scene(a.scene);
  if (!scene) query_die(2, scene.error());
  const engine::Scene& s = scene.value();
  Result<std::vector<geom::Pose>> poses = geom::read_poses(a.poses);
  if (!poses) query_die(2, poses.error());
  geom::TreeConfig params = geom::DefaultTreeConfig();
  params.leaf_faces = a.leaf_faces;
  const std::string cache = a.no_cache ? "" : a.cache_dir;
  Result<geom::Mesh> pm = engine::load_body(s.probe, "probe");
  if (!pm) query_die(2, s.file + ": " + pm.error());
  const Body probe = body_or_exit(std::move(pm).value(), params, cache);
  std::vector<SceneObject> objects;
  const std::vector<engine::ObjectSpec> specs = engine::scene_objects(s);
  for (std::size_t k = 0; k < specs.size(); ++k) {
    Result<geom::Mesh> om =
        engine::load_body(specs[k].body, s.objects.empty() ? "object" : "object[" + std::to_string(k + 1) + "]");
    if (!om) query_die(2, s.file + ": " + om.error());
    Body b = body_or_exit(std::move(om).value(), params, cache);
    const geom::Pose place = specs[k].placement.pose();
    const BoundingSphere bound = b.bounding_sphere().moved(place);
    objects.push_back({specs[k].name, std::move(b), place, place.inverse(), bound});
  }
  const BoundingSphere probe_bound = probe.bounding_sphere();

  std::unique_ptr<Fleet> fleet;
  if (a.workers > 0 || !a.connect.empty()) {
    const FleetSpec spec = fleet_spec(a, curve);
    std::vector<engine::FleetObject> fo;
    for (const SceneObject& o : objects) fo.push_back({&o.body.mesh(), &o.body.tree()});
    Result<std::unique_ptr<Fleet>> f = start_fleet(spec, probe.mesh(), fo);
    if (!f) query_die(2, f.error());
    fleet = std::move(f).value();
  }
  std::vector<std::optional<ComputeCollision>> colliders(objects.size());
  CollisionRequest request;
  request.approximate_layer = a.approx_layer;
  request.sort_pairs = true;
  if (const std::string bad = check(request); !bad.empty()) query_die(2, "--approx-layer: " + bad);
  CollisionResult result;
  net::RoundResult round;
  std::vector<std::vector<geom::FacePair>> pairs(objects.size());
  std::vector<std::uint32_t> tmp;
  std::string out;
  char line[160];
  std::uint64_t seq = 0;
  for (std::size_t i = 0; i < poses.value().size(); ++i) {
    const geom::Pose& pose = poses.value()[i];
    std::size_t total_pairs = 0;
    std::uint32_t total_contacts = 0;
    for (std::size_t k = 0; k < objects.size(); ++k) {
      SceneObject& o = objects[k];
      pairs[k].clear();
      if (!probe_bound.moved(pose).meets(o.bound)) continue;  // out of the probe's reach: no pairs
      const geom::Pose rel = o.to_object * pose;
      if (fleet && fleet->clients[k]) {
        fleet->clients[k]->round(++seq, rel, net::Clock::now() + std::chrono::seconds(30), round);
        if (!round.complete)
          query_die(1, "pose " + std::to_string(i) + ", " + o.name + ": only " + std::to_string(round.workers_replied) +
                           " of " + std::to_string(round.workers_asked) + " workers answered");
        pairs[k].assign(round.pairs.begin(), round.pairs.end());
      } else {
        if (!colliders[k]) colliders[k].emplace(probe, o.body);
        colliders[k]->at_relative(rel, request, result);
        pairs[k].assign(result.pairs.begin(), result.pairs.end());
      }
      std::sort(pairs[k].begin(), pairs[k].end());
      total_pairs += pairs[k].size();
      total_contacts += geom::count_faces(pairs[k], tmp).contacts();
    }
    std::snprintf(line, sizeof line, "pose %zu pairs %zu contacts %u\n", i, total_pairs, total_contacts);
    out += line;
    for (std::size_t k = 0; k < objects.size(); ++k) {
      std::snprintf(line, sizeof line, "object %zu pairs %zu contacts %u ", k, pairs[k].size(),
                    geom::count_faces(pairs[k], tmp).contacts());
      out += line;
      out += objects[k].name + "\n";
      if (!a.count_only)
        for (const geom::FacePair& p : pairs[k]) {
          std::snprintf(line, sizeof line, "%u %u\n", p.probe, p.object);
          out += line;
        }
    }
    if (out.size() > (1 << 20)) {
      std::fputs(out.c_str(), stdout);
      out.clear();
    }
  }
  std::fputs(out.c_str(), stdout);
}

void run_query(const QueryArgs& a) {
  // CURVE keys first: a bad key file fails before any mesh is loaded.
  Result<ClientCurve> curve = load_client_curve(a.server_key, a.client_key, "--server-key", "--client-key");
  if (!curve) {
    std::fprintf(stderr, "spheretouch: %s\n", curve.error().c_str());
    throw CLI::RuntimeError(2);
  }
  if (!a.scene.empty()) {
    if (!a.probe.empty() || !a.object.empty())
      query_die(2, "--scene names the probe and the objects: give no PROBE OBJECT");
    if (a.blocks > 0) query_die(2, "--blocks is for a PROBE OBJECT query (with --scene use --workers)");
    return run_scene_query(a, curve.value());
  }
  if (a.probe.empty() || a.object.empty()) query_die(2, "give PROBE and OBJECT mesh files, or --scene SCENE");
  geom::LoadedMesh probe_file = load_or_exit(a.probe, a.load);
  geom::LoadedMesh object_file = load_or_exit(a.object, a.load);
  Result<std::vector<geom::Pose>> poses = geom::read_poses(a.poses);
  if (!poses) {
    std::fprintf(stderr, "spheretouch: %s\n", poses.error().c_str());
    throw CLI::RuntimeError(2);
  }
  geom::TreeConfig params = geom::DefaultTreeConfig();
  params.leaf_faces = a.leaf_faces;
  const std::string cache = a.no_cache ? "" : a.cache_dir;
  ComputeCollision collider(body_or_exit(std::move(probe_file.mesh), params, cache),
                            body_or_exit(std::move(object_file.mesh), params, cache));
  const geom::Mesh& probe = collider.probe().mesh();
  const geom::Mesh& object = collider.object().mesh();
  const geom::SphereTree& otree = collider.object().tree();

  // --workers N / --connect: the same query through scatter-gather over workers.
  std::unique_ptr<Fleet> fleet;
  if (a.workers > 0 || !a.connect.empty()) {
    const FleetSpec spec = fleet_spec(a, curve.value());
    Result<std::unique_ptr<Fleet>> f = start_fleet(spec, probe, object, otree);
    if (!f) {
      std::fprintf(stderr, "spheretouch: %s\n", f.error().c_str());
      throw CLI::RuntimeError(2);
    }
    fleet = std::move(f).value();
  }
  net::RoundResult round;

  // --blocks W: the object's layer-n spheres split block-cyclically over W in-process "workers";
  // the query runs once per worker restricted to its blocks, and the results are merged.
  std::vector<std::vector<std::uint32_t>> roots;
  if (a.blocks > 0) {
    Result<geom::Partition> part = geom::make_partition(otree, a.layer, a.blocks, a.block_size);
    if (!part) {
      std::fprintf(stderr, "spheretouch: --blocks: %s\n", part.error().c_str());
      throw CLI::RuntimeError(2);
    }
    for (std::uint32_t w = 0; w < a.blocks; ++w) roots.push_back(part.value().worker_roots(w));
  }

  CollisionRequest request;
  request.approximate_layer = a.approx_layer;
  request.sort_pairs = false;  // the merged pairs are sorted below
  if (const std::string bad = check(request); !bad.empty()) {
    std::fprintf(stderr, "spheretouch: --approx-layer: %s\n", bad.c_str());
    throw CLI::RuntimeError(2);
  }
  CollisionResult result;
  std::vector<geom::FacePair> merged;
  std::vector<std::uint32_t> tmp;
  std::vector<double> times_us;
  std::string out;
  char line[96];
  for (std::size_t i = 0; i < poses.value().size(); ++i) {
    const geom::Pose& pose = poses.value()[i];
    times_us.clear();
    geom::CollideStats stats;
    for (int r = 0; r < a.repeat; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      merged.clear();
      stats = {};
      if (fleet) {
        // Exactness needs every block: a generous deadline, and an incomplete round is an error.
        fleet->client().round(i * std::uint64_t(a.repeat) + std::uint64_t(r) + 1, pose,
                              net::Clock::now() + std::chrono::seconds(30), round);
        if (!round.complete) {
          std::fprintf(stderr, "spheretouch: pose %zu: only %u of %u workers answered (%u of %u blocks)\n", i,
                       round.workers_replied, round.workers_asked, round.blocks_covered, round.blocks_total);
          throw CLI::RuntimeError(1);
        }
        merged.insert(merged.end(), round.pairs.begin(), round.pairs.end());
        stats.node_pairs = round.stats.sphere_tests;
        stats.tri_pairs = round.stats.tri_tests;
      } else if (roots.empty()) {
        collider.at_relative(pose, request, result);
        merged.insert(merged.end(), result.pairs.begin(), result.pairs.end());
        stats = result.stats;
      } else {
        for (const auto& w : roots) {
          request.object_roots = w;
          request.restrict_object = true;
          collider.at_relative(pose, request, result);
          merged.insert(merged.end(), result.pairs.begin(), result.pairs.end());
          stats.node_pairs += result.stats.node_pairs;
          stats.tri_pairs += result.stats.tri_pairs;
        }
      }
      std::sort(merged.begin(), merged.end());
      times_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    }
    std::nth_element(times_us.begin(), times_us.begin() + times_us.size() / 2, times_us.end());
    const std::uint32_t contacts = geom::count_faces(merged, tmp).contacts();
    std::snprintf(line, sizeof line, "pose %zu pairs %zu contacts %u\n", i, merged.size(), contacts);
    out += line;
    if (!a.count_only)
      for (const geom::FacePair& p : merged) {
        std::snprintf(line, sizeof line, "%u %u\n", p.probe, p.object);
        out += line;
      }
    if (out.size() > (1 << 20)) {
      std::fputs(out.c_str(), stdout);
      out.clear();
    }
    if (a.stats)
      std::fprintf(stderr, "stats pose %zu query_us %.1f node_pairs %llu tri_tests %llu\n", i,
                   times_us[times_us.size() / 2], static_cast<unsigned long long>(stats.node_pairs),
                   static_cast<unsigned long long>(stats.tri_pairs));
  }
  std::fputs(out.c_str(), stdout);
}

}  // namespace

void add_query(CLI::App& app) {
  auto a = std::make_shared<QueryArgs>();
  CLI::App* cmd =
      app.add_subcommand("query",
                         "Every colliding (probe face, object face) pair for each pose, exactly. Prints per pose\n"
                         "'pose <i> pairs <n> contacts <c>' then n lines '<probe_face> <object_face>' sorted.");
  cmd->add_option("probe", a->probe, "probe mesh (the hand)")->check(CLI::ExistingFile);
  cmd->add_option("object", a->object, "object mesh")->check(CLI::ExistingFile);
  cmd->add_option("--scene", a->scene,
                  "instead of PROBE OBJECT: the scene's probe against each of its objects ([object] or [[object]], "
                  "placed; poses in the world frame). Per pose the totals, then 'object <k> pairs <n> contacts <c> "
                  "<name>' and that object's pairs, for every object")
      ->check(CLI::ExistingFile);
  cmd->add_option("--poses", a->poses,
                  "pose file: one pose per line, 16 numbers (row-major 4x4 rigid transform mapping probe to object "
                  "coordinates, last row 0 0 0 1); '#' starts a comment")
      ->required()
      ->check(CLI::ExistingFile);
  add_load_options(cmd, a->load);
  cmd->add_flag("--count-only", a->count_only, "print only the 'pose ...' header lines");
  cmd->add_option("--leaf-faces", a->leaf_faces, "faces per leaf sphere (speed knob; results are exact for any value)")
      ->check(CLI::Range(1u, geom::kMaxLeafFaces))
      ->capture_default_str();
  cmd->add_option("--blocks", a->blocks,
                  "split the object's layer-n spheres block-cyclically into W blocks sets, query each, merge "
                  "(must give the same output)")
      ->check(CLI::Range(1u, 4096u));
  cmd->add_option("--layer", a->layer, "sphere layer distributed by --blocks")->capture_default_str();
  cmd->add_option("--block-size", a->block_size, "layer-n spheres per block for --blocks")
      ->check(CLI::Range(1u, 1u << 20))
      ->capture_default_str();
  cmd->add_option("--repeat", a->repeat, "run each query R times (for --stats timing)")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  cmd->add_flag("--stats", a->stats,
                "per pose on stderr: 'stats pose <i> query_us <median> node_pairs <n> tri_tests <m>'");
  cmd->add_option("--approx-layer", a->approx_layer,
                  "approximate mode: stop the descent at sphere layer K (-1 = leaf spheres) and report the faces of "
                  "overlapping spheres without triangle tests; not exact (a superset)")
      ->check(CLI::Range(-1, 64));
  cmd->add_option("--workers", a->workers,
                  "run the query over N in-process workers (inproc://), the object's layer-n sphere blocks dealt "
                  "block-cyclically; same output")
      ->check(CLI::Range(1, 64));
  CLI::Option* connect = cmd->add_option(
      "--connect", a->connect, "run the query over worker daemons EP1,EP2,... (tcp:// or ipc://); same output");
  CLI::Option* server_key =
      cmd->add_option("--server-key", a->server_key,
                      "CURVE (with --connect): the workers' public key file, PREFIX.pub from `spheretouch keygen`")
          ->type_name("FILE")
          ->needs(connect);
  CLI::Option* client_key =
      cmd->add_option("--client-key", a->client_key,
                      "CURVE (with --connect): this client's key pair PREFIX: PREFIX.key (mode 0600) and PREFIX.pub; "
                      "its public key must be in the workers' allowed_clients")
          ->type_name("PREFIX")
          ->needs(connect);
  server_key->needs(client_key);
  client_key->needs(server_key);
  cmd->add_option("--tree-cache", a->cache_dir, "directory of cached sphere trees")->capture_default_str();
  cmd->add_flag("--no-cache", a->no_cache, "build trees in memory only");
  cmd->callback([a] { run_query(*a); });
}

}  // namespace st::app
