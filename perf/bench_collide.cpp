// spheretouch-bench collide: exact collide() query time (median of --runs, warm scratch, single
// thread) of a probe against an object at the poses of a pose file, with contacts and counters;
// --find-poses writes such a file with poses near given contact counts (fingertip pushed into the
// object's surface along the normal, depth found by bisection).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "bench.hpp"
#include "geom/collide.hpp"
#include "geom/mesh_io.hpp"
#include "geom/sphere_tree.hpp"

namespace st::bench {
namespace {

using geom::Mesh;
using geom::Pose;
using geom::Vec3;

struct Scene {
  Mesh probe, object;
  geom::SphereTree pt, ot;
};

std::uint32_t contacts_at(const Scene& s, const Pose& pose, geom::CollideScratch& sc, geom::CollideResult& r) {
  geom::collide(s.probe, s.pt, s.object, s.ot, pose, {}, sc, r);
  return r.contacts();
}

/// Pose that puts the probe's tip (its extreme vertex along its longest box axis, pointing away
/// from the box centre) `depth_mm` below object vertex `vo`, tip direction along -normal.
Pose fingertip_pose(const Mesh& probe, const Mesh& object, std::uint32_t vo, const Vec3& normal, double depth_mm) {
  const geom::Box b = probe.local_bounds();
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (b.hi[k] - b.lo[k] > b.hi[axis] - b.lo[axis]) axis = k;
  std::uint32_t tip = 0;
  for (std::uint32_t v = 0; v < probe.num_vertices(); ++v)
    if (probe.local[v][axis] > probe.local[tip][axis]) tip = v;
  const Vec3 dir = (probe.local[tip] - b.centre()).normalized();
  Pose pose = Pose::Identity();
  pose.linear() = Eigen::Quaterniond::FromTwoVectors(dir, -normal).toRotationMatrix();
  pose.translation() = object.vertex(vo) - depth_mm * normal - pose.linear() * probe.vertex(tip);
  return pose;
}

/// Searches object sites (seeded) and depths (bisection) for a pose with about `target` contacts
/// (within 10%). Returns false when none is found within `tries` sites.
bool find_pose_for_contacts(const Scene& s, std::uint32_t target, std::uint64_t seed, int tries, Pose& out,
                            std::uint32_t& got) {
  std::vector<Vec3> n(s.object.num_vertices(), Vec3::Zero());
  for (const auto& t : s.object.faces) {
    const Vec3 fn = (s.object.local[t[1]] - s.object.local[t[0]]).cross(s.object.local[t[2]] - s.object.local[t[0]]);
    for (auto v : t) n[v] += fn;
  }
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<std::uint32_t> pick(0, static_cast<std::uint32_t>(s.object.num_vertices() - 1));
  geom::CollideScratch sc;
  geom::CollideResult r;
  const double diag = s.probe.local_bounds().diagonal();
  for (int t = 0; t < tries; ++t) {
    const std::uint32_t vo = pick(rng);
    if (n[vo].norm() == 0) continue;
    const Vec3 normal = n[vo].normalized();
    double lo = 0, hi = 0.5 * diag;
    if (contacts_at(s, fingertip_pose(s.probe, s.object, vo, normal, hi), sc, r) < target) continue;
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (lo + hi);
      const std::uint32_t c = contacts_at(s, fingertip_pose(s.probe, s.object, vo, normal, mid), sc, r);
      if (c >= target) hi = mid; else lo = mid;
      if (std::abs(double(c) - target) <= 0.1 * target) { out = fingertip_pose(s.probe, s.object, vo, normal, mid); got = c; return true; }
    }
  }
  return false;
}

std::vector<std::pair<Pose, std::string>> read_poses(const std::string& path) {
  std::ifstream in(path);
  if (!in) { std::fprintf(stderr, "%s: cannot open\n", path.c_str()); throw CLI::RuntimeError(2); }
  std::vector<std::pair<Pose, std::string>> out;
  std::string line, comment;
  for (int ln = 1; std::getline(in, line); ++ln) {
    const auto hash = line.find('#');
    if (hash != std::string::npos) { comment = line.substr(hash + 1); line.resize(hash); }
    std::istringstream is(line);
    double m[16];
    int k = 0;
    while (k < 16 && is >> m[k]) ++k;
    if (k == 0) continue;
    if (k != 16) { std::fprintf(stderr, "%s:%d: expected 16 numbers, got %d\n", path.c_str(), ln, k); throw CLI::RuntimeError(2); }
    Pose p;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) p.matrix()(i, j) = m[4 * i + j];
    out.emplace_back(p, comment);
    comment.clear();
  }
  return out;
}

}  // namespace

void add_collide(CLI::App& app) {
  struct Args {
    std::string probe, object, poses, find_out, targets = "100,500,1000,1500";
    int runs = 200;
    unsigned leaf = geom::DefaultTreeParams().leaf_faces;
    std::uint64_t seed = 1;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("collide", "Exact collide() median query time at the poses of a pose file (single thread)");
  cmd->add_option("--probe", a->probe, "probe mesh (the hand)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--object", a->object, "object mesh")->required()->check(CLI::ExistingFile);
  cmd->add_option("--poses", a->poses, "pose file to time (16 numbers a line)");
  cmd->add_option("--find-poses", a->find_out, "write a pose file with poses near --targets contacts");
  cmd->add_option("--targets", a->targets, "contact counts for --find-poses")->capture_default_str();
  cmd->add_option("--seed", a->seed, "site choice for --find-poses")->capture_default_str();
  cmd->add_option("--runs", a->runs, "queries per pose")->check(CLI::Range(1, 100000))->capture_default_str();
  cmd->add_option("--leaf-faces", a->leaf, "faces per leaf (both trees)")->check(CLI::Range(1u, geom::kMaxLeafFaces))->capture_default_str();
  cmd->callback([a] {
    Scene s;
    for (auto [path, mesh] : {std::pair{&a->probe, &s.probe}, std::pair{&a->object, &s.object}}) {
      auto m = geom::load_mesh(*path);
      if (!m) { std::fprintf(stderr, "%s\n", m.error().c_str()); throw CLI::RuntimeError(2); }
      *mesh = std::move(m.value().mesh);
    }
    s.pt = geom::SphereTree::build(s.probe, {a->leaf}).value();
    s.ot = geom::SphereTree::build(s.object, {a->leaf}).value();
    if (!a->find_out.empty()) {
      std::ofstream out(a->find_out);
      out << "# " << a->probe << " x " << a->object << ": fingertip pushed along the surface normal; "
          << "spheretouch-bench collide --find-poses (seed " << a->seed << ")\n";
      std::stringstream ts(a->targets);
      std::string tok;
      while (std::getline(ts, tok, ',')) {
        const auto target = static_cast<std::uint32_t>(std::stoul(tok));
        Pose p;
        std::uint32_t got = 0;
        if (!find_pose_for_contacts(s, target, a->seed + target, 200, p, got)) {
          std::fprintf(stderr, "no pose found near %u contacts\n", target);
          continue;
        }
        out << "# contacts " << got << " (target " << target << ")\n";
        char buf[64];
        for (int i = 0; i < 4; ++i)
          for (int j = 0; j < 4; ++j) {
            std::snprintf(buf, sizeof buf, "%.17g", p.matrix()(i, j));
            out << buf << (i == 3 && j == 3 ? "\n" : " ");
          }
        std::printf("target %5u: contacts %u\n", target, got);
      }
    }
    if (a->poses.empty()) return;
    geom::CollideScratch sc;
    geom::CollideResult r;
    std::printf("leaf_faces %u; probe %zu faces, object %zu faces\n", a->leaf, s.probe.num_faces(), s.object.num_faces());
    std::printf("%8s %8s %10s %10s %10s %10s %10s\n", "contacts", "pairs", "node_pairs", "leaf_pairs", "tri_pairs", "median_ms", "min_ms");
    for (const auto& [pose, comment] : read_poses(a->poses)) {
      std::vector<double> t;
      t.reserve(a->runs);
      geom::collide(s.probe, s.pt, s.object, s.ot, pose, {}, sc, r);  // warm
      for (int i = 0; i < a->runs; ++i) {
        const auto t0 = std::chrono::steady_clock::now();
        geom::collide(s.probe, s.pt, s.object, s.ot, pose, {}, sc, r);
        t.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      }
      std::sort(t.begin(), t.end());
      std::printf("%8u %8zu %10llu %10llu %10llu %10.4f %10.4f\n", r.contacts(), r.pairs.size(),
                  static_cast<unsigned long long>(r.stats.node_pairs), static_cast<unsigned long long>(r.stats.leaf_pairs),
                  static_cast<unsigned long long>(r.stats.tri_pairs),
                  t[t.size() / 2], t.front());
    }
  });
}

}  // namespace st::bench
