// SPDX-License-Identifier: BSD-3-Clause
// Tree cache policy: see tree_cache.hpp.
#include <spheretouch/engine/tree_cache.hpp>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <unistd.h>

#include <spheretouch/geom/tree_io.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

std::string default_tree_cache_dir() {
  if (const char* d = std::getenv("ST_TREE_CACHE"); d && *d) return d;
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/spheretouch/trees";
  if (const char* h = std::getenv("HOME"); h && *h) return std::string(h) + "/.cache/spheretouch/trees";
  return ".cache/trees";
}

std::string tree_cache_path(const std::string& dir, const geom::Mesh& mesh, const geom::TreeConfig& params) {
  char name[32];
  std::snprintf(name, sizeof name, "%016llx.stree", static_cast<unsigned long long>(geom::tree_hash(mesh, params)));
  return dir + "/" + name;
}

Result<CachedTree> tree_for(const geom::Mesh& mesh, const geom::TreeConfig& params, const std::string& cache_dir) {
  CachedTree out{{}, TreeSource::built, "", ""};
  if (!cache_dir.empty()) {
    out.path = tree_cache_path(cache_dir, mesh, params);
    std::error_code ec;
    if (std::filesystem::exists(out.path, ec)) {
      Result<geom::SphereTree> r = geom::read_tree(out.path, mesh, params);
      if (r) {
        out.tree = std::move(r).value();
        out.source = TreeSource::cached;
        return out;
      }
      out.note = r.error();
      out.source = r.error().find(": stale:") != std::string::npos ? TreeSource::rebuilt_stale : TreeSource::rebuilt_corrupt;
    }
  }
  Result<geom::SphereTree> built = geom::SphereTree::build(mesh, params);
  if (!built) return Error{built.error()};
  out.tree = std::move(built).value();
  if (!out.path.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(cache_dir, ec);
    // Write to a temporary name and rename, so a concurrent reader never sees half a file.
    const std::string tmp = out.path + ".tmp" + std::to_string(::getpid());
    if (Status s = geom::write_tree(out.tree, tmp); !s) {
      out.note += (out.note.empty() ? "" : "; ") + std::string("cache not written: ") + s.error();
    } else {
      std::filesystem::rename(tmp, out.path, ec);
      if (ec) out.note += (out.note.empty() ? "" : "; ") + std::string("cache not written: ") + ec.message();
    }
  }
  return out;
}

}  // namespace st::engine
