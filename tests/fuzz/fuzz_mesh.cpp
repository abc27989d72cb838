// SPDX-License-Identifier: BSD-3-Clause
// libFuzzer target: the mesh importer (geom/mesh_io.hpp) on whole files in memory, through
// parse_mesh, the same dispatch load_mesh uses. The first input byte picks the format (low two
// bits: 0 OFF, 1 OBJ, 2 PLY: ASCII by our reader, binary by assimp, chosen by content as for a
// file, 3 STL ASCII or binary by assimp); the rest is the file.
// A mesh that loads must be usable without further checks: at least one face, every index in
// range, every coordinate finite (relative to the origin and absolute), degenerate faces listed
// ascending and in range, validate() passing.
#include <cstdint>
#include <string>
#include <string_view>

#include "fuzz_check.hpp"
#include <spheretouch/geom/mesh_io.hpp>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static const std::string kExt[4] = {".off", ".obj", ".ply", ".stl"};
  const std::string& ext = kExt[data[0] & 3];
  const std::string_view bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  st::Result<st::geom::LoadedMesh> r = st::geom::parse_mesh(bytes, ext, "fuzz" + ext);
  if (!r) {
    ST_FUZZ_CHECK(!r.error().empty(), "a refusal says why");
    return 0;
  }
  const st::geom::Mesh& m = r.value().mesh;
  const st::geom::LoadReport& rep = r.value().report;
  ST_FUZZ_CHECK(!m.faces.empty(), "a loaded mesh has faces");
  ST_FUZZ_CHECK(m.origin.allFinite(), "origin finite");
  for (const st::geom::Vec3& v : m.local) {
    ST_FUZZ_CHECK(v.allFinite(), "local coordinates finite");
    ST_FUZZ_CHECK((m.origin + v).allFinite(), "absolute coordinates finite");
  }
  for (const st::geom::Tri& f : m.faces)
    for (std::uint32_t i : f) ST_FUZZ_CHECK(i < m.local.size(), "vertex index in range");
  for (std::size_t i = 0; i < rep.degenerate.size(); ++i) {
    ST_FUZZ_CHECK(rep.degenerate[i] < m.faces.size(), "degenerate face index in range");
    ST_FUZZ_CHECK(i == 0 || rep.degenerate[i] > rep.degenerate[i - 1], "degenerate faces ascending");
  }
  ST_FUZZ_CHECK(rep.polygons >= 1 && rep.polygons <= m.faces.size(), "polygon count");
  ST_FUZZ_CHECK(m.validate().ok(), "validate() accepts what the loader returned");
  return 0;
}
