// SPDX-License-Identifier: BSD-3-Clause
// Helpers shared by the geom suites: the model set under $ST_SOURCE_ROOT/.cache/models, a
// brute-force collision reference and pose builders.
#pragma once
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/tri_tri.hpp>
#include "test_util.hpp"

namespace st::test {

/// The identity rotation moved by t (a probe placed by translation only).
inline geom::Pose pose_at(const geom::Vec3& t) {
  geom::Pose p = geom::Pose::Identity();
  p.translation() = t;
  return p;
}

/// An n × n grid of unit squares at z = height, two faces each (counter-clockwise seen from +z:
/// normal +z); square (i, j) spans [i, i + 1] × [j, j + 1], faces 2(j·n + i) and + 1.
inline geom::Mesh grid(int n, double height = 0) {
  geom::Mesh m;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.local.emplace_back(i, j, height);
  auto at = [n](int i, int j) { return std::uint32_t(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      m.faces.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.faces.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  return m;
}

/// The mesh as a soup: every face its own three corners (as PLY and OFF exporters often write
/// them), the faces in their order.
inline geom::Mesh soup(const geom::Mesh& m) {
  geom::Mesh s;
  s.name = m.name;
  s.origin = m.origin;
  for (const geom::Tri& t : m.faces) {
    const auto b = std::uint32_t(s.local.size());
    for (std::uint32_t v : t) s.local.push_back(m.local[v]);
    s.faces.push_back({b, b + 1, b + 2});
  }
  return s;
}

/// A model of the set, loaded once per process. A missing model set fails the test (never skips):
/// run scripts/models.sh.
inline const geom::Mesh* model_mesh(const std::string& name) {
  static std::map<std::string, geom::Mesh> cache;
  auto it = cache.find(name);
  if (it == cache.end()) {
    auto r = geom::load_mesh(st::test::model(name));
    REQUIRE_MESSAGE(r.ok(), r.error());  // error() is empty on success (the message is built then too, with -s)
    it = cache.emplace(name, std::move(r.value().mesh)).first;
  }
  return &it->second;
}

/// Exact reference: every (probe, object) face pair, through tri_tri_overlap on the transformed
/// doubles of transform_to_object/apply. Candidates are cut by exact double AABB tests (two closed
/// triangles that share a point have overlapping boxes), so this equals all-pairs exactly.
/// `all_pairs` forces the literal loop over every pair (slow; for small probes).
inline std::vector<geom::FacePair> brute_force(const geom::Mesh& probe, const geom::Mesh& object,
                                               const geom::Pose& pose, bool all_pairs = false) {
  using geom::Vec3;
  const geom::RelTransform rt = geom::transform_to_object(pose, probe, object);
  std::vector<Vec3> pv(probe.local.size());
  for (std::size_t i = 0; i < pv.size(); ++i) pv[i] = geom::apply(rt, probe.local[i]);
  auto box_of = [](const Vec3& a, const Vec3& b, const Vec3& c) {
    geom::Box bx;
    bx.grow(a);
    bx.grow(b);
    bx.grow(c);
    return bx;
  };
  auto meet = [](const geom::Box& a, const geom::Box& b) {
    return (a.lo.array() <= b.hi.array()).all() && (b.lo.array() <= a.hi.array()).all();
  };
  std::vector<geom::Box> pb(probe.faces.size()), ob(object.faces.size());
  geom::Box pall, oall;
  for (std::size_t f = 0; f < pb.size(); ++f) {
    const auto& t = probe.faces[f];
    pb[f] = box_of(pv[t[0]], pv[t[1]], pv[t[2]]);
    pall.grow(pb[f].lo);
    pall.grow(pb[f].hi);
  }
  std::vector<std::uint32_t> oc, pc;
  for (std::size_t f = 0; f < ob.size(); ++f) {
    const auto& t = object.faces[f];
    ob[f] = box_of(object.local[t[0]], object.local[t[1]], object.local[t[2]]);
    if (all_pairs || meet(ob[f], pall)) {
      oc.push_back(static_cast<std::uint32_t>(f));
      oall.grow(ob[f].lo);
      oall.grow(ob[f].hi);
    }
  }
  for (std::size_t f = 0; f < pb.size(); ++f)
    if (all_pairs || (!oall.empty() && meet(pb[f], oall))) pc.push_back(static_cast<std::uint32_t>(f));
  std::vector<geom::FacePair> out;
  auto test_pair = [&](std::uint32_t p, std::uint32_t o) {
    const auto& t = probe.faces[p];
    const auto& u = object.faces[o];
    if (geom::tri_tri_overlap(pv[t[0]], pv[t[1]], pv[t[2]], object.local[u[0]], object.local[u[1]], object.local[u[2]]))
      out.push_back({p, o});
  };
  if (all_pairs) {
    for (std::uint32_t p : pc)
      for (std::uint32_t o : oc) test_pair(p, o);
  } else if (!oc.empty() && !pc.empty()) {
    // Uniform grid over the candidate object boxes (cell ~ 2x the mean box extent): a probe box
    // visits only the cells it overlaps. The same exact box test then decides, so the result is
    // still exactly all-pairs; the grid only skips pairs whose boxes are in disjoint cells.
    Vec3 mean = Vec3::Zero();
    for (std::uint32_t o : oc) mean += ob[o].hi - ob[o].lo;
    const double cell = std::max(2.0 * mean.maxCoeff() / double(oc.size()), 1e-300);
    const Vec3 origin = oall.lo;
    Eigen::Vector3i dims;
    for (int k = 0; k < 3; ++k) dims[k] = std::clamp(static_cast<int>((oall.hi[k] - oall.lo[k]) / cell) + 1, 1, 256);
    auto cell_of = [&](double x, int k) {
      const double c = (x - origin[k]) / (oall.hi[k] - oall.lo[k] > 0 ? (oall.hi[k] - oall.lo[k]) : 1.0) * dims[k];
      return std::clamp(static_cast<int>(std::floor(c)), 0, dims[k] - 1);
    };
    std::vector<std::vector<std::uint32_t>> grid(std::size_t(dims.prod()));
    auto idx = [&](int x, int y, int z) {
      return (std::size_t(z) * dims.y() + std::size_t(y)) * dims.x() + std::size_t(x);
    };
    for (std::uint32_t o : oc)
      for (int z = cell_of(ob[o].lo.z(), 2); z <= cell_of(ob[o].hi.z(), 2); ++z)
        for (int y = cell_of(ob[o].lo.y(), 1); y <= cell_of(ob[o].hi.y(), 1); ++y)
          for (int x = cell_of(ob[o].lo.x(), 0); x <= cell_of(ob[o].hi.x(), 0); ++x) grid[idx(x, y, z)].push_back(o);
    std::vector<std::uint32_t> seen(object.faces.size(), ~0u);
    for (std::uint32_t p : pc) {
      // Probe boxes beyond the grid are clamped into its border cells (cell_of clamps).
      for (int z = cell_of(pb[p].lo.z(), 2); z <= cell_of(pb[p].hi.z(), 2); ++z)
        for (int y = cell_of(pb[p].lo.y(), 1); y <= cell_of(pb[p].hi.y(), 1); ++y)
          for (int x = cell_of(pb[p].lo.x(), 0); x <= cell_of(pb[p].hi.x(), 0); ++x)
            for (std::uint32_t o : grid[idx(x, y, z)]) {
              if (seen[o] == p) continue;
              seen[o] = p;
              if (meet(pb[p], ob[o])) test_pair(p, o);
            }
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

/// Area-weighted vertex normals (outward for a CCW-from-outside mesh).
inline std::vector<geom::Vec3> vertex_normals(const geom::Mesh& m) {
  std::vector<geom::Vec3> n(m.local.size(), geom::Vec3::Zero());
  for (const auto& t : m.faces) {
    const geom::Vec3 fn = (m.local[t[1]] - m.local[t[0]]).cross(m.local[t[2]] - m.local[t[0]]);
    for (auto v : t) n[v] += fn;
  }
  for (auto& v : n)
    if (v.norm() > 0) v.normalize();
  return n;
}

/// Random rotation (uniform quaternion).
inline Eigen::Matrix3d random_rotation(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  return q.toRotationMatrix();
}

/// Pose (probe file -> object file) that puts probe vertex vp at `depth_mm` below object vertex vo
/// along the object's normal there, with a random rotation.
inline geom::Pose pose_near(const geom::Mesh& probe, std::uint32_t vp, const geom::Mesh& object, std::uint32_t vo,
                            const geom::Vec3& normal, double depth_mm, const Eigen::Matrix3d& R) {
  geom::Pose pose = geom::Pose::Identity();
  pose.linear() = R;
  const geom::Vec3 target = object.vertex(vo) - depth_mm * normal;
  pose.translation() = target - R * probe.vertex(vp);
  return pose;
}

}  // namespace st::test
