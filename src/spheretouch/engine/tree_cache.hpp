// SPDX-License-Identifier: BSD-3-Clause
// Sphere-tree cache for the command line: trees are read from a versioned file when it matches
// the mesh and parameters, and rebuilt (and rewritten) when it is missing, stale or corrupt.
#pragma once
#include <spheretouch/abi.hpp>
#include <string>

#include <spheretouch/geom/sphere_tree.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

/// Where cached trees live: $ST_TREE_CACHE, else $XDG_CACHE_HOME/spheretouch/trees, else
/// ~/.cache/spheretouch/trees.
std::string default_tree_cache_dir();

/// How a tree was obtained, for messages and tests.
enum class TreeSource { built, cached, rebuilt_stale, rebuilt_corrupt };

/// A tree and where it came from.
struct CachedTree {
  geom::SphereTree tree;  ///< the tree
  TreeSource source;      ///< built fresh, read from the cache, or rebuilt because the file was bad
  std::string path;       ///< cache file used ("" without a cache)
  std::string note;       ///< why a cached file was rejected
};

/// The tree of `mesh` for `params`, from `cache_dir` when valid ("" = no cache). A bad cache file
/// is never trusted: it is rebuilt and rewritten (a failed write is reported in `note`).
Result<CachedTree> tree_for(const geom::Mesh& mesh, const geom::TreeConfig& params, const std::string& cache_dir);

/// Cache file name for a mesh + params: <dir>/<16 hex digits of the mesh/params hash>.stree.
std::string tree_cache_path(const std::string& dir, const geom::Mesh& mesh, const geom::TreeConfig& params);

}  // namespace st::engine
