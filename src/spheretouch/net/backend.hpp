// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// CollisionBackend: the narrow interface a worker answers queries through. The collision core
/// (SphereTree + collide() restricted to the worker's blocks, tree_backend.hpp) is the one the
/// daemon and the engine use; reference_backend.hpp is an independent, exact-by-construction
/// one the distributed tests compare against. A backend is built once per
/// block set (cold: may allocate, may take a while) and then queried many times (hot).
#pragma once
#include <spheretouch/abi.hpp>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include <spheretouch/net/block_set.hpp>
#include <spheretouch/net/protocol.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// What one query may cost: the pairs it may append and the work it may do (sphere tests,
/// candidate and exact triangle tests: geom::CollideStats::work()).
struct QueryBudget {
  std::size_t max_pairs = SIZE_MAX;     ///< stop once more than this many pairs were appended
  std::uint64_t max_work = UINT64_MAX;  ///< stop once the work passes this (stats.work_limit_hit)
};

/// Collides the probe against one worker's share of the object.
class CollisionBackend {
 public:
  virtual ~CollisionBackend() = default;
  /// Builds the backend's structures (e.g. its own sphere tree with set.leaf_faces) for `set`.
  virtual Status load(const BlockSet& set) = 0;
  /// Appends every colliding (probe face, GLOBAL object face) pair at `pose` (probe file coords →
  /// object file coords) to `out`, in any order, each pair once, leaving out the faces of the
  /// blocks in `skip` (global block ids, ascending; ids not held are ignored); returns the work
  /// counters. Stops as soon as more than `budget.max_pairs` pairs were appended (then out holds
  /// more than max_pairs, at most a few thousand more) or the work passed `budget.max_work`
  /// (stats.work_limit_hit): the caller answers "too large" without computing everything.
  virtual QueryStats query(const geom::Pose& pose, std::span<const std::uint32_t> skip, std::vector<FacePair>& out,
                           const QueryBudget& budget) = 0;
  /// As query(), but only the faces of the held blocks in `only` (global block ids, ascending;
  /// ids not held are ignored): the client assist answers a few blocks from a set of them all.
  virtual QueryStats query_only(const geom::Pose& pose, std::span<const std::uint32_t> only, std::vector<FacePair>& out,
                                const QueryBudget& budget) = 0;
  /// The held blocks the last query() or query_only() did any work in, by ascending global id,
  /// with that work (geom::NodeWork's units): what the client weighs to deal the next round. A
  /// backend that does not count returns none (this default).
  virtual const std::vector<WorkedBlock>& worked() const {
    static const std::vector<WorkedBlock> none;
    return none;
  }
};

/// Makes an empty backend; a worker calls it once per block set it loads.
using BackendFactory = std::function<std::unique_ptr<CollisionBackend>()>;

}  // namespace st::net
