// Block-cyclic partition (see partition.hpp).
#include "geom/partition.hpp"

namespace st::geom {

std::span<const std::uint32_t> Partition::block(std::uint32_t k) const {
  const std::size_t b = std::size_t{k} * block_size;
  if (b >= layer_nodes.size()) return {};
  const std::size_t e = std::min(layer_nodes.size(), b + block_size);
  return {layer_nodes.data() + b, e - b};
}

std::vector<std::uint32_t> Partition::worker_roots(std::uint32_t w) const {
  std::vector<std::uint32_t> out;
  for (std::uint32_t k = w; k < num_blocks(); k += workers)
    for (std::uint32_t n : block(k)) out.push_back(n);
  return out;
}

Result<Partition> make_partition(const SphereTree& tree, std::uint32_t layer, std::uint32_t workers,
                                 std::uint32_t block_size) {
  if (workers == 0) return fail("partition: workers must be >= 1");
  if (block_size == 0) return fail("partition: block size must be >= 1");
  if (tree.nodes.empty()) return fail("partition: empty sphere tree");
  Partition p;
  p.layer = layer;
  p.workers = workers;
  p.block_size = block_size;
  p.layer_nodes = tree.layer(layer);
  return p;
}

SubtreeExtent subtree_extent(const SphereTree& tree, std::uint32_t root) {
  const SphereNode& h = tree.nodes[root];
  const SphereNodeCold& c = tree.cold[root];
  SubtreeExtent e{root, 0, 0, c.face_begin, c.face_end};
  if (!h.leaf) {
    e.desc_begin = h.first;
    e.desc_end = c.desc_end;
  }
  return e;
}

}  // namespace st::geom
