// Sphere-tree backend: see tree_backend.hpp.
#include "net/tree_backend.hpp"

#include <algorithm>
#include <chrono>

#include "geom/collide.hpp"
#include "geom/partition.hpp"

namespace st::net {
namespace {

class TreeBackend final : public CollisionBackend {
 public:
  explicit TreeBackend(bool per_block) : per_block_(per_block) {}
  Status load(const BlockSet& set) override {
    geom::TreeConfig params = geom::DefaultTreeConfig();
    params.leaf_faces = std::clamp<std::uint32_t>(set.leaf_faces, 1, geom::kMaxLeafFaces);
    set_ = set;
    Result<geom::SphereTree> pt = geom::SphereTree::build(set_.probe, params);
    if (!pt) return fail("probe tree: ", pt.error());
    probe_tree_ = std::move(pt).value();
    empty_ = set_.object.faces.empty();
    if (!empty_) {
      // One subtree per block: the blocks of a share lie apart (block-cyclic, random), and one
      // tree over all of them would put spheres around the gaps between blocks.
      Result<geom::SphereTree> ot = geom::SphereTree::build(
          set_.object, params,
          per_block_ ? std::span<const std::uint32_t>(set_.block_faces) : std::span<const std::uint32_t>());
      if (!ot) return fail("object share tree: ", ot.error());
      object_tree_ = std::move(ot).value();
    }
    scratch_ = geom::CollideScratch{};
    return Ok{};
  }

  QueryStats query(const geom::Pose& pose, std::vector<FacePair>& out, std::size_t max_pairs) override {
    QueryStats st;
    if (empty_) return st;
    const auto t0 = std::chrono::steady_clock::now();
    // The share keeps the object's origin and local coordinates bit for bit, so collide()
    // computes the same transformed doubles as a single-process query.
    geom::CollideConfig opt = geom::DefaultCollideConfig();
    opt.max_pairs = max_pairs;
    geom::collide(set_.probe, probe_tree_, set_.object, object_tree_, pose, opt, scratch_, result_);
    out.reserve(out.size() + result_.pairs.size());
    for (const geom::FacePair& p : result_.pairs) out.push_back({p.probe, set_.object_face_ids[p.object]});
    st.sphere_tests = result_.stats.node_pairs;
    st.tri_tests = result_.stats.tri_pairs;
    st.compute_ns =
        std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count());
    return st;
  }

 private:
  BlockSet set_;
  geom::SphereTree probe_tree_, object_tree_;
  geom::CollideScratch scratch_;
  geom::CollideResult result_;
  bool empty_ = true;
  bool per_block_ = true;
};

}  // namespace

BackendFactory tree_backend_factory(bool per_block) {
  return [per_block] { return std::make_unique<TreeBackend>(per_block); };
}

Result<Blocks> tree_blocks(const geom::SphereTree& tree, std::uint32_t layer, std::uint32_t block_size) {
  Result<geom::Partition> part = geom::make_partition(tree, layer, 1, block_size);
  if (!part) return Error{part.error()};
  Blocks blocks(part.value().num_blocks());
  for (std::uint32_t b = 0; b < blocks.size(); ++b) {
    for (std::uint32_t node : part.value().block(b))
      blocks[b].insert(blocks[b].end(), tree.faces_begin(node), tree.faces_end(node));
    std::sort(blocks[b].begin(), blocks[b].end());
  }
  return blocks;
}

}  // namespace st::net
