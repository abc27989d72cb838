// SPDX-License-Identifier: BSD-3-Clause
// Uniform-grid + separating-axis reference backend (reference_backend.hpp).
#include <spheretouch/net/reference_backend.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <unordered_map>

namespace st::inline SPHERETOUCH_ABI::net {

namespace {

using geom::Vec3;

// Projects a triangle onto an axis: [lo, hi].
inline void project(const Vec3& axis, const Vec3& p0, const Vec3& p1, const Vec3& p2, double& lo, double& hi) {
  const double d0 = axis.dot(p0), d1 = axis.dot(p1), d2 = axis.dot(p2);
  lo = std::min({d0, d1, d2});
  hi = std::max({d0, d1, d2});
}

inline bool separates(const Vec3& axis, const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1,
                      const Vec3& b2) {
  double alo, ahi, blo, bhi;
  project(axis, a0, a1, a2, alo, ahi);
  project(axis, b0, b1, b2, blo, bhi);
  return ahi < blo || bhi < alo;  // strict: touching triangles are not separated (closed sets)
}

struct Box3 {
  Vec3 lo, hi;
  static Box3 of(const Vec3& a, const Vec3& b, const Vec3& c) {
    return {a.cwiseMin(b).cwiseMin(c), a.cwiseMax(b).cwiseMax(c)};
  }
  bool overlaps(const Box3& o) const {
    return (lo.array() <= o.hi.array()).all() && (o.lo.array() <= hi.array()).all();
  }
};

class GridBackend final : public CollisionBackend {
 public:
  Status load(const BlockSet& s) override {
    probe_ = s.probe;
    object_ = s.object;
    ids_ = s.object_face_ids;
    const std::size_t nf = object_.faces.size();
    boxes_.resize(nf);
    bounds_ = {Vec3::Constant(INFINITY), Vec3::Constant(-INFINITY)};
    double extent_sum = 0;
    for (std::size_t f = 0; f < nf; ++f) {
      const auto& t = object_.faces[f];
      boxes_[f] = Box3::of(object_.local[t[0]], object_.local[t[1]], object_.local[t[2]]);
      bounds_.lo = bounds_.lo.cwiseMin(boxes_[f].lo);
      bounds_.hi = bounds_.hi.cwiseMax(boxes_[f].hi);
      extent_sum += (boxes_[f].hi - boxes_[f].lo).maxCoeff();
    }
    // Cell ≈ 2 mean face extents: a face overlaps few cells, a cell holds few faces.
    cell_ = nf ? std::max(2.0 * extent_sum / double(nf), 1e-9) : 1.0;
    const Vec3 span = nf ? Vec3(bounds_.hi - bounds_.lo) : Vec3::Zero();
    for (int k = 0; k < 3; ++k) dims_[k] = std::clamp<std::int64_t>(std::int64_t(span[k] / cell_) + 1, 1, 1 << 20);
    cells_.clear();
    for (std::size_t f = 0; f < nf; ++f) {
      std::int64_t lo[3], hi[3];
      cell_range(boxes_[f], lo, hi);
      for (auto x = lo[0]; x <= hi[0]; ++x)
        for (auto y = lo[1]; y <= hi[1]; ++y)
          for (auto z = lo[2]; z <= hi[2]; ++z) cells_[key(x, y, z)].push_back(static_cast<std::uint32_t>(f));
    }
    stamp_.assign(nf, 0);
    epoch_ = 0;
    blocks_ = s.blocks;
    face_block_.resize(nf);
    for (std::size_t b = 0, f = 0; b < s.block_faces.size(); ++b)
      for (std::uint32_t k = 0; k < s.block_faces[b] && f < nf; ++k) face_block_[f++] = static_cast<std::uint32_t>(b);
    skipped_.assign(blocks_.size(), 0);
    skipped_list_.clear();
    return Ok{};
  }

  QueryStats query(const geom::Pose& pose, std::span<const std::uint32_t> skip, std::vector<FacePair>& out,
                   const QueryBudget& budget) override {
    for (std::size_t i : skipped_list_) skipped_[i] = 0;  // last query's marks
    skipped_list_.clear();
    for (std::uint32_t b : skip)
      if (auto it = std::lower_bound(blocks_.begin(), blocks_.end(), b); it != blocks_.end() && *it == b) {
        skipped_[std::size_t(it - blocks_.begin())] = 1;
        skipped_list_.push_back(std::size_t(it - blocks_.begin()));
      }
    return run(pose, out, budget);
  }

  QueryStats query_only(const geom::Pose& pose, std::span<const std::uint32_t> only, std::vector<FacePair>& out,
                        const QueryBudget& budget) override {
    skipped_list_.clear();
    for (std::size_t i = 0; i < blocks_.size(); ++i) {
      skipped_[i] = !std::binary_search(only.begin(), only.end(), blocks_[i]);
      if (skipped_[i]) skipped_list_.push_back(i);
    }
    return run(pose, out, budget);
  }

 private:
  // One query, leaving out the blocks marked in skipped_.
  QueryStats run(const geom::Pose& pose, std::vector<FacePair>& out, const QueryBudget& budget) {
    const std::size_t start = out.size();
    const auto t0 = std::chrono::steady_clock::now();
    QueryStats st;
    const bool any_skipped = !skipped_list_.empty();
    // Relative transform probe-local → object-local, composed once in double (large
    // offsets live only in poses and origins; never transform through the far-away file frame per vertex).
    const geom::Pose rel = Eigen::Translation3d(-object_.origin) * pose * Eigen::Translation3d(probe_.origin);
    moved_.resize(probe_.local.size());
    for (std::size_t v = 0; v < moved_.size(); ++v) moved_[v] = rel * probe_.local[v];
    if (object_.faces.empty()) return st;
    for (std::uint32_t pf = 0; pf < probe_.faces.size(); ++pf) {
      const auto& t = probe_.faces[pf];
      const Vec3 &p0 = moved_[t[0]], &p1 = moved_[t[1]], &p2 = moved_[t[2]];
      const Box3 pb = Box3::of(p0, p1, p2);
      ++st.sphere_tests;
      if (!pb.overlaps(bounds_)) continue;
      if (++epoch_ == 0) {
        std::fill(stamp_.begin(), stamp_.end(), 0);
        epoch_ = 1;
      }
      std::int64_t lo[3], hi[3];
      cell_range(pb, lo, hi);
      for (auto x = lo[0]; x <= hi[0]; ++x)
        for (auto y = lo[1]; y <= hi[1]; ++y)
          for (auto z = lo[2]; z <= hi[2]; ++z) {
            auto it = cells_.find(key(x, y, z));
            if (it == cells_.end()) continue;
            for (std::uint32_t of : it->second) {
              if (stamp_[of] == epoch_) continue;
              stamp_[of] = epoch_;
              if (any_skipped && skipped_[face_block_[of]]) continue;
              ++st.sphere_tests;
              if (!pb.overlaps(boxes_[of])) continue;  // exact filter: the result cannot depend on the grid
              const auto& u = object_.faces[of];
              ++st.tri_tests;
              if (sat_tri_overlap(p0, p1, p2, object_.local[u[0]], object_.local[u[1]], object_.local[u[2]]))
                out.push_back({pf, ids_[of]});
              if (out.size() - start > budget.max_pairs) return timed(st, t0);  // the caller refuses the query
              if (st.sphere_tests + geom::kExactTestWork * st.tri_tests > budget.max_work) {
                st.work_limit_hit = true;  // the same refusal: every test here is an exact one
                return timed(st, t0);
              }
            }
          }
    }
    return timed(st, t0);
  }

  // `st` with its compute time since t0 (the worker weighs clients by it).
  static QueryStats timed(QueryStats st, std::chrono::steady_clock::time_point t0) {
    st.compute_ns = static_cast<std::uint64_t>(
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count());
    return st;
  }
  static std::uint64_t key(std::int64_t x, std::int64_t y, std::int64_t z) {
    return std::uint64_t(x) | std::uint64_t(y) << 21 | std::uint64_t(z) << 42;
  }
  // Cells overlapped by a box, clamped to the grid (floor is monotone, so overlapping boxes share a cell).
  void cell_range(const Box3& b, std::int64_t lo[3], std::int64_t hi[3]) const {
    for (int k = 0; k < 3; ++k) {
      const double l = std::floor((b.lo[k] - bounds_.lo[k]) / cell_), h = std::floor((b.hi[k] - bounds_.lo[k]) / cell_);
      lo[k] = std::int64_t(std::clamp(l, 0.0, double(dims_[k] - 1)));
      hi[k] = std::int64_t(std::clamp(h, 0.0, double(dims_[k] - 1)));
    }
  }

  geom::Mesh probe_, object_;
  std::vector<std::uint32_t> ids_;
  std::vector<Box3> boxes_;
  Box3 bounds_;
  double cell_ = 1;
  std::int64_t dims_[3] = {1, 1, 1};
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> cells_;
  std::vector<std::uint32_t> stamp_;
  std::uint32_t epoch_ = 0;
  std::vector<std::uint32_t> blocks_;      // global ids of the held blocks, ascending
  std::vector<std::uint32_t> face_block_;  // share face -> index into blocks_
  std::vector<std::uint8_t> skipped_;      // per held block: left out of this query
  std::vector<std::size_t> skipped_list_;  // the blocks marked in skipped_
  std::vector<Vec3> moved_;
};

}  // namespace

bool sat_tri_overlap(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1, const Vec3& b2) {
  // Translate so a0 is the origin: smaller magnitudes, less cancellation in the projections.
  const Vec3 A[3] = {Vec3::Zero(), a1 - a0, a2 - a0}, B[3] = {b0 - a0, b1 - a0, b2 - a0};
  const Vec3 ea[3] = {A[1] - A[0], A[2] - A[1], A[0] - A[2]}, eb[3] = {B[1] - B[0], B[2] - B[1], B[0] - B[2]};
  const Vec3 na = ea[0].cross(ea[1]), nb = eb[0].cross(eb[1]);
  // 17 candidate axes (Gottschalk et al. 1996 / Eberly): the two normals, the nine edge-edge
  // cross products, and the six in-plane edge normals that separate coplanar triangles.
  // A zero axis projects everything to 0 and never separates, so degenerate cases need no branch.
  if (separates(na, A[0], A[1], A[2], B[0], B[1], B[2])) return false;
  if (separates(nb, A[0], A[1], A[2], B[0], B[1], B[2])) return false;
  for (const Vec3& e : ea)
    for (const Vec3& f : eb)
      if (separates(e.cross(f), A[0], A[1], A[2], B[0], B[1], B[2])) return false;
  for (const Vec3& e : ea)
    if (separates(na.cross(e), A[0], A[1], A[2], B[0], B[1], B[2])) return false;
  for (const Vec3& f : eb)
    if (separates(nb.cross(f), A[0], A[1], A[2], B[0], B[1], B[2])) return false;
  return true;
}

std::unique_ptr<CollisionBackend> make_reference_backend() { return std::make_unique<GridBackend>(); }

BackendFactory reference_backend_factory() {
  return [] { return make_reference_backend(); };
}

std::vector<FacePair> reference_collide(const geom::Mesh& probe, const geom::Mesh& object, const geom::Pose& pose) {
  Blocks all(1);
  all[0].resize(object.faces.size());
  std::iota(all[0].begin(), all[0].end(), 0u);
  const std::uint32_t id = 0;
  auto set = make_block_set(probe, object, all, std::span(&id, 1), 8);
  std::vector<FacePair> out;
  if (!set) return out;
  GridBackend b;
  (void)b.load(set.value());
  b.query(pose, {}, out, {});
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace st::net
