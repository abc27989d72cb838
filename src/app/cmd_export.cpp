// SPDX-License-Identifier: BSD-3-Clause
// spheretouch export IN -o OUT.{off,ply,obj}: convert, rescale and Loop-subdivide a mesh (the model set
// is built with it: scripts/models.sh).
#include <cmath>
#include <cstdio>

#include "app/commands.hpp"
#include "app/mesh_options.hpp"
#include <spheretouch/geom/subdivide.hpp>

namespace st::app {
namespace {

struct ExportArgs {
  std::string in, out;
  geom::LoadConfig load;
  double diagonal_mm = 0;
  int levels = 0;
};

}  // namespace

void add_export(CLI::App& app) {
  auto a = std::make_shared<ExportArgs>();
  CLI::App* cmd = app.add_subcommand(
      "export",
      "Write a mesh as OFF, PLY or OBJ (by the output's extension; double precision, face order kept), "
      "optionally rescaled and Loop-subdivided");
  cmd->add_option("mesh", a->in, "input mesh")->required()->check(CLI::ExistingFile);
  cmd->add_option("-o,--out", a->out, "output mesh: .off, .ply (ASCII) or .obj, by its extension")->required();
  add_load_options(cmd, a->load);
  cmd->add_option("--diagonal", a->diagonal_mm,
                  "scale the input so its bounding-box diagonal is this many mm (before subdividing, so every "
                  "level of a model shares one frame)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--subdivide", a->levels, "Loop subdivision levels (each level: 4x faces); needs a closed manifold")
      ->check(CLI::Range(0, 6));
  cmd->callback([a] {
    geom::LoadedMesh lm = load_or_exit(a->in, a->load);
    geom::Mesh mesh = std::move(lm.mesh);
    if (a->diagonal_mm > 0) {
      const double d = mesh.bounds().diagonal();
      if (!(d > 0)) {
        std::fprintf(stderr, "spheretouch: %s: bounding-box diagonal is 0, cannot scale to %g mm\n", a->in.c_str(),
                     a->diagonal_mm);
        throw CLI::RuntimeError(2);
      }
      mesh.scale(a->diagonal_mm / d);
      mesh.recentre();
    }
    for (int l = 1; l <= a->levels; ++l) {
      std::fprintf(stderr, "subdividing %s: level %d of %d (%zu -> %zu faces)\n", a->in.c_str(), l, a->levels,
                   mesh.num_faces(), 4 * mesh.num_faces());
      Result<geom::Mesh> r = geom::loop_subdivide(mesh, 1);
      if (!r) {
        std::fprintf(stderr, "spheretouch: %s\n", r.error().c_str());
        throw CLI::RuntimeError(2);
      }
      mesh = std::move(r).value();
    }
    if (Status s = geom::write_mesh(mesh, a->out); !s) {
      std::fprintf(stderr, "spheretouch: %s\n", s.error().c_str());
      throw CLI::RuntimeError(2);
    }
    std::fprintf(stderr, "wrote %s: %zu faces, %zu vertices, diagonal %.6g mm\n", a->out.c_str(), mesh.num_faces(),
                 mesh.num_vertices(), mesh.bounds().diagonal());
  });
}

}  // namespace st::app
