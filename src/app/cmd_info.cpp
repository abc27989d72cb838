// SPDX-License-Identifier: BSD-3-Clause
// spheretouch info MESH...: what a mesh file holds and how it was read.
#include <cstdio>

#include "app/commands.hpp"
#include "app/mesh_options.hpp"

namespace st::app {
namespace {

struct InfoArgs {
  std::vector<std::string> paths;
  geom::LoadConfig load;
};

void print_info(const geom::LoadedMesh& lm) {
  const geom::Mesh& m = lm.mesh;
  const geom::LoadReport& r = lm.report;
  const geom::Box b = m.bounds();
  const geom::Topology t = m.topology();
  std::printf("%s\n", m.name.c_str());
  std::printf("  reader      %s; precision %s\n", r.reader.c_str(), r.precision.c_str());
  std::printf("  faces       %zu (from %zu polygons, %zu fan-triangulated", m.num_faces(), r.polygons, r.fanned_polygons);
  if (r.skipped_primitives) std::printf(", %zu points/lines ignored", r.skipped_primitives);
  std::printf(")\n  vertices    %zu", m.num_vertices());
  if (r.welded_vertices) std::printf(" (%zu exact duplicates welded)", r.welded_vertices);
  std::printf("\n  bounds      [%.6g, %.6g, %.6g] .. [%.6g, %.6g, %.6g] mm, diagonal %.6g mm\n", b.lo.x(), b.lo.y(),
              b.lo.z(), b.hi.x(), b.hi.y(), b.hi.z(), b.diagonal());
  std::printf("  centre      [%.17g, %.17g, %.17g] mm (body-local origin)\n", m.origin.x(), m.origin.y(), m.origin.z());
  std::printf("  topology    %s, %s (%zu boundary, %zu non-manifold, %zu misoriented edges)\n",
              t.closed() ? "closed" : "open", t.manifold() ? "manifold" : "not manifold", t.boundary_edges,
              t.nonmanifold_edges, t.misoriented_edges);
  std::printf("  degenerate  %zu", r.degenerate.size());
  if (!r.degenerate.empty()) {
    std::printf(" (first:");
    for (std::size_t i = 0; i < r.degenerate.size() && i < 5; ++i) std::printf(" %u", r.degenerate[i]);
    std::printf("%s)", r.degenerate.size() > 5 ? " ..." : "");
  }
  std::printf("; policy: %.*s\n", int(geom::DEGENERATE_POLICY.size()), geom::DEGENERATE_POLICY.data());
  std::printf("  load time   %.3f s\n", r.seconds);
}

}  // namespace

void add_info(CLI::App& app) {
  auto args = std::make_shared<InfoArgs>();
  CLI::App* cmd = app.add_subcommand("info",
                                     "Describe mesh files: faces, vertices, bounds, closed/manifold, "
                                     "degenerate faces, which reader and precision, load time");
  cmd->add_option("meshes", args->paths, "mesh files (.off .obj .ply read in double; .stl .gltf .glb ... via assimp)")
      ->required()
      ->check(CLI::ExistingFile);
  add_load_options(cmd, args->load);
  cmd->callback([args] {
    int failed = 0;
    for (const std::string& p : args->paths) {
      Result<geom::LoadedMesh> r = geom::load_mesh(p, args->load);
      if (!r) {
        std::fprintf(stderr, "spheretouch: %s\n", r.error().c_str());
        ++failed;
        continue;
      }
      print_info(r.value());
      std::fflush(stdout);
      if (!r.value().report.size_warning.empty())
        std::fprintf(stderr, "spheretouch: %s\n", r.value().report.size_warning.c_str());
    }
    if (failed) throw CLI::RuntimeError(2);
  });
}

}  // namespace st::app
