// SPDX-License-Identifier: BSD-3-Clause
// spheretouch: the command line. Subcommands are registered from commands.hpp.
#include <malloc.h>

#include <cstdio>

#include "app/commands.hpp"

int main(int argc, char** argv) {
  // One malloc arena: the short-lived threads that encode block sets after a worker fault would
  // each get an arena of their own, and glibc keeps those arenas' freed megabytes resident for
  // good; in the one main arena malloc_trim() gives them back (memory stays flat through faults,
  // perf/soak.sh). No real-time path allocates (the haptic tick is tested allocation-free).
  mallopt(M_ARENA_MAX, 1);
  CLI::App app{
      "spheretouch: touch virtual objects of millions of triangles through a haptic device.\n"
      "Exact face-level collision with layered boundary spheres, distributed over workers,\n"
      "force at 1 kHz. Units: millimetres, newtons, seconds."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "spheretouch 0.1.0");
  st::app::add_info(app);
  st::app::add_export(app);
  st::app::add_query(app);
  st::app::add_build(app);
  st::app::add_run(app);
  st::app::add_monitor(app);
  st::app::add_servo(app);
  st::app::add_keygen(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) { return app.exit(e); }
  return 0;
}
