// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// SphereTree persistence: a versioned little-endian binary file that is read back without
/// rebuilding. A stale file (built from another mesh or other params) and a corrupt one (bad
/// magic, version, size or checksum) are told apart in the error message.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <spheretouch/geom/sphere_tree.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

inline constexpr std::uint32_t kTreeFormatVersion = 1;  ///< bump when the layout or build changes

/// Writes `tree` to `path` (header: magic "STSPHTR1", version, mesh hash, sizes, payload checksum).
Status write_tree(const SphereTree& tree, const std::string& path);

/// Reads a tree written by write_tree for `mesh` built with `params`. Errors: "corrupt: ..." (magic,
/// version, size, checksum, structure) or "stale: ..." (mesh/params hash differs).
Result<SphereTree> read_tree(const std::string& path, const Mesh& mesh, const TreeConfig& params = DefaultTreeConfig());
/// read_tree on a file's bytes already in memory; `path` names it in messages.
Result<SphereTree> parse_tree(std::span<const std::uint8_t> bytes, const std::string& path, const Mesh& mesh,
                              const TreeConfig& params = DefaultTreeConfig());
/// For the tree-cache fuzzer: rewrites the header of a tree file's bytes so that it names `mesh`
/// and `params` and its checksum matches its payload, as an attacker who can write the cache
/// file can (neither is cryptographic). What stays is the structure check, which must refuse
/// every tree collide() cannot walk safely and exactly.
void seal_tree_bytes(std::vector<std::uint8_t>& bytes, const Mesh& mesh, const TreeConfig& params = DefaultTreeConfig());

}  // namespace st::geom
