// SPDX-License-Identifier: BSD-3-Clause
// Shared by the libFuzzer targets (tests/fuzz/fuzz_*.cpp): a property check that survives
// NDEBUG (the replay builds are release builds) and aborts, so libFuzzer saves the input.
#pragma once
#include <cstdio>
#include <cstdlib>

/// Aborts with the failed condition and a note when `cond` is false.
#define ST_FUZZ_CHECK(cond, what)                                                                        \
  do {                                                                                                   \
    if (!(cond)) {                                                                                       \
      std::fprintf(stderr, "%s:%d: fuzz property violated: %s (%s)\n", __FILE__, __LINE__, #cond, what); \
      std::abort();                                                                                      \
    }                                                                                                    \
  } while (0)
