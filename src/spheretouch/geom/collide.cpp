// SPDX-License-Identifier: BSD-3-Clause
// Simultaneous descent of two SphereTrees (paper §3.3; traversal after Coal/FCL: relative
// transform, larger node first, explicit stack), then a leaf-pair stage of box masks.
//
// Why no pair is ever missed. Let x be a point common to probe triangle P' (the fl-transformed
// vertices apply(rt, v)) and object triangle O. Every filter tests a convex set that contains x:
//  * object node sphere (c_o, r_o): contains O's vertices exactly (sphere_tree.cpp), hence O, hence x;
//  * probe node sphere: each apply(rt, v) lies within s·r_p of R c_p + t, where s >= ||R||_2
//    (Gershgorin bound on R^T R, so slightly non-orthonormal poses are covered) — hence within
//    s·r_p + (rounding of apply and of the centre) of the computed centre;
//  * probe face box: min/max of the very doubles tri_tri_overlap sees, widened to float (exact
//    containment, float_below/float_above); a probe leaf box is the union of its face boxes;
//  * object face box: float rounded outward from the doubles (exact containment); an object leaf
//    box is the union of its face boxes.
// Box against box is pure comparison (no arithmetic), so it rejects only disjoint boxes.
// Sphere-sphere (sphere_mask) and leaf box-sphere tests run in float. Let M bound every centre,
// radius and coordinate involved (M = |t| + s(|c_p root| + r_p root) + |c_o root| + r_o root:
// every node's centre lies in the hull of its vertices, hence in the root sphere). The float
// probe centre is within 2^-24·M·√3 + 1e-14·M of the exact R c_p + t; radii are rounded once;
// the differences, squares and sums lose at most a few 2^-24 relative. Together that is below
// 4e-7·M in distance, and the probe radius (or, box-sphere, the object radius) is widened by
// slack = 1e-5·M, 25x that. So a filter rejects only when the true sets are disjoint, and the final
// set equals {(p, o) : tri_tri_overlap(same doubles)}. Each face is in exactly one leaf and each
// leaf pair is reached at most once, so no pair is reported twice.
#include <spheretouch/geom/collide.hpp>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>
#include <limits>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/coherent.hpp>
#include <spheretouch/geom/predicates.hpp>
#include <spheretouch/geom/simd.hpp>
#include <spheretouch/geom/tri_tri.hpp>

// GCC 12's AVX-512 min/max intrinsics pass _mm512_undefined_ps() (a self-initialised variable) as
// the unused merge source, which -Wmaybe-uninitialized reports wherever they are inlined.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

namespace st::inline SPHERETOUCH_ABI::geom {
namespace {

// Error-free transformations (Dekker/Knuth; Ogita, Rump, Oishi 2005 "Accurate sum and dot product").
inline void two_sum(double a, double b, double& s, double& e) {
  s = a + b;
  const double z = s - a;
  e = (a - (s - z)) + (b - z);
}

// sum of terms, accurate to ~1 ulp of the result (Sum2 of Ogita-Rump-Oishi, products split exactly).
double accurate_sum(const double* prod_a, const double* prod_b, int np, const double* add, int na) {
  double s = 0, comp = 0;
  for (int i = 0; i < np; ++i) {
    const double p = prod_a[i] * prod_b[i];
    const double pe = std::fma(prod_a[i], prod_b[i], -p);
    double e;
    two_sum(s, p, s, e);
    comp += e + pe;
  }
  for (int i = 0; i < na; ++i) {
    double e;
    two_sum(s, add[i], s, e);
    comp += e;
  }
  return s + comp;
}

inline Vec3 centre_of(const SphereNode& n) { return Vec3(n.centre[0], n.centre[1], n.centre[2]); }

}  // namespace

RelTransform transform_to_object(const Pose& pose, const Mesh& probe, const Mesh& object) {
  RelTransform rt;
  rt.R = pose.linear();
  for (int i = 0; i < 3; ++i) {
    const double a[3] = {rt.R(i, 0), rt.R(i, 1), rt.R(i, 2)};
    const double b[3] = {probe.origin.x(), probe.origin.y(), probe.origin.z()};
    const double add[2] = {pose.translation()[i], -object.origin[i]};
    rt.t[i] = accurate_sum(a, b, 3, add, 2);
  }
  return rt;
}

std::uint32_t CollideScratch::next_generation() {
  if (++gen_ == 0) {
    std::fill(cstamp_.begin(), cstamp_.end(), 0u);
    std::fill(lstamp_.begin(), lstamp_.end(), 0u);
    std::fill(pmark_.begin(), pmark_.end(), 0u);
    std::fill(omark_.begin(), omark_.end(), 0u);
    gen_ = 1;
  }
  return gen_;
}

namespace {
// The tree was built for this mesh: every face it names is one of the mesh's (a worker's tree of
// its blocks names a subset). O(faces): evaluated only where asserts are checked.
[[maybe_unused]] bool names_faces_of(const SphereTree& tree, const Mesh& mesh) {
  for (const std::uint32_t f : tree.face_order)
    if (f >= mesh.faces.size()) return false;
  return true;
}
}  // namespace

void CollideScratch::prepare(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object,
                             const SphereTree& object_tree) {
  ST_ASSERT(names_faces_of(probe_tree, probe), "collide(): the probe tree was built for the probe mesh");
  ST_ASSERT(names_faces_of(object_tree, object), "collide(): the object tree was built for the object mesh");
  // The probe's part is derived again only for another probe: a client answering several object
  // blocks (net::ScatterConfig::assist_blocks) switches object trees every query, and the probe's
  // leaves take far longer to derive than a block's spheres.
  const bool same_probe = pkey_ == probe_tree.nodes.data() && phash_ == probe_tree.mesh_hash &&
                          lidx_.size() == probe_tree.face_order.size() && cstamp_.size() == probe_tree.nodes.size() &&
                          pmark_.size() == probe.faces.size();
  if (!same_probe) prepare_probe(probe, probe_tree);
  // Object spheres as float SoA, so the children of a node (contiguous) load as whole vectors.
  nstride_o_ = object_tree.nodes.size() + kMaxChildren;
  osph_.assign(4 * nstride_o_, 0.0f);
  for (std::size_t i = 0; i < object_tree.nodes.size(); ++i) {
    const SphereNode& h = object_tree.nodes[i];
    for (int k = 0; k < 3; ++k) osph_[k * nstride_o_ + i] = h.centre[k];
    osph_[3 * nstride_o_ + i] = h.radius;
  }
  obox_.assign(object_tree.nodes.size(), {});
  for (std::size_t i = 0; i < object_tree.nodes.size(); ++i) {
    const SphereNode& h = object_tree.nodes[i];
    if (!h.leaf) continue;
    const float inf = std::numeric_limits<float>::infinity();
    std::array<float, 8> b = {inf, inf, inf, -inf, -inf, -inf, 0, 0};
    for (std::uint32_t slot = h.first; slot < h.first + h.count; ++slot)
      for (int k = 0; k < 3; ++k) {
        b[k] = std::min(b[k], object_tree.face_boxes[slot].lo[k]);
        b[3 + k] = std::max(b[3 + k], object_tree.face_boxes[slot].hi[k]);
      }
    obox_[i] = b;
  }
  osph_key_ = object_tree.nodes.data();
  osph_hash_ = object_tree.mesh_hash;
  if (omark_.size() != object.faces.size()) omark_.assign(object.faces.size(), 0);
  // DFS with "replace one entry by at most 8": depth of the stack <= 1 + 7 (Dp + Do).
  const std::uint32_t cap = 8 * (probe_tree.num_depths + object_tree.num_depths) + 8;
  if (stack_.size() < cap) stack_.resize(cap);
  stack_cap_ = static_cast<std::uint32_t>(stack_.size());
}

void CollideScratch::prepare_probe(const Mesh& probe, const SphereTree& probe_tree) {
  auto fit = [](auto& v, std::size_t n) {
    if (v.size() != n) v.assign(n, {});
  };
  // Probe leaves as little meshes (distinct vertices per leaf, faces as indices into them).
  lvrange_.assign(probe_tree.nodes.size(), {0, 0});
  std::vector<Vec3> verts;  // AoS while the leaves are walked, then SoA into lverts_
  lidx_.assign(probe_tree.face_order.size(), {0, 0, 0});
  {
    std::vector<std::uint32_t> at(probe.local.size(), kNoNode), stamp(probe.local.size(), kNoNode);
    for (std::uint32_t i = 0; i < probe_tree.num_nodes(); ++i) {
      const SphereNode& h = probe_tree.nodes[i];
      if (!h.leaf) continue;
      const auto begin = static_cast<std::uint32_t>(verts.size());
      for (std::uint32_t slot = h.first; slot < h.first + h.count; ++slot) {
        const Tri& t = probe.faces[probe_tree.face_order[slot]];
        for (int k = 0; k < 3; ++k) {
          const std::uint32_t v = t[k];
          if (stamp[v] != i) {
            stamp[v] = i;
            at[v] = static_cast<std::uint32_t>(verts.size());
            verts.push_back(probe.local[v]);
          }
          lidx_[slot][k] = at[v];
        }
      }
      lvrange_[i] = {begin, static_cast<std::uint32_t>(verts.size())};
    }
  }
  nverts_ = verts.size();
  lverts_.assign(3 * nverts_, 0.0);
  lverts_.shrink_to_fit();
  for (std::size_t v = 0; v < nverts_; ++v)
    for (int c = 0; c < 3; ++c) lverts_[c * nverts_ + v] = verts[v][c];
  ptx_.assign(3 * nverts_, 0.0);
  ptx_.shrink_to_fit();
  vbnd_.assign(6 * nverts_, 0.0f);
  vbnd_.shrink_to_fit();
  pkey_ = probe_tree.nodes.data();
  phash_ = probe_tree.mesh_hash;
  fit(cstamp_, probe_tree.nodes.size());
  nstride_p_ = probe_tree.nodes.size() + kMaxChildren;
  psph_.assign(4 * nstride_p_, 0.0f);
  fit(lstamp_, probe_tree.nodes.size());
  lbox_.resize(probe_tree.nodes.size());
  pstride_ = probe_tree.face_order.size() + kMaxLeafFaces;  // whole-vector loads past a leaf's end stay inside
  pbox_.assign(6 * pstride_, 0.0f);
  fit(pmark_, probe.faces.size());
}

std::size_t CollideScratch::bytes() const {
  auto b = [](const auto& v) { return v.capacity() * sizeof(v[0]); };
  return b(lvrange_) + b(lverts_) + b(lidx_) + b(ptx_) + b(cstamp_) + b(psph_) + b(osph_) + b(obox_) + b(lstamp_) +
         b(lbox_) + b(vbnd_) + b(pbox_) + b(pmark_) + b(omark_) + b(stack_) + b(sort_keys_);
}

// One query, traversal and leaf stage, per instruction set (collide_traversal.inl; the primary
// template is never defined). Every ISA gives the same masks, so the same pairs and counters.
template <class Lanes>
struct CollideQuery;
template <class Lanes>
struct CoherentQuery;

#define ST_COLLIDE_SIMD simd::scalar
#define ST_COLLIDE_WIDE_SIMD simd::scalar
#include "collide_traversal.inl"
#include "coherent_traversal.inl"
#undef ST_COLLIDE_SIMD
#undef ST_COLLIDE_WIDE_SIMD
#if defined(ST_SIMD_X86)
#define ST_COLLIDE_SIMD simd::sse2
#define ST_COLLIDE_WIDE_SIMD simd::sse2
#include "collide_traversal.inl"
#include "coherent_traversal.inl"
#undef ST_COLLIDE_SIMD
#undef ST_COLLIDE_WIDE_SIMD
ST_TARGET_AVX2_BEGIN
#define ST_COLLIDE_SIMD simd::avx2
#define ST_COLLIDE_WIDE_SIMD simd::avx2
#include "collide_traversal.inl"
#include "coherent_traversal.inl"
#undef ST_COLLIDE_SIMD
#undef ST_COLLIDE_WIDE_SIMD
ST_TARGET_END
ST_TARGET_AVX512_BEGIN
#define ST_COLLIDE_SIMD simd::avx2
#define ST_COLLIDE_WIDE_SIMD simd::avx512
#include "collide_traversal.inl"
#include "coherent_traversal.inl"
#undef ST_COLLIDE_SIMD
#undef ST_COLLIDE_WIDE_SIMD
ST_TARGET_END
#endif

namespace {

// What every query on a pose needs besides the trees: the transform, the bound s >= ||R||_2,
// the float tests' slack and the magnitude of the coordinates, and the scratch's generation.
struct QueryFrame {
  RelTransform rt;
  double s = 1;
  float slack = 0;
  double mag = 0;
  std::uint32_t gen = 0;
};

// Calls f(std::type_identity<Lanes>{}) with the lanes of the ISA simd::active_isa() names.
template <class F>
auto on_active_isa(F&& f) {
  switch (simd::active_isa()) {
#if defined(ST_SIMD_X86)
    case simd::Isa::avx512:
      return f(std::type_identity<simd::avx512::Lanes>{});
    case simd::Isa::avx2:
      return f(std::type_identity<simd::avx2::Lanes>{});
    case simd::Isa::sse2:
      return f(std::type_identity<simd::sse2::Lanes>{});
#endif
    default:
      return f(std::type_identity<simd::scalar::Lanes>{});
  }
}

// The query on one ISA's kernels: everything but the set-up, which is the same for all.
template <class Lanes>
void run_query(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree,
               const CollideConfig& options, CollideScratch& scratch, CollideResult& result, const QueryFrame& f) {
  CollideQuery<Lanes> q{probe, probe_tree, object, object_tree, options, scratch, result, f.rt};
  q.gen = f.gen;
  q.exact = options.stop_layer == kExact;
  q.stop = options.stop_layer >= 0 ? static_cast<std::uint32_t>(options.stop_layer) : 0xffffffffu;
  q.s = f.s;
  q.slack = f.slack;
  if (!options.restrict_object) {
    q.descend(0, 0);
  } else {
    for (const std::uint32_t r : options.object_roots)
      if (r < object_tree.num_nodes() && !result.stats.pair_limit_hit && !result.stats.work_limit_hit) q.descend(0, r);
  }
  result.stats.exact_evals = detail::exact_evaluations - q.evals0;
}

// The query on the active ISA, sorted if asked.
void query(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree,
           const CollideConfig& options, CollideScratch& scratch, CollideResult& result, const QueryFrame& f) {
  on_active_isa([&](auto isa) {
    run_query<typename decltype(isa)::type>(probe, probe_tree, object, object_tree, options, scratch, result, f);
  });
  if (options.sort_pairs) scratch.sort(result.pairs);
}

// The coherent collider's round on one ISA's kernels (coherent_traversal.inl).
template <class Lanes>
bool run_coherent(CoherentCollider& cc, const Mesh& probe, const SphereTree& probe_tree, const Mesh& object,
                  const SphereTree& object_tree, const CollideConfig& options, CollideScratch& scratch,
                  CollideResult& result, const QueryFrame& f, std::uint32_t round, double reach, std::uint32_t builds,
                  bool rerooting) {
  CoherentQuery<Lanes> q{{probe, probe_tree, object, object_tree, options, scratch, result, f.rt}, cc};
  q.gen = f.gen;
  q.s = f.s;
  q.slack = f.slack;
  q.round = round;
  q.reach = reach;
  q.reach_f = static_cast<float>(reach * (1 - 1e-6));
  q.builds_left = builds * q.kBuildUnits;
  q.rerooting = rerooting;
  return q.run();
}

// Checks the inputs, readies the scratch and fills `f`; false when there is nothing to collide
// (result then says why, as collide() documents).
bool frame_query(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree,
                 const Pose& pose, CollideScratch& scratch, CollideResult& result, QueryFrame& f) {
  if (probe_tree.nodes.empty() || object_tree.nodes.empty()) return false;
  if (!pose.matrix().allFinite()) return false;  // boundaries validate poses; never crash here
  if (probe_tree.num_depths > kMaxTreeDepth || object_tree.num_depths > kMaxTreeDepth) {
    result.stats.truncated = 1;  // the stack is sized from num_depths: never from an unchecked value
    return false;
  }
  scratch.prepare_for(probe, probe_tree, object, object_tree);
  f.rt = transform_to_object(pose, probe, object);
  // s >= ||R||_2: sqrt of the largest row sum of |R^T R| (Gershgorin), widened for its rounding.
  const Eigen::Matrix3d G = f.rt.R.transpose() * f.rt.R;
  const double g = G.cwiseAbs().rowwise().sum().maxCoeff();
  f.s = std::sqrt(g) * (1 + 1e-12);
  const SphereNode& rp = probe_tree.nodes[0];
  const SphereNode& ro = object_tree.nodes[0];
  f.mag = f.rt.t.norm() + f.s * (centre_of(rp).norm() + rp.radius) + centre_of(ro).norm() + ro.radius;
  f.slack = static_cast<float>(1e-5 * f.mag) + 1e-30f;
  f.gen = scratch.next_generation();
  return true;
}

// collide() would answer nothing after one sphere test per object root: the probe's root sphere
// is apart from each root the query descends from, by more than the float tests' slack (so the
// float test collide() makes agrees; the padded radii enclose every face, so no pair is missed).
bool roots_apart(const SphereTree& probe_tree, const SphereTree& object_tree, const CollideConfig& options,
                 const QueryFrame& f, std::uint64_t& tests) {
  const SphereNode& rp = probe_tree.nodes[0];
  const Vec3 c = apply(f.rt, centre_of(rp));
  const double r = f.s * rp.radius + f.slack;
  const auto apart = [&](std::uint32_t o) {
    ++tests;
    const SphereNode& ro = object_tree.nodes[o];
    return (c - centre_of(ro)).norm() > r + ro.radius + f.slack;
  };
  if (!options.restrict_object) return apart(0);
  for (const std::uint32_t o : options.object_roots)
    if (o < object_tree.num_nodes() && !apart(o)) return false;
  return true;
}

}  // namespace

void SortedRuns::end(std::vector<FacePair>& pairs) {
  const auto first = pairs.begin() + std::ptrdiff_t(starts_.empty() ? 0 : starts_.back());
  if (!std::is_sorted(first, pairs.end())) std::sort(first, pairs.end());
}

namespace {
constexpr int kRadixDigitBits = 11;  // radix_passes(): digits of at most this many bits

// The widths of the pairs' largest probe and object indices (an or of them has the max's width).
struct KeyBits {
  int probe = 0, object = 0;
};
KeyBits key_bits(std::span<const FacePair> pairs) {
  std::uint32_t probe = 0, object = 0;
  for (const FacePair& p : pairs) probe |= p.probe, object |= p.object;
  return {int(std::bit_width(probe)), int(std::bit_width(object))};
}
// sort_face_pairs() with the key widths known (defined with radix_passes, below).
void sort_pairs_keyed(std::span<FacePair> pairs, std::vector<std::uint64_t>& scratch, KeyBits kb);
}  // namespace

void SortedRuns::merge(std::vector<FacePair>& pairs) {
  starts_.push_back(pairs.size());
  std::size_t runs = 0;  // non-empty ones
  for (std::size_t j = 0; j + 1 < starts_.size(); ++j) runs += starts_[j + 1] > starts_[j];
  if (runs > 2) {  // the merge's passes against the radix sort's
    const KeyBits kb = key_bits(pairs);
    const int bits = kb.probe + kb.object;
    if (int(std::bit_width(runs - 1)) > std::max(1, (bits + kRadixDigitBits - 1) / kRadixDigitBits)) {
      sort_pairs_keyed(pairs, keys_, kb);
      starts_.clear();
      return;
    }
  }
  while (starts_.size() > 2) {
    merged_.resize(pairs.size());
    next_.clear();
    for (std::size_t j = 0; j + 1 < starts_.size(); j += 2) {
      const auto a = std::ptrdiff_t(starts_[j]), b = std::ptrdiff_t(starts_[j + 1]);
      if (j + 2 < starts_.size())
        std::merge(pairs.begin() + a, pairs.begin() + b, pairs.begin() + b,
                   pairs.begin() + std::ptrdiff_t(starts_[j + 2]), merged_.begin() + a);
      else
        std::copy(pairs.begin() + a, pairs.begin() + b, merged_.begin() + a);
      next_.push_back(starts_[j]);
    }
    next_.push_back(pairs.size());
    pairs.swap(merged_);
    starts_.swap(next_);
  }
  starts_.clear();
}

namespace {
// LSD radix passes over the keys a[0, n), b[0, n) their room: the fewest digits of at most 11
// bits that cover the keys' `bits`, as even as they go (20 bits: two of 10), one stable counting
// pass each, lowest first; a digit every key shares moves nothing and is skipped. Returns the
// array that holds the keys ascending (a or b).
template <class Key>
Key* radix_passes(Key* a, Key* b, std::size_t n, int bits) {
  constexpr int kMaxDigit = kRadixDigitBits;
  const int passes = std::max(1, (bits + kMaxDigit - 1) / kMaxDigit), digit = (bits + passes - 1) / passes;
  const std::size_t buckets = std::size_t(1) << digit;
  std::uint32_t count[std::size_t(1) << kMaxDigit];
  for (int shift = 0; shift < bits; shift += digit) {
    std::fill(count, count + buckets, 0u);
    for (std::size_t i = 0; i < n; ++i) ++count[(a[i] >> shift) & (buckets - 1)];
    if (count[(a[0] >> shift) & (buckets - 1)] == n) continue;
    std::uint32_t sum = 0;
    for (std::size_t j = 0; j < buckets; ++j) sum += std::exchange(count[j], sum);
    for (std::size_t i = 0; i < n; ++i) b[count[(a[i] >> shift) & (buckets - 1)]++] = a[i];
    std::swap(a, b);
  }
  return a;
}

// sort_distinct_ids on ids[0, n) with tmp[0, n) for the passes: the count of distinct ids, which
// are left ascending in ids[0, count).
std::size_t sort_distinct(std::uint32_t* ids, std::size_t n, std::uint32_t* tmp) {
  if (n < 256) {  // a few: the comparison sort is as quick as clearing the counts
    std::sort(ids, ids + n);
  } else {
    const std::uint32_t* sorted = radix_passes(ids, tmp, n, std::bit_width(*std::max_element(ids, ids + n)));
    if (sorted != ids) std::copy(sorted, sorted + n, ids);
  }
  ST_ASSERT(std::is_sorted(ids, ids + n), "the radix passes leave the ids ascending");
  return static_cast<std::size_t>(std::unique(ids, ids + n) - ids);
}

void sort_pairs_keyed(std::span<FacePair> pairs, std::vector<std::uint64_t>& scratch, KeyBits kb) {
  const std::size_t n = pairs.size();
  if (n < 64) {  // a handful: the comparison sort is quicker than clearing the counts
    std::sort(pairs.begin(), pairs.end());
    return;
  }
  const int object_bits = kb.object, bits = kb.probe + kb.object;
  scratch.resize(2 * n);
  std::uint64_t* keys = scratch.data();
  // The order of the keys is (probe, object).
  for (std::size_t i = 0; i < n; ++i) keys[i] = (std::uint64_t(pairs[i].probe) << object_bits) | pairs[i].object;
  const std::uint64_t* sorted = radix_passes(keys, keys + n, n, bits);
  const std::uint64_t object_mask = (std::uint64_t(1) << object_bits) - 1;
  for (std::size_t i = 0; i < n; ++i)
    pairs[i] = {std::uint32_t(sorted[i] >> object_bits), std::uint32_t(sorted[i] & object_mask)};
  ST_ASSERT(std::is_sorted(pairs.begin(), pairs.end()), "the radix passes leave the pairs in (probe, object) order");
}
}  // namespace

void sort_face_pairs(std::span<FacePair> pairs, std::vector<std::uint64_t>& scratch) {
  sort_pairs_keyed(pairs, scratch, key_bits(pairs));
}

void sort_distinct_ids(std::vector<std::uint32_t>& ids, std::vector<std::uint32_t>& scratch) {
  scratch.resize(ids.size());
  ids.resize(sort_distinct(ids.data(), ids.size(), scratch.data()));
}

FaceCounts count_faces(std::span<const FacePair> pairs, std::vector<std::uint32_t>& scratch) {
  const std::size_t n = pairs.size();
  scratch.resize(2 * n);  // the ids, then the passes' room
  const auto distinct = [&](auto field) {
    for (std::size_t i = 0; i < n; ++i) scratch[i] = pairs[i].*field;
    return static_cast<std::uint32_t>(sort_distinct(scratch.data(), n, scratch.data() + n));
  };
  return {distinct(&FacePair::probe), distinct(&FacePair::object)};
}

void distinct_faces(std::span<const FacePair> pairs, std::vector<std::uint32_t>& probe_faces,
                    std::vector<std::uint32_t>& object_faces, std::vector<std::uint32_t>& scratch) {
  ST_ASSERT(std::is_sorted(pairs.begin(), pairs.end()), "distinct_faces takes pairs sorted by (probe, object)");
  probe_faces.clear();
  object_faces.clear();
  for (const FacePair& f : pairs) {
    if (probe_faces.empty() || probe_faces.back() != f.probe) probe_faces.push_back(f.probe);
    object_faces.push_back(f.object);
  }
  sort_distinct_ids(object_faces, scratch);  // radix passes: 0.6 of std::sort's time at 1,500
}

void CollideScratch::prepare_for(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object,
                                 const SphereTree& object_tree) {
  if (pkey_ != probe_tree.nodes.data() || phash_ != probe_tree.mesh_hash ||
      lidx_.size() != probe_tree.face_order.size() || omark_.size() != object.faces.size() ||
      cstamp_.size() != probe_tree.nodes.size() || osph_key_ != object_tree.nodes.data() ||
      osph_hash_ != object_tree.mesh_hash || nstride_o_ != object_tree.nodes.size() + kMaxChildren ||
      stack_cap_ < 8 * (probe_tree.num_depths + object_tree.num_depths) + 8)
    prepare(probe, probe_tree, object, object_tree);
}

void collide(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree,
             const Pose& pose, const CollideConfig& options, CollideScratch& scratch, CollideResult& result) {
  result.clear();
  QueryFrame f;
  if (frame_query(probe, probe_tree, object, object_tree, pose, scratch, result, f))
    query(probe, probe_tree, object, object_tree, options, scratch, result, f);
}

void CoherentCollider::collide(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object,
                               const SphereTree& object_tree, const Pose& pose, const CollideConfig& options,
                               CollideResult& result) {
  ++stats_.rounds;
  if (options.stop_layer != kExact || !options.tri_filter) {  // nothing to cache: the plain query
    ++stats_.plain_rounds;
    geom::collide(probe, probe_tree, object, object_tree, pose, options, scratch_, result);
    return;
  }
  if (same_setup(probe_tree, object_tree, options)) {
    pending_setup_ = 0;
  } else {
    // Another setup: adopted (a rebuild) when the round before asked for it too, or when there is
    // no front to keep; met once, collide() answers and the front stays (coherent.hpp, top).
    const std::uint64_t key = setup_key(probe_tree, object_tree, options);
    if (have_front_ && key != pending_setup_) {
      pending_setup_ = key;
      ++stats_.plain_rounds;
      geom::collide(probe, probe_tree, object, object_tree, pose, options, scratch_, result);
      return;
    }
    pending_setup_ = 0;
    adopt(probe_tree, object_tree, options);
  }
  if (round_ >= 0xfffffff0u) reset();
  result.clear();
  QueryFrame f;
  if (!frame_query(probe, probe_tree, object, object_tree, pose, scratch_, result, f)) {
    drop();
    return;
  }
  // The probe clear of the object: collide()'s answer, no pair, after a sphere test per root, and
  // nothing else (no timing, no step: a scene's far objects cost what collide() costs). The front
  // goes: as fine as the contact it was made for, of no use until the probe comes back, and then
  // rebuilt at about a plain round's cost.
  if (roots_apart(probe_tree, object_tree, options, f, result.stats.node_pairs)) {
    ++stats_.plain_rounds;
    if (have_front_) drop();
    last_rt_ = f.rt;
    have_last_ = true;
    near_.radius = -1;
    last_pairs_ = 0;
    note_pool();
    return;
  }
  // The step: of the probe leaves near the object when there are any (what the certificates
  // care about), else of the whole probe.
  const SphereNode& root = probe_tree.nodes[0];
  const bool near = near_.radius >= 0;
  const double step =
      !have_last_
          ? 0.0
          : moved_since(last_rt_, f.rt, near ? near_.centre : Vec3(root.centre[0], root.centre[1], root.centre[2]),
                        near ? near_.radius : double(root.radius));
  last_rt_ = f.rt;
  have_last_ = true;
  const std::uint32_t round = round_++;
  // A jump (every certificate would fail), a spell of plain rounds, or (arbitrate) the plain round
  // that times collide() now and then, the cache kept. A jump out of rounds answered from a front
  // (a jerk out of slow motion) rebuilds the front at once instead: the round after it would
  // rebuild it anyway, warm where the jump is cold, so a jerk costs one rebuild and no plain
  // round. A jump in the round after a rebuild (fast motion, which no front pays for: a second
  // jump in a row, or motion fast from the start) runs collide() and drops the cache.
  const bool timing = config_.arbitrate && have_front_ && round % kTimeEvery == kTimeEvery - 1 && !settled(round);
  const bool jump = step > max_step_;
  const bool rebuild_now = jump && have_front_ && ramp_ > 0 && !timing && round >= plain_until_;
  if (rebuild_now) drop();
  if ((jump && !rebuild_now) || round < plain_until_ || timing) {
    if (!timing && have_front_) drop();
    ++stats_.plain_rounds;
    // Only the timed rounds read the clock: two reads cost as much as a light round.
    const auto t0 = timing ? std::chrono::steady_clock::now() : std::chrono::steady_clock::time_point{};
    query(probe, probe_tree, object, object_tree, options, scratch_, result, f);
    last_pairs_ = result.pairs.size();
    if (timing) {
      const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
      // A contact of about the size last timed smooths the time; another replaces it (a time of a
      // larger contact would keep the collider from ever timing collide() again: settled()).
      plain_ns_ = plain_ns_ > 0 && alike(last_pairs_, timed_pairs_) ? 0.7 * plain_ns_ + 0.3 * ns : ns;
      timed_round_ = round;
      timed_pairs_ = last_pairs_;
    }
    note_contact(probe, result);
    note_pool();
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  if (!jump) step_ = std::max(step, step_ * 0.9);  // a jerk says nothing of the motion after it (reach_)
  poses_[round % kPoses] = {f.rt, f.mag, round};
  reach_ = choose_reach();
  if (rebuild_due()) drop();
  const bool rerooting = reroot_due();  // decided once: the round changes what it reads
  const bool ok = on_active_isa([&](auto isa) {
    return run_coherent<typename decltype(isa)::type>(*this, probe, probe_tree, object, object_tree, options, scratch_,
                                                      result, f, round, reach_, build_budget(), rerooting);
  });
  if (!ok) {  // the pool is full: this round, and the next 64, by collide()
    ++stats_.overflows;
    ++stats_.plain_rounds;
    drop();
    plain_until_ = round_ + 63;
    result.clear();
    f.gen = scratch_.next_generation();
    query(probe, probe_tree, object, object_tree, options, scratch_, result, f);
    note_pool();
    return;
  }
  if (result.stats.pair_limit_hit || result.stats.work_limit_hit || result.stats.truncated != 0) {
    drop();  // a front cut short proves nothing about what it did not reach
  } else {
    const bool rebuilt = !have_front_;
    front_.swap(next_front_);
    old_groups_.clear();
    compact_groups();
    if (rebuilt || rerooting) rooted_size_ = entries(), rooted_pairs_ = result.pairs.size();
    ramp_ = rebuilt ? 0 : ramp_ + 1;
    have_front_ = true;
    if (garbage_ > 4096 && 2 * garbage_ > cands_.size()) compact();
    // arbitrate: certificates that cost more than the plain query they save (light contact,
    // where collide() itself takes microseconds) give way to it for kPlainSpell rounds.
    const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
    if (rebuilt) rebuild_ns_ = ns, rebuild_round_ = round, rebuild_pairs_ = result.pairs.size();
    coherent_ns_ = coherent_rounds_ > 0 ? 0.95 * coherent_ns_ + 0.05 * ns : ns;
    ++coherent_rounds_;
    if (config_.arbitrate && coherent_rounds_ >= 64 && plain_ns_ > 0) {
      if (coherent_ns_ > 0.95 * plain_ns_) {  // each time it gives way again, for twice as long
        ++stats_.gave_way;
        drop();
        plain_until_ = round_ + (kPlainSpell << std::min<std::uint32_t>(spells_, 5));
        spells_ += 1;
        coherent_rounds_ = 0;
      } else if (coherent_rounds_ >= 512) {
        spells_ = 0;  // it has paid for a while: the next spell is short again
      }
    }
  }
  note_contact(probe, result);
  last_pairs_ = result.pairs.size();
  note_pool();
  if (options.sort_pairs) scratch_.sort(result.pairs);
}

}  // namespace st::geom
