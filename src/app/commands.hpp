// SPDX-License-Identifier: BSD-3-Clause
// The `spheretouch` subcommands. Each lives in its own cmd_*.cpp and registers itself on the
// root CLI11 app; a failing command throws CLI::RuntimeError(exit_code) after printing why.
#pragma once
#include <CLI/CLI.hpp>
#include <csignal>
#include <cstdio>
#include <string>

#include <spheretouch/engine/text.hpp>

namespace st::app {

void add_info(CLI::App& app);     ///< spheretouch info MESH...
void add_export(CLI::App& app);   ///< spheretouch export IN -o OUT (scale, subdivide, write OFF)
void add_query(CLI::App& app);    ///< spheretouch query PROBE OBJECT --poses FILE
void add_build(CLI::App& app);    ///< spheretouch build MESH -o FILE (sphere-tree file)
void add_run(CLI::App& app);      ///< spheretouch run SCENE [--split] (the main job)
void add_servo(CLI::App& app);    ///< spheretouch servo ... (hidden: the servo process of run --split)
void add_monitor(CLI::App& app);  ///< spheretouch monitor [--name SEGMENT] (watch a live run)
void add_keygen(CLI::App& app);   ///< spheretouch keygen --out PREFIX (CURVE key pair files)

/// Prints "<who>: <msg>" on stderr and ends the command with exit status `code`.
[[noreturn]] inline void fail_command(const char* who, int code, const std::string& msg) {
  std::fprintf(stderr, "%s: %s\n", who, msg.c_str());
  throw CLI::RuntimeError(code);
}

/// SIGINT, SIGTERM and SIGHUP call `handler` (it only records the signal): a closed terminal
/// ends a run like Ctrl-C, with the summary kept and the shared-memory segment removed.
inline void on_stop_signals(void (*handler)(int)) {
  struct sigaction sa {};
  sa.sa_handler = handler;
  sigemptyset(&sa.sa_mask);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaction(sig, &sa, nullptr);
}

using engine::appendf;  ///< printf-style append (engine/text.hpp)

}  // namespace st::app
