// SPDX-License-Identifier: BSD-3-Clause
// Generated scenes for spheretouch-bench force (see force_scenes.hpp).
#include "force_scenes.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <unordered_map>

namespace st::bench {

CellSolid CellSolid::empty(std::vector<double> xs, std::vector<double> ys, std::vector<double> zs) {
  CellSolid s;
  s.lines = {std::move(xs), std::move(ys), std::move(zs)};
  s.solid.assign(std::size_t(s.cells(0)) * std::size_t(s.cells(1)) * std::size_t(s.cells(2)), 0);
  return s;
}

bool CellSolid::at(int i, int j, int k) const {
  if (i < 0 || j < 0 || k < 0 || i >= cells(0) || j >= cells(1) || k >= cells(2)) return false;
  return solid[(std::size_t(i) * std::size_t(cells(1)) + std::size_t(j)) * std::size_t(cells(2)) + std::size_t(k)] != 0;
}

void CellSolid::set(int i, int j, int k, bool v) {
  assert(i >= 0 && j >= 0 && k >= 0 && i < cells(0) && j < cells(1) && k < cells(2));
  solid[(std::size_t(i) * std::size_t(cells(1)) + std::size_t(j)) * std::size_t(cells(2)) + std::size_t(k)] = v;
}

geom::Mesh cell_mesh(const CellSolid& s, int split, const Eigen::Isometry3d& place, const char* name) {
  geom::Mesh m;
  m.name = name;
  const std::int64_t M = 1 + split * std::max({s.cells(0), s.cells(1), s.cells(2)});
  std::unordered_map<std::int64_t, std::uint32_t> ids;
  // A lattice point: L[a] counts split-ths of cells along axis a.
  auto vertex = [&](const std::array<int, 3>& L) {
    const std::int64_t key = (std::int64_t(L[0]) * M + L[1]) * M + L[2];
    auto [it, fresh] = ids.try_emplace(key, std::uint32_t(m.local.size()));
    if (fresh) {
      Eigen::Vector3d p;
      for (int a = 0; a < 3; ++a) {
        const int cell = std::min(L[a] / split, s.cells(a) - 1);
        const double frac = double(L[a] - cell * split) / split;
        p[a] = s.lines[a][cell] + frac * (s.lines[a][cell + 1] - s.lines[a][cell]);
      }
      m.local.push_back(place * p);
    }
    return it->second;
  };
  for (int i = 0; i < s.cells(0); ++i)
    for (int j = 0; j < s.cells(1); ++j)
      for (int k = 0; k < s.cells(2); ++k) {
        if (!s.at(i, j, k)) continue;
        const std::array<int, 3> c{i, j, k};
        for (int a = 0; a < 3; ++a)
          for (int sign : {-1, 1}) {
            std::array<int, 3> nb = c;
            nb[a] += sign;
            if (s.at(nb[0], nb[1], nb[2])) continue;
            // The face on side `sign` of axis a; u, v the other axes with e_u × e_v = e_a.
            const int u = (a + 1) % 3, v = (a + 2) % 3;
            for (int p = 0; p < split; ++p)
              for (int q = 0; q < split; ++q) {
                std::array<int, 3> L{};
                L[a] = (c[a] + (sign > 0 ? 1 : 0)) * split;
                auto corner = [&](int du, int dv) {
                  std::array<int, 3> x = L;
                  x[u] = c[u] * split + p + du;
                  x[v] = c[v] * split + q + dv;
                  return vertex(x);
                };
                const std::uint32_t p00 = corner(0, 0), p10 = corner(1, 0), p11 = corner(1, 1), p01 = corner(0, 1);
                if (sign > 0) {
                  m.faces.push_back({p00, p10, p11});
                  m.faces.push_back({p00, p11, p01});
                } else {
                  m.faces.push_back({p00, p11, p10});
                  m.faces.push_back({p00, p01, p11});
                }
              }
          }
      }
  m.recentre();
  return m;
}

Truth box_truth(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Isometry3d& place, double r,
                const Eigen::Vector3d& centre) {
  const Eigen::Vector3d q = place.inverse() * centre;
  const Eigen::Vector3d p = q.cwiseMax(lo).cwiseMin(hi);
  const double d = (q - p).norm();
  assert(d > 0 && "box_truth: the ball's centre must be outside the box");
  Truth t;
  t.depth_mm = std::max(0.0, r - d);
  t.clearance_mm = std::max(0.0, d - r);
  if (t.depth_mm > 0) t.normal = place.linear() * ((q - p) / d);
  return t;
}

Truth cavity_truth(const std::vector<Wall>& walls, double r, const Eigen::Vector3d& centre) {
  Truth t;
  const std::size_t n = walls.size();
  auto gap = [&](std::size_t i, const Eigen::Vector3d& x) { return walls[i].n.dot(x) - walls[i].offset - r; };
  double least = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < n; ++i) least = std::min(least, gap(i, centre));
  if (least >= 0) {
    t.clearance_mm = least;
    return t;
  }
  // Active sets of one to three walls: t = N_Sᵀ λ with N_S (c + t) = b_S, λ >= 0, every wall kept.
  double best = std::numeric_limits<double>::infinity();
  Eigen::Vector3d best_t = Eigen::Vector3d::Zero();
  auto consider = [&](const std::vector<std::size_t>& S) {
    const int k = int(S.size());
    Eigen::MatrixXd N(k, 3);
    Eigen::VectorXd b(k);
    for (int i = 0; i < k; ++i) {
      N.row(i) = walls[S[i]].n.transpose();
      b(i) = -gap(S[i], centre);
    }
    const Eigen::MatrixXd G = N * N.transpose();
    if (std::abs(G.determinant()) < 1e-12) return;
    const Eigen::VectorXd lambda = G.ldlt().solve(b);
    if ((lambda.array() < -1e-12).any()) return;
    const Eigen::Vector3d step = N.transpose() * lambda;
    for (std::size_t i = 0; i < n; ++i)
      if (gap(i, centre + step) < -1e-9) return;
    if (step.norm() < best) best = step.norm(), best_t = step;
  };
  for (std::size_t i = 0; i < n; ++i) {
    consider({i});
    for (std::size_t j = i + 1; j < n; ++j) {
      consider({i, j});
      for (std::size_t k = j + 1; k < n; ++k) consider({i, j, k});
    }
  }
  assert(std::isfinite(best));
  t.depth_mm = best;
  t.normal = best > 0 ? Eigen::Vector3d(best_t / best) : Eigen::Vector3d::Zero();
  return t;
}

}  // namespace st::bench
