// spheretouch-bench subcommands. Each benchmark lives in its own bench_*.cpp and registers
// itself here; every one prints a table, or one JSON object with --json.
#pragma once
#include <CLI/CLI.hpp>

namespace st::bench {

void add_load(CLI::App& app);     ///< mesh loading time (issue 2: the 832k-face armadillo)
void add_scatter(CLI::App& app);  ///< scatter-gather round trip of an empty query, N workers × transport

}  // namespace st::bench
