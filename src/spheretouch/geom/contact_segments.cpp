// SPDX-License-Identifier: BSD-3-Clause
// The patch contact model's segment kernel (contact_segments.hpp): per (object face, probe face)
// row, the intersection segment along n_object × n_probe and its vector area, four rows at a time
// in GCC/Clang vector extensions, compiled for the baseline and for AVX2 (contact_segments_kernel.inl)
// and chosen at run time with the collision core's kernels (simd.hpp: one switch for all).
#include <spheretouch/geom/contact_segments.hpp>

#include <cmath>
#include <cstring>
#include <limits>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/simd.hpp>

// The segment computation's 4-lane vectors (D4 below) are passed between always-inlined helpers
// of this file only: no ABI is crossed, so GCC's note that passing them changes without AVX is moot.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace st::inline SPHERETOUCH_ABI::geom {

namespace {

// Four rows of the segment computation at once, one per lane, in GCC/Clang vector extensions:
// lane-wise operators, so the formulas read as scalar ones, and the compiler picks AVX, SSE or
// plain instructions. A row is an (object face, probe face) pair; the two faces' records are read
// straight from their FaceRec (four rows' worth of 4 fields turned into 4 columns in registers),
// so nothing is copied into a batch first.
typedef double D4 __attribute__((vector_size(32)));
using M4 = decltype(D4{} < D4{});  ///< per-lane flags (all bits set or none), from comparisons

namespace seg_base {
#define ST_SEG_SQRT4(x) \
  D4 { std::sqrt((x)[0]), std::sqrt((x)[1]), std::sqrt((x)[2]), std::sqrt((x)[3]) }
#include "contact_segments_kernel.inl"
#undef ST_SEG_SQRT4
}  // namespace seg_base
#if defined(ST_SIMD_X86)
ST_TARGET_AVX2_BEGIN
namespace seg_avx2 {
#define ST_SEG_SQRT4(x) D4(_mm256_sqrt_pd(x))
#include "contact_segments_kernel.inl"
#undef ST_SEG_SQRT4
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
/// Sum of a vector's lanes.
inline double lanes_sum(const D4& x) { return (x[0] + x[1]) + (x[2] + x[3]); }

}  // namespace

SegmentAreaSum::SegmentAreaSum(const Vec3& origin) : origin_{origin.x(), origin.y(), origin.z()} {}

void SegmentAreaSum::run(int n) {
  ST_ASSERT(n % 4 == 0 && n <= kBatch, "whole groups of four rows");
#if defined(ST_SIMD_X86)
  if (simd::active_isa() >= simd::Isa::avx2)
    seg_avx2::sum_rows(object_, probe_, n, origin_, sum_);
  else
#endif
    seg_base::sum_rows(object_, probe_, n, origin_, sum_);
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
  D4 sx, sy, sz;
  std::memcpy(&sx, sum_[0], sizeof(D4));
  std::memcpy(&sy, sum_[1], sizeof(D4));
  std::memcpy(&sz, sum_[2], sizeof(D4));
  return Vec3(lanes_sum(sx), lanes_sum(sy), lanes_sum(sz));
}

double SegmentAreaSum::abs_sum() const {
  ST_ASSERT(n_ == 0, "finish() ran after the last add()");
  D4 sabs;
  std::memcpy(&sabs, sum_[3], sizeof(D4));
  return lanes_sum(sabs);
}

double SegmentAreaSum::length() const {
  ST_ASSERT(n_ == 0, "finish() ran after the last add()");
  D4 s;
  std::memcpy(&s, sum_[4], sizeof(D4));
  return lanes_sum(s);
}

Vec3 SegmentAreaSum::centroid() const {
  ST_ASSERT(n_ == 0, "finish() ran after the last add()");
  const double len = length();
  const Vec3 o(origin_[0], origin_[1], origin_[2]);
  if (!(len > 0)) return o;
  D4 mx, my, mz;
  std::memcpy(&mx, sum_[5], sizeof(D4));
  std::memcpy(&my, sum_[6], sizeof(D4));
  std::memcpy(&mz, sum_[7], sizeof(D4));
  return o + Vec3(lanes_sum(mx), lanes_sum(my), lanes_sum(mz)) / len;
}

bool SegmentAreaSum::area_centroid(const Vec3& n, Vec3& out) const {
  ST_ASSERT(n_ == 0, "finish() ran after the last add()");
  const double an = n.dot(area());
  if (!(an > 0)) return false;
  Vec3 moment = Vec3::Zero();  // Σ (a·n) (s0 + s1), relative to the origin
  for (int j = 0; j < 3; ++j)
    for (int k = 0; k < 3; ++k) {
      D4 s;
      std::memcpy(&s, sum_[8 + 3 * j + k], sizeof(D4));
      moment[k] += n[j] * lanes_sum(s);
    }
  out = Vec3(origin_[0], origin_[1], origin_[2]) + moment / (3 * an);
  return out.allFinite();
}

void FirstSegment::run() {
  Vec3 m;
  bool found = false;
#if defined(ST_SIMD_X86)
  if (simd::active_isa() >= simd::Isa::avx2)
    found = seg_avx2::first_midpoint(object_, probe_, m);
  else
#endif
    found = seg_base::first_midpoint(object_, probe_, m);
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
