// Block-cyclic partition of an object's layer-n spheres over W workers (paper §3.4; Pacheco,
// "Parallel Programming with MPI", block-cyclic distribution): runs of B consecutive layer-n nodes
// (depth-first, spatially coherent order) form blocks, block k goes to worker k mod W.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "geom/sphere_tree.hpp"

namespace st::geom {

/// The blocks of one layer and their owners. Every face is below exactly one block node.
struct Partition {
  std::uint32_t layer = 0;                 ///< sphere layer n that was distributed
  std::uint32_t workers = 1;               ///< W
  std::uint32_t block_size = 1;            ///< B, layer nodes per block
  std::vector<std::uint32_t> layer_nodes;  ///< SphereTree::layer(n)

  std::uint32_t num_blocks() const {  ///< ceil(|layer| / B)
    return static_cast<std::uint32_t>((layer_nodes.size() + block_size - 1) / block_size);
  }
  std::uint32_t owner(std::uint32_t block) const { return block % workers; }  ///< worker of a block
  std::span<const std::uint32_t> block(std::uint32_t k) const;                ///< node indices of block k
  /// Subtree roots of worker w (its blocks' nodes, in block order): CollideConfig::object_roots.
  std::vector<std::uint32_t> worker_roots(std::uint32_t w) const;
};

/// Block-cyclic partition of `tree`'s layer n over `workers` with `block_size` nodes per block.
/// Fails on workers == 0 or block_size == 0.
Result<Partition> make_partition(const SphereTree& tree, std::uint32_t layer, std::uint32_t workers,
                                 std::uint32_t block_size);

/// Where a subtree lives in the flat arrays, for shipping a worker's blocks: the root node, its descendants nodes[desc_begin, desc_end) and its faces
/// face_order[face_begin, face_end) (also face_boxes). Child indices inside the range are absolute.
struct SubtreeExtent {
  std::uint32_t root;        ///< the subtree root
  std::uint32_t desc_begin;  ///< first descendant (== desc_end for a leaf)
  std::uint32_t desc_end;    ///< one past the last descendant
  std::uint32_t face_begin;  ///< first face slot
  std::uint32_t face_end;    ///< one past the last face slot
};
SubtreeExtent subtree_extent(const SphereTree& tree, std::uint32_t root);  ///< extent of one subtree

}  // namespace st::geom
