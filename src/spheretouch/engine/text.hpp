// SPDX-License-Identifier: BSD-3-Clause
// Text helpers of the run's summary and the command line.
#pragma once
#include <spheretouch/abi.hpp>
#include <sys/random.h>

#include <cstdarg>
#include <cstdio>
#include <string>

namespace st::inline SPHERETOUCH_ABI::engine {

/// Appends printf-style text to `out`, whatever its length; the compiler checks the format
/// against the arguments.
[[gnu::format(printf, 2, 3)]] inline void appendf(std::string& out, const char* fmt, ...) {
  va_list ap, again;
  va_start(ap, fmt);
  va_copy(again, ap);
  const int n = std::vsnprintf(nullptr, 0, fmt, ap);
  va_end(ap);
  if (n > 0) {
    const std::size_t at = out.size();
    out.resize(at + std::size_t(n) + 1);
    std::vsnprintf(out.data() + at, std::size_t(n) + 1, fmt, again);
    out.resize(at + std::size_t(n));
  }
  va_end(again);
}

/// `bytes` random bytes from the kernel's CSPRNG (getrandom) as hexadecimal digits: names and
/// tokens another user must not guess.
inline std::string random_hex(std::size_t bytes) {
  std::string out;
  for (std::size_t i = 0; i < bytes; ++i) {
    unsigned char b = 0;
    while (getrandom(&b, 1, 0) != 1) {}
    char h[3];
    std::snprintf(h, sizeof h, "%02x", b);
    out += h;
  }
  return out;
}

}  // namespace st::engine
