// SPDX-License-Identifier: BSD-3-Clause
// The public collision API over geom::collide() (see collide.hpp).
#include <spheretouch/collide.hpp>

#include <algorithm>
#include <utility>

namespace st {
inline namespace SPHERETOUCH_ABI {

Result<Body> Body::make(Mesh mesh, const TreeConfig& params, const Pose& frame) {
  if (Status s = mesh.validate(); !s.ok()) return fail(mesh.name, ": ", s.error());
  Result<SphereTree> tree = SphereTree::build(mesh, params);
  if (!tree.ok()) return fail(mesh.name, ": ", tree.error());
  return Body(std::make_shared<const Mesh>(std::move(mesh)),
              std::make_shared<const SphereTree>(std::move(tree).value()), frame);
}

Result<Body> Body::make(std::shared_ptr<const Mesh> mesh, std::shared_ptr<const SphereTree> tree, const Pose& frame,
                        std::span<const std::uint32_t> groups) {
  if (!mesh || !tree) return fail("Body::make: mesh and tree must not be null");
  if (const std::uint64_t h = geom::tree_hash(*mesh, tree->params, groups); tree->mesh_hash != h)
    return fail(mesh->name, ": the tree was built for another mesh or with other parameters (hash ", tree->mesh_hash,
                ", this mesh gives ", h, groups.empty() ? "" : " with these groups", ")");
  if (!frame.matrix().allFinite()) return fail(mesh->name, ": the frame is not finite");
  return Body(std::move(mesh), std::move(tree), frame);
}

std::string check(const CollisionRequest& request) {
  if (request.max_pairs == 0) return "max_pairs: must be >= 1 (SIZE_MAX for all pairs)";
  if (request.approximate_layer < geom::kExact)
    return "approximate_layer: must be kExact (-2), kLeafSpheres (-1) or a layer >= 0";
  return {};
}

void CollisionResult::clear() {
  pairs.clear();
  probe_faces = object_faces = 0;
  complete = true;
  bad_request = false;
  stats = {};
}

Pose relative_pose(const Pose& probe_frame, const Pose& object_frame) {
  // Rigid frames: the inverse rotation is the transpose.
  Pose rel;
  rel.linear() = object_frame.linear().transpose() * probe_frame.linear();
  rel.translation() = object_frame.linear().transpose() * (probe_frame.translation() - object_frame.translation());
  return rel;
}

Pose relative_pose(const Body& probe, const Body& object) { return relative_pose(probe.frame(), object.frame()); }

namespace {

// The inner query, then the request's cap and order applied to its result.
void run(const Body& probe, const Body& object, const Pose& relative, const CollisionRequest& request,
         geom::CollideScratch& scratch, geom::CollideResult& inner, CollisionResult& result,
         geom::CoherentCollider* coherent = nullptr) {
  result.clear();
  if (!check(request).empty() || (request.node_work && request.node_work->work.size() < object.tree().num_nodes())) {
    result.bad_request = true;
    return;
  }
  geom::CollideConfig options = geom::DefaultCollideConfig();
  options.stop_layer = request.approximate_layer;
  options.object_roots = request.object_roots;
  options.restrict_object = request.restrict_object;
  options.tri_filter = request.tri_filter;
  options.max_work = request.max_work;
  options.node_work = request.node_work;
  // geom::collide stops once more than options.max_pairs are found: stop at the first max_pairs.
  const bool capped = request.max_pairs != SIZE_MAX;
  options.max_pairs = capped ? request.max_pairs - 1 : SIZE_MAX;
  // Uncapped, the inner query sorts (a radix sort); capped, the first max_pairs found are kept,
  // then sorted below.
  options.sort_pairs = request.sort_pairs && !capped;
  if (coherent)
    coherent->collide(probe.mesh(), probe.tree(), object.mesh(), object.tree(), relative, options, inner);
  else
    geom::collide(probe.mesh(), probe.tree(), object.mesh(), object.tree(), relative, options, scratch, inner);
  result.stats = inner.stats;
  // Swapped, not copied: both vectors keep their capacity, so later queries allocate nothing.
  result.pairs.swap(inner.pairs);
  result.probe_faces = inner.probe_faces;
  result.object_faces = inner.object_faces;
  if (inner.stats.work_limit_hit) result.complete = false;
  if (inner.stats.pair_limit_hit) {
    result.complete = false;
    if (result.pairs.size() > request.max_pairs) {
      // The traversal finishes the leaf pair it was in: keep the first max_pairs and recount.
      result.pairs.resize(request.max_pairs);
      std::vector<std::uint32_t> ids;
      const geom::FaceCounts counts = geom::count_faces(result.pairs, ids);
      result.probe_faces = counts.probe_faces;
      result.object_faces = counts.object_faces;
    }
  }
  if (request.sort_pairs && capped) std::sort(result.pairs.begin(), result.pairs.end());
}

}  // namespace

ComputeCollision::ComputeCollision(Body probe, Body object) : probe_(std::move(probe)), object_(std::move(object)) {
  scratch_.prepare(probe_.mesh(), probe_.tree(), object_.mesh(), object_.tree());
}

void ComputeCollision::set_object(Body object) {
  object_ = std::move(object);
  if (coherent_) coherent_->reset();
}

void ComputeCollision::set_coherent(bool on, const geom::CoherentConfig& config) {
  if (on)
    coherent_ = std::make_unique<geom::CoherentCollider>(config);
  else
    coherent_.reset();
}

void ComputeCollision::operator()(const CollisionRequest& request, CollisionResult& result) {
  run(probe_, object_, relative_pose(probe_, object_), request, scratch_, inner_, result, coherent_.get());
}

void ComputeCollision::operator()(const Pose& probe_frame, const Pose& object_frame, const CollisionRequest& request,
                                  CollisionResult& result) {
  run(probe_, object_, relative_pose(probe_frame, object_frame), request, scratch_, inner_, result, coherent_.get());
}

void ComputeCollision::at_relative(const Pose& relative, const CollisionRequest& request, CollisionResult& result) {
  run(probe_, object_, relative, request, scratch_, inner_, result, coherent_.get());
}

void collide(const Body& probe, const Body& object, const CollisionRequest& request, CollisionResult& result) {
  geom::CollideScratch scratch;
  geom::CollideResult inner;
  run(probe, object, relative_pose(probe, object), request, scratch, inner, result);
}

}  // namespace SPHERETOUCH_ABI
}  // namespace st
