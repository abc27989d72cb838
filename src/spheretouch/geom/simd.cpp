// SPDX-License-Identifier: BSD-3-Clause
// The run-time choice of the SIMD kernels' instruction set (simd.hpp).
#include <spheretouch/geom/simd.hpp>

#include <atomic>
#include <cstdlib>

namespace st::inline SPHERETOUCH_ABI::geom::simd {
namespace {

Isa detect() {
#if defined(ST_SIMD_X86)
  __builtin_cpu_init();
  // AVX2 kernels are compiled with FMA too (the same Haswell generation; every AVX2 CPU has it).
  const bool avx2 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  if (avx2 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl")) return Isa::avx512;
  if (avx2) return Isa::avx2;
  return Isa::sse2;
#else
  return Isa::scalar;
#endif
}

// The active ISA; -1 until first asked for (then best_isa(), lowered by ST_SIMD).
std::atomic<int> g_active{-1};

int initial() {
  Isa isa = best_isa();
  if (const char* env = std::getenv("ST_SIMD")) {
    Isa want;
    // An unknown name or an ISA the CPU lacks is ignored: the kernels are exact on every ISA, so
    // the variable only ever chooses among equally correct paths.
    if (parse_isa(env, want) && want <= isa) isa = want;
  }
  return static_cast<int>(isa);
}

}  // namespace

Isa best_isa() {
  static const Isa best = detect();
  return best;
}

Isa active_isa() {
  int a = g_active.load(std::memory_order_relaxed);
  if (a < 0) [[unlikely]] {
    int expected = -1;
    g_active.compare_exchange_strong(expected, initial(), std::memory_order_relaxed);
    a = g_active.load(std::memory_order_relaxed);
  }
  return static_cast<Isa>(a);
}

bool set_isa(Isa isa) {
  if (isa > best_isa()) return false;
  g_active.store(static_cast<int>(isa), std::memory_order_relaxed);
  return true;
}

const char* isa_name(Isa isa) {
  switch (isa) {
    case Isa::scalar:
      return "scalar";
    case Isa::sse2:
      return "sse2";
    case Isa::avx2:
      return "avx2";
    case Isa::avx512:
      return "avx512";
  }
  return "?";
}

bool parse_isa(std::string_view name, Isa& isa) {
  for (const Isa i : {Isa::scalar, Isa::sse2, Isa::avx2, Isa::avx512})
    if (name == isa_name(i)) {
      isa = i;
      return true;
    }
  return false;
}

}  // namespace st::geom::simd
