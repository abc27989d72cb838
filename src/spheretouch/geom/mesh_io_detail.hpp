// SPDX-License-Identifier: BSD-3-Clause
// Internal to the mesh readers (mesh_io*.cpp): the text tokenizer, number parsing, the error
// helper, polygon fanning, vertex welding and the common end of every reader. Not installed.
#pragma once
#include <spheretouch/abi.hpp>
#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include <spheretouch/geom/mesh_io.hpp>

namespace st::inline SPHERETOUCH_ABI::geom::detail {

/// The one error helper of the text readers: "name:line" then the message pieces.
template <class... Args>
Error fail_at_line(const std::string& name, std::size_t line, Args&&... args) {
  return fail(name, ":", line, std::forward<Args>(args)...);
}

/// Reads a whole file; the error names the file.
Result<std::string> slurp(const std::string& path);

/// The path's extension in lower case, with its dot ("" when it has none).
std::string lower_ext(const std::string& path);

/// Splits text into lines and lines into whitespace-separated tokens, counting line numbers.
class Lines {
 public:
  explicit Lines(std::string_view text) : text_(text) {}
  /// Next line with `#...` comments and surrounding blanks removed; false at end of text.
  bool next(std::string_view& line, bool strip_comments = true) {
    while (pos_ < text_.size()) {
      std::size_t end = text_.find('\n', pos_);
      if (end == std::string_view::npos) end = text_.size();
      line = text_.substr(pos_, end - pos_);
      pos_ = end + 1;
      ++line_no_;
      if (strip_comments) {
        const auto hash = line.find('#');
        if (hash != std::string_view::npos) line = line.substr(0, hash);
      }
      while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.remove_suffix(1);
      while (!line.empty() && std::isspace(static_cast<unsigned char>(line.front()))) line.remove_prefix(1);
      if (!line.empty()) return true;
    }
    return false;
  }
  std::size_t line_no() const { return line_no_; }  ///< 1-based number of the last line returned
  /// Byte offset just past the last line returned (where a binary PLY body starts).
  std::size_t offset() const { return std::min(pos_, text_.size()); }

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t line_no_ = 0;
};

/// Pops the next whitespace-separated token from `s`; empty when none is left.
std::string_view token(std::string_view& s);

/// Correctly rounded decimal -> double (std::from_chars); accepts a leading '+'.
bool to_double(std::string_view t, double& out);

bool to_int(std::string_view t, long long& out);

std::string quote(std::string_view t);

/// Appends the fan triangulation of one polygon, (v0, vk, vk+1), to `faces`.
void fan(const std::vector<std::uint32_t>& poly, std::vector<Tri>& faces, LoadReport& rep);

Result<LoadedMesh> finish(const std::string& name, const std::vector<Vec3>& pos, std::vector<Tri> faces, LoadReport rep);

/// Welds exact-duplicate vertices (formats like STL repeat them per face), so closedness and
/// subdivision see the real topology; +0 and -0 weld together. Welding never reorders faces.
class Welder {
 public:
  /// Index of `q` among the distinct vertices so far, adding it if new.
  std::uint32_t add(const Vec3& q) {
    ++raw_;
    auto [slot, fresh] = index_of_.try_emplace(q, static_cast<std::uint32_t>(pos_.size()));
    if (fresh) pos_.push_back(q);
    return slot->second;
  }
  const std::vector<Vec3>& positions() const { return pos_; }  ///< distinct vertices, first-seen order
  std::size_t welded() const { return raw_ - pos_.size(); }    ///< duplicates merged

 private:
  struct Hash {
    std::size_t operator()(const Vec3& v) const {
      std::size_t h = 1469598103934665603ull;
      for (int i = 0; i < 3; ++i) {
        std::uint64_t b;
        const double d = v[i] == 0.0 ? 0.0 : v[i];  // +0 and -0 weld together
        std::memcpy(&b, &d, 8);
        h = (h ^ b) * 1099511628211ull;
      }
      return h;
    }
  };
  std::unordered_map<Vec3, std::uint32_t, Hash> index_of_;
  std::vector<Vec3> pos_;
  std::size_t raw_ = 0;
};

/// True when assimp has an importer for this extension (".gltf").
bool assimp_reads(const std::string& ext);
/// Reads `path` with assimp in a confined, budgeted child process (mesh_io_assimp.cpp).
Result<LoadedMesh> load_with_assimp(const std::string& path, const LoadConfig& o);

}  // namespace st::geom::detail
