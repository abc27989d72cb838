// SPDX-License-Identifier: BSD-3-Clause
// Generated scenes for `spheretouch-bench force`: the meshes people bring (CAD-like solids with
// large flat faces, creases, pockets and thin plates), written by the bench (no download), and
// the analytic truth for a ball: the smallest translation that clears it (its depth and
// direction), which the rendered force is compared with.
#pragma once
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include <spheretouch/geom/mesh.hpp>

namespace st::bench {

/// What a ball centred at c penetrates, and how far it is from the solid when clear.
struct Truth {
  double depth_mm = 0;                              ///< |t| of the smallest clearing translation t, 0 when clear
  Eigen::Vector3d normal{Eigen::Vector3d::Zero()};  ///< t / |t| (zero when clear)
  double clearance_mm = 0;                          ///< the gap between ball and solid, mm (0 while touching or in)
};
/// The truth at a ball centre (object frame, mm).
using TruthFn = std::function<Truth(const Eigen::Vector3d& centre)>;

/// A solid made of cells of a rectilinear grid: its lines per axis (increasing, mm) and which
/// cells are solid. Boxes, L-shaped creases, inner corners and pockets are a few cells each.
struct CellSolid {
  std::array<std::vector<double>, 3> lines;  ///< grid lines along x, y, z, mm
  std::vector<std::uint8_t> solid;           ///< per cell (i, j, k): index (i·ny + j)·nz + k
  /// A grid of the given lines with every cell empty.
  static CellSolid empty(std::vector<double> xs, std::vector<double> ys, std::vector<double> zs);
  int cells(int axis) const { return int(lines[axis].size()) - 1; }  ///< cells along an axis
  bool at(int i, int j, int k) const;                                ///< solid (false outside the grid)
  void set(int i, int j, int k, bool v);                             ///< marks a cell
};

/// The solid's boundary as a closed triangle mesh: every cell face between a solid and an empty
/// cell, split into split × split squares of two triangles (split 1: CAD-like faces as large as the
/// cells; vertices shared on a lattice, so the mesh is watertight at any split), placed by `place`.
geom::Mesh cell_mesh(const CellSolid& s, int split, const Eigen::Isometry3d& place, const char* name);

/// A half-space x·n >= offset (n unit) that a ball centre must keep to (planes of a cavity's walls).
struct Wall {
  Eigen::Vector3d n;
  double offset;
};

/// Truth for a ball of radius r against an axis-aligned box [lo, hi] placed by `place` (a convex
/// solid: the smallest translation is r − the distance from the centre, along the gradient).
/// The centre must be outside the box.
Truth box_truth(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Isometry3d& place, double r,
                const Eigen::Vector3d& centre);

/// Truth for a ball of radius r inside a cavity bounded by walls (the free space near the contact
/// is their intersection): t = the projection of the centre onto {x : x·n_i >= offset_i + r},
/// found by enumerating the active sets of up to three walls (KKT: λ >= 0, every wall kept).
/// Valid away from the cavity's rims (the scripts stay there).
Truth cavity_truth(const std::vector<Wall>& walls, double r, const Eigen::Vector3d& centre);

}  // namespace st::bench
