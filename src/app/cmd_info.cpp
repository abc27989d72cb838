// SPDX-License-Identifier: BSD-3-Clause
// spheretouch info MESH...: what a mesh file holds and how it was read.
// spheretouch info --scene SCENE: the same for the scene's probe and every object, with each
// object's placement, world bounds and material.
#include <cstdio>

#include "app/commands.hpp"
#include "app/mesh_options.hpp"
#include <spheretouch/engine/scene.hpp>

namespace st::app {
namespace {

struct InfoArgs {
  std::vector<std::string> paths;
  std::string scene;
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
  if (t.shared_corners)
    std::printf(
        " (%zu at the position of another, kept as the file numbers them; one corner to the topology, the "
        "winding and the contact model)",
        t.shared_corners);
  std::printf("\n  bounds      [%.6g, %.6g, %.6g] .. [%.6g, %.6g, %.6g] mm, diagonal %.6g mm\n", b.lo.x(), b.lo.y(),
              b.lo.z(), b.hi.x(), b.hi.y(), b.hi.z(), b.diagonal());
  std::printf("  centre      [%.17g, %.17g, %.17g] mm (body-local origin)\n", m.origin.x(), m.origin.y(), m.origin.z());
  std::printf("  topology    %s, %s (%zu boundary, %zu non-manifold, %zu misoriented edges)\n",
              t.closed() ? "closed" : "open", t.manifold() ? "manifold" : "not manifold", t.boundary_edges,
              t.nonmanifold_edges, t.misoriented_edges);
  const std::string w = geom::describe_winding(r.orientation);
  std::printf("  winding     %s\n", !w.empty()            ? w.c_str()
                                    : r.orientation.parts ? "consistent and outward as read"
                                                          : "as read");
  std::printf("  degenerate  %zu", r.degenerate.size());
  if (!r.degenerate.empty()) {
    std::printf(" (first:");
    for (std::size_t i = 0; i < r.degenerate.size() && i < 5; ++i) std::printf(" %u", r.degenerate[i]);
    std::printf("%s)", r.degenerate.size() > 5 ? " ..." : "");
  }
  std::printf("; policy: %.*s\n", int(geom::DEGENERATE_POLICY.size()), geom::DEGENERATE_POLICY.data());
  std::printf("  load time   %.3f s\n", r.seconds);
}

/// A body of a scene: the file's description (or the generated shape's counts), then `extra`.
int print_scene_body(const engine::BodySpec& b, const std::string& field, const std::string& title) {
  std::printf("%s:\n", title.c_str());
  if (b.builtin.empty()) {
    geom::LoadConfig o;
    o.units = b.units;
    o.scale = b.scale;
    o.orient = b.orient;
    Result<geom::LoadedMesh> r = geom::load_mesh(b.mesh, o);
    if (!r) {
      std::fprintf(stderr, "spheretouch: [%s] %s\n", field.c_str(), r.error().c_str());
      return 1;
    }
    print_info(r.value());
    return 0;
  }
  Result<geom::Mesh> m = engine::load_body(b, field);
  if (!m) {
    std::fprintf(stderr, "spheretouch: %s\n", m.error().c_str());
    return 1;
  }
  const geom::Box bx = m.value().bounds();
  std::printf(
      "%s (generated)\n  faces       %zu\n  vertices    %zu\n  bounds      [%.6g, %.6g, %.6g] .. [%.6g, %.6g, "
      "%.6g] mm\n",
      b.builtin.c_str(), m.value().num_faces(), m.value().num_vertices(), bx.lo.x(), bx.lo.y(), bx.lo.z(), bx.hi.x(),
      bx.hi.y(), bx.hi.z());
  return 0;
}

void scene_info(const std::string& path) {
  Result<engine::Scene> sr = engine::load_scene(path);
  if (!sr) {
    std::fprintf(stderr, "spheretouch: %s\n", sr.error().c_str());
    throw CLI::RuntimeError(2);
  }
  const engine::Scene& s = sr.value();
  int failed = print_scene_body(s.probe, "probe", "probe");
  const std::vector<engine::ObjectSpec> objs = engine::scene_objects(s);
  for (std::size_t k = 0; k < objs.size(); ++k) {
    const engine::ObjectSpec& o = objs[k];
    const std::string field = s.objects.empty() ? "object" : "object[" + std::to_string(k + 1) + "]";
    if (print_scene_body(o.body, field, "object " + std::to_string(k + 1) + " \"" + o.name + "\"")) {
      ++failed;
      continue;
    }
    const geom::Vec3& p = o.placement.position_mm;
    const geom::Vec3& r = o.placement.rotation_deg;
    std::printf("  placement   position [%.6g, %.6g, %.6g] mm, rotation [%.6g, %.6g, %.6g] deg (XYZ)\n", p.x(), p.y(),
                p.z(), r.x(), r.y(), r.z());
    const rt::ForceLawConfig& l = o.material.law;
    if (l.kind == rt::LawKind::linear)
      std::printf("  material    linear law %.6g N/mm", l.spring_N_per_mm);
    else
      std::printf("  material    log law a %.6g, b %.6g N", l.a, l.b_N);
    std::printf(", damping %.6g N s/mm, friction static %.3g dynamic %.3g\n", o.material.damping_N_s_per_mm,
                o.material.friction.static_mu, o.material.friction.dynamic_mu);
  }
  if (failed) throw CLI::RuntimeError(2);
}

}  // namespace

void add_info(CLI::App& app) {
  auto args = std::make_shared<InfoArgs>();
  CLI::App* cmd = app.add_subcommand("info",
                                     "Describe mesh files: faces, vertices, bounds, closed/manifold, "
                                     "degenerate faces, which reader and precision, load time");
  CLI::Option* meshes = cmd->add_option("meshes", args->paths,
                                        "mesh files (.off .obj .ply read in double; .stl .gltf .glb ... via assimp)")
                            ->check(CLI::ExistingFile);
  cmd->add_option("--scene", args->scene,
                  "instead of mesh files: the scene's probe and every object, with placements and materials")
      ->check(CLI::ExistingFile)
      ->excludes(meshes);
  add_load_options(cmd, args->load);
  cmd->callback([args] {
    if (!args->scene.empty()) return scene_info(args->scene);
    if (args->paths.empty()) {
      std::fprintf(stderr, "spheretouch: info: give mesh files, or --scene SCENE\n");
      throw CLI::RuntimeError(2);
    }
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
