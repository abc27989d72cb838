// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench collide: exact collide() query time (median of --runs, warm scratch, single
// thread) of a probe against an object at the poses of a pose file, with contacts and counters;
// --find-poses writes such a file with poses near given contact counts (fingertip pushed into the
// object's surface along the normal, depth found by bisection).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "bench.hpp"
#include "bench_json.hpp"
#ifdef ST_HAVE_FCL
#include "fcl_peer.hpp"
#endif
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/simd.hpp>
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/pose_io.hpp>
#include <spheretouch/geom/sphere_tree.hpp>

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
      if (c >= target)
        hi = mid;
      else
        lo = mid;
      if (std::abs(double(c) - target) <= 0.1 * target) {
        out = fingertip_pose(s.probe, s.object, vo, normal, mid);
        got = c;
        return true;
      }
    }
  }
  return false;
}

std::vector<std::pair<Pose, std::string>> read_poses(const std::string& path) {
  Result<std::vector<geom::PoseLine>> lines = geom::read_pose_lines(path);
  if (!lines) {
    std::fprintf(stderr, "%s\n", lines.error().c_str());
    throw CLI::RuntimeError(2);
  }
  std::vector<std::pair<Pose, std::string>> out;
  for (geom::PoseLine& l : lines.value()) out.emplace_back(l.pose, std::move(l.comment));
  return out;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// One pose's figures (times in microseconds).
struct PoseRow {
  std::string comment;
  std::uint32_t contacts = 0;
  std::size_t pairs = 0;
  geom::CollideStats stats;
  double p50_us = 0, p95_us = 0, min_us = 0;
  /// The same query without the triangle filter (every candidate through the exact test: the path
  /// before it), timed in alternating blocks with the one above; and whether its pairs are the same.
  double base_p50_us = 0, base_p95_us = 0, base_min_us = 0;
  bool base_same = true;
  bool fcl = false;
  double fcl_p50_us = 0, fcl_p95_us = 0, fcl_min_us = 0;
  std::size_t fcl_pairs = 0, only_ours = 0, only_fcl = 0;
  std::vector<std::string> diffs;  ///< first few disagreements, with FCL's triangle distance
};

}  // namespace

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

void use_isa(const std::string& name) {
  if (name.empty()) return;
  geom::simd::Isa isa;
  if (!geom::simd::parse_isa(name, isa)) {
    std::fprintf(stderr, "--isa %s: expected scalar, sse2, avx2 or avx512\n", name.c_str());
    throw CLI::RuntimeError(2);
  }
  if (!geom::simd::set_isa(isa)) {
    std::fprintf(stderr, "--isa %s: this CPU or build has at most %s\n", name.c_str(),
                 geom::simd::isa_name(geom::simd::best_isa()));
    throw CLI::RuntimeError(2);
  }
}

geom::Mesh load_mesh_or_exit(const std::string& path) {
  auto m = geom::load_mesh(path);
  if (!m) {
    std::fprintf(stderr, "%s\n", m.error().c_str());
    throw CLI::RuntimeError(2);
  }
  return std::move(m.value().mesh);
}

void add_collide(CLI::App& app) {
  struct Args {
    std::string probe, object, poses, find_out, build_mesh, targets = "100,500,1000,1500";
    int runs = 200;
    unsigned leaf = geom::DefaultTreeConfig().leaf_faces;
    std::uint64_t seed = 1;
    bool fcl = false, json = false;
    std::string isa;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd =
      app.add_subcommand("collide", "Exact collide() median query time at the poses of a pose file (single thread)");
  cmd->add_option("--probe", a->probe, "probe mesh (the hand)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--object", a->object, "object mesh")->required()->check(CLI::ExistingFile);
  cmd->add_option("--poses", a->poses, "pose file to time (16 numbers a line)");
  cmd->add_option("--find-poses", a->find_out, "write a pose file with poses near --targets contacts");
  cmd->add_option("--targets", a->targets, "contact counts for --find-poses")->capture_default_str();
  cmd->add_option("--seed", a->seed, "site choice for --find-poses")->capture_default_str();
  cmd->add_option("--runs", a->runs, "queries per pose")->check(CLI::Range(1, 100000))->capture_default_str();
  cmd->add_option("--leaf-faces", a->leaf, "faces per leaf (both trees)")
      ->check(CLI::Range(1u, geom::kMaxLeafFaces))
      ->capture_default_str();
  cmd->add_flag("--fcl", a->fcl,
                "also time FCL 0.7 (BVHModel<OBBRSS>, all contacts) on the same poses and compare pair sets");
  cmd->add_option("--build-mesh", a->build_mesh, "also time our tree build and FCL's OBBRSS build of this mesh")
      ->check(CLI::ExistingFile);
  cmd->add_flag("--json", a->json, "print one JSON object instead of the table");
  cmd->add_option("--isa", a->isa,
                  "run the SIMD kernels on this instruction set (scalar, sse2, avx2, avx512; default: the best the CPU "
                  "has, or ST_SIMD)");
  cmd->callback([a] {
    use_isa(a->isa);
#ifndef ST_HAVE_FCL
    if (a->fcl || !a->build_mesh.empty()) {
      std::fprintf(stderr, "--fcl/--build-mesh: this spheretouch-bench was built without FCL (libfcl-dev)\n");
      throw CLI::RuntimeError(2);
    }
#endif
    Scene s;
    s.probe = load_mesh_or_exit(a->probe);
    s.object = load_mesh_or_exit(a->object);
    auto t0 = std::chrono::steady_clock::now();
    s.pt = geom::SphereTree::build(s.probe, {a->leaf}).value();
    const double probe_build_s = seconds_since(t0);
    t0 = std::chrono::steady_clock::now();
    s.ot = geom::SphereTree::build(s.object, {a->leaf}).value();
    const double object_build_s = seconds_since(t0);
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
    if (a->poses.empty() && a->build_mesh.empty()) return;

    // Build of a large mesh (832,000 faces in at most 1 s), ours vs FCL's OBBRSS.
    double big_build_s = 0, big_fcl_build_s = 0, big_bytes_per_face = 0;
    std::size_t big_faces = 0;
    if (!a->build_mesh.empty()) {
      auto m = geom::load_mesh(a->build_mesh);
      if (!m) {
        std::fprintf(stderr, "%s\n", m.error().c_str());
        throw CLI::RuntimeError(2);
      }
      const geom::Mesh& big = m.value().mesh;
      big_faces = big.num_faces();
      std::vector<double> bs;
      for (int r = 0; r < 3; ++r) {
        t0 = std::chrono::steady_clock::now();
        const geom::SphereTree t = geom::SphereTree::build(big, {a->leaf}).value();
        bs.push_back(seconds_since(t0));
        big_bytes_per_face = double(t.bytes()) / double(big_faces);
      }
      big_build_s = *std::min_element(bs.begin(), bs.end());
#ifdef ST_HAVE_FCL
      big_fcl_build_s = fcl_build_seconds(big);
#endif
    }

    std::vector<PoseRow> rows;
    double fcl_build_s = 0;
    std::size_t scratch_bytes = 0;
    if (!a->poses.empty()) {
#ifdef ST_HAVE_FCL
      std::unique_ptr<FclPeer> peer;
      if (a->fcl) {
        peer = std::make_unique<FclPeer>(s.probe, s.object);
        fcl_build_s = peer->build_seconds();
      }
#endif
      geom::CollideScratch sc;
      geom::CollideResult r;
      for (const auto& [pose, comment] : read_poses(a->poses)) {
        PoseRow row;
        row.comment = comment;
        std::vector<double> ours, base, theirs;
        ours.reserve(a->runs);
        base.reserve(a->runs);
        geom::CollideConfig no_filter;
        no_filter.tri_filter = false;
        geom::CollideResult rb;
        geom::collide(s.probe, s.pt, s.object, s.ot, pose, no_filter, sc, rb);  // warm
        geom::collide(s.probe, s.pt, s.object, s.ot, pose, {}, sc, r);
        // Ours and FCL's in alternating blocks of 10 queries, so a change of machine load during
        // the run affects both alike while each still runs warm, back to back.
        for (int done = 0; done < a->runs;) {
          const int block = std::min(10, a->runs - done);
          for (int i = 0; i < block; ++i) {
            t0 = std::chrono::steady_clock::now();
            geom::collide(s.probe, s.pt, s.object, s.ot, pose, {}, sc, r);
            ours.push_back(1e6 * seconds_since(t0));
          }
          for (int i = 0; i < block; ++i) {
            t0 = std::chrono::steady_clock::now();
            geom::collide(s.probe, s.pt, s.object, s.ot, pose, no_filter, sc, rb);
            base.push_back(1e6 * seconds_since(t0));
          }
#ifdef ST_HAVE_FCL
          for (int i = 0; peer && i < block; ++i) {
            double q = 0;
            (void)peer->collide(pose, &q);
            theirs.push_back(1e6 * q);
          }
#endif
          done += block;
        }
        row.contacts = r.contacts();
        row.pairs = r.pairs.size();
        row.stats = r.stats;
        row.p50_us = percentile(ours, 0.5);
        row.p95_us = percentile(ours, 0.95);
        row.min_us = percentile(ours, 0.0);
        row.base_p50_us = percentile(base, 0.5);
        row.base_p95_us = percentile(base, 0.95);
        row.base_min_us = percentile(base, 0.0);
        {
          geom::CollideConfig o = no_filter;
          o.sort_pairs = true;
          geom::CollideResult sorted_base, sorted;
          geom::collide(s.probe, s.pt, s.object, s.ot, pose, o, sc, sorted_base);
          o.tri_filter = true;
          geom::collide(s.probe, s.pt, s.object, s.ot, pose, o, sc, sorted);
          row.base_same = sorted.pairs == sorted_base.pairs;
        }
#ifdef ST_HAVE_FCL
        if (peer) {
          row.fcl = true;
          row.fcl_p50_us = percentile(theirs, 0.5);
          row.fcl_p95_us = percentile(theirs, 0.95);
          row.fcl_min_us = percentile(theirs, 0.0);
          const auto fp = peer->collide(pose);
          geom::CollideConfig o;
          o.sort_pairs = true;
          geom::collide(s.probe, s.pt, s.object, s.ot, pose, o, sc, r);
          row.fcl_pairs = fp.size();
          std::size_t i = 0, j = 0;
          auto note = [&, &at = pose](const char* who, std::uint32_t pf, std::uint32_t of) {  // clang < 16: no binding captures
            if (row.diffs.size() >= 5) return;
            char buf[160];
            std::snprintf(buf, sizeof buf, "only %s: probe %u object %u (FCL tri distance %.3g mm)", who, pf, of,
                          peer->tri_distance(at, pf, of));
            row.diffs.emplace_back(buf);
          };
          while (i < r.pairs.size() || j < fp.size()) {
            const bool take_ours =
                j == fp.size() || (i < r.pairs.size() && std::pair{r.pairs[i].probe, r.pairs[i].object} < fp[j]);
            const bool take_fcl =
                i == r.pairs.size() || (j < fp.size() && fp[j] < std::pair{r.pairs[i].probe, r.pairs[i].object});
            if (take_ours) {
              ++row.only_ours;
              note("ours", r.pairs[i].probe, r.pairs[i].object);
              ++i;
            } else if (take_fcl) {
              ++row.only_fcl;
              note("FCL", fp[j].first, fp[j].second);
              ++j;
            } else {
              ++i;
              ++j;
            }
          }
        }
#endif
        rows.push_back(std::move(row));
      }
      scratch_bytes = sc.bytes();
    }

    const double bpf_probe = double(s.pt.bytes()) / double(s.probe.num_faces());
    const double bpf_object = double(s.ot.bytes()) / double(s.object.num_faces());
    if (a->json) {
      Json build = {{"probe_s", round_to(probe_build_s, 4)},
                    {"object_s", round_to(object_build_s, 4)},
                    {"probe_bytes_per_face", round_to(bpf_probe, 1)},
                    {"object_bytes_per_face", round_to(bpf_object, 1)},
                    {"scratch_bytes", scratch_bytes},
                    {"fcl_both_s", round_to(fcl_build_s, 4)}};
      if (!a->build_mesh.empty()) {
        build["big_mesh"] = a->build_mesh;
        build["big_faces"] = big_faces;
        build["big_s"] = round_to(big_build_s, 4);
        build["big_bytes_per_face"] = round_to(big_bytes_per_face, 1);
        build["big_fcl_s"] = round_to(big_fcl_build_s, 4);
      }
      Json poses = Json::array();
      for (const PoseRow& w : rows) {
        Json p = {{"contacts", w.contacts},
                  {"pairs", w.pairs},
                  {"p50_us", round_to(w.p50_us, 2)},
                  {"p95_us", round_to(w.p95_us, 2)},
                  {"min_us", round_to(w.min_us, 2)},
                  {"node_pairs", w.stats.node_pairs},
                  {"leaf_pairs", w.stats.leaf_pairs},
                  {"tri_tests", w.stats.tri_pairs},
                  {"tri_exact", w.stats.tri_exact},
                  {"base_p50_us", round_to(w.base_p50_us, 2)},
                  {"base_p95_us", round_to(w.base_p95_us, 2)},
                  {"base_min_us", round_to(w.base_min_us, 2)},
                  {"filter_ratio", round_to(w.p50_us / w.base_p50_us, 4)},
                  {"filter_same_pairs", w.base_same}};
        if (w.fcl) {
          p["fcl_p50_us"] = round_to(w.fcl_p50_us, 2);
          p["fcl_p95_us"] = round_to(w.fcl_p95_us, 2);
          p["fcl_min_us"] = round_to(w.fcl_min_us, 2);
          p["ratio"] = round_to(w.p50_us / w.fcl_p50_us, 4);
          p["fcl_pairs"] = w.fcl_pairs;
          p["only_ours"] = w.only_ours;
          p["only_fcl"] = w.only_fcl;
        }
        poses.push_back(std::move(p));
      }
      print_json({{"probe", a->probe},
                  {"object", a->object},
                  {"probe_faces", s.probe.num_faces()},
                  {"object_faces", s.object.num_faces()},
                  {"leaf_faces", a->leaf},
                  {"runs", a->runs},
                  {"isa", geom::simd::isa_name(geom::simd::active_isa())},
                  {"build", std::move(build)},
                  {"poses", std::move(poses)}});
      return;
    }
    std::printf(
        "leaf_faces %u; probe %zu faces (tree %.3f s, %.1f B/face), object %zu faces (tree %.3f s, %.1f B/face)",
        a->leaf, s.probe.num_faces(), probe_build_s, bpf_probe, s.object.num_faces(), object_build_s, bpf_object);
    if (a->fcl) std::printf("; FCL OBBRSS build of both %.3f s", fcl_build_s);
    std::printf("; %d runs per pose; query scratch %.1f MB; SIMD %s\n", a->runs, double(scratch_bytes) / 1e6,
                geom::simd::isa_name(geom::simd::active_isa()));
    if (!rows.empty()) {
      std::printf("%8s %8s %10s %10s %10s %9s %9s %9s %9s %9s %7s %5s", "contacts", "pairs", "node_pairs", "leaf_pairs",
                  "tri_tests", "tri_exact", "p50_ms", "p95_ms", "min_ms", "base_p50", "filter", "same");
      if (a->fcl)
        std::printf(" %9s %9s %7s %9s %9s %8s", "fcl_p50", "fcl_min", "ratio", "fcl_pairs", "only_ours", "only_fcl");
      std::printf("\n");
    }
    for (const PoseRow& w : rows) {
      std::printf("%8u %8zu %10llu %10llu %10llu %9llu %9.4f %9.4f %9.4f %9.4f %7.3f %5s", w.contacts, w.pairs,
                  static_cast<unsigned long long>(w.stats.node_pairs),
                  static_cast<unsigned long long>(w.stats.leaf_pairs), static_cast<unsigned long long>(w.stats.tri_pairs),
                  static_cast<unsigned long long>(w.stats.tri_exact), w.p50_us / 1e3, w.p95_us / 1e3, w.min_us / 1e3,
                  w.base_p50_us / 1e3, w.p50_us / w.base_p50_us, w.base_same ? "yes" : "NO");
      if (w.fcl)
        std::printf(" %9.4f %9.4f %7.3f %9zu %9zu %8zu", w.fcl_p50_us / 1e3, w.fcl_min_us / 1e3,
                    w.p50_us / w.fcl_p50_us, w.fcl_pairs, w.only_ours, w.only_fcl);
      std::printf("\n");
      for (const std::string& d : w.diffs) std::printf("           %s\n", d.c_str());
    }
    if (!a->build_mesh.empty())
      std::printf("build %s (%zu faces): ours %.3f s (min of 3, %.1f B/face), FCL OBBRSS %.3f s (1 run)\n",
                  a->build_mesh.c_str(), big_faces, big_build_s, big_bytes_per_face, big_fcl_build_s);
  });
}

}  // namespace st::bench
