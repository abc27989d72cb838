// Checked reading of one TOML table: every value is range-checked, every error names the file,
// line, field path and what was expected, and keys nobody asked for are rejected at the end.
#pragma once
#include <toml++/toml.h>

#include <cmath>
#include <set>
#include <string>
#include <vector>

#include "geom/result.hpp"

namespace st::app {

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
  /// True when the table has `key`.
  bool has(const char* key) const { return t_ && t_->contains(key); }
  /// Fails on the first error, or on any key that was never read ("unknown key").
  Status finish() {
    if (!error_.empty()) return Error{error_};
    if (t_)
      for (const auto& [k, v] : *t_)
        if (!seen_.count(std::string(k.str())))
          return fail(where(&v), field(std::string(k.str())),
                      ": unknown key (check the spelling; configs/demo.toml lists every field)");
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
    auto s = [](double x) {
      std::ostringstream o;
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

}  // namespace st::app
