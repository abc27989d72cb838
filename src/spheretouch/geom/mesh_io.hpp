// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Mesh import and export. OFF, OBJ, PLY and STL (ASCII and binary) are read by our own parsers
/// in double precision (correctly rounded std::from_chars), because Debian's assimp rounds to
/// float, and because assimp 5.2.5 crashes on a truncated binary PLY header and leaks on a
/// truncated ASCII STL (found by tests/fuzz); every other format goes through assimp with no
/// post-processing, so face order is kept.
#pragma once
#include <spheretouch/abi.hpp>
#include <string>
#include <string_view>
#include <vector>

#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/orient.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// How a file is turned into a Mesh.
struct LoadConfig {
  double scale = 1.0;        ///< extra factor applied after the unit conversion
  std::string units = "mm";  ///< unit of the file's coordinates: um, mm, cm, m, in
  /// Make the faces' winding consistent and outward (orient_faces(): closed parts face out of
  /// their material, open ones keep their majority's winding), as the contact models read it: a
  /// face wound inward pulls the probe in. false keeps the file's winding.
  bool orient = true;
  // Formats read by assimp (glTF, FBX, ...) are read in a child process, confined and budgeted:
  /// Let the file open other files (a glTF's .bin buffers), but only regular files inside its own
  /// directory. Off: it may open nothing but itself (embedded data: URIs still work).
  bool allow_external_files = false;
  /// Memory assimp may use: this floor plus assimp_memory_per_byte × the input's bytes (the file,
  /// plus its directory's files when allow_external_files). Past it the load is refused.
  std::uint32_t assimp_memory_floor_mb = 512;
  std::uint32_t assimp_memory_per_byte = 64;  ///< bytes of memory per byte of input, on top of the floor
  std::uint32_t assimp_cpu_seconds = 120;     ///< CPU time assimp may take
};

/// What the loader did, for `spheretouch info` and logs.
struct LoadReport {
  std::string reader;                     ///< which path read the file (ours or assimp's importer)
  std::string precision;                  ///< "double" (ours) or "float" (assimp's ai_real)
  std::size_t polygons = 0;               ///< polygons in the file
  std::size_t fanned_polygons = 0;        ///< polygons with more than 3 corners, fan-triangulated
  std::size_t skipped_primitives = 0;     ///< points and lines in the file (not surfaces; ignored)
  std::size_t welded_vertices = 0;        ///< exact duplicate vertices merged (assimp path only)
  std::vector<std::uint32_t> degenerate;  ///< zero-area faces (kept, see DEGENERATE_POLICY)
  OrientReport orientation;               ///< what orient_faces() changed (LoadConfig::orient; else nothing)
  double seconds = 0;                     ///< wall time to read and build the mesh
  /// A size implausible for a touchable object in the units the mesh was read in (a mesh in
  /// metres read as millimetres is 1000x too small): what and which units would fit; else empty.
  std::string size_warning;
};

/// Objects a person touches through a haptic device, in mm: a bounding-box diagonal outside
/// [kPlausibleMinMm, kPlausibleMaxMm] after units and scale earns LoadReport::size_warning.
inline constexpr double kPlausibleMinMm = 1.0;
inline constexpr double kPlausibleMaxMm = 1e5;  ///< 100 m

/// Degenerate (zero-area) faces are kept where they are: they take part in collision as the
/// segment or point they span, and no other face is renumbered.
inline constexpr std::string_view DEGENERATE_POLICY = "kept (tested as the segment or point they span)";

/// A loaded mesh and the report of how it was loaded.
struct LoadedMesh {
  Mesh mesh;          ///< the body, recentred (origin = snapped bounding-box centre)
  LoadReport report;  ///< how it was read
};

/// Factor from `units` to millimetres, or an error naming the unit.
Result<double> unit_to_mm(std::string_view units);

/// Reads any supported mesh file. Face i of the result is the i-th triangle of the file,
/// polygons fan-triangulated in order: (v0, v1, v2), (v0, v2, v3), ...
Result<LoadedMesh> load_mesh(const std::string& path, const LoadConfig& options = {});

/// Parses OFF / OBJ / PLY already in memory; `name` is used in messages.
Result<LoadedMesh> parse_off(std::string_view text, const std::string& name);
Result<LoadedMesh> parse_obj(std::string_view text, const std::string& name);  ///< OBJ text
/// PLY, ASCII or binary (either byte order): vertex x, y, z of any scalar type, faces from the
/// face element's vertex_indices (or vertex_index) list; other elements and properties are skipped.
Result<LoadedMesh> parse_ply(std::string_view text, const std::string& name);

/// STL, binary (recognised by its exact size, 84 + 50 x facets bytes) or ASCII ("solid ...",
/// several solids allowed); exact-duplicate vertices are welded, facets keep file order.
Result<LoadedMesh> parse_stl(std::string_view bytes, const std::string& name);

/// Parses a whole mesh file already in memory, exactly as load_mesh reads a file with extension
/// `ext` (lower case with the dot): ".off", ".obj", ".ply" or ".stl". Other formats go through
/// assimp and may reference companion files, so they are read from a path only (load_mesh).
/// No unit conversion or scaling.
Result<LoadedMesh> parse_mesh(std::string_view bytes, const std::string& ext, const std::string& name);

/// Writes OFF with shortest round-trip doubles (reads back to the same coordinates).
Status write_off(const Mesh& mesh, const std::string& path);
/// Writes the format `path`'s extension names: .off, .ply (ASCII, double) or .obj, shortest
/// round-trip doubles, faces in order (each reads back to the same mesh); any other extension is
/// refused with a message naming it, and nothing is written.
Status write_mesh(const Mesh& mesh, const std::string& path);

/// File extensions the loader accepts (ours and assimp's), lower case with the dot.
std::vector<std::string> supported_extensions();

}  // namespace st::geom
