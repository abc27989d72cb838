// SPDX-License-Identifier: BSD-3-Clause
// The patch contact model's segment kernel (contact_segments.hpp): per (object face, probe face)
// row, the intersection segment along n_object × n_probe and its vector area, four rows at a time
// in simd.hpp's Quad, compiled per ISA (contact_segments_kernel.inl) and chosen at run time with
// the collision core's kernels (simd.hpp: one vocabulary, one switch for all).
#include <spheretouch/geom/contact_segments.hpp>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/simd.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

namespace {

// Four rows of the segment computation at once, one per lane, in simd.hpp's Quad (four doubles)
// of each ISA: lane-wise operators, so the formulas read as scalar ones. A row is an (object
// face, probe face) pair; the two faces' records are read straight from their FaceRec (four
// rows' worth of 4 fields turned into 4 columns in registers), so nothing is copied first.
namespace seg_scalar {
#define ST_SEG_SIMD scalar
#include "contact_segments_kernel.inl"
#undef ST_SEG_SIMD
}  // namespace seg_scalar
#if defined(ST_SIMD_X86)
namespace seg_sse2 {
#define ST_SEG_SIMD sse2
#include "contact_segments_kernel.inl"
#undef ST_SEG_SIMD
}  // namespace seg_sse2
ST_TARGET_AVX2_BEGIN
namespace seg_avx2 {
#define ST_SEG_SIMD avx2
#include "contact_segments_kernel.inl"
#undef ST_SEG_SIMD
}  // namespace seg_avx2
ST_TARGET_END
#endif

/// A record with no normal: padding rows (no segment, nothing added).
const FaceRec& no_record() {
  static const FaceRec r = [] {
    FaceRec z;
    z.v[0] = z.v[1] = z.v[2] = z.n = Vec3::Zero();
    z.c = 0;
    return z;
  }();
  return r;
}
/// Sum of a row of four lane sums, in the order the lanes were added before (pairs first).
inline double lanes_sum(const double (&x)[4]) { return (x[0] + x[1]) + (x[2] + x[3]); }

}  // namespace

SegmentAreaSum::SegmentAreaSum(const Vec3& origin) : origin_{origin.x(), origin.y(), origin.z()} {}

void SegmentAreaSum::run(int n) {
  ST_ASSERT(n % 4 == 0 && n <= kBatch, "whole groups of four rows");
  switch (simd::active_isa()) {
#if defined(ST_SIMD_X86)
    case simd::Isa::avx512:
    case simd::Isa::avx2:
      seg_avx2::sum_rows(object_, probe_, n, origin_, sum_);
      break;
    case simd::Isa::sse2:
      seg_sse2::sum_rows(object_, probe_, n, origin_, sum_);
      break;
#endif
    default:
      seg_scalar::sum_rows(object_, probe_, n, origin_, sum_);
      break;
  }
  n_ = 0;
}

void SegmentAreaSum::finish() {
  if (n_ == 0) return;
  int n = n_;
  for (; n % 4 != 0; ++n) object_[n] = probe_[n] = &no_record();  // the last group's padding
  run(n);
}

Vec3 SegmentAreaSum::area() const {
  ST_ASSERT(n_ == 0, "finish() ran after the last add()");
  return Vec3(lanes_sum(sum_[0]), lanes_sum(sum_[1]), lanes_sum(sum_[2]));
}

double SegmentAreaSum::abs_sum() const {
  ST_ASSERT(n_ == 0, "finish() ran after the last add()");
  return lanes_sum(sum_[3]);
}

double SegmentAreaSum::length() const {
  ST_ASSERT(n_ == 0, "finish() ran after the last add()");
  return lanes_sum(sum_[4]);
}

Vec3 SegmentAreaSum::centroid() const {
  ST_ASSERT(n_ == 0, "finish() ran after the last add()");
  const double len = length();
  const Vec3 o(origin_[0], origin_[1], origin_[2]);
  if (!(len > 0)) return o;
  return o + Vec3(lanes_sum(sum_[5]), lanes_sum(sum_[6]), lanes_sum(sum_[7])) / len;
}

bool SegmentAreaSum::area_centroid(const Vec3& n, Vec3& out) const {
  ST_ASSERT(n_ == 0, "finish() ran after the last add()");
  const double an = n.dot(area());
  if (!(an > 0)) return false;
  Vec3 moment = Vec3::Zero();  // Σ (a·n) (s0 + s1), relative to the origin
  for (int j = 0; j < 3; ++j)
    for (int k = 0; k < 3; ++k) moment[k] += n[j] * lanes_sum(sum_[8 + 3 * j + k]);
  out = Vec3(origin_[0], origin_[1], origin_[2]) + moment / (3 * an);
  return out.allFinite();
}

void FirstSegment::run() {
  Vec3 m;
  bool found = false;
  switch (simd::active_isa()) {
#if defined(ST_SIMD_X86)
    case simd::Isa::avx512:
    case simd::Isa::avx2:
      found = seg_avx2::first_midpoint(object_, probe_, m);
      break;
    case simd::Isa::sse2:
      found = seg_sse2::first_midpoint(object_, probe_, m);
      break;
#endif
    default:
      found = seg_scalar::first_midpoint(object_, probe_, m);
      break;
  }
  if (found && !found_) {
    midpoint_ = m;
    found_ = true;
  }
  n_ = 0;
}

void FirstSegment::finish() {
  if (found_ || n_ == 0) return;
  for (int k = n_; k < 4; ++k) object_[k] = probe_[k] = &no_record();
  run();
}

}  // namespace st::geom
