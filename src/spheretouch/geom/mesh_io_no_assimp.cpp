// SPDX-License-Identifier: BSD-3-Clause
// Mesh I/O built without assimp (-Dassimp=disabled, or a core-only build): the project's own
// double-precision readers (OFF, OBJ, PLY, STL) are all there is; any other format is refused
// with a message saying why, instead of the importer list mesh_io_assimp.cpp would consult.
#include <spheretouch/geom/mesh_io_detail.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

Result<LoadedMesh> detail::load_with_assimp(const std::string& path, const LoadConfig&) {
  return fail(path,
              ": this spheretouch was built without assimp (meson -Dassimp=disabled): only .off, .obj, .ply "
              "and .stl are read; convert the mesh, or rebuild with libassimp-dev");
}

// Every other extension would be assimp's: load_with_assimp() then says it is not built in.
bool detail::assimp_reads(const std::string& ext) { return !ext.empty(); }

std::vector<std::string> supported_extensions() { return {".off", ".obj", ".ply", ".stl"}; }

}  // namespace st::geom
