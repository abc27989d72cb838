// SPDX-License-Identifier: BSD-3-Clause
// Command-line options shared by every subcommand that loads a mesh (--units, --scale, --keep-winding).
#pragma once
#include <CLI/CLI.hpp>

#include <spheretouch/geom/mesh_io.hpp>

namespace st::app {

/// Adds --units, --scale and --keep-winding to `cmd`, writing into `opts`.
inline void add_load_options(CLI::App* cmd, geom::LoadConfig& opts) {
  cmd->add_option("--units", opts.units, "unit of the file's coordinates: um, mm, cm, m, in (converted to mm)")
      ->capture_default_str();
  cmd->add_option("--scale", opts.scale, "extra scale factor applied after the unit conversion")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag(
      "--keep-winding", [&opts](std::int64_t) { opts.orient = false; },
      "keep the file's face winding (default: made consistent and outward, as the force needs)");
}

/// Loads a mesh or prints the error and throws CLI::RuntimeError(2).
inline geom::LoadedMesh load_or_exit(const std::string& path, const geom::LoadConfig& opts) {
  Result<geom::LoadedMesh> r = geom::load_mesh(path, opts);
  if (!r) {
    std::fprintf(stderr, "spheretouch: %s\n", r.error().c_str());
    throw CLI::RuntimeError(2);
  }
  if (!r.value().report.size_warning.empty())
    std::fprintf(stderr, "spheretouch: %s\n", r.value().report.size_warning.c_str());
  return std::move(r).value();
}

}  // namespace st::app
