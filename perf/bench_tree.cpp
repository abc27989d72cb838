// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench tree MESH...: SphereTree build time (median of N runs), nodes, leaves, layers
// and bytes per face, against the "832,000 faces in at most 1 s" target.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "bench.hpp"
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/sphere_tree.hpp>

namespace st::bench {

void add_tree(CLI::App& app) {
  struct Args {
    std::vector<std::string> paths;
    int runs = 3;
    unsigned leaf = geom::DefaultTreeConfig().leaf_faces;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("tree", "Median wall time to build the sphere tree of each mesh (single thread)");
  cmd->add_option("meshes", a->paths, "mesh files")->required()->check(CLI::ExistingFile);
  cmd->add_option("--runs", a->runs, "builds per mesh")->check(CLI::Range(1, 100))->capture_default_str();
  cmd->add_option("--leaf-faces", a->leaf, "faces per leaf")->check(CLI::Range(1u, geom::kMaxLeafFaces))->capture_default_str();
  cmd->callback([a] {
    for (const std::string& path : a->paths) {
      Result<geom::LoadedMesh> m = geom::load_mesh(path);
      if (!m) {
        std::fprintf(stderr, "%s\n", m.error().c_str());
        throw CLI::RuntimeError(2);
      }
      const geom::Mesh& mesh = m.value().mesh;
      std::vector<double> s;
      std::size_t bytes = 0, nodes = 0, leaves = 0, depths = 0;
      for (int r = 0; r < a->runs; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        Result<geom::SphereTree> t = geom::SphereTree::build(mesh, {a->leaf});
        s.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        if (!t) {
          std::fprintf(stderr, "%s\n", t.error().c_str());
          throw CLI::RuntimeError(2);
        }
        bytes = t.value().bytes();
        nodes = t.value().num_nodes();
        leaves = t.value().num_leaves();
        depths = t.value().num_depths;
      }
      std::sort(s.begin(), s.end());
      std::printf(
          "%-45s %8zu faces leaf %2u: build median %.3f s min %.3f s  nodes %zu leaves %zu layers %zu  %.1f B/face\n",
          path.c_str(), mesh.num_faces(), a->leaf, s[s.size() / 2], s.front(), nodes, leaves, depths,
          double(bytes) / double(mesh.num_faces()));
    }
  });
}

}  // namespace st::bench
