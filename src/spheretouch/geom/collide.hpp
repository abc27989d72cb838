// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// collide(): exact face-level collision of a probe (the hand) against an object by simultaneous
/// descent of their SphereTrees with the relative transform (paper §3.3, Coal/FCL traversal).
// Nothing is transformed wholesale: sphere centres and probe vertices are mapped as visited.
#pragma once
#include <spheretouch/abi.hpp>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/sphere_tree.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// Probe local frame -> object local frame (mesh.hpp): p_obj_local = R p_probe_local + t. The ONE arithmetic every
/// caller (collide, references in tests, tools) uses, so "the same transformed doubles" is literal.
struct RelTransform {
  Eigen::Matrix3d R;  ///< pose.linear()
  Vec3 t;             ///< R probe.origin + pose.translation() - object.origin, rounded once
};

/// R and t for `pose` (probe frame -> object frame). t is computed with error-free
/// transformations (fma TwoProduct + TwoSum) and rounded once, so origins at 1e6 mm lose nothing.
RelTransform transform_to_object(const Pose& pose, const Mesh& probe, const Mesh& object);

/// p mapped by rt: each coordinate fma(R_i0, x, fma(R_i1, y, fma(R_i2, z, t_i))), identical on every
/// compiler setting (no contraction freedom).
inline Vec3 apply(const RelTransform& rt, const Vec3& p) {
  Vec3 out;
  for (int i = 0; i < 3; ++i)
    out[i] = std::fma(rt.R(i, 0), p.x(), std::fma(rt.R(i, 1), p.y(), std::fma(rt.R(i, 2), p.z(), rt.t[i])));
  return out;
}

/// A colliding face pair, named by input-file face indices.
struct FacePair {
  std::uint32_t probe;                                                  ///< probe face index
  std::uint32_t object;                                                 ///< object face index
  friend bool operator==(const FacePair&, const FacePair&) = default;   ///< both indices equal
  friend auto operator<=>(const FacePair&, const FacePair&) = default;  ///< by probe, then object face
};

/// Distinct probe faces and distinct object faces of a pair list: paper §3.5's "number of
/// contacts" is their sum. The one definition every counter uses.
struct FaceCounts {
  std::uint32_t probe_faces = 0;                                         ///< distinct probe faces
  std::uint32_t object_faces = 0;                                        ///< distinct object faces
  std::uint32_t contacts() const { return probe_faces + object_faces; }  ///< paper §3.5
};
/// Counts the pairs' distinct faces (any order; `scratch` is reused, no allocation once warm).
FaceCounts count_faces(std::span<const FacePair> pairs, std::vector<std::uint32_t>& scratch);
/// The distinct faces of pairs sorted by (probe, object) and unique (a merged round's, as
/// net::RoundResult holds them): both lists ascending; `scratch` is reused (no allocation once warm).
void distinct_faces(std::span<const FacePair> pairs, std::vector<std::uint32_t>& probe_faces,
                    std::vector<std::uint32_t>& object_faces, std::vector<std::uint32_t>& scratch);

/// Sorts `ids` ascending and drops repeats, as std::sort + std::unique would, in a few linear
/// passes (an LSD radix sort of digits of at most 11 bits over the ids' used bits: 2 for a mesh
/// of up to ~4 million faces), a comparison sort below 256 ids. `scratch` is reused (no
/// allocation once warm).
void sort_distinct_ids(std::vector<std::uint32_t>& ids, std::vector<std::uint32_t>& scratch);

/// Sorts pairs by (probe, object), as std::sort would, in a few linear passes (an LSD radix
/// sort of digits of at most 11 bits over the key's used bits: 3 passes for two meshes of ~60,000 faces).
/// `scratch` is reused (no allocation once warm).
void sort_face_pairs(std::span<FacePair> pairs, std::vector<std::uint64_t>& scratch);

/// Face pairs gathered in sorted runs (each worker's answer, sorted where it was computed),
/// merged in the end without sorting them again: a k-way merge in log2(k) passes of std::merge,
/// or, when that takes more passes than sort_face_pairs' radix sort of the pairs' keys would
/// (k = 32 runs against 4 radix passes for two meshes of up to ~1 million faces), that sort: a
/// pass of either costs about the same per pair (32 runs of 1,482 pairs in all, from hand_L2 x
/// armadillo_L2: merged in 25 µs, radix-sorted in 14 µs; 16 runs: 16 and 14 µs; 8: 9 and 14).
/// Its scratch is kept: no allocation once warm.
class SortedRuns {
 public:
  void clear() { starts_.clear(); }                      ///< no runs
  void begin(std::size_t at) { starts_.push_back(at); }  ///< a run starts at index `at`
  /// Ends the run begun last, at the end of `pairs`, sorting it if it is not sorted.
  void end(std::vector<FacePair>& pairs);
  /// Merges the runs of `pairs` (the first starting at 0, each ending where the next begins, the
  /// last at the end) into one sorted sequence; then no runs.
  void merge(std::vector<FacePair>& pairs);

 private:
  std::vector<std::size_t> starts_, next_;
  std::vector<FacePair> merged_;
  std::vector<std::uint64_t> keys_;  // sort_face_pairs()'s room
};

/// Approximate-mode stop layers (CollideConfig::stop_layer).
inline constexpr int kExact = -2;        ///< full exact descent (default)
inline constexpr int kLeafSpheres = -1;  ///< stop at leaf spheres, no triangle tests

/// Work per object node (CollideConfig::node_work): where a query spent its triangle tests, so
/// that a caller holding blocks of the object (a worker) can tell which of them cost it the most.
/// Each leaf pair that tested candidate triangle pairs charges 1 plus their number to its object
/// leaf (in all, tri_pairs plus the leaf pairs that had any); sphere tests are not charged
/// (charging each cost 3-6 % of a query; the triangle tests are most of a contact's work). The
/// coherent collider charges the tests it makes (an answer it reuses costs nothing). The caller
/// sizes `work` to the object tree's nodes, zeroed; the query lists each node the first time it
/// charges it in `touched`; clear() zeroes those.
struct NodeWork {
  std::vector<std::uint32_t> work;     ///< per object node: work charged (saturates at UINT32_MAX)
  std::vector<std::uint32_t> touched;  ///< nodes with work > 0, in the order first charged
  /// Adds n (> 0) to `node`.
  void charge(std::uint32_t node, std::uint32_t n) {
    std::uint32_t& w = work[node];
    if (w == 0) touched.push_back(node);
    w = w > UINT32_MAX - n ? UINT32_MAX : w + n;
  }
  /// A leaf pair that tested `tris` candidate triangle pairs: 1 plus them to `leaf` (none: nothing).
  void charge_leaf_pair(std::uint32_t leaf, std::uint64_t tris) {
    if (tris != 0) charge(leaf, 1 + std::uint32_t(tris < UINT32_MAX - 1 ? tris : UINT32_MAX - 1));
  }
  /// Zeroes what the last queries charged.
  void clear() {
    for (std::uint32_t n : touched) work[n] = 0;
    touched.clear();
  }
};

/// What a query does.
struct CollideConfig {
  /// kExact: triangle tests. kLeafSpheres or a layer K >= 0: stop where both nodes are at layer K
  /// (or leaves) and report every face pair of the overlapping sphere pair (a superset of exact).
  int stop_layer = kExact;
  bool sort_pairs = false;  ///< sort `pairs` by (probe, object)
  /// With restrict_object: only these object subtree roots (a worker's blocks, partition.hpp; may
  /// be empty = nothing). Must be disjoint subtrees (e.g. nodes of one layer).
  std::span<const std::uint32_t> object_roots{};
  bool restrict_object = false;   ///< use object_roots instead of the whole object
  bool approx_face_pairs = true;  ///< approximate mode: also expand sphere pairs into face pairs
  /// Stop the traversal once more than this many pairs are found (stats.pair_limit_hit); the result
  /// then holds at most max_pairs plus one leaf pair's worth (64 × 64). A worker answering a
  /// hostile block set (every face on top of every other) must not compute N² pairs first.
  std::size_t max_pairs = SIZE_MAX;
  /// Stop the traversal once its work (CollideStats::work(): sphere tests, candidate triangle
  /// pairs and exact tests, weighted by their cost) exceeds this (stats.work_limit_hit). Pairs
  /// bound what a query returns, not what it costs: faces piled so that their boxes overlap but
  /// they never touch give N² tests and no pair. A worker sizes it from the request (Limits).
  std::uint64_t max_work = UINT64_MAX;
  /// Decide triangle pairs with the certified float filter first (collide_traversal.inl, up to 16
  /// pairs per instruction on AVX-512), the exact test only for those it leaves undecided. Exact
  /// either way (the same pairs); false runs the exact test on every candidate (for measuring).
  bool tri_filter = true;
  /// Exact mode: charge the triangle tests to the object's leaves (NodeWork; `work` sized to the
  /// object tree's nodes). Null: not counted.
  NodeWork* node_work = nullptr;
};
inline CollideConfig DefaultCollideConfig() { return {}; }  ///< exact, unsorted, whole object

/// Candidate triangle pairs the leaf stage gathers before its filter runs (one AVX-512 step).
inline constexpr std::uint32_t kTriBatch = 16;

/// Work units (CollideStats::work()) of one exact triangle test: a sphere test or a candidate
/// pair through the float filter is one unit (a few ns), an exact test 40–80 ns.
inline constexpr std::uint64_t kExactTestWork = 16;
/// Work units of one exact-arithmetic predicate evaluation (predicates.hpp), which a vertex in
/// the other triangle's plane forces: ~0.1–0.5 µs each, a test making up to a dozen.
inline constexpr std::uint64_t kExpansionWork = 64;

/// Counters of one query (Box2D-style, for tests and benchmarks).
struct CollideStats {
  std::uint64_t node_pairs = 0;    ///< sphere pairs tested
  std::uint64_t leaf_pairs = 0;    ///< leaf-leaf pairs reached (exact mode)
  std::uint64_t tri_pairs = 0;     ///< candidate triangle pairs (face boxes overlapping) tested
  std::uint64_t tri_exact = 0;     ///< of those, decided by tri_tri_overlap (the filter's undecided)
  std::uint64_t exact_evals = 0;   ///< exact-arithmetic predicate evaluations (inputs on a plane or line)
  std::uint64_t sphere_pairs = 0;  ///< approximate mode: overlapping sphere pairs reported
  /// probe leaves whose vertices were transformed and face boxes made (exact mode; once a leaf a
  /// query): a worker pays this for every probe leaf its blocks meet, so it grows with the workers
  std::uint64_t probe_leaves = 0;
  /// traversals stopped: a tree deeper than its num_depths (or > kMaxTreeDepth); 0 for valid trees
  std::uint64_t truncated = 0;
  bool pair_limit_hit = false;  ///< the traversal stopped at CollideConfig::max_pairs
  bool work_limit_hit = false;  ///< the traversal stopped at CollideConfig::max_work
  /// The work the budget counts, in units of 3-15 ns on this VM (a sphere test ~3 ns, a candidate
  /// triangle pair through the filter ~10-15 ns in a pile):
  /// sphere tests + candidate triangle pairs + kExactTestWork × exact tests + kExpansionWork ×
  /// exact-arithmetic evaluations.
  std::uint64_t work() const {
    return node_pairs + tri_pairs + kExactTestWork * tri_exact + kExpansionWork * exact_evals;
  }
};

/// Output of a query; caller-owned, reused across queries (clear() keeps capacity).
struct CollideResult {
  std::vector<FacePair> pairs;  ///< colliding (or, approximate mode, candidate) face pairs
  std::vector<std::pair<std::uint32_t, std::uint32_t>> sphere_pairs;  ///< approximate mode: (probe node, object node)
  std::uint32_t probe_faces = 0;                                      ///< distinct probe faces in `pairs`
  std::uint32_t object_faces = 0;                                     ///< distinct object faces in `pairs`
  CollideStats stats;                                                 ///< counters
  std::uint32_t contacts() const { return probe_faces + object_faces; }  ///< paper §3.5 "number of contacts"
  /// Empties the result for the next query, keeping the vectors' capacity.
  void clear() {
    pairs.clear();
    sphere_pairs.clear();
    probe_faces = object_faces = 0;
    stats = {};
  }
};

/// Per-caller scratch: per-query caches of transformed probe vertices, centres and leaf face boxes
/// (generation stamps), contact stamps, explicit stack. Sized on first use for a (probe, object) pair; later queries allocate nothing.
class CollideScratch {
 public:
  /// Sizes everything for these meshes/trees (also done lazily by collide()).
  void prepare(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree);
  /// prepare() unless it was done for these meshes and trees already (what collide() does first).
  void prepare_for(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree);
  /// Heap bytes held (the per-query caches and what is derived from the two trees).
  std::size_t bytes() const;
  /// Sorts pairs by (probe, object) with the scratch's keys (sort_face_pairs).
  void sort(std::span<FacePair> pairs) { sort_face_pairs(pairs, sort_keys_); }
  /// A new query's generation: what each query stamps its per-node caches with.
  std::uint32_t next_generation();

 private:
  void prepare_probe(const Mesh& probe, const SphereTree& probe_tree);  // prepare()'s probe part
  template <class Lanes>
  friend struct CollideQuery;  // collide.cpp: one per instruction set
  template <class Lanes>
  friend struct CoherentQuery;  // coherent_traversal.inl: the coherent collider's round
  friend class CoherentCollider;
  friend void collide(const Mesh&, const SphereTree&, const Mesh&, const SphereTree&, const Pose&, const CollideConfig&,
                      CollideScratch&, CollideResult&);
  std::uint32_t gen_ = 0;
  std::vector<std::uint64_t> sort_keys_;  // sort_face_pairs' scratch (CollideConfig::sort_pairs)
  // Probe leaves as little meshes, so a query transforms a leaf's vertices in one sequential pass
  // (derived from the probe tree once, keyed by pkey_/phash_):
  // Vertices are held by coordinate (x of every leaf vertex, then y, then z: component c of vertex
  // v at c * nverts_ + v), so a leaf's transform is three sequential streams the compiler vectorizes.
  std::vector<std::array<std::uint32_t, 2>> lvrange_;  // probe leaf node -> its vertices [begin, end) in lverts_
  std::vector<double> lverts_;  // distinct vertices of each leaf, leaves one after another, probe-local, SoA
  std::vector<std::array<std::uint32_t, 3>> lidx_;  // probe slot -> its face's vertices as indices into lverts_
  std::vector<double> ptx_;  // lverts_ transformed into object-local, SoA (valid for leaves stamped this query)
  std::size_t nverts_ = 0;   // the leaves' vertices: the stride of lverts_ and ptx_
  /// Leaf vertex v transformed this query (the very doubles the exact test sees).
  Vec3 ptx(std::uint32_t v) const { return {ptx_[v], ptx_[nverts_ + v], ptx_[2 * nverts_ + v]}; }
  const void* pkey_ = nullptr;         // probe tree the above was derived from (nodes.data()) ...
  std::uint64_t phash_ = 0;            // ... and its mesh_hash
  std::vector<std::uint32_t> cstamp_;  // probe node -> generation its CHILDREN's spheres were transformed
  std::vector<float> psph_;  // probe node spheres in object-local, SoA (x, y, z, s·r + slack) by node, stride nstride_p_
  std::size_t nstride_p_ = 0;               // probe nodes + padding for 8-wide loads
  std::vector<float> osph_;                 // object node spheres, SoA (x, y, z, r) by node, stride nstride_o_
  std::size_t nstride_o_ = 0;               // object nodes + padding for 8-wide loads
  std::vector<std::array<float, 8>> obox_;  // object leaf: union of its face boxes (lo xyz, hi xyz, pad)
  const void* osph_key_ = nullptr;          // object tree osph_ was filled from (nodes.data()) ...
  std::uint64_t osph_hash_ = 0;             // ... and its mesh_hash
  std::vector<std::uint32_t> lstamp_;       // probe leaf node -> generation it was transformed (ptx_, vbnd_, lbox_)
  std::vector<std::array<float, 8>> lbox_;  // probe leaf: union of its face boxes (lo xyz, hi xyz); [6] != 0: in pbox_
  std::vector<float> vbnd_;                 // ptx_'s float bounds, SoA: lo x, y, z, hi x, y, z (stride nverts_)
  std::vector<float> pbox_;                 // probe face boxes by slot, SoA: component k at k * pstride_
  std::size_t pstride_ = 0;                 // slots + padding for whole-vector loads
  std::vector<std::uint32_t> pmark_;        // probe face -> generation it was counted as a contact
  std::vector<std::uint32_t> omark_;        // object face -> generation it was counted
  std::vector<std::pair<std::uint32_t, std::uint32_t>> stack_;
  std::uint32_t stack_cap_ = 0;
};

/// Collides probe (posed by `pose`: probe frame -> object frame) with object. The pair
/// set is exactly {(p, o) : tri_tri_overlap(apply(rt, probe p's vertices), object o's vertices)}
/// (restricted to object_roots if given). Never throws; allocates only while warming up.
void collide(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree,
             const Pose& pose, const CollideConfig& options, CollideScratch& scratch, CollideResult& result);

}  // namespace st::geom
