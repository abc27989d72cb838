// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The patch contact model's contact regions: one body's colliding faces grouped into regions
/// (faces sharing a vertex join) over one union-find, so that the depth search can look for
/// maxima in the regions none of its remembered maxima follows (contact_depth.cpp).
#pragma once
#include <spheretouch/abi.hpp>
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace st::inline SPHERETOUCH_ABI::geom {

struct PatchBody;  // contact_patch.hpp

/// Disjoint sets of 0 .. size() − 1 (union-find with path halving). A set's root is its smallest
/// member, so the roots, and labels numbered from them, depend on the sets only, not on the order
/// of the unite() calls that made them.
class UnionFind {
 public:
  /// Makes n sets {0} .. {n − 1}.
  void reset(std::uint32_t n) {
    parent_.resize(n);
    for (std::uint32_t i = 0; i < n; ++i) parent_[i] = i;
  }
  /// Removes every set.
  void clear() { parent_.clear(); }
  /// Adds the set {size()}; returns its member.
  std::uint32_t add() {
    parent_.push_back(size());
    return parent_.back();
  }
  /// The root of i's set: its smallest member.
  std::uint32_t root(std::uint32_t i) {
    while (parent_[i] != i) i = parent_[i] = parent_[parent_[i]];
    return i;
  }
  /// Joins the sets of a and b.
  void unite(std::uint32_t a, std::uint32_t b) {
    a = root(a), b = root(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }
  /// Members of all sets.
  std::uint32_t size() const { return static_cast<std::uint32_t>(parent_.size()); }
  /// Members room is held for (memory accounting).
  std::size_t capacity() const { return parent_.capacity(); }

 private:
  std::vector<std::uint32_t> parent_;  ///< per member: a member of its set no larger than it (a root: itself)
};

/// Groups T's colliding faces of this round (faces sharing a vertex join) into
/// T.group_label[slot], labels 0 .. n − 1; returns n. A face keeps the group it was given at the
/// last grouping (carried with its fixed part, so a group is followed from round to round);
/// only faces new since then are joined, through the colliding faces around their corners
/// (this round's face marks, stamped `epoch`); with many new faces, every face is grouped afresh.
/// A group that has split since stays one: a region that separated from a followed one is found
/// by the patrol (see DepthSearch).
std::uint32_t group_faces(PatchBody& T, std::uint32_t epoch);

/// The groups a search for new regions opens when no maximum was lost: T's faces that began
/// colliding since the last search (not covered), joined through shared vertices; a set of
/// them sharing no vertex with a covered face is a new region. Labels in T.group_label (0: the
/// covered faces), which are open in T.group_open; returns the label count.
std::uint32_t new_groups(PatchBody& T);

}  // namespace st::geom
