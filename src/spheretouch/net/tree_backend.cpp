// SPDX-License-Identifier: BSD-3-Clause
// Sphere-tree backend: see tree_backend.hpp.
#include <spheretouch/net/tree_backend.hpp>

#include <algorithm>
#include <chrono>
#include <memory>
#include <optional>
#include <utility>

#include <spheretouch/collide.hpp>
#include <spheretouch/geom/partition.hpp>
#include <spheretouch/net/worker_service.hpp>

namespace st::inline SPHERETOUCH_ABI::net {
namespace {

/// A tree whose densest spot piles more than `max` leaves (geom::crowding) is refused.
Status check_crowding(const geom::SphereTree& tree, const geom::Mesh& mesh, std::uint32_t max, const char* what) {
  if (max == 0) return Ok{};
  const geom::Crowding c = geom::crowding(tree, max + 1);
  if (c.leaves <= max) return Ok{};
  const geom::SphereNode& n = tree.nodes[c.leaf];
  const geom::Vec3 at = mesh.origin + geom::Vec3(n.centre[0], n.centre[1], n.centre[2]);
  return fail(what, ": more than ", max, " leaves of ", tree.params.leaf_faces, " faces piled around (", at.x(), ", ",
              at.y(), ", ", at.z(), ") mm: faces on top of each other, refused (a surface has a few dozen at one spot)");
}

class TreeBackend final : public CollisionBackend {
 public:
  TreeBackend(bool per_block, std::uint32_t max_crowding, bool coherent)
      : per_block_(per_block), coherent_(coherent), max_crowding_(max_crowding) {}
  Status load(const BlockSet& set) override {
    geom::TreeConfig params = geom::DefaultTreeConfig();
    params.leaf_faces = std::clamp<std::uint32_t>(set.leaf_faces, 1, geom::kMaxLeafFaces);
    set_ = set;
    collider_.reset();
    worked_.clear();
    // The meshes move into the bodies the collider shares; set_ keeps the ids and blocks.
    auto probe = std::make_shared<const geom::Mesh>(std::exchange(set_.probe, {}));
    auto object = std::make_shared<const geom::Mesh>(std::exchange(set_.object, {}));
    Result<geom::SphereTree> pt = geom::SphereTree::build(*probe, params);
    if (!pt) return fail("probe tree: ", pt.error());
    if (Status st = check_crowding(pt.value(), *probe, max_crowding_, "probe"); !st) return st;
    empty_ = object->faces.empty();
    if (empty_) return Ok{};
    // One subtree per block: the blocks of a share lie apart (block-cyclic, random), and one
    // tree over all of them would put spheres around the gaps between blocks.
    const std::span<const std::uint32_t> groups =
        per_block_ ? std::span<const std::uint32_t>(set_.block_faces) : std::span<const std::uint32_t>();
    Result<geom::SphereTree> ot = geom::SphereTree::build(*object, params, groups);
    if (!ot) return fail("object share tree: ", ot.error());
    if (Status st = check_crowding(ot.value(), *object, max_crowding_, "object share"); !st) return st;
    object_tree_ = std::make_shared<const geom::SphereTree>(std::move(ot).value());
    const geom::SphereTree& tree = *object_tree_;
    // One tree over the whole share (per_block_ false) mixes blocks in its leaves: no roots,
    // and a Query's skip list is then ignored (the skipped blocks are answered too).
    block_roots_.clear();
    if (per_block_) block_roots_ = geom::group_roots(tree, set_.object_face_ids.size(), set_.block_faces);
    is_root_.assign(tree.num_nodes(), 0);
    for (const auto& roots : block_roots_)
      for (std::uint32_t r : roots) is_root_[r] = 1;
    // Each node's held block (the subtrees under its roots), for the work of each block.
    node_block_.assign(tree.num_nodes(), kNoBlock);
    for (std::uint32_t b = 0; b < block_roots_.size(); ++b)
      for (std::uint32_t r : block_roots_[b]) {
        stack_.assign(1, r);
        while (!stack_.empty()) {
          const std::uint32_t i = stack_.back();
          stack_.pop_back();
          node_block_[i] = b;
          if (!tree.nodes[i].leaf)
            for (std::uint32_t c = tree.nodes[i].first; c < tree.nodes[i].first + tree.nodes[i].count; ++c)
              stack_.push_back(c);
        }
      }
    node_work_.work.assign(per_block_ ? tree.num_nodes() : 0, 0);
    node_work_.touched.clear();
    block_work_.assign(set_.blocks.size(), 0);
    worked_.clear();
    cut_.assign(tree.num_nodes(), 0);
    stamp_ = 0;
    Result<Body> pb = Body::make(std::move(probe), std::make_shared<const geom::SphereTree>(std::move(pt).value()));
    if (!pb) return fail("probe: ", pb.error());
    Result<Body> ob = Body::make(std::move(object), object_tree_, geom::Pose::Identity(), groups);
    if (!ob) return fail("object share: ", ob.error());
    collider_.emplace(std::move(pb).value(), std::move(ob).value());
    geom::CoherentConfig coherent;
    coherent.max_bytes = kCoherentCacheBytes;
    collider_->set_coherent(coherent_, coherent);
    return Ok{};
  }

  /// Blocks left out: roots_ becomes the largest subtrees holding none of them (the skipped
  /// blocks' roots and their ancestors are cut out; every other node below the root is covered
  /// once), so the descent keeps the top levels' culling. False when no held block is skipped.
  bool cover_without(std::span<const std::uint32_t> skip) {
    const geom::SphereTree& tree = *object_tree_;
    if (++stamp_ == 0) {
      std::fill(cut_.begin(), cut_.end(), 0);
      stamp_ = 1;
    }
    bool any = false;
    for (std::uint32_t id : skip) {
      const auto it = std::lower_bound(set_.blocks.begin(), set_.blocks.end(), id);
      if (it == set_.blocks.end() || *it != id) continue;
      for (std::uint32_t r : block_roots_[std::size_t(it - set_.blocks.begin())]) {
        cut_[r] = stamp_;  // the block itself
        any = true;
        for (std::uint32_t a = tree.cold[r].parent; a != geom::kNoNode && cut_[a] != stamp_; a = tree.cold[a].parent)
          cut_[a] = stamp_;  // ancestors: split into their children
      }
    }
    if (!any) return false;
    roots_.clear();
    stack_.assign(1, 0);
    while (!stack_.empty()) {
      const std::uint32_t i = stack_.back();
      stack_.pop_back();
      if (cut_[i] != stamp_) {
        roots_.push_back(i);
      } else if (!tree.nodes[i].leaf && !is_block_root(i)) {
        const geom::SphereNode& n = tree.nodes[i];
        for (std::uint32_t c = n.first + n.count; c-- > n.first;) stack_.push_back(c);
      }
    }
    return true;
  }

  QueryStats query(const geom::Pose& pose, std::span<const std::uint32_t> skip, std::vector<FacePair>& out,
                   const QueryBudget& budget) override {
    if (empty_) return {};
    const bool restrict = !skip.empty() && !block_roots_.empty() && cover_without(skip);
    return run(pose, restrict, out, budget);
  }

  QueryStats query_only(const geom::Pose& pose, std::span<const std::uint32_t> only, std::vector<FacePair>& out,
                        const QueryBudget& budget) override {
    if (empty_) return {};
    // A tree over the whole share (per_block_ false) cannot leave blocks out: it answers them all.
    roots_.clear();
    for (std::uint32_t id : only)
      if (const auto it = std::lower_bound(set_.blocks.begin(), set_.blocks.end(), id);
          it != set_.blocks.end() && *it == id) {
        const auto& r = block_roots_[std::size_t(it - set_.blocks.begin())];
        roots_.insert(roots_.end(), r.begin(), r.end());
      }
    return run(pose, !block_roots_.empty(), out, budget);
  }

 private:
  // One query, over roots_ when `restrict`.
  QueryStats run(const geom::Pose& pose, bool restrict, std::vector<FacePair>& out, const QueryBudget& budget) {
    QueryStats st;
    const auto t0 = std::chrono::steady_clock::now();
    // The share keeps the object's origin and local coordinates bit for bit, so the query
    // computes the same transformed doubles as a single-process query.
    // The service refuses more than max_pairs: the query stops one past it.
    CollisionRequest request = CollisionRequest::past_limit(budget.max_pairs);
    request.max_work = budget.max_work;
    request.sort_pairs = false;  // the client's merge sorts
    if (restrict) {
      request.restrict_object = true;
      request.object_roots = roots_;
    }
    if (!node_work_.work.empty()) request.node_work = &node_work_;
    collider_->at_relative(pose, request, result_);
    note_worked();
    out.reserve(out.size() + result_.pairs.size());
    for (const geom::FacePair& p : result_.pairs) out.push_back({p.probe, set_.object_face_ids[p.object]});
    st.sphere_tests = result_.stats.node_pairs;
    st.tri_tests = result_.stats.tri_pairs;
    st.work_limit_hit = result_.stats.work_limit_hit;
    st.compute_ns =
        std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count());
    return st;
  }

  // worked_ from what the query charged to the share tree's nodes, summed per held block.
  void note_worked() {
    worked_.clear();
    if (node_work_.touched.empty()) return;
    for (std::uint32_t n : node_work_.touched) {
      const std::uint32_t b = node_block_[n];
      if (b == kNoBlock) continue;  // above the blocks' roots: the share tree's own top
      std::uint32_t& w = block_work_[b];
      if (w == 0) worked_.push_back({b, 0});
      const std::uint32_t add = node_work_.work[n];
      w = w > UINT32_MAX - add ? UINT32_MAX : w + add;
    }
    node_work_.clear();
    for (WorkedBlock& x : worked_) {
      x.work = std::exchange(block_work_[x.block], 0);
      x.block = set_.blocks[x.block];  // held index -> global id (ascending like set_.blocks)
    }
    std::sort(worked_.begin(), worked_.end(),
              [](const WorkedBlock& a, const WorkedBlock& b) { return a.block < b.block; });
  }

 public:
  const std::vector<WorkedBlock>& worked() const override { return worked_; }

 private:
  static constexpr std::uint32_t kNoBlock = UINT32_MAX;
  std::vector<std::uint32_t> node_block_;  // per share-tree node: its held block's index, or kNoBlock
  geom::NodeWork node_work_;               // what a query charged to the share tree's nodes
  std::vector<std::uint32_t> block_work_;  // scratch: per held block, work summed (0 between queries)
  std::vector<WorkedBlock> worked_;        // the last query's blocks with work, by global id
  BlockSet set_;                           // the ids and blocks (its meshes are moved into the collider's bodies)
  std::shared_ptr<const geom::SphereTree> object_tree_;  // the share's tree (shared with the collider)
  std::optional<ComputeCollision> collider_;             // empty for an empty share
  CollisionResult result_;
  std::vector<std::vector<std::uint32_t>> block_roots_;  // per held block: the share tree's nodes covering exactly it
  std::vector<std::uint32_t> roots_;                     // scratch: the roots of the blocks queried
  std::vector<std::uint8_t> is_root_;                    // per node: it is a held block's root
  std::vector<std::uint32_t> cut_, stack_;               // per node: stamp of the query that cut it; scratch
  std::uint32_t stamp_ = 0;
  bool is_block_root(std::uint32_t i) const { return i < is_root_.size() && is_root_[i]; }
  bool empty_ = true;
  bool per_block_ = true;
  bool coherent_ = true;
  std::uint32_t max_crowding_ = kDefaultMaxCrowding;
};

}  // namespace

BackendFactory tree_backend_factory(bool per_block, std::uint32_t max_crowding, bool coherent) {
  return [per_block, max_crowding, coherent] { return std::make_unique<TreeBackend>(per_block, max_crowding, coherent); };
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
