// SPDX-License-Identifier: BSD-3-Clause
// The analytic shapes the contact-model tests share (contact_depth_test, contact_patch_test): a
// 40 mm box (faces at ±20), a 10 mm ball (5,120 faces: vertex spacing ~0.7 mm, so the deepest
// vertex is within ~0.01 mm of the sphere's deepest point), and the depth target for them.
#pragma once
#include <spheretouch/geom/primitives.hpp>

namespace st::test {

inline constexpr double kDepthTol = 0.05;  // mm: the depth target for analytic shapes (docs/user-guide/force-rendering.md)

inline const geom::Mesh& box40() {
  static const geom::Mesh m = geom::make_box({40, 40, 40});
  return m;
}

inline const geom::Mesh& ball10() {
  static const geom::Mesh m = geom::make_icosphere(10, 16);
  return m;
}

}  // namespace st::test
