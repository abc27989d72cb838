// SPDX-License-Identifier: BSD-3-Clause
// FCL 0.7 as the peer in benchmarks: BVHModel<OBBRSS>, all contacts (num_max_contacts
// unlimited), same meshes and poses as ours in the same run. Compiled only with libfcl-dev.
#pragma once
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include <spheretouch/geom/mesh.hpp>

namespace st::bench {

/// Both bodies as FCL OBBRSS hierarchies in their body-local frames.
class FclPeer {
 public:
  FclPeer(const geom::Mesh& probe, const geom::Mesh& object);  ///< builds both BVHs
  ~FclPeer();
  /// All colliding (probe face, object face) pairs for a pose mapping probe file coordinates to
  /// object file coordinates, sorted. `query_s`, if given, receives the wall time of fcl::collide
  /// alone (the per-pose query; BVH construction and the copy/sort of contacts are not in it).
  std::vector<std::pair<std::uint32_t, std::uint32_t>> collide(const geom::Pose& pose, double* query_s = nullptr) const;
  /// FCL's own triangle distance (mm) between probe face pf (posed) and object face of, to show
  /// how close the pairs where FCL and the exact test disagree are.
  double tri_distance(const geom::Pose& pose, std::uint32_t pf, std::uint32_t of) const;
  double build_seconds() const { return build_s_; }  ///< time to build both BVHs

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  double build_s_ = 0;
};

/// Seconds FCL takes to build one OBBRSS hierarchy of `mesh`.
double fcl_build_seconds(const geom::Mesh& mesh);

}  // namespace st::bench
