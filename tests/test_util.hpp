// SPDX-License-Identifier: BSD-3-Clause
// Helpers shared by the doctest suites: temporary directories, files, and where the model set is.
#pragma once
#include <doctest/doctest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>

namespace st::test {

/// True in AddressSanitizer and ThreadSanitizer builds. There the brute-force references run
/// 20–50× slower than in the release build, so the tests that loop over many poses take fewer
/// of them (same code paths, fewer repetitions); the release build runs them all.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
inline constexpr bool kSanitizerBuild = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
inline constexpr bool kSanitizerBuild = true;
#else
inline constexpr bool kSanitizerBuild = false;
#endif
#else
inline constexpr bool kSanitizerBuild = false;
#endif

/// A fresh directory under the system temp dir, removed when the object dies.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    std::random_device rd;
    path = std::filesystem::temp_directory_path() / ("spheretouch-test-" + std::to_string(rd()) + std::to_string(rd()));
    std::filesystem::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  std::string file(const std::string& name) const { return (path / name).string(); }  ///< path of a file inside
};

/// True when `part` occurs in `s` (for checking messages).
inline bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

/// Writes `data` to `path` (binary).
inline void write_file(const std::string& path, const std::string& data) {
  std::ofstream o(path, std::ios::binary);
  o.write(data.data(), static_cast<std::streamsize>(data.size()));
  REQUIRE(o.good());
}

/// x moved by `ulps` representable doubles (up for ulps > 0, down for ulps < 0).
inline double nudge(double x, int ulps) {
  for (; ulps > 0; --ulps) x = std::nextafter(x, HUGE_VAL);
  for (; ulps < 0; ++ulps) x = std::nextafter(x, -HUGE_VAL);
  return x;
}

/// The whole file (empty when it cannot be read).
inline std::string read_file(const std::string& path) {
  std::ifstream i(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(i), std::istreambuf_iterator<char>());
}

/// Directory of the model set (scripts/models.sh): $ST_MODEL_DIR, else $ST_SOURCE_ROOT/.cache/models.
inline std::string models_dir() {
  if (const char* d = std::getenv("ST_MODEL_DIR")) return d;
  if (const char* r = std::getenv("ST_SOURCE_ROOT")) return std::string(r) + "/.cache/models";
  return ".cache/models";
}

/// Path of a model-set mesh; fails the test (never skips) when the model set has not been built.
inline std::string model(const std::string& name) {
  const std::string p = models_dir() + "/" + name;
  INFO("model set missing: run scripts/models.sh (looked for " << p << ")");
  REQUIRE(std::filesystem::exists(p));
  return p;
}

/// Directory of the build tree (for running the built executables), from meson's test env.
inline std::string build_root() {
  if (const char* b = std::getenv("ST_BUILD_ROOT")) return b;
  return "build";
}

}  // namespace st::test

#include <array>
#include <cstdio>
#include <sys/wait.h>

namespace st::test {

/// Output (stdout and stderr together) and exit code of a shell command.
struct CommandResult {
  int exit_code = -1;
  std::string output;
};

/// Runs `command` through /bin/sh and captures its output.
inline CommandResult run_command(const std::string& command) {
  CommandResult r;
  FILE* p = popen(("{ " + command + "; } 2>&1").c_str(), "r");
  REQUIRE(p != nullptr);
  std::array<char, 4096> buf;
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), p)) > 0;) r.output.append(buf.data(), n);
  const int status = pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

/// Path of the built `spheretouch` command line.
inline std::string spheretouch_exe() { return build_root() + "/spheretouch"; }

}  // namespace st::test
