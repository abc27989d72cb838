// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench: the benchmark programs behind perf/RESULTS.md.
#include "bench.hpp"

#include <cstdio>
#include <ctime>

namespace st::bench {

double process_cpu_us() {
  timespec ts{};
  ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e6 + double(ts.tv_nsec) * 1e-3;
}

void die(const std::string& msg) { die("", msg); }

void die(const char* command, const std::string& msg) {
  std::fprintf(stderr, "spheretouch-bench%s%s: %s\n", *command ? " " : "", command, msg.c_str());
  throw CLI::RuntimeError(2);
}

}  // namespace st::bench

int main(int argc, char** argv) {
  CLI::App app{
      "spheretouch-bench: benchmarks behind perf/RESULTS.md (ratios against baselines "
      "measured in the same run)"};
  app.require_subcommand(1);
  st::bench::add_load(app);
  st::bench::add_tree(app);
  st::bench::add_collide(app);
  st::bench::add_slides(app);
  st::bench::add_exchange(app);
  st::bench::add_haptic(app);
  st::bench::add_scatter(app);
  st::bench::add_echo(app);
  st::bench::add_tables(app);
  st::bench::add_force(app);
  st::bench::add_hostile(app);
  st::bench::add_scale(app);
  st::bench::add_scene(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) { return app.exit(e); }
  return 0;
}
