// SPDX-License-Identifier: BSD-3-Clause
// st::load_mesh (load_mesh.hpp): geom::load_mesh's mesh, without its report.
#include <spheretouch/load_mesh.hpp>

namespace st {
inline namespace SPHERETOUCH_ABI {

Result<Mesh> load_mesh(const std::string& path, const LoadConfig& options) {
  Result<geom::LoadedMesh> r = geom::load_mesh(path, options);
  if (!r) return Error{r.error()};
  return std::move(r).value().mesh;
}

}  // namespace SPHERETOUCH_ABI
}  // namespace st
