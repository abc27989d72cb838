// SPDX-License-Identifier: BSD-3-Clause
// spheretouch build MESH [-o FILE]: build a mesh's sphere tree and write it to a versioned file
// that later runs read instead of rebuilding (default: the tree cache).
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "app/commands.hpp"
#include "app/mesh_options.hpp"
#include <spheretouch/engine/tree_cache.hpp>
#include <spheretouch/geom/tree_io.hpp>

namespace st::app {

using engine::default_tree_cache_dir;
using engine::tree_cache_path;

void add_build(CLI::App& app) {
  struct Args {
    std::string mesh, out;
    geom::LoadConfig load;
    std::uint32_t leaf_faces = geom::DefaultTreeConfig().leaf_faces;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("build",
                                     "Build a mesh's layered boundary spheres and write them to a tree file "
                                     "(magic, version, mesh+parameter hash, checksum)");
  cmd->add_option("mesh", a->mesh, "mesh file")->required()->check(CLI::ExistingFile);
  cmd->add_option("-o,--out", a->out, "tree file to write (default: the tree cache, " + default_tree_cache_dir() + ")");
  add_load_options(cmd, a->load);
  cmd->add_option("--leaf-faces", a->leaf_faces, "faces per leaf sphere")
      ->check(CLI::Range(1u, geom::kMaxLeafFaces))
      ->capture_default_str();
  cmd->callback([a] {
    const geom::LoadedMesh lm = load_or_exit(a->mesh, a->load);
    geom::TreeConfig params = geom::DefaultTreeConfig();
    params.leaf_faces = a->leaf_faces;
    const auto t0 = std::chrono::steady_clock::now();
    Result<geom::SphereTree> tree = geom::SphereTree::build(lm.mesh, params);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!tree) {
      std::fprintf(stderr, "spheretouch: %s\n", tree.error().c_str());
      throw CLI::RuntimeError(2);
    }
    std::string out = a->out;
    if (out.empty()) {
      const std::string dir = default_tree_cache_dir();
      std::error_code ec;
      std::filesystem::create_directories(dir, ec);
      out = tree_cache_path(dir, lm.mesh, params);
    }
    if (Status s = geom::write_tree(tree.value(), out); !s) {
      std::fprintf(stderr, "spheretouch: %s\n", s.error().c_str());
      throw CLI::RuntimeError(2);
    }
    const geom::SphereTree& t = tree.value();
    std::printf("%s: %u faces, %u nodes, %u leaves, %u layers, %.1f bytes/face, built in %.3f s -> %s\n",
                a->mesh.c_str(), t.num_faces(), t.num_nodes(), t.num_leaves(), t.num_depths,
                double(t.bytes()) / t.num_faces(), secs, out.c_str());
  });
}

}  // namespace st::app
