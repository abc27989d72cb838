// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Exact triangle-triangle overlap test for closed triangles (touching counts as colliding).
/// Right for coplanar, edge-on-edge, vertex-on-face and degenerate triangles; exact on the
/// double inputs (floating-point filter with an exact fallback), no scale-dependent epsilon.
#pragma once
#include <spheretouch/abi.hpp>
#include <spheretouch/geom/mesh.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// True when closed triangles (a0,a1,a2) and (b0,b1,b2) share at least one point. Exact.
/// A zero-area triangle is the segment or point its vertices span. Hot path: no allocation,
/// no exceptions. Exact whenever every nonzero coordinate is ≥ 2^-306 times the largest
/// coordinate magnitude of the six vertices (tri_tri.cpp); false if any coordinate is NaN/Inf.
bool tri_tri_overlap(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1, const Vec3& b2) noexcept;

}  // namespace st::geom
