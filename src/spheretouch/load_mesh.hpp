// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// <spheretouch/load_mesh.hpp>: a mesh file as a Mesh for Body::make. Link `spheretouch-meshio`
/// (pkg-config; CMake spheretouch::meshio): OFF, OBJ, PLY and STL are read by the project's own
/// double-precision readers, other formats through assimp (a confined child process) when the
/// library was built with it. Face i of the Mesh is the file's i-th triangle (polygons
/// fan-triangulated in file order).
#pragma once
#include <spheretouch/abi.hpp>
#include <string>

#include <spheretouch/collide.hpp>
#include <spheretouch/geom/mesh_io.hpp>

namespace st {
inline namespace SPHERETOUCH_ABI {

using geom::LoadConfig;

/// Reads `path` as `options` say (units, scale, assimp's budget). The error names the file and
/// the line, face or field at fault. A size implausible for its units is loaded anyway; use
/// geom::load_mesh for the LoadReport that says so.
Result<Mesh> load_mesh(const std::string& path, const LoadConfig& options = {});

}  // namespace SPHERETOUCH_ABI
}  // namespace st
