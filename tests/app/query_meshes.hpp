// SPDX-License-Identifier: BSD-3-Clause
// The small bodies the query and keygen suites query: a capsule (probe) and an icosphere
// (object) written as OFF files, and three poses: far apart, pressed in, rotated.
#pragma once
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/primitives.hpp>
#include "test_util.hpp"

namespace st::test {

inline const char* kQueryPoses =
    "# far apart\n1 0 0 100 0 1 0 0 0 0 1 0 0 0 0 1\n"
    "# fingertip pressed into the sphere\n1 0 0 0 0 1 0 0 0 0 1 -22 0 0 0 1\n"
    "\n0 -1 0 3 1 0 0 1 0 0 1 -20 0 0 0 1   # rotated about z\n";

/// Writes the two meshes and the pose file into a temporary directory.
struct QueryMeshes {
  TempDir dir;
  std::string probe = dir.file("probe.off"), object = dir.file("object.off"), poses = dir.file("poses.txt");
  QueryMeshes() {
    REQUIRE(geom::write_off(geom::make_capsule(4, 20, 24), probe).ok());
    REQUIRE(geom::write_off(geom::make_icosphere(10, 12), object).ok());
    write_file(poses, kQueryPoses);
  }
};

}  // namespace st::test
