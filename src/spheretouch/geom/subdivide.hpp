// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Loop subdivision (Charles Loop, "Smooth Subdivision Surfaces Based on Triangles", 1987) for
/// closed, oriented 2-manifold meshes: each level turns every face into four. Deterministic.
#pragma once
#include <spheretouch/abi.hpp>
#include <spheretouch/geom/mesh.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// Subdivides `levels` times. Face f of level k becomes faces 4f..4f+3 of level k+1: the corners
/// at v0, v1, v2 then the middle triangle. Old vertices keep their indices; edge vertices follow
/// in order of first use (face order, edge v0v1, v1v2, v2v0). Errors on open or non-manifold input.
Result<Mesh> loop_subdivide(const Mesh& mesh, int levels);

}  // namespace st::geom
