// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// SphereTree: the layered boundary spheres of paper §3.3 (Fujiwara's octree-like hierarchy) over
/// one body, in its body-local frame. Balanced: every leaf holds floor(F/M) or ceil(F/M) faces
/// (M = ceil(F/leaf_faces)), the "almost constant number of faces per leaf" of the paper.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <span>
#include <vector>

#include <spheretouch/geom/mesh.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// How a SphereTree is built. Part of the tree file's hash (tree_io.hpp).
struct TreeConfig {
  /// Upper bound on faces per leaf; leaves hold floor(F/M) or ceil(F/M) faces, M = ceil(F/leaf_faces),
  /// so every leaf is in (leaf_faces/2, leaf_faces] once F >= leaf_faces. Default 24: since collide()
  /// filters a leaf pair's faces with 8-wide box masks, exact queries of hand_L2 x elephant at
  /// 100..1,500 contacts time best at 24..48 (8 is 30..45% slower, 16 about 10%), and 24 keeps
  /// leaf spheres (approximate mode) the smallest of those (perf/RESULTS.md at commit 09e4e24, "Collision core").
  std::uint32_t leaf_faces = 24;
};
inline TreeConfig DefaultTreeConfig() { return {}; }  ///< Box2D-style default config
inline constexpr std::uint32_t kMaxLeafFaces = 64;    ///< collide() keeps a leaf's faces in 64-bit masks
inline constexpr int kMaxChildren = 8;                ///< octree: up to 8 children per node
/// Deepest tree a file may hold: build() splits each node's leaves in up to 8 equal groups, so
/// 2^32 faces need at most 12 layers; 64 leaves room and keeps collide()'s stack small.
inline constexpr std::uint32_t kMaxTreeDepth = 64;

/// Hot node: the fields the descent touches, 24 bytes (Box2D v3 hot/cold split).
/// Sphere in the body-local frame, float, padded so it encloses every vertex below it EXACTLY
/// (see sphere_tree.cpp, "Conservative float spheres").
struct SphereNode {
  float centre[3];      ///< sphere centre, body-local mm (12 B)
  float radius;         ///< padded radius, mm (4 B)
  std::uint32_t first;  ///< inner: index of the first child (children contiguous); leaf: first slot in face_order
  std::uint16_t count;  ///< inner: number of children 1..8; leaf: number of faces
  std::uint8_t leaf;    ///< 1 for a leaf
  std::uint8_t depth;   ///< layer of this node (root = 0)
};
static_assert(sizeof(SphereNode) == 24, "hot node size is pinned");

/// Cold node: bookkeeping not read by the descent, 48 bytes.
struct SphereNodeCold {
  double centre[3];          ///< minimal enclosing sphere of the vertices (Welzl), body-local mm
  double radius;             ///< its radius (unpadded), mm
  std::uint32_t face_begin;  ///< faces below this node are face_order[face_begin, face_end)
  std::uint32_t face_end;    ///< one past the last slot
  std::uint32_t desc_end;    ///< descendants of an inner node are nodes [first, desc_end); == first for a leaf
  std::uint32_t parent;      ///< parent node, kNoNode for the root
};
static_assert(sizeof(SphereNodeCold) == 48, "cold node size is pinned");

inline constexpr std::uint32_t kNoNode = 0xffffffffu;  ///< "no such node"

/// Float AABB of one face, rounded outward (contains the exact double triangle), 24 bytes.
struct FaceBox {
  float lo[3];  ///< minimum corner, body-local mm
  float hi[3];  ///< maximum corner, body-local mm
};

/// Layered boundary spheres of one body. Node 0 is the root. Layout: the children of a node are
/// contiguous, and all descendants of a node are the contiguous range [first, desc_end), so a
/// subtree is {node} + one node range + one face_order range (easy to extract and ship).
struct SphereTree {
  TreeConfig params;                      ///< what it was built with
  std::uint64_t mesh_hash = 0;            ///< hash of the mesh's vertices, faces and params (tree_io.hpp)
  std::uint32_t num_vertices = 0;         ///< vertex count of the mesh it was built for
  std::uint32_t num_depths = 0;           ///< number of layers (max depth + 1)
  std::vector<SphereNode> nodes;          ///< hot nodes
  std::vector<SphereNodeCold> cold;       ///< cold nodes, same indices
  std::vector<std::uint32_t> face_order;  ///< face ids in leaf order (every face exactly once)
  std::vector<FaceBox> face_boxes;        ///< per slot of face_order: outward-rounded face AABB

  /// Builds the tree (single thread). Fails on an empty or invalid mesh or leaf_faces out of [1, 64].
  /// `groups` (optional): sizes of consecutive runs of faces in the mesh's face order (summing to
  /// the face count; empty runs are skipped) that no node below the top levels mixes. Each run
  /// gets the subtree a tree over that run alone would have, and the top levels split whole runs
  /// by the median of their centroids. A worker's share of the object's blocks is built this way:
  /// the blocks lie apart, and a leaf or sphere spanning two of them would enclose the gap.
  static Result<SphereTree> build(const Mesh& mesh, const TreeConfig& params = DefaultTreeConfig(),
                                  std::span<const std::uint32_t> groups = {});

  std::uint32_t num_faces() const { return static_cast<std::uint32_t>(face_order.size()); }  ///< faces covered
  std::uint32_t num_nodes() const { return static_cast<std::uint32_t>(nodes.size()); }       ///< nodes
  std::uint32_t num_leaves() const;                                                          ///< leaf count
  /// Node indices of layer n in depth-first (spatially coherent) order: the nodes of depth n, and
  /// leaves shallower than n standing for themselves. Covers every face exactly once.
  std::vector<std::uint32_t> layer(std::uint32_t n) const;
  /// Face ids below node i (face_order[face_begin, face_end)).
  const std::uint32_t* faces_begin(std::uint32_t i) const { return face_order.data() + cold[i].face_begin; }
  const std::uint32_t* faces_end(std::uint32_t i) const {
    return face_order.data() + cold[i].face_end;
  }                           ///< end of faces_begin
  std::size_t bytes() const;  ///< heap bytes held by the tree
};

/// Per group of faces (SphereTree::build()'s `groups`: sizes of consecutive runs of the face ids
/// 0..num_faces-1), the largest nodes whose faces all lie in that group, in depth-first order:
/// the roots to collide() that group alone from (CollideConfig::object_roots). A tree built with
/// these groups has one such node per non-empty group. Empty when a leaf mixes two groups (a tree
/// built without them) or the groups do not cover the faces.
std::vector<std::vector<std::uint32_t>> group_roots(const SphereTree& tree, std::size_t num_faces,
                                                    std::span<const std::uint32_t> groups);

/// How crowded the tree's densest spot is: the most leaves of at least half a leaf's radius whose
/// spheres meet that leaf's sphere (`leaf` names it), counted up to `stop` (the count stops
/// there). A surface has a few dozen at most (the neighbours around a point); faces piled on
/// each other (a block set made to cost N² triangle tests) have as many as the pile's leaves.
struct Crowding {
  std::uint32_t leaves = 0;      ///< the largest count found (≤ stop)
  std::uint32_t leaf = kNoNode;  ///< a leaf with that count
};
Crowding crowding(const SphereTree& tree, std::uint32_t stop);  ///< see Crowding

/// 64-bit hash of the mesh's vertex bytes (local + origin), faces, the build parameters and the
/// face groups (if any).
std::uint64_t tree_hash(const Mesh& mesh, const TreeConfig& params, std::span<const std::uint32_t> groups = {});

/// Minimal enclosing sphere of points (Welzl's algorithm, move-to-front variant, Gärtner 1999),
/// radius then enlarged to the largest computed distance so it encloses every point. Reorders pts.
void min_sphere(std::vector<Vec3>& pts, Vec3& centre, double& radius);

}  // namespace st::geom
