// SphereTree persistence: a versioned little-endian binary file that is read back without
// rebuilding. A stale file (built from another mesh or other params) and a corrupt one (bad
// magic, version, size or checksum) are told apart in the error message.
#pragma once
#include <cstdint>
#include <string>

#include "geom/sphere_tree.hpp"

namespace st::geom {

inline constexpr std::uint32_t kTreeFormatVersion = 1;  ///< bump when the layout or build changes

/// Writes `tree` to `path` (header: magic "STSPHTR1", version, mesh hash, sizes, payload checksum).
Status write_tree(const SphereTree& tree, const std::string& path);

/// Reads a tree written by write_tree for `mesh` built with `params`. Errors: "corrupt: ..." (magic,
/// version, size, checksum, structure) or "stale: ..." (mesh/params hash differs).
Result<SphereTree> read_tree(const std::string& path, const Mesh& mesh, const TreeParams& params = DefaultTreeParams());

}  // namespace st::geom
