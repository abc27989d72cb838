// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Small generated meshes (closed, outward-oriented) so tests and the embedded default need no
/// download: an icosphere, a box and a capsule fingertip.
#pragma once
#include <spheretouch/abi.hpp>
#include <spheretouch/geom/mesh.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// Geodesic sphere: an icosahedron whose edges are split into `frequency` parts, projected onto
/// the sphere; 20·frequency² faces (frequency 7 gives 980, the paper's ~960-face ball).
Mesh make_icosphere(double radius_mm, int frequency);

/// Axis-aligned box centred at the origin with the given full side lengths; 12 faces.
Mesh make_box(const Vec3& size_mm);

/// Capsule along +z: a cylinder of `length_mm` between two hemispheres of `radius_mm`, with
/// `segments` around and `segments / 2` rings per hemisphere. Its tip (the fingertip) is at
/// z = length/2 + radius.
Mesh make_capsule(double radius_mm, double length_mm, int segments);

}  // namespace st::geom
