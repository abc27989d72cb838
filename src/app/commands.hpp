// The `spheretouch` subcommands. Each lives in its own cmd_*.cpp and registers itself on the
// root CLI11 app; a failing command throws CLI::RuntimeError(exit_code) after printing why.
#pragma once
#include <CLI/CLI.hpp>
#include <cstdarg>
#include <cstdio>
#include <string>

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

}  // namespace st::app
