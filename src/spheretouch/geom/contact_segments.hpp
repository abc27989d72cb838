// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The patch contact model's segment kernel: the intersection segment of each colliding (object
/// face, probe face) row and its vector area, summed over the rows (Stokes: the vector area of the
/// object surface inside the probe, FD's direction), or the first segment's midpoint (the areas'
/// origin). Rows are computed four at a time; the SIMD stays in contact_segments.cpp.
#pragma once
#include <spheretouch/abi.hpp>
#include <spheretouch/geom/mesh.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// A colliding face as the patch model's segment computation reads it: its vertices in the
/// round's common frame (the local frame of the body with more colliding faces), its unit normal
/// (zero: degenerate, no direction) and its plane's offset c = n·v0.
struct FaceRec {
  Vec3 v[3];  ///< vertices, mm, in the round's common frame
  Vec3 n;     ///< unit normal (zero for a degenerate face)
  double c;   ///< plane offset n·v0, mm
};
static_assert(sizeof(FaceRec) == 13 * sizeof(double), "FaceRec is read as 13 doubles");

/// Σa and Σ|a| over rows (an object face, a probe face), a = the vector area ½ (s0 − o) × (s1 − o)
/// of the rows' intersection segment s0 s1 along n_object × n_probe, measured from an origin o
/// (no segment: nothing added). The rows are gathered four at a time, and summed per lane in the
/// order added, so the sums are a function of the rows and their order.
class SegmentAreaSum {
 public:
  /// Areas measured from `origin` (common frame).
  explicit SegmentAreaSum(const Vec3& origin);
  /// Adds a row (both records stay in place until finish()).
  void add(const FaceRec* object, const FaceRec* probe) {
    object_[n_] = object, probe_[n_] = probe;
    if (++n_ == kBatch) run(kBatch);
  }
  /// Computes the rows not computed yet; call once, after the last add().
  void finish();
  /// Σa over the rows (after finish()).
  Vec3 area() const;
  /// Σ|a| over the rows (after finish()).
  double abs_sum() const;
  /// The curve's length: Σ|s1 − s0| over the rows (after finish()).
  double length() const;
  /// The curve's centroid: its segments' midpoints weighted by their lengths, common frame (the
  /// origin when there is no segment).
  Vec3 centroid() const;
  /// The centroid of the area the curve encloses, seen along the unit direction `n` (the patch's
  /// centre: where a uniform pressure's resultant acts), common frame: the fan of triangles
  /// (o, s0, s1) weighted by their areas along n, Σ (a·n) (o + s0 + s1) / 3 / Σ a·n. For a closed
  /// planar curve it is the enclosed region's centroid whatever o is. False when Σ a·n is not
  /// positive (no area along n).
  bool area_centroid(const Vec3& n, Vec3& out) const;

 private:
  static constexpr int kBatch = 32;  ///< rows gathered per call of run(), a multiple of 4
  void run(int n);                   ///< computes rows [0, n), n a multiple of 4, and empties the batch
  double origin_[3];
  /// per component (x, y, z of Σa, Σ|a|, Σ length, x, y, z of Σ length · midpoint, then the nine
  /// Σ a_j (s0 + s1)_k), per lane: row 4k + lane's share
  double sum_[17][4] = {};
  const FaceRec* object_[kBatch];
  const FaceRec* probe_[kBatch];
  int n_ = 0;
};

/// The midpoint of the first row's segment (rows as in SegmentAreaSum), common frame: rows are
/// computed four at a time as they are added, and none after the four that hold a segment.
class FirstSegment {
 public:
  /// Adds a row (callers stop adding once found()).
  void add(const FaceRec* object, const FaceRec* probe) {
    object_[n_] = object, probe_[n_] = probe;
    if (++n_ == 4) run();
  }
  /// Computes the rows not computed yet (a last group of fewer than four).
  void finish();
  /// Whether a row had a segment.
  bool found() const { return found_; }
  /// The first segment's midpoint (zero: none found).
  const Vec3& midpoint() const { return midpoint_; }

 private:
  void run();  ///< computes the four rows gathered
  Vec3 midpoint_{Vec3::Zero()};
  bool found_ = false;
  const FaceRec* object_[4];
  const FaceRec* probe_[4];
  int n_ = 0;
};

}  // namespace st::geom
