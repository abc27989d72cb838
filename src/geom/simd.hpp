// Float lanes for collide.cpp's filter kernels, so each kernel is written once: AVX2 (8 lanes) with
// -march on a CPU that has it, SSE2 (4 lanes) on any other x86-64, one plain float elsewhere or
// with -Dsimd=false (ST_NO_SIMD). Each operation is one IEEE float operation per lane, so a kernel
// gives the same bits on all three, except that a compiler may contract the scalar multiply and
// add into a fused multiply-add (GCC does by default when the target has FMA); the filters built
// on these are conservative by far more than that rounding (see the top of collide.cpp).
#pragma once
#include <cstdint>

#if !defined(ST_NO_SIMD) && defined(__AVX2__)
#define ST_SIMD_AVX2 1
#include <immintrin.h>
#elif !defined(ST_NO_SIMD) && defined(__SSE2__)
#define ST_SIMD_SSE2 1
#include <emmintrin.h>
#endif

namespace st::geom::simd {

#if defined(ST_SIMD_AVX2)

/// One flag per lane, held as the all-ones/all-zeros lanes that AVX comparisons produce.
struct Mask {
  __m256 v;  ///< the flags

  /// Lanes l < live are set (live may exceed the width).
  static Mask first(std::uint32_t live) {
    const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256i n = _mm256_set1_epi32(static_cast<int>(live < 8 ? live : 8));
    return {_mm256_castsi256_ps(_mm256_cmpgt_epi32(n, lane))};
  }
  std::uint32_t bits() const { return static_cast<std::uint32_t>(_mm256_movemask_ps(v)); }  ///< bit l = lane l
  friend Mask operator&(Mask a, Mask b) { return {_mm256_and_ps(a.v, b.v)}; }               ///< lane-wise and
};

/// 8 floats.
struct Lanes {
  static constexpr int width = 8;  ///< floats per step
  __m256 v;                        ///< the floats

  static Lanes load(const float* p) { return {_mm256_loadu_ps(p)}; }  ///< p[0, 8), unaligned
  static Lanes broadcast(float x) { return {_mm256_set1_ps(x)}; }     ///< x in every lane
  /// Lane l = p[l·Stride] for l < live, 0 for the others, whose addresses are never read (the
  /// gather is masked, so the last record of an array can be gathered without padding).
  template <int Stride>
  static Lanes gather(const float* p, std::uint32_t live) {
    const __m256i idx =
        _mm256_setr_epi32(0, Stride, 2 * Stride, 3 * Stride, 4 * Stride, 5 * Stride, 6 * Stride, 7 * Stride);
    return {_mm256_mask_i32gather_ps(_mm256_setzero_ps(), p, idx, Mask::first(live).v, 4)};
  }
  friend Lanes operator+(Lanes a, Lanes b) { return {_mm256_add_ps(a.v, b.v)}; }  ///< lane-wise a + b
  friend Lanes operator-(Lanes a, Lanes b) { return {_mm256_sub_ps(a.v, b.v)}; }  ///< lane-wise a - b
  friend Lanes operator*(Lanes a, Lanes b) { return {_mm256_mul_ps(a.v, b.v)}; }  ///< lane-wise a · b
  /// a <= b per lane; false where either is NaN, as in scalar float.
  friend Mask operator<=(Lanes a, Lanes b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ)}; }
  /// a >= b per lane; false where either is NaN, as in scalar float.
  friend Mask operator>=(Lanes a, Lanes b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GE_OQ)}; }
};

#elif defined(ST_SIMD_SSE2)

/// One flag per lane, held as the all-ones/all-zeros lanes that SSE comparisons produce.
struct Mask {
  __m128 v;  ///< the flags

  /// Lanes l < live are set (live may exceed the width).
  static Mask first(std::uint32_t live) {
    const __m128i lane = _mm_setr_epi32(0, 1, 2, 3);
    const __m128i n = _mm_set1_epi32(static_cast<int>(live < 4 ? live : 4));
    return {_mm_castsi128_ps(_mm_cmpgt_epi32(n, lane))};
  }
  std::uint32_t bits() const { return static_cast<std::uint32_t>(_mm_movemask_ps(v)); }  ///< bit l = lane l
  friend Mask operator&(Mask a, Mask b) { return {_mm_and_ps(a.v, b.v)}; }               ///< lane-wise and
};

/// 4 floats.
struct Lanes {
  static constexpr int width = 4;  ///< floats per step
  __m128 v;                        ///< the floats

  static Lanes load(const float* p) { return {_mm_loadu_ps(p)}; }  ///< p[0, 4), unaligned
  static Lanes broadcast(float x) { return {_mm_set1_ps(x)}; }     ///< x in every lane
  /// Lane l = p[l·Stride] for l < live, 0 for the others, whose addresses are never read.
  template <int Stride>
  static Lanes gather(const float* p, std::uint32_t live) {
    if (live >= 4) [[likely]]
      return {_mm_setr_ps(p[0], p[Stride], p[2 * Stride], p[3 * Stride])};
    return {_mm_setr_ps(live > 0 ? p[0] : 0.0f, live > 1 ? p[Stride] : 0.0f, live > 2 ? p[2 * Stride] : 0.0f, 0.0f)};
  }
  friend Lanes operator+(Lanes a, Lanes b) { return {_mm_add_ps(a.v, b.v)}; }  ///< lane-wise a + b
  friend Lanes operator-(Lanes a, Lanes b) { return {_mm_sub_ps(a.v, b.v)}; }  ///< lane-wise a - b
  friend Lanes operator*(Lanes a, Lanes b) { return {_mm_mul_ps(a.v, b.v)}; }  ///< lane-wise a · b
  /// a <= b per lane; false where either is NaN, as in scalar float.
  friend Mask operator<=(Lanes a, Lanes b) { return {_mm_cmple_ps(a.v, b.v)}; }
  /// a >= b per lane; false where either is NaN, as in scalar float.
  friend Mask operator>=(Lanes a, Lanes b) { return {_mm_cmpge_ps(a.v, b.v)}; }
};

#else

/// One flag.
struct Mask {
  bool v;  ///< the flag

  static Mask first(std::uint32_t live) { return {live > 0}; }                      ///< set when live > 0
  std::uint32_t bits() const { return v; }                                          ///< bit 0 = the flag
  friend Mask operator&(Mask a, Mask b) { return {static_cast<bool>(a.v & b.v)}; }  ///< and, no branch
};

/// One float.
struct Lanes {
  static constexpr int width = 1;  ///< floats per step
  float v;                         ///< the float

  static Lanes load(const float* p) { return {*p}; }  ///< p[0]
  static Lanes broadcast(float x) { return {x}; }     ///< x
  /// p[0] when live > 0, else 0 without reading p.
  template <int Stride>
  static Lanes gather(const float* p, std::uint32_t live) {
    return {live > 0 ? *p : 0.0f};
  }
  friend Lanes operator+(Lanes a, Lanes b) { return {a.v + b.v}; }   ///< a + b
  friend Lanes operator-(Lanes a, Lanes b) { return {a.v - b.v}; }   ///< a - b
  friend Lanes operator*(Lanes a, Lanes b) { return {a.v * b.v}; }   ///< a · b
  friend Mask operator<=(Lanes a, Lanes b) { return {a.v <= b.v}; }  ///< a <= b (false for NaN)
  friend Mask operator>=(Lanes a, Lanes b) { return {a.v >= b.v}; }  ///< a >= b (false for NaN)
};

#endif

}  // namespace st::geom::simd
