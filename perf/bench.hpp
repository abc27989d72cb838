// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench subcommands. Each benchmark lives in its own bench_*.cpp and registers
// itself here; every one prints a table, or one JSON object with --json.
#pragma once
#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>
#include <vector>

#include <spheretouch/geom/mesh.hpp>

namespace st::bench {

/// A TCP port on 127.0.0.1 that was free a moment ago (for workers the benchmarks start).
int free_tcp_port();
/// Prints "spheretouch-bench: msg" to stderr and ends the command with exit status 2.
[[noreturn]] void die(const std::string& msg);
/// Prints "spheretouch-bench <command>: msg" to stderr and ends the command with exit status 2.
[[noreturn]] void die(const char* command, const std::string& msg);
/// The 1 kHz servo's tick (rt::kDefaultRateHz), ns: the simulated clock of the force benches.
inline constexpr std::int64_t kTickNs = 1'000'000;
/// CPU time of this process so far (every thread, user + system), µs.
double process_cpu_us();

// Shared by the collision benches (defined in bench_collide.cpp).
/// The q-quantile of v (q in [0, 1]; 0 for an empty v).
double percentile(std::vector<double> v, double q);
/// --isa: runs the SIMD kernels on the instruction set named (empty: leaves the default); a name
/// it does not know or the CPU lacks is an error (exit 2) that says which.
void use_isa(const std::string& name);
/// The mesh at path; an unreadable file is an error (exit 2) naming it.
geom::Mesh load_mesh_or_exit(const std::string& path);

void add_load(CLI::App& app);     ///< mesh loading time (the 832k-face armadillo)
void add_tree(CLI::App& app);     ///< sphere-tree build time and bytes/face
void add_collide(CLI::App& app);  ///< collide() query time at contact buckets, pose finder
void add_slides(CLI::App& app);  ///< the coherent collider against collide() along slides and a jerk (bench_slides.cpp)
void add_exchange(CLI::App& app);  ///< TripleBuffer vs mutex take-newest latency
void add_haptic(CLI::App& app);    ///< HapticLoop vs bare clock_nanosleep wake-up latency
void add_echo(CLI::App& app);      ///< hidden: a raw ZeroMQ echo process (scatter --spawn's floor)
void add_scatter(CLI::App& app);   ///< scatter-gather round trip of an empty query, N workers × transport
void add_tables(CLI::App& app);  ///< the paper's tables: table1, table2, table3, peers, trade, icosphere (bench_tables.cpp)
void add_force(CLI::App& app);    ///< force rendering quality per contact model, simulated time (bench_force.cpp)
void add_hostile(CLI::App& app);  ///< security reproducers against a live worker (bench_hostile.cpp)
void add_scale(CLI::App& app);    ///< scale-out model: worker shares timed alone per W and mapping (bench_scale.cpp)
void add_scene(CLI::App& app);    ///< a round's cost against the number of objects in a scene (bench_scene.cpp)

}  // namespace st::bench
