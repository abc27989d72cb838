// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// BlockSet: what one worker needs in memory to answer queries (paper §3.4) — self-contained
/// geometry, not tree internals. The whole probe mesh, plus the worker's share of the object:
/// the faces of its blocks (block-cyclic over the object's layer-n spheres) with their GLOBAL
/// face indices and only the vertices they use, and the tree parameters the worker builds its own
/// sphere tree with. Exact results do not depend on the tree's shape, so the union of the
/// workers' pairs equals the single-process result. The canonical encoding is hashed (BLAKE2b)
/// to address block sets by content: a worker that already holds a hash is not sent it again.
#pragma once
#include <spheretouch/abi.hpp>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/partition.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/net/protocol.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// One worker's share of the work, as geometry.
struct BlockSet {
  /// The scene object it is a share of (0: the first, or only, object); < Limits::max_objects.
  /// Part of the content: the same geometry as two objects makes two sets.
  std::uint32_t object_id = 0;
  std::uint32_t leaf_faces = geom::DefaultTreeConfig().leaf_faces;  ///< sphere-tree leaf size the worker builds with
  std::uint32_t object_faces_total = 0;        ///< faces of the whole object (global ids are below it)
  std::uint32_t blocks_total = 0;              ///< blocks in the whole partition
  std::vector<std::uint32_t> blocks;           ///< global block ids held, strictly ascending
  geom::Mesh probe;                            ///< the whole probe: origin, local vertices, faces
  geom::Mesh object;                           ///< the share: object origin, used vertices, faces into them
  std::vector<std::uint32_t> object_face_ids;  ///< global index of each share face: by block, ascending within one
  std::vector<std::uint32_t> block_faces;      ///< share faces of each held block (same order as `blocks`)
};

/// The object's faces grouped in blocks (global face ids per block); block b of the sphere
/// tree's layer n becomes blocks[b].
using Blocks = std::vector<std::vector<std::uint32_t>>;

/// Builds the block set of `block_ids` (any order, no duplicates): their faces block by block
/// (blocks ascending, each block's faces in ascending global order; a face listed by an earlier
/// block too is kept there only), the object vertices they use in ascending original order, the
/// whole probe. The worker builds one subtree per block (SphereTree::build's groups).
Result<BlockSet> make_block_set(const geom::Mesh& probe, const geom::Mesh& object, const Blocks& blocks,
                                std::span<const std::uint32_t> block_ids, std::uint32_t leaf_faces,
                                std::uint32_t object_id = 0);

/// Canonical little-endian encoding ("STBS" v3: v1 plus the faces per block, the share's faces
/// grouped by block; v3 the object id in v2's reserved u16); equal block sets give equal bytes.
std::vector<std::uint8_t> encode_block_set(const BlockSet& s);
/// Content digest of an encoding: BLAKE2b-256 (libsodium's crypto_generichash) over every byte.
using Digest = std::array<std::uint8_t, 32>;
/// Content digest of an encoding: BLAKE2b-256 over every byte.
Digest block_set_digest(std::span<const std::uint8_t> encoded);
/// The key a block set is named by on the wire: the digest's first 8 bytes, little-endian. A
/// second set with a given key costs ~2^64 BLAKE2b evaluations to find (FNV-1a, used before,
/// could be matched in microseconds).
std::uint64_t block_set_hash(std::span<const std::uint8_t> encoded);
std::uint64_t digest_key(const Digest& d);  ///< the key of a digest (block_set_hash's value)
/// Decodes and validates an encoding: counts against `limits`, every face index in range,
/// ids strictly ascending and below their totals, every coordinate finite.
Result<BlockSet> decode_block_set(std::span<const std::uint8_t> encoded, const Limits& limits);

/// The blocks of each worker, dealt by `mapping` (geom::block_owners), ascending in each list.
std::vector<std::vector<std::uint32_t>> deal_blocks(std::uint32_t num_blocks, std::uint32_t workers,
                                                    geom::Mapping mapping, std::uint64_t seed = 1);
/// The worker that keeps a standby copy of block `block` owned by `owner` (ScatterConfig::replicas):
/// one of the other workers, drawn by a hash of the block, so that the blocks of one contact
/// (neighbours in the tree's order, which block-cyclic deals to neighbouring workers) have their
/// copies spread over the fleet. `owner` itself when there is no other worker.
std::uint32_t second_holder(std::uint32_t block, std::uint32_t owner, std::uint32_t workers);
/// The standby copies each worker keeps when `shares` (worker -> its blocks, deal_blocks()) are
/// replicated once: block b of shares[w] goes to second_holder(b, w, W). Ascending in each list;
/// all empty for fewer than two workers.
std::vector<std::vector<std::uint32_t>> standby_shares(const std::vector<std::vector<std::uint32_t>>& shares);
/// Block-cyclic mapping (paper §3.4, [10]): block b goes to worker b mod workers.
std::vector<std::vector<std::uint32_t>> block_cyclic(std::uint32_t num_blocks, std::uint32_t workers);

/// Blocks without a sphere tree (the benchmarks' scatter floor and hostile clients, and tests):
/// faces sorted along a Morton curve of their centroids and cut into runs of `faces_per_block`
/// (spatially compact blocks, like the spheres of one layer; runs use the tree's layer-n blocks).
Blocks spatial_blocks(const geom::Mesh& object, std::uint32_t faces_per_block);

}  // namespace st::net
