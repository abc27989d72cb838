// SPDX-License-Identifier: BSD-3-Clause
// Checked reading of TOML configuration, the one reader of scene files (src/spheretouch/engine/scene.cpp) and
// worker daemon configs (src/spheretouch/net/worker_config.cpp): every value is type- and range-checked,
// every error names the file, line, field path and what was expected, and keys nobody asked for
// are rejected at the end with the list of known ones. Header-only: the net library and the
// application both use it, and neither installs it.
#pragma once
#include <spheretouch/abi.hpp>
#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <spheretouch/geom/result.hpp>

namespace st::inline SPHERETOUCH_ABI::config {

/// Parses TOML text; a syntax error names the file, line and column.
inline Result<toml::table> parse_toml(std::string_view text, const std::string& file) {
  try {
    return toml::parse(text, file);
  } catch (const toml::parse_error& e) {
    return fail(file, ":", e.source().begin.line, ":", e.source().begin.column, ": TOML syntax: ", e.description());
  }
}

/// Reads fields of one table; the first error sticks and later reads become no-ops.
class TomlReader {
 public:
  /// `table` may be null (section absent: every field keeps its default). `path` is the dotted
  /// section name used in messages ("force"), `file` the scene file.
  TomlReader(const toml::table* table, std::string path, std::string file)
      : t_(table), path_(std::move(path)), file_(std::move(file)) {}

  /// Optional number in [lo, hi]; integers are accepted where a float is expected.
  void number(const char* key, double& out, double lo, double hi) {
    const toml::node* n = find(key);
    if (!n) return;
    std::optional<double> v = n->value<double>();
    if (!v || !n->is_number()) return bad(n, key, "a number");
    if (!std::isfinite(*v) || *v < lo || *v > hi) return bad(n, key, range(lo, hi), *v);
    out = *v;
  }
  /// Optional integer in [lo, hi].
  template <class Int>
  void integer(const char* key, Int& out, long long lo, long long hi) {
    const toml::node* n = find(key);
    if (!n) return;
    if (!n->is_integer()) return bad(n, key, "an integer");
    const long long v = n->as_integer()->get();
    if (v < lo || v > hi) return bad(n, key, range(double(lo), double(hi)), double(v));
    out = static_cast<Int>(v);
  }
  /// Optional integer in [lo, hi], or the string "auto" (then `out` = `auto_value`).
  template <class Int>
  void integer_or_auto(const char* key, Int& out, long long lo, long long hi, Int auto_value) {
    const toml::node* n = find(key);
    if (!n) return;
    if (n->is_string() && n->as_string()->get() == "auto") {
      out = auto_value;
      return;
    }
    if (!n->is_integer()) return bad(n, key, "an integer or \"auto\"");
    integer(key, out, lo, hi);
  }
  /// Optional boolean.
  void boolean(const char* key, bool& out) {
    const toml::node* n = find(key);
    if (!n) return;
    if (!n->is_boolean()) return bad(n, key, "true or false");
    out = n->as_boolean()->get();
  }
  /// Optional string; when `choices` is non-empty the value must be one of them.
  void string(const char* key, std::string& out, const std::vector<std::string>& choices = {}) {
    const toml::node* n = find(key);
    if (!n) return;
    if (!n->is_string()) return bad(n, key, "a string");
    const std::string v = n->as_string()->get();
    if (!choices.empty() && std::find(choices.begin(), choices.end(), v) == choices.end()) {
      std::string list;
      for (const auto& c : choices) list += (list.empty() ? "" : ", ") + c;
      return bad(n, key, "one of " + list + " (found '" + v + "')");
    }
    out = v;
  }
  /// Optional array of exactly `count` finite numbers (or any count when count == 0).
  void numbers(const char* key, std::vector<double>& out, std::size_t count) {
    const toml::node* n = find(key);
    if (!n) return;
    const toml::array* arr = n->as_array();
    if (!arr || (count && arr->size() != count))
      return bad(n, key, count ? "an array of " + std::to_string(count) + " numbers" : std::string("an array of numbers"));
    std::vector<double> v;
    for (const toml::node& e : *arr) {
      std::optional<double> d = e.value<double>();
      if (!d || !e.is_number() || !std::isfinite(*d)) return bad(&e, key, "finite numbers in the array");
      v.push_back(*d);
    }
    out = std::move(v);
  }
  /// Optional array of integers, each in [lo, hi].
  template <class Int>
  void integers(const char* key, std::vector<Int>& out, long long lo, long long hi) {
    const toml::node* n = find(key);
    if (!n) return;
    const toml::array* arr = n->as_array();
    if (!arr) return bad(n, key, "an array of integers");
    std::vector<Int> v;
    for (const toml::node& e : *arr) {
      if (!e.is_integer()) return bad(&e, key, "an integer for each element");
      const long long x = e.as_integer()->get();
      if (x < lo || x > hi) return bad(&e, key, range(double(lo), double(hi)), double(x));
      v.push_back(static_cast<Int>(x));
    }
    out = std::move(v);
  }
  /// Optional array of strings.
  void strings(const char* key, std::vector<std::string>& out) {
    const toml::node* n = find(key);
    if (!n) return;
    const toml::array* arr = n->as_array();
    if (!arr) return bad(n, key, "an array of strings");
    std::vector<std::string> v;
    for (const toml::node& e : *arr) {
      if (!e.is_string()) return bad(&e, key, "strings in the array");
      v.push_back(e.as_string()->get());
    }
    out = std::move(v);
  }
  /// Marks a key as known without reading it here (a sub-table read by another reader).
  void known(const char* key) { seen_.insert(key); }
  /// Optional sub-table `key` (marked known): null when absent or after an error; an error when
  /// `key` is there but not a table.
  const toml::table* table(const char* key) {
    const toml::node* n = find(key);
    if (!n) return nullptr;
    if (!n->is_table()) {
      bad(n, key, std::string("a [") + field(key) + "] table");
      return nullptr;
    }
    return n->as_table();
  }
  /// True when the table has `key`.
  bool has(const char* key) const { return t_ && t_->contains(key); }
  /// Fails on the first error, or on any key that was never read: "unknown key 'path.key'"
  /// with the keys this table knows (every reader asks for all its keys before finish()).
  Status finish() {
    if (!error_.empty()) return Error{error_};
    if (t_)
      for (const auto& [k, v] : *t_)
        if (!seen_.count(std::string(k.str()))) {
          std::string list;
          for (const std::string& s : seen_) list += (list.empty() ? "" : ", ") + s;
          return fail(where(&v), "unknown key '", field(std::string(k.str())), "' (known",
                      path_.empty() ? std::string() : " in [" + path_ + "]", ": ", list, ")");
        }
    return Ok{};
  }
  /// Records an error about `key` from outside (cross-field checks).
  void error(const char* key, const std::string& what) {
    if (error_.empty()) error_ = where(t_ && t_->contains(key) ? t_->get(key) : nullptr) + field(key) + ": " + what;
  }

 private:
  const toml::node* find(const char* key) {
    seen_.insert(key);
    if (!t_ || !error_.empty()) return nullptr;
    return t_->get(key);
  }
  std::string field(const std::string& key) const { return (path_.empty() ? "" : path_ + ".") + key; }
  std::string where(const toml::node* n) const {
    if (n && n->source().begin.line) return file_ + ":" + std::to_string(n->source().begin.line) + ": ";
    return file_ + ": ";
  }
  static std::string range(double lo, double hi) {
    auto s = [](double x) {  // integers in full (1048576, not 1.04858e+06)
      std::ostringstream o;
      if (x == std::floor(x) && std::abs(x) < 1e15)
        o << static_cast<long long>(x);
      else
        o << x;
      return o.str();
    };
    return "a value in [" + s(lo) + ", " + s(hi) + "]";
  }
  void bad(const toml::node* n, const char* key, const std::string& expected, double found) {
    std::ostringstream o;
    o.precision(17);
    o << found;
    bad(n, key, expected + " (found " + o.str() + ")");
  }
  void bad(const toml::node* n, const char* key, const std::string& expected) {
    if (error_.empty()) error_ = where(n) + field(key) + ": expected " + expected;
  }

  const toml::table* t_;
  std::string path_, file_, error_;
  std::set<std::string> seen_;
};

}  // namespace st::config
