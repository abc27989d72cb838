// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The SIMD vocabulary of the collision core: float lanes per instruction set, so each kernel is
/// written once, and the choice of instruction set at RUN time, so one binary runs on any x86-64
/// (no -march in any build flag; docs/library.md, "Portable binaries").
//
// * Lanes/Mask come in one namespace per ISA: scalar (1 float), sse2 (4: the x86-64 baseline),
//   avx2 (8; with FMA) and avx512 (16; F, VL). min/max follow the SSE instructions' rule (the
//   second operand when either is NaN) on every ISA. Each operation is one IEEE float operation per
//   lane, so a kernel gives the same bits on all of them (the project compiles with
//   -ffp-contract=off: no multiply-add is fused behind the kernel's back).
// * Code for an ISA above the baseline lives between ST_TARGET_AVX2_BEGIN (or _AVX512_) and ST_TARGET_END: GCC's `#pragma GCC target` (Clang: `#pragma clang attribute`) compiles the
//   functions DEFINED there for that ISA. Templates and inline functions defined elsewhere (the
//   standard library, Eigen) keep the baseline, so no AVX instruction can leak into code that runs
//   on a CPU without it through a shared inline copy. Nothing may be #included inside a region.
// * active_isa() is what the dispatching code (collide.cpp) runs: the best the CPU has, lowered by
//   the environment variable ST_SIMD (scalar, sse2, avx2, avx512) or set_isa(); with -Dsimd=false
//   (ST_NO_SIMD) or off x86-64 only the scalar path exists.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <string_view>

#if !defined(ST_NO_SIMD) && defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
/// Defined when the x86-64 SIMD paths (SSE2, AVX2, AVX-512) are compiled in.
#define ST_SIMD_X86 1
#include <immintrin.h>
#endif

#if defined(ST_SIMD_X86) && defined(__clang__)
/// Starts a region whose functions are compiled for AVX2 + FMA (ends at ST_TARGET_END).
#define ST_TARGET_AVX2_BEGIN _Pragma("clang attribute push(__attribute__((target(\"avx2,fma\"))), apply_to = function)")
/// Starts a region whose functions are compiled for AVX-512 F + VL (and AVX2 + FMA).
#define ST_TARGET_AVX512_BEGIN \
  _Pragma("clang attribute push(__attribute__((target(\"avx2,fma,avx512f,avx512vl\"))), apply_to = function)")
/// Ends the region ST_TARGET_AVX2_BEGIN or ST_TARGET_AVX512_BEGIN started.
#define ST_TARGET_END _Pragma("clang attribute pop")
#elif defined(ST_SIMD_X86)
/// Starts a region whose functions are compiled for AVX2 + FMA (ends at ST_TARGET_END).
#define ST_TARGET_AVX2_BEGIN _Pragma("GCC push_options") _Pragma("GCC target(\"avx2,fma\")")
/// Starts a region whose functions are compiled for AVX-512 F + VL (and AVX2 + FMA).
#define ST_TARGET_AVX512_BEGIN _Pragma("GCC push_options") _Pragma("GCC target(\"avx2,fma,avx512f,avx512vl\")")
/// Ends the region ST_TARGET_AVX2_BEGIN or ST_TARGET_AVX512_BEGIN started.
#define ST_TARGET_END _Pragma("GCC pop_options")
#endif

/// SIMD lanes per instruction set and the run-time choice among them.
namespace st::inline SPHERETOUCH_ABI::geom::simd {

/// An instruction set a kernel can run on, in increasing order of width.
enum class Isa : std::uint8_t {
  scalar = 0,  ///< one float at a time (any CPU; the only path with -Dsimd=false)
  sse2 = 1,    ///< 4 floats (every x86-64)
  avx2 = 2,    ///< 8 floats, with FMA (Haswell and later)
  avx512 = 3,  ///< 16 floats, AVX-512 F and VL (Skylake-SP and later)
};

/// The widest ISA this CPU and this build support (ignores ST_SIMD and set_isa()).
Isa best_isa();
/// The ISA the kernels run now: best_isa(), or lower if ST_SIMD or set_isa() asked for it.
Isa active_isa();
/// Runs the kernels on `isa` from now on (all threads); false, changing nothing, when this CPU or
/// build lacks it. For tests and benchmarks that compare the paths.
bool set_isa(Isa isa);
/// "scalar", "sse2", "avx2" or "avx512".
const char* isa_name(Isa isa);
/// The ISA named `name` (as isa_name() spells it); false when the name is none of them.
bool parse_isa(std::string_view name, Isa& isa);

// Per ISA: Mask (one flag per lane; first(live), bits(), &, |) and Lanes (width floats: load,
// broadcast, gather, + - * /, min, max, abs, sqrt, comparisons, select, hmin, hmax), the collision core's; and Quad
// and QuadMask (four doubles, one record per lane: + - * /, sqrt, <, >, select, transpose), the
// contact model's segment kernel's (AVX-512 runs the AVX2 Quad). Operators are free functions,
// not in-class friends: GCC does not give friends defined in a class the target of their region.

/// One float at a time: any CPU, and the only path with -Dsimd=false.
namespace scalar {

/// One flag.
struct Mask {
  bool v;  ///< the flag

  static Mask first(std::uint32_t live) { return {live > 0}; }  ///< set when live > 0
  std::uint32_t bits() const { return v; }                      ///< bit 0 = the flag
};
inline Mask operator&(Mask a, Mask b) { return {static_cast<bool>(a.v & b.v)}; }  ///< and, no branch
inline Mask operator|(Mask a, Mask b) { return {static_cast<bool>(a.v | b.v)}; }  ///< or, no branch

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
};
inline Lanes operator+(Lanes a, Lanes b) { return {a.v + b.v}; }             ///< a + b
inline Lanes operator-(Lanes a, Lanes b) { return {a.v - b.v}; }             ///< a - b
inline Lanes operator*(Lanes a, Lanes b) { return {a.v * b.v}; }             ///< a · b
inline Lanes min(Lanes a, Lanes b) { return {a.v < b.v ? a.v : b.v}; }       ///< as minps (b if NaN)
inline Lanes max(Lanes a, Lanes b) { return {a.v > b.v ? a.v : b.v}; }       ///< as maxps (b if NaN)
inline Lanes abs(Lanes a) { return {__builtin_fabsf(a.v)}; }                 ///< |a|
inline Lanes operator/(Lanes a, Lanes b) { return {a.v / b.v}; }             ///< a / b, correctly rounded
inline Lanes sqrt(Lanes a) { return {__builtin_sqrtf(a.v)}; }                ///< √a, correctly rounded
inline Mask operator<=(Lanes a, Lanes b) { return {a.v <= b.v}; }            ///< a <= b (false for NaN)
inline Mask operator>=(Lanes a, Lanes b) { return {a.v >= b.v}; }            ///< a >= b (false for NaN)
inline Mask operator>(Lanes a, Lanes b) { return {a.v > b.v}; }              ///< a > b (false for NaN)
inline Lanes select(Mask m, Lanes a, Lanes b) { return {m.v ? a.v : b.v}; }  ///< m ? a : b
inline float hmin(Lanes a) { return a.v; }                                   ///< least lane (lanes not NaN)
inline float hmax(Lanes a) { return a.v; }                                   ///< greatest lane (lanes not NaN)

/// Four doubles, one record per lane (the contact model's segment kernel), as a loop per operation.
struct Quad {
  double v[4];  ///< the doubles

  static Quad broadcast(double x) { return {{x, x, x, x}}; }                           ///< x in every lane
  static Quad set(double a, double b, double c, double d) { return {{a, b, c, d}}; }   ///< lanes a, b, c, d
  static Quad load(const double* p) { return {{p[0], p[1], p[2], p[3]}}; }             ///< p[0, 4)
  void store(double* p) const { p[0] = v[0], p[1] = v[1], p[2] = v[2], p[3] = v[3]; }  ///< to p[0, 4)
  double lane(int l) const { return v[l]; }                                            ///< lane l
};
/// One flag per lane of a Quad.
struct QuadMask {
  bool v[4];  ///< the flags

  std::uint32_t bits() const { return v[0] | v[1] << 1 | v[2] << 2 | v[3] << 3; }  ///< bit l = lane l
};
/// Lane-wise a + b.
inline Quad operator+(Quad a, Quad b) { return {{a.v[0] + b.v[0], a.v[1] + b.v[1], a.v[2] + b.v[2], a.v[3] + b.v[3]}}; }
/// Lane-wise a - b.
inline Quad operator-(Quad a, Quad b) { return {{a.v[0] - b.v[0], a.v[1] - b.v[1], a.v[2] - b.v[2], a.v[3] - b.v[3]}}; }
/// Lane-wise a · b.
inline Quad operator*(Quad a, Quad b) { return {{a.v[0] * b.v[0], a.v[1] * b.v[1], a.v[2] * b.v[2], a.v[3] * b.v[3]}}; }
/// Lane-wise a / b.
inline Quad operator/(Quad a, Quad b) { return {{a.v[0] / b.v[0], a.v[1] / b.v[1], a.v[2] / b.v[2], a.v[3] / b.v[3]}}; }
/// Lane-wise a < b (false for NaN).
inline QuadMask operator<(Quad a, Quad b) {
  return {{a.v[0] < b.v[0], a.v[1] < b.v[1], a.v[2] < b.v[2], a.v[3] < b.v[3]}};
}
/// Lane-wise a > b (false for NaN).
inline QuadMask operator>(Quad a, Quad b) {
  return {{a.v[0] > b.v[0], a.v[1] > b.v[1], a.v[2] > b.v[2], a.v[3] > b.v[3]}};
}
/// Lane-wise and.
inline QuadMask operator&(QuadMask a, QuadMask b) {
  return {{a.v[0] && b.v[0], a.v[1] && b.v[1], a.v[2] && b.v[2], a.v[3] && b.v[3]}};
}
/// Lane-wise or.
inline QuadMask operator|(QuadMask a, QuadMask b) {
  return {{a.v[0] || b.v[0], a.v[1] || b.v[1], a.v[2] || b.v[2], a.v[3] || b.v[3]}};
}
/// Lane-wise exclusive or.
inline QuadMask operator^(QuadMask a, QuadMask b) {
  return {{a.v[0] != b.v[0], a.v[1] != b.v[1], a.v[2] != b.v[2], a.v[3] != b.v[3]}};
}
/// m ? a : b per lane.
inline Quad select(QuadMask m, Quad a, Quad b) {
  return {{m.v[0] ? a.v[0] : b.v[0], m.v[1] ? a.v[1] : b.v[1], m.v[2] ? a.v[2] : b.v[2], m.v[3] ? a.v[3] : b.v[3]}};
}
/// √a per lane, correctly rounded.
inline Quad sqrt(Quad a) {
  return {{__builtin_sqrt(a.v[0]), __builtin_sqrt(a.v[1]), __builtin_sqrt(a.v[2]), __builtin_sqrt(a.v[3])}};
}
/// Four rows of four doubles (r[k][0, 4)) as four columns: c_j lane k = r[k][j].
inline void transpose(const double* const r[4], Quad& c0, Quad& c1, Quad& c2, Quad& c3) {
  c0 = Quad::set(r[0][0], r[1][0], r[2][0], r[3][0]);
  c1 = Quad::set(r[0][1], r[1][1], r[2][1], r[3][1]);
  c2 = Quad::set(r[0][2], r[1][2], r[2][2], r[3][2]);
  c3 = Quad::set(r[0][3], r[1][3], r[2][3], r[3][3]);
}

}  // namespace scalar

#if defined(ST_SIMD_X86)

/// 4 floats (SSE2, every x86-64).
namespace sse2 {

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
};
inline Mask operator&(Mask a, Mask b) { return {_mm_and_ps(a.v, b.v)}; }  ///< lane-wise and
inline Mask operator|(Mask a, Mask b) { return {_mm_or_ps(a.v, b.v)}; }   ///< lane-wise or

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
};
inline Lanes operator+(Lanes a, Lanes b) { return {_mm_add_ps(a.v, b.v)}; }     ///< lane-wise a + b
inline Lanes operator-(Lanes a, Lanes b) { return {_mm_sub_ps(a.v, b.v)}; }     ///< lane-wise a - b
inline Lanes operator*(Lanes a, Lanes b) { return {_mm_mul_ps(a.v, b.v)}; }     ///< lane-wise a · b
inline Lanes min(Lanes a, Lanes b) { return {_mm_min_ps(a.v, b.v)}; }           ///< lane-wise min (b if NaN)
inline Lanes max(Lanes a, Lanes b) { return {_mm_max_ps(a.v, b.v)}; }           ///< lane-wise max (b if NaN)
inline Lanes abs(Lanes a) { return {_mm_andnot_ps(_mm_set1_ps(-0.0f), a.v)}; }  ///< lane-wise |a|
inline Lanes operator/(Lanes a, Lanes b) { return {_mm_div_ps(a.v, b.v)}; }     ///< lane-wise a / b, correctly rounded
inline Lanes sqrt(Lanes a) { return {_mm_sqrt_ps(a.v)}; }                       ///< lane-wise √a, correctly rounded
/// a <= b per lane; false where either is NaN, as in scalar float.
inline Mask operator<=(Lanes a, Lanes b) { return {_mm_cmple_ps(a.v, b.v)}; }
/// a >= b per lane; false where either is NaN, as in scalar float.
inline Mask operator>=(Lanes a, Lanes b) { return {_mm_cmpge_ps(a.v, b.v)}; }
/// a > b per lane; false where either is NaN, as in scalar float.
inline Mask operator>(Lanes a, Lanes b) { return {_mm_cmpgt_ps(a.v, b.v)}; }
/// m ? a : b per lane.
inline Lanes select(Mask m, Lanes a, Lanes b) { return {_mm_or_ps(_mm_and_ps(m.v, a.v), _mm_andnot_ps(m.v, b.v))}; }
/// The least lane (lanes not NaN).
inline float hmin(Lanes a) {
  const __m128 m = _mm_min_ps(a.v, _mm_movehl_ps(a.v, a.v));
  return _mm_cvtss_f32(_mm_min_ss(m, _mm_shuffle_ps(m, m, 1)));
}
/// The greatest lane (lanes not NaN).
inline float hmax(Lanes a) {
  const __m128 m = _mm_max_ps(a.v, _mm_movehl_ps(a.v, a.v));
  return _mm_cvtss_f32(_mm_max_ss(m, _mm_shuffle_ps(m, m, 1)));
}

/// Four doubles, one record per lane (the contact model's segment kernel), as two SSE2 halves.
struct Quad {
  __m128d lo;  ///< lanes 0-1
  __m128d hi;  ///< lanes 2-3

  static Quad broadcast(double x) { return {_mm_set1_pd(x), _mm_set1_pd(x)}; }  ///< x in every lane
  /// Lanes a, b, c, d.
  static Quad set(double a, double b, double c, double d) { return {_mm_setr_pd(a, b), _mm_setr_pd(c, d)}; }
  static Quad load(const double* p) { return {_mm_loadu_pd(p), _mm_loadu_pd(p + 2)}; }  ///< p[0, 4)
  void store(double* p) const { _mm_storeu_pd(p, lo), _mm_storeu_pd(p + 2, hi); }       ///< to p[0, 4)
  double lane(int l) const {                                                            ///< lane l
    alignas(16) double t[4];
    store(t);
    return t[l];
  }
};
/// One flag per lane of a Quad (all bits set or none).
struct QuadMask {
  __m128d lo;  ///< lanes 0-1
  __m128d hi;  ///< lanes 2-3

  std::uint32_t bits() const {  ///< bit l = lane l
    return static_cast<std::uint32_t>(_mm_movemask_pd(lo) | _mm_movemask_pd(hi) << 2);
  }
};
inline Quad operator+(Quad a, Quad b) { return {_mm_add_pd(a.lo, b.lo), _mm_add_pd(a.hi, b.hi)}; }          ///< a + b
inline Quad operator-(Quad a, Quad b) { return {_mm_sub_pd(a.lo, b.lo), _mm_sub_pd(a.hi, b.hi)}; }          ///< a - b
inline Quad operator*(Quad a, Quad b) { return {_mm_mul_pd(a.lo, b.lo), _mm_mul_pd(a.hi, b.hi)}; }          ///< a · b
inline Quad operator/(Quad a, Quad b) { return {_mm_div_pd(a.lo, b.lo), _mm_div_pd(a.hi, b.hi)}; }          ///< a / b
inline QuadMask operator<(Quad a, Quad b) { return {_mm_cmplt_pd(a.lo, b.lo), _mm_cmplt_pd(a.hi, b.hi)}; }  ///< a < b
inline QuadMask operator>(Quad a, Quad b) { return {_mm_cmpgt_pd(a.lo, b.lo), _mm_cmpgt_pd(a.hi, b.hi)}; }  ///< a > b
inline QuadMask operator&(QuadMask a, QuadMask b) { return {_mm_and_pd(a.lo, b.lo), _mm_and_pd(a.hi, b.hi)}; }  ///< and
inline QuadMask operator|(QuadMask a, QuadMask b) { return {_mm_or_pd(a.lo, b.lo), _mm_or_pd(a.hi, b.hi)}; }    ///< or
inline QuadMask operator^(QuadMask a, QuadMask b) { return {_mm_xor_pd(a.lo, b.lo), _mm_xor_pd(a.hi, b.hi)}; }  ///< xor
/// m ? a : b per lane.
inline Quad select(QuadMask m, Quad a, Quad b) {
  return {_mm_or_pd(_mm_and_pd(m.lo, a.lo), _mm_andnot_pd(m.lo, b.lo)),
          _mm_or_pd(_mm_and_pd(m.hi, a.hi), _mm_andnot_pd(m.hi, b.hi))};
}
inline Quad sqrt(Quad a) { return {_mm_sqrt_pd(a.lo), _mm_sqrt_pd(a.hi)}; }  ///< √a per lane, correctly rounded
/// Four rows of four doubles (r[k][0, 4)) as four columns: c_j lane k = r[k][j].
inline void transpose(const double* const r[4], Quad& c0, Quad& c1, Quad& c2, Quad& c3) {
  const Quad x0 = Quad::load(r[0]), x1 = Quad::load(r[1]), x2 = Quad::load(r[2]), x3 = Quad::load(r[3]);
  c0 = {_mm_unpacklo_pd(x0.lo, x1.lo), _mm_unpacklo_pd(x2.lo, x3.lo)};
  c1 = {_mm_unpackhi_pd(x0.lo, x1.lo), _mm_unpackhi_pd(x2.lo, x3.lo)};
  c2 = {_mm_unpacklo_pd(x0.hi, x1.hi), _mm_unpacklo_pd(x2.hi, x3.hi)};
  c3 = {_mm_unpackhi_pd(x0.hi, x1.hi), _mm_unpackhi_pd(x2.hi, x3.hi)};
}

}  // namespace sse2

ST_TARGET_AVX2_BEGIN
/// 8 floats (AVX2 with FMA).
namespace avx2 {

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
};
inline Mask operator&(Mask a, Mask b) { return {_mm256_and_ps(a.v, b.v)}; }  ///< lane-wise and
inline Mask operator|(Mask a, Mask b) { return {_mm256_or_ps(a.v, b.v)}; }   ///< lane-wise or

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
};
inline Lanes operator+(Lanes a, Lanes b) { return {_mm256_add_ps(a.v, b.v)}; }        ///< lane-wise a + b
inline Lanes operator-(Lanes a, Lanes b) { return {_mm256_sub_ps(a.v, b.v)}; }        ///< lane-wise a - b
inline Lanes operator*(Lanes a, Lanes b) { return {_mm256_mul_ps(a.v, b.v)}; }        ///< lane-wise a · b
inline Lanes min(Lanes a, Lanes b) { return {_mm256_min_ps(a.v, b.v)}; }              ///< lane-wise min (b if NaN)
inline Lanes max(Lanes a, Lanes b) { return {_mm256_max_ps(a.v, b.v)}; }              ///< lane-wise max (b if NaN)
inline Lanes abs(Lanes a) { return {_mm256_andnot_ps(_mm256_set1_ps(-0.0f), a.v)}; }  ///< lane-wise |a|
inline Lanes operator/(Lanes a, Lanes b) { return {_mm256_div_ps(a.v, b.v)}; }  ///< lane-wise a / b, correctly rounded
inline Lanes sqrt(Lanes a) { return {_mm256_sqrt_ps(a.v)}; }                    ///< lane-wise √a, correctly rounded
/// a <= b per lane; false where either is NaN, as in scalar float.
inline Mask operator<=(Lanes a, Lanes b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ)}; }
/// a >= b per lane; false where either is NaN, as in scalar float.
inline Mask operator>=(Lanes a, Lanes b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GE_OQ)}; }
/// a > b per lane; false where either is NaN, as in scalar float.
inline Mask operator>(Lanes a, Lanes b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GT_OQ)}; }
/// m ? a : b per lane.
inline Lanes select(Mask m, Lanes a, Lanes b) { return {_mm256_blendv_ps(b.v, a.v, m.v)}; }
/// The least lane (lanes not NaN).
inline float hmin(Lanes a) {
  __m128 m = _mm_min_ps(_mm256_castps256_ps128(a.v), _mm256_extractf128_ps(a.v, 1));
  m = _mm_min_ps(m, _mm_movehl_ps(m, m));
  return _mm_cvtss_f32(_mm_min_ss(m, _mm_shuffle_ps(m, m, 1)));
}
/// The greatest lane (lanes not NaN).
inline float hmax(Lanes a) {
  __m128 m = _mm_max_ps(_mm256_castps256_ps128(a.v), _mm256_extractf128_ps(a.v, 1));
  m = _mm_max_ps(m, _mm_movehl_ps(m, m));
  return _mm_cvtss_f32(_mm_max_ss(m, _mm_shuffle_ps(m, m, 1)));
}

/// Four doubles, one record per lane (the contact model's segment kernel).
struct Quad {
  __m256d v;  ///< the doubles

  static Quad broadcast(double x) { return {_mm256_set1_pd(x)}; }  ///< x in every lane
  /// Lanes a, b, c, d.
  static Quad set(double a, double b, double c, double d) { return {_mm256_setr_pd(a, b, c, d)}; }
  static Quad load(const double* p) { return {_mm256_loadu_pd(p)}; }  ///< p[0, 4)
  void store(double* p) const { _mm256_storeu_pd(p, v); }             ///< to p[0, 4)
  double lane(int l) const {                                          ///< lane l
    alignas(32) double t[4];
    store(t);
    return t[l];
  }
};
/// One flag per lane of a Quad (all bits set or none).
struct QuadMask {
  __m256d v;  ///< the flags

  std::uint32_t bits() const { return static_cast<std::uint32_t>(_mm256_movemask_pd(v)); }  ///< bit l = lane l
};
inline Quad operator+(Quad a, Quad b) { return {_mm256_add_pd(a.v, b.v)}; }                   ///< a + b
inline Quad operator-(Quad a, Quad b) { return {_mm256_sub_pd(a.v, b.v)}; }                   ///< a - b
inline Quad operator*(Quad a, Quad b) { return {_mm256_mul_pd(a.v, b.v)}; }                   ///< a · b
inline Quad operator/(Quad a, Quad b) { return {_mm256_div_pd(a.v, b.v)}; }                   ///< a / b
inline QuadMask operator<(Quad a, Quad b) { return {_mm256_cmp_pd(a.v, b.v, _CMP_LT_OQ)}; }   ///< a < b (false for NaN)
inline QuadMask operator>(Quad a, Quad b) { return {_mm256_cmp_pd(a.v, b.v, _CMP_GT_OQ)}; }   ///< a > b (false for NaN)
inline QuadMask operator&(QuadMask a, QuadMask b) { return {_mm256_and_pd(a.v, b.v)}; }       ///< and
inline QuadMask operator|(QuadMask a, QuadMask b) { return {_mm256_or_pd(a.v, b.v)}; }        ///< or
inline QuadMask operator^(QuadMask a, QuadMask b) { return {_mm256_xor_pd(a.v, b.v)}; }       ///< xor
inline Quad select(QuadMask m, Quad a, Quad b) { return {_mm256_blendv_pd(b.v, a.v, m.v)}; }  ///< m ? a : b per lane
inline Quad sqrt(Quad a) { return {_mm256_sqrt_pd(a.v)}; }  ///< √a per lane, correctly rounded
/// Four rows of four doubles (r[k][0, 4)) as four columns: c_j lane k = r[k][j].
inline void transpose(const double* const r[4], Quad& c0, Quad& c1, Quad& c2, Quad& c3) {
  const __m256d x0 = _mm256_loadu_pd(r[0]), x1 = _mm256_loadu_pd(r[1]), x2 = _mm256_loadu_pd(r[2]),
                x3 = _mm256_loadu_pd(r[3]);
  const __m256d t0 = _mm256_unpacklo_pd(x0, x1), t1 = _mm256_unpackhi_pd(x0, x1);
  const __m256d t2 = _mm256_unpacklo_pd(x2, x3), t3 = _mm256_unpackhi_pd(x2, x3);
  c0 = {_mm256_permute2f128_pd(t0, t2, 0x20)};
  c1 = {_mm256_permute2f128_pd(t1, t3, 0x20)};
  c2 = {_mm256_permute2f128_pd(t0, t2, 0x31)};
  c3 = {_mm256_permute2f128_pd(t1, t3, 0x31)};
}

}  // namespace avx2
ST_TARGET_END

ST_TARGET_AVX512_BEGIN
/// 16 floats (AVX-512 F and VL).
namespace avx512 {

/// One flag per lane, in an AVX-512 mask register.
struct Mask {
  __mmask16 v;  ///< bit l = lane l

  /// Lanes l < live are set (live may exceed the width).
  static Mask first(std::uint32_t live) { return {static_cast<__mmask16>(live >= 16 ? 0xffffu : (1u << live) - 1u)}; }
  std::uint32_t bits() const { return v; }  ///< bit l = lane l
};
inline Mask operator&(Mask a, Mask b) { return {static_cast<__mmask16>(a.v & b.v)}; }  ///< lane-wise and
inline Mask operator|(Mask a, Mask b) { return {static_cast<__mmask16>(a.v | b.v)}; }  ///< lane-wise or

/// 16 floats.
struct Lanes {
  static constexpr int width = 16;  ///< floats per step
  __m512 v;                         ///< the floats

  static Lanes load(const float* p) { return {_mm512_loadu_ps(p)}; }  ///< p[0, 16), unaligned
  static Lanes broadcast(float x) { return {_mm512_set1_ps(x)}; }     ///< x in every lane
  /// Lane l = p[l·Stride] for l < live, 0 for the others, whose addresses are never read.
  template <int Stride>
  static Lanes gather(const float* p, std::uint32_t live) {
    const __m512i idx = _mm512_mullo_epi32(_mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
                                           _mm512_set1_epi32(Stride));
    return {_mm512_mask_i32gather_ps(_mm512_setzero_ps(), Mask::first(live).v, idx, p, 4)};
  }
};
inline Lanes operator+(Lanes a, Lanes b) { return {_mm512_add_ps(a.v, b.v)}; }  ///< lane-wise a + b
inline Lanes operator-(Lanes a, Lanes b) { return {_mm512_sub_ps(a.v, b.v)}; }  ///< lane-wise a - b
inline Lanes operator*(Lanes a, Lanes b) { return {_mm512_mul_ps(a.v, b.v)}; }  ///< lane-wise a · b
inline Lanes min(Lanes a, Lanes b) { return {_mm512_min_ps(a.v, b.v)}; }        ///< lane-wise min (b if NaN)
inline Lanes max(Lanes a, Lanes b) { return {_mm512_max_ps(a.v, b.v)}; }        ///< lane-wise max (b if NaN)
inline Lanes abs(Lanes a) { return {_mm512_abs_ps(a.v)}; }                      ///< lane-wise |a|
inline Lanes operator/(Lanes a, Lanes b) { return {_mm512_div_ps(a.v, b.v)}; }  ///< lane-wise a / b, correctly rounded
inline Lanes sqrt(Lanes a) { return {_mm512_sqrt_ps(a.v)}; }                    ///< lane-wise √a, correctly rounded
/// a <= b per lane; false where either is NaN, as in scalar float.
inline Mask operator<=(Lanes a, Lanes b) { return {_mm512_cmp_ps_mask(a.v, b.v, _CMP_LE_OQ)}; }
/// a >= b per lane; false where either is NaN, as in scalar float.
inline Mask operator>=(Lanes a, Lanes b) { return {_mm512_cmp_ps_mask(a.v, b.v, _CMP_GE_OQ)}; }
/// a > b per lane; false where either is NaN, as in scalar float.
inline Mask operator>(Lanes a, Lanes b) { return {_mm512_cmp_ps_mask(a.v, b.v, _CMP_GT_OQ)}; }
inline Lanes select(Mask m, Lanes a, Lanes b) { return {_mm512_mask_blend_ps(m.v, b.v, a.v)}; }  ///< m ? a : b per lane
inline float hmin(Lanes a) { return _mm512_reduce_min_ps(a.v); }  ///< the least lane (lanes not NaN)
inline float hmax(Lanes a) { return _mm512_reduce_max_ps(a.v); }  ///< the greatest lane (lanes not NaN)

}  // namespace avx512
ST_TARGET_END

#endif  // ST_SIMD_X86

}  // namespace st::geom::simd
