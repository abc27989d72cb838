// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// <spheretouch/collide.hpp>: the collision core's public API (depends on Eigen only; link the
/// `spheretouch` pkg-config package). In the spirit of Coal's collide(o1, o2, request, result)
/// and ComputeCollision: a Body pairs a mesh with its sphere tree and its frame, a request says
/// what to compute, a result answers colliding(), the pairs and the counters, and a
/// ComputeCollision keeps the scratch of one (probe, object) pair between queries.
//
// Frames, one name each (the same names are used by every header of the project):
//  * world frame: where Body::frame() places a body; any fixed frame of the caller's.
//  * object frame: the object mesh's file coordinates. The relative pose, contacts, forces and
//    every vector of a ContactModel except probe_point are in it.
//  * probe frame: the probe mesh's file coordinates (ContactModel::probe_point).
// The relative pose (probe frame -> object frame) of two bodies is object.frame()^-1 · probe.frame().
//
// The pair set is exact: {(p, o) : the probe face p, posed, and the object face o intersect},
// faces named by their index in the input file, the same set geom::collide() returns (that is the
// inner function; this API adds nothing to its arithmetic). In approximate mode it is a superset.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <spheretouch/geom/coherent.hpp>
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/result.hpp>
#include <spheretouch/geom/sphere_tree.hpp>

namespace st {
inline namespace SPHERETOUCH_ABI {

using geom::CollideStats;
using geom::FacePair;
using geom::Mesh;
using geom::Pose;
using geom::SphereTree;
using geom::TreeConfig;
using geom::Vec3;

/// A sphere bounding a body (its tree's root, padded so that it covers the float centre's rounding).
struct BoundingSphere {
  Vec3 centre{Vec3::Zero()};  ///< mm
  double radius = 0;          ///< mm
  /// True when the two spheres meet (touching counts; a relative slack of 1e-9 keeps rounding
  /// from separating a grazing pair): the test that lets a scene skip an object out of reach.
  bool meets(const BoundingSphere& o) const {
    const double reach = radius + o.radius;
    return (centre - o.centre).squaredNorm() <= reach * reach * (1 + 1e-9) + 1e-9;
  }
  /// The sphere moved by a rigid pose.
  BoundingSphere moved(const Pose& p) const { return {p * centre, radius}; }
};

/// A collidable body: a mesh, the sphere tree built for it, and its frame (object or probe frame
/// -> world frame). Mesh and tree are shared, immutable and may back many bodies.
class Body {
 public:
  /// Validates the mesh and builds its tree. The error names the bad face or vertex.
  static Result<Body> make(Mesh mesh, const TreeConfig& params = geom::DefaultTreeConfig(),
                           const Pose& frame = Pose::Identity());
  /// A body from a mesh and a tree already built (or read from a file) for it. The error says
  /// when the tree was built for another mesh or with other parameters (its hash differs).
  /// `groups`: the run sizes the tree was built with (SphereTree::build's `groups`, e.g. a
  /// worker's blocks, whose subtrees CollisionRequest::object_roots names), empty when none.
  static Result<Body> make(std::shared_ptr<const Mesh> mesh, std::shared_ptr<const SphereTree> tree,
                           const Pose& frame = Pose::Identity(), std::span<const std::uint32_t> groups = {});

  const Mesh& mesh() const { return *mesh_; }                               ///< the mesh (faces by input-file index)
  const SphereTree& tree() const { return *tree_; }                         ///< its sphere tree
  const Pose& frame() const { return frame_; }                              ///< body frame -> world frame
  void set_frame(const Pose& frame) { frame_ = frame; }                     ///< moves the body
  const std::shared_ptr<const Mesh>& shared_mesh() const { return mesh_; }  ///< for sharing
  const std::shared_ptr<const SphereTree>& shared_tree() const { return tree_; }  ///< for sharing
  /// Bounds the mesh, in its file coordinates (body frame): the tree's root sphere.
  BoundingSphere bounding_sphere() const {
    const geom::SphereNode& r = tree_->nodes[0];
    return {mesh_->origin + Vec3(r.centre[0], r.centre[1], r.centre[2]), double(r.radius)};
  }

 private:
  Body(std::shared_ptr<const Mesh> mesh, std::shared_ptr<const SphereTree> tree, const Pose& frame)
      : mesh_(std::move(mesh)), tree_(std::move(tree)), frame_(frame) {}
  std::shared_ptr<const Mesh> mesh_;
  std::shared_ptr<const SphereTree> tree_;
  Pose frame_ = Pose::Identity();
};

/// What a query computes. Start from DefaultCollisionRequest() or one of the named requests.
struct CollisionRequest {
  /// Stop once this many pairs are found (>= 1; SIZE_MAX = all pairs). The result then holds
  /// exactly max_pairs pairs (the first ones the traversal met) and complete == false.
  std::size_t max_pairs = SIZE_MAX;
  /// geom::kExact (triangle tests), geom::kLeafSpheres (stop at leaf spheres) or a layer K >= 0:
  /// approximate mode reports every face pair of the overlapping sphere pairs there (a superset).
  int approximate_layer = geom::kExact;
  bool sort_pairs = true;  ///< pairs sorted by (probe face, object face)
  /// With restrict_object: only the object subtrees under these node indices (a worker's blocks:
  /// geom::group_roots, partition.hpp), which must be disjoint subtrees; empty = nothing. The
  /// span must outlive the query.
  std::span<const std::uint32_t> object_roots{};
  bool restrict_object = false;  ///< use object_roots instead of the whole object
  /// Decide candidate triangle pairs with the certified float filter before the exact test (the
  /// same pairs either way; false measures the exact test alone).
  bool tri_filter = true;
  /// Stop once the traversal's work (geom::CollideStats::work()) exceeds this: complete == false
  /// and stats.work_limit_hit. UINT64_MAX: no budget. A service answering requests it does not
  /// trust sets one (a worker's Limits::work_base + work_per_pair × pairs).
  std::uint64_t max_work = UINT64_MAX;
  /// Charge the query's work to the object tree's nodes (geom::NodeWork, `work` sized to the
  /// object tree's nodes, else the result is a bad_request): which parts of the object cost it (a
  /// worker's per-block work). Null: not counted. Must outlive the query.
  geom::NodeWork* node_work = nullptr;

  static CollisionRequest all_pairs() { return {}; }                                       ///< every colliding pair
  static CollisionRequest first_pair() { return {.max_pairs = 1}; }                        ///< "do they touch?"
  static CollisionRequest capped(std::size_t n) { return {.max_pairs = n}; }               ///< at most n pairs
  static CollisionRequest approximate(int layer) { return {.approximate_layer = layer}; }  ///< superset
  /// A service's limit: at most `limit` pairs are an answer; the query stops at limit + 1 pairs,
  /// so a result with `complete == false` has passed it (a worker's max_pairs, net::Limits).
  static CollisionRequest past_limit(std::size_t limit) {
    return {.max_pairs = limit >= SIZE_MAX - 1 ? SIZE_MAX : limit + 1};
  }
};
inline CollisionRequest DefaultCollisionRequest() { return {}; }  ///< all pairs, exact, sorted
/// Empty when the request is usable, else a message naming the bad field.
std::string check(const CollisionRequest& request);

/// What a query found. Reuse one across queries: clear() keeps the capacity.
struct CollisionResult {
  std::vector<FacePair> pairs;     ///< (probe face, object face), file indices
  std::uint32_t probe_faces = 0;   ///< distinct probe faces in `pairs`
  std::uint32_t object_faces = 0;  ///< distinct object faces in `pairs`
  bool complete = true;            ///< false when the query stopped at max_pairs or max_work (more pairs may exist)
  bool bad_request = false;        ///< the request failed check(): nothing was computed
  CollideStats stats;              ///< traversal counters

  bool colliding() const { return !pairs.empty(); }                      ///< any pair found
  std::uint32_t contacts() const { return probe_faces + object_faces; }  ///< paper §3.5 "number of contacts"
  void clear();                                                          ///< empties, keeps capacity
};

/// The collision of one (probe, object) pair, kept between queries: the per-query caches are
/// sized on the first query and reused (later queries allocate nothing). Not thread-safe: one
/// per thread and pair.
class ComputeCollision {
 public:
  /// The pair to collide; the caches are sized on the first query.
  ComputeCollision(Body probe, Body object);
  /// Collides the bodies at their frames.
  void operator()(const CollisionRequest& request, CollisionResult& result);
  /// Collides the bodies at these frames (probe frame -> world, object frame -> world); the
  /// bodies' own frames are not changed.
  void operator()(const Pose& probe_frame, const Pose& object_frame, const CollisionRequest& request,
                  CollisionResult& result);
  /// Collides at a relative pose (probe frame -> object frame), the pose the rest of the
  /// project passes around; the bodies' frames are not used.
  void at_relative(const Pose& relative, const CollisionRequest& request, CollisionResult& result);

  /// Replaces the object and keeps the probe's caches (derived from the probe's tree, which take
  /// far longer to build than an object's): one probe against several objects or object blocks
  /// in turn. The object's caches are derived again on the next query.
  void set_object(Body object);

  /// Carries certificates between exact queries (geom::CoherentCollider, coherent.hpp): the same
  /// pairs, in less time when the probe moves little between queries (the haptic loop: a few
  /// hundredths of a millimetre a round). Off by default; turning it on or off forgets them.
  void set_coherent(bool on, const geom::CoherentConfig& config = {});
  /// The coherent collider when set_coherent(true) (its stats(), bytes()), else null.
  const geom::CoherentCollider* coherent() const { return coherent_.get(); }

  Body& probe() { return probe_; }    ///< the first body
  Body& object() { return object_; }  ///< the second body
  /// Heap held between queries (with the coherent collider's cache when on).
  std::size_t scratch_bytes() const { return scratch_.bytes() + (coherent_ ? coherent_->bytes() : 0); }

 private:
  Body probe_, object_;
  geom::CollideScratch scratch_;
  geom::CollideResult inner_;
  std::unique_ptr<geom::CoherentCollider> coherent_;
};

/// One query, with its own scratch (allocates; use ComputeCollision for repeated queries).
void collide(const Body& probe, const Body& object, const CollisionRequest& request, CollisionResult& result);

/// probe frame -> object frame for two bodies: object.frame()^-1 · probe.frame() (rigid frames).
Pose relative_pose(const Body& probe, const Body& object);
/// The same for two frames given directly.
Pose relative_pose(const Pose& probe_frame, const Pose& object_frame);

}  // namespace SPHERETOUCH_ABI
}  // namespace st
