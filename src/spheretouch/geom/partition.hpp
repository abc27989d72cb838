// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Partition of an object's layer-n spheres over W workers (paper §3.4): runs of B consecutive
/// layer-n nodes (depth-first, spatially coherent order) form blocks, and a mapping deals the blocks
/// to workers. Block-cyclic (Pacheco, "Parallel Programming with MPI"): block k goes to worker
/// k mod W, so a contact region, which covers neighbouring blocks, is spread over the workers; the
/// alternatives are here to measure that choice (spheretouch-bench scale): contiguous (worker w gets
/// one run of ~blocks/W neighbouring blocks) and random (each block to a seeded random worker).
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <spheretouch/geom/sphere_tree.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// How blocks are dealt to workers.
enum class Mapping : std::uint8_t {
  block_cyclic,  ///< block k to worker k mod W (the paper's, the default)
  contiguous,    ///< block k to worker floor(k W / blocks): W runs of neighbouring blocks
  random,        ///< block k to a worker drawn from a seeded generator
};
const char* to_string(Mapping m);  ///< "block-cyclic", "contiguous", "random"
/// Parses to_string()'s names; false for anything else.
bool parse_mapping(std::string_view name, Mapping& out);

/// The worker of each of `num_blocks` blocks dealt over `workers` (>= 1) by `mapping` (`seed` for
/// Mapping::random): owners[k] < workers. Block-cyclic and contiguous leave no worker without a
/// block when num_blocks >= workers; random may.
std::vector<std::uint32_t> block_owners(std::uint32_t num_blocks, std::uint32_t workers, Mapping mapping,
                                        std::uint64_t seed = 1);

/// The blocks of one layer and their owners. Every face is below exactly one block node.
struct Partition {
  std::uint32_t layer = 0;                  ///< sphere layer n that was distributed
  std::uint32_t workers = 1;                ///< W
  std::uint32_t block_size = 1;             ///< B, layer nodes per block
  std::vector<std::uint32_t> layer_nodes;   ///< SphereTree::layer(n)
  Mapping mapping = Mapping::block_cyclic;  ///< how blocks were dealt
  std::vector<std::uint32_t> owners;        ///< owners[k]: the worker of block k

  std::uint32_t num_blocks() const {  ///< ceil(|layer| / B)
    return static_cast<std::uint32_t>((layer_nodes.size() + block_size - 1) / block_size);
  }
  std::uint32_t owner(std::uint32_t block) const { return owners[block]; }  ///< worker of a block
  std::span<const std::uint32_t> block(std::uint32_t k) const;              ///< node indices of block k
  /// Subtree roots of worker w (its blocks' nodes, in block order): CollideConfig::object_roots.
  std::vector<std::uint32_t> worker_roots(std::uint32_t w) const;
};

/// Partition of `tree`'s layer n over `workers` with `block_size` nodes per block, dealt by
/// `mapping` (`seed` for Mapping::random). Fails on workers == 0 or block_size == 0. A worker may
/// own no block (more workers than blocks, or a random deal).
Result<Partition> make_partition(const SphereTree& tree, std::uint32_t layer, std::uint32_t workers,
                                 std::uint32_t block_size, Mapping mapping = Mapping::block_cyclic, std::uint64_t seed = 1);

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

/// What choose_split() may pick and how it judges (the automatic split, issue 17).
struct SplitModelConfig {
  std::uint32_t sites = 64;                 ///< contact regions sampled (leaves evenly spaced in tree order)
  double contact_radius = 10;               ///< radius of a contact region, object mm (the probe's patch)
  std::uint32_t max_block_size = 32;        ///< block sizes tried: 1, 2, 4, ... up to this
  std::uint32_t min_blocks_per_worker = 1;  ///< a worker always holds at least this many blocks
  /// Cost of a block a worker enters, in faces tested: keeps the model from cutting into ever
  /// smaller blocks. 1 was fitted to spheretouch-bench scale (elephant, armadillo L1 and L2,
  /// W = 8): larger values picked larger blocks that measured worse (perf/RESULTS.md at commit 09e4e24).
  double block_cost_faces = 1;
  /// Two splits within this relative cost are a tie, won by the one with fewer blocks (0: the
  /// cheapest wins; the measurements did not favour fewer blocks).
  double tie = 0;
  /// Within this relative cost of the pick, a smaller block size at its layer wins. The model
  /// charges a block entered block_cost_faces whatever its size, and so favours larger blocks by a
  /// little; a worker's tree over blocks of several nodes costs more than it says: at W = 2 and 4
  /// on armadillo_L2's ~1,000- and ~1,500-contact poses, block size 1 at the same layer made up to
  /// 23 % fewer sphere tests and 1.4-5.4x fewer probe-leaf transforms (spheretouch-bench scale,
  /// counted work) where the model put it 0.8-1.9 % behind.
  double smaller_blocks_tie = 0.05;
};

/// The automatic split: layer and block size for `workers` workers and `mapping`.
struct SplitChoice {
  ///@{
  std::uint32_t layer = 0, block_size = 1, blocks = 0;  ///< the split: layer n, nodes per block, blocks
  ///@}
  double predicted_max = 0;   ///< mean over the sampled regions of the slowest worker's work (faces)
  double predicted_mean = 0;  ///< mean over the regions of the mean worker's work (faces)
  /// predicted_max / predicted_mean (1: balanced).
  double imbalance() const { return predicted_mean > 0 ? predicted_max / predicted_mean : 1.0; }
  std::uint32_t candidates = 0;  ///< splits compared
  std::string why;               ///< one line for the run's summary
};

/// choose_split()'s `fixed_layer` when the layer is not pinned.
inline constexpr std::uint32_t kFree = 0xffffffffu;
/// Picks the layer and block size that minimise the predicted critical path of a round: contact
/// regions (`cfg.sites` spheres of `cfg.contact_radius` around leaves spread over the object) are
/// dealt to the workers by each candidate split; a worker's work in a region = faces of its leaves
/// the region reaches + block_cost_faces per block of its that the region enters; the split's cost
/// is the mean over regions of the busiest worker's work. Candidates: every layer 0..depth-1 and
/// block sizes 1, 2, 4, ... that give every worker at least min_blocks_per_worker blocks (none is
/// ever empty). `fixed_layer` (kFree = free) / `fixed_block_size` (0 = free) pin one knob (the
/// manual override of one). Fails when no candidate gives `workers` workers a block each.
Result<SplitChoice> choose_split(const SphereTree& tree, std::uint32_t workers, Mapping mapping,
                                 const SplitModelConfig& cfg = {}, std::uint32_t fixed_layer = kFree,
                                 std::uint32_t fixed_block_size = 0);

}  // namespace st::geom
