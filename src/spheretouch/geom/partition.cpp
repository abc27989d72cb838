// SPDX-License-Identifier: BSD-3-Clause
// Partition of a layer over workers (see partition.hpp).
#include <spheretouch/geom/partition.hpp>
#include <spheretouch/geom/check.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace st::inline SPHERETOUCH_ABI::geom {

std::span<const std::uint32_t> Partition::block(std::uint32_t k) const {
  const std::size_t b = std::size_t{k} * block_size;
  if (b >= layer_nodes.size()) return {};
  const std::size_t e = std::min(layer_nodes.size(), b + block_size);
  return {layer_nodes.data() + b, e - b};
}

std::vector<std::uint32_t> Partition::worker_roots(std::uint32_t w) const {
  std::vector<std::uint32_t> out;
  for (std::uint32_t k = 0; k < num_blocks(); ++k)
    if (owners[k] == w)
      for (std::uint32_t n : block(k)) out.push_back(n);
  return out;
}

const char* to_string(Mapping m) {
  switch (m) {
    case Mapping::block_cyclic:
      return "block-cyclic";
    case Mapping::contiguous:
      return "contiguous";
    case Mapping::random:
      return "random";
  }
  return "?";
}

bool parse_mapping(std::string_view name, Mapping& out) {
  for (Mapping m : {Mapping::block_cyclic, Mapping::contiguous, Mapping::random})
    if (name == to_string(m)) {
      out = m;
      return true;
    }
  return false;
}

std::vector<std::uint32_t> block_owners(std::uint32_t num_blocks, std::uint32_t workers, Mapping mapping,
                                        std::uint64_t seed) {
  std::vector<std::uint32_t> owners(num_blocks);
  if (workers == 0) return owners;
  std::uint64_t state = seed;
  for (std::uint32_t k = 0; k < num_blocks; ++k) {
    switch (mapping) {
      case Mapping::block_cyclic:
        owners[k] = k % workers;
        break;
      case Mapping::contiguous:
        owners[k] = static_cast<std::uint32_t>(std::uint64_t{k} * workers / num_blocks);
        break;
      case Mapping::random: {
        // splitmix64: a fixed, portable sequence (std:: distributions differ between libraries).
        std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        owners[k] = static_cast<std::uint32_t>((z ^ (z >> 31)) % workers);
        break;
      }
    }
    ST_ASSERT(owners[k] < workers, "every block goes to one of the workers");
  }
  return owners;
}

Result<Partition> make_partition(const SphereTree& tree, std::uint32_t layer, std::uint32_t workers,
                                 std::uint32_t block_size, Mapping mapping, std::uint64_t seed) {
  if (workers == 0) return fail("partition: workers must be >= 1");
  if (block_size == 0) return fail("partition: block size must be >= 1");
  if (tree.nodes.empty()) return fail("partition: empty sphere tree");
  Partition p;
  p.layer = layer;
  p.workers = workers;
  p.block_size = block_size;
  p.layer_nodes = tree.layer(layer);
  p.mapping = mapping;
  p.owners = block_owners(p.num_blocks(), workers, mapping, seed);
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

namespace {

/// For every leaf (by its position in layer(depth)), its faces and the position of its ancestor
/// in each layer's list.
struct LeafMap {
  std::vector<std::uint32_t> leaf_node;                  // node index of leaf position i
  std::vector<std::uint32_t> leaf_faces;                 // faces below it
  std::vector<std::vector<std::uint32_t>> pos_in_layer;  // [layer][leaf position] -> position in layer(layer)
  std::vector<std::uint32_t> layer_size;                 // |layer(l)|
};

LeafMap map_leaves(const SphereTree& t) {
  LeafMap m;
  std::vector<std::uint32_t> leaf_pos(t.num_nodes(), kNoNode);
  for (std::uint32_t i = 0; i < t.num_nodes(); ++i)
    if (t.nodes[i].leaf) {
      leaf_pos[i] = std::uint32_t(m.leaf_node.size());
      m.leaf_node.push_back(i);
      m.leaf_faces.push_back(t.cold[i].face_end - t.cold[i].face_begin);
    }
  m.pos_in_layer.resize(t.num_depths);
  m.layer_size.resize(t.num_depths);
  m.layer_size[0] = 1;  // the root: one block of everything
  m.pos_in_layer[0].assign(m.leaf_node.size(), 0);
  for (std::uint32_t l = 1; l < t.num_depths; ++l) {
    const std::vector<std::uint32_t> nodes = t.layer(l);
    m.layer_size[l] = std::uint32_t(nodes.size());
    std::vector<std::uint32_t>& pos = m.pos_in_layer[l];
    pos.assign(m.leaf_node.size(), 0);
    for (std::uint32_t p = 0; p < nodes.size(); ++p) {
      const std::uint32_t n = nodes[p];
      if (t.nodes[n].leaf) {
        pos[leaf_pos[n]] = p;
        continue;
      }
      for (std::uint32_t d = t.nodes[n].first; d < t.cold[n].desc_end; ++d)
        if (t.nodes[d].leaf) pos[leaf_pos[d]] = p;
    }
  }
  return m;
}

/// Leaf positions whose spheres reach the ball (c, r).
void leaves_near(const SphereTree& t, const std::vector<std::uint32_t>& leaf_pos, const Vec3& c, double r,
                 std::vector<std::uint32_t>& out) {
  out.clear();
  std::vector<std::uint32_t> stack{0};
  while (!stack.empty()) {
    const std::uint32_t i = stack.back();
    stack.pop_back();
    const SphereNode& h = t.nodes[i];
    const Vec3 d = Vec3(h.centre[0], h.centre[1], h.centre[2]) - c;
    const double reach = double(h.radius) + r;
    if (d.squaredNorm() > reach * reach) continue;
    if (h.leaf) {
      out.push_back(leaf_pos[i]);
      continue;
    }
    for (std::uint32_t k = 0; k < h.count; ++k) stack.push_back(h.first + k);
  }
}

}  // namespace

Result<SplitChoice> choose_split(const SphereTree& tree, std::uint32_t workers, Mapping mapping,
                                 const SplitModelConfig& cfg, std::uint32_t fixed_layer, std::uint32_t fixed_block_size) {
  if (workers == 0) return fail("split: workers must be >= 1");
  if (tree.nodes.empty()) return fail("split: empty sphere tree");
  if (!(cfg.contact_radius >= 0) || !std::isfinite(cfg.contact_radius))
    return fail("split: contact radius must be finite and >= 0");
  if (fixed_layer != kFree) fixed_layer = std::min(fixed_layer, tree.num_depths - 1);  // deeper: the same leaves
  const LeafMap m = map_leaves(tree);
  if (workers > m.leaf_node.size())  // no layer has more nodes than there are leaves
    return fail("split: no layer of this object's sphere tree (", tree.num_depths, " layers, ", m.leaf_node.size(),
                " leaves) gives ", workers, " workers a block each: use fewer workers or a smaller leaf_faces");
  std::vector<std::uint32_t> leaf_pos(tree.num_nodes(), kNoNode);
  for (std::uint32_t i = 0; i < m.leaf_node.size(); ++i) leaf_pos[m.leaf_node[i]] = i;

  // The sampled contact regions, as the leaves each reaches.
  const std::uint32_t nsites =
      std::max<std::uint32_t>(1, std::min<std::uint32_t>(cfg.sites, std::uint32_t(m.leaf_node.size())));
  std::vector<std::vector<std::uint32_t>> regions(nsites);
  for (std::uint32_t s = 0; s < nsites; ++s) {
    const std::uint32_t leaf =
        m.leaf_node[std::size_t(s) * m.leaf_node.size() / nsites + m.leaf_node.size() / (2 * nsites)];
    const SphereNodeCold& c = tree.cold[leaf];
    leaves_near(tree, leaf_pos, Vec3(c.centre[0], c.centre[1], c.centre[2]), cfg.contact_radius, regions[s]);
  }

  std::vector<std::uint32_t> sizes;  // block sizes tried, ascending
  if (fixed_block_size)
    sizes.push_back(fixed_block_size);
  else
    for (std::uint32_t B = 1; B <= std::max(cfg.max_block_size, 1u); B *= 2) sizes.push_back(B);
  SplitChoice best;
  bool have = false;
  double best_cost = 0;
  struct Tried {
    std::uint32_t layer, block_size, blocks;
    double cost, mean;
  };
  std::vector<Tried> tried;  // for cfg.smaller_blocks_tie
  std::vector<double> load(workers);
  std::vector<std::uint32_t> seen;  // last region that entered each block
  for (std::uint32_t layer = 0; layer < tree.num_depths; ++layer) {
    if (fixed_layer != kFree && layer != fixed_layer) continue;
    for (std::uint32_t B : sizes) {
      const std::uint32_t nb = (m.layer_size[layer] + B - 1) / B;
      if (nb < std::uint64_t(workers) * cfg.min_blocks_per_worker) break;  // larger B: fewer blocks still
      const std::vector<std::uint32_t> owners = block_owners(nb, workers, mapping);
      std::vector<std::uint32_t> held(workers, 0);
      for (std::uint32_t o : owners) ++held[o];
      if (*std::min_element(held.begin(), held.end()) < cfg.min_blocks_per_worker) continue;  // random deals
      seen.assign(nb, kNoNode);
      double sum_max = 0, sum_mean = 0;
      for (std::uint32_t s = 0; s < nsites; ++s) {
        std::fill(load.begin(), load.end(), 0.0);
        for (std::uint32_t leaf : regions[s]) {
          const std::uint32_t b = m.pos_in_layer[layer][leaf] / B;
          double add = m.leaf_faces[leaf];
          if (seen[b] != s) {
            seen[b] = s;
            add += cfg.block_cost_faces;
          }
          load[owners[b]] += add;
        }
        double mx = 0, total = 0;
        for (double v : load) {
          mx = std::max(mx, v);
          total += v;
        }
        sum_max += mx;
        sum_mean += total / workers;
      }
      const double cost = sum_max / nsites;
      ++best.candidates;
      tried.push_back({layer, B, nb, cost, sum_mean / nsites});
      // The cheapest wins; within cfg.tie of the best, the one with fewer blocks.
      const bool better =
          !have || cost < best_cost * (1 - cfg.tie) || (cost <= best_cost * (1 + cfg.tie) && nb < best.blocks);
      if (better) {
        have = true;
        best_cost = cost;
        best.layer = layer;
        best.block_size = B;
        best.blocks = nb;
        best.predicted_max = cost;
        best.predicted_mean = sum_mean / nsites;
      }
    }
  }
  if (!have)
    return fail("split: no layer of this object's sphere tree (", tree.num_depths, " layers, ", m.leaf_node.size(),
                " leaves) gives ", workers, " workers a block each", fixed_layer != kFree ? " at the fixed layer" : "",
                fixed_block_size ? " with the fixed block size" : "", ": use fewer workers");
  // The smallest block size at the pick's layer within cfg.smaller_blocks_tie of its cost.
  for (const Tried& t : tried)
    if (t.layer == best.layer && t.block_size < best.block_size &&
        t.cost <= best_cost * (1 + std::max(0.0, cfg.smaller_blocks_tie))) {
      best.block_size = t.block_size;
      best.blocks = t.blocks;
      best.predicted_max = t.cost;
      best.predicted_mean = t.mean;
    }
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "layer %u, block size %u: %u blocks, %s over %u workers; predicted busiest/mean worker %.2f over %u "
                "contact regions of radius %.3g mm (best of %u splits)",
                best.layer, best.block_size, best.blocks, to_string(mapping), workers, best.imbalance(), nsites,
                cfg.contact_radius, best.candidates);
  best.why = buf;
  return best;
}

}  // namespace st::geom
