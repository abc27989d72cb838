// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// ReferenceBackend: a simple, deterministic CollisionBackend — a uniform grid over the share's
/// faces, an exact bounding-box filter, and a separating-axis triangle test (closed triangles).
/// It shares no code with collide() (the daemon's backend, tree_backend.hpp), so it is the
/// reference the distributed tests compare against: whether a pair collides depends only on the
/// two triangles' coordinates, never on the grid or the share, so the union of the workers'
/// results equals the result over the whole object bit for bit.
#pragma once
#include <spheretouch/abi.hpp>
#include <spheretouch/net/backend.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// Grid + SAT backend; see the file comment.
std::unique_ptr<CollisionBackend> make_reference_backend();

/// The backend factory for make_reference_backend.
BackendFactory reference_backend_factory();

/// Separating-axis test of closed triangles (touching counts). Deterministic in double, not
/// exact near degeneracies; geom::tri_tri_overlap replaces it with the collision core.
bool sat_tri_overlap(const geom::Vec3& a0, const geom::Vec3& a1, const geom::Vec3& a2, const geom::Vec3& b0,
                     const geom::Vec3& b1, const geom::Vec3& b2);

/// All colliding pairs of two whole meshes at `pose`, sorted (single-process reference).
std::vector<FacePair> reference_collide(const geom::Mesh& probe, const geom::Mesh& object, const geom::Pose& pose);

}  // namespace st::net
