// SPDX-License-Identifier: BSD-3-Clause
// The benchmarks' --json output: one nlohmann-json document per run, built as values and printed
// once, so that strings are escaped and a non-finite figure comes out as null, never as invalid JSON.
#pragma once
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include <nlohmann/json.hpp>

namespace st::bench {

/// Keys stay in the order they are set: the order the printf-written documents had.
using Json = nlohmann::ordered_json;

/// `x` rounded to `digits` decimals exactly as printf's "%.*f" rounds it: the precision a figure is
/// reported at (timings far below their noise are not digits worth keeping in the committed
/// results). Non-finite values pass through, and print as null.
inline double round_to(double x, int digits) {
  char buf[400];  // "%.*f" of the largest double: 309 digits before the point
  if (!std::isfinite(x) || digits < 0 || digits > 40) return x;
  std::snprintf(buf, sizeof buf, "%.*f", digits, x);
  return std::strtod(buf, nullptr);
}

/// `x` rounded to `digits` significant digits, as printf's "%.*g" rounds it.
inline double round_sig(double x, int digits) {
  char buf[64];
  if (!std::isfinite(x) || digits < 1 || digits > 40) return x;
  std::snprintf(buf, sizeof buf, "%.*g", digits, x);
  return std::strtod(buf, nullptr);
}

/// Prints `j` on stdout, one value a line (indent 1), and a newline. Invalid UTF-8 in a string (a
/// file name) is replaced rather than thrown on.
inline void print_json(const Json& j) {
  std::printf("%s\n", j.dump(1, ' ', false, Json::error_handler_t::replace).c_str());
}

}  // namespace st::bench
