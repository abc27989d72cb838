// SPDX-License-Identifier: BSD-3-Clause
// Mesh bookkeeping: bounds, topology, degeneracy, validation, re-centring.
#include <spheretouch/geom/mesh.hpp>

#include <algorithm>
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstring>

namespace st::inline SPHERETOUCH_ABI::geom {

Box Mesh::local_bounds() const {
  Box b;
  for (const Vec3& p : local) b.grow(p);
  return b;
}

Box Mesh::bounds() const {
  Box b = local_bounds();
  if (!b.empty()) {
    b.lo += origin;
    b.hi += origin;
  }
  return b;
}

Topology Mesh::topology() const {
  // One record per directed half-edge, keyed by its undirected edge; sorting groups the uses
  // of each edge together (no hash map: deterministic and cache-friendly).
  struct Half {
    std::uint64_t key;
    bool forward;
  };
  const std::vector<std::uint32_t> same = coincident_vertices(*this);
  std::vector<Half> halves;
  halves.reserve(faces.size() * 3);
  for (const Tri& f : faces) {
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = f[k] < same.size() ? same[f[k]] : f[k];
      const std::uint32_t b = f[(k + 1) % 3] < same.size() ? same[f[(k + 1) % 3]] : f[(k + 1) % 3];
      if (a == b) continue;  // an edge of a degenerate face with a repeated vertex has no extent
      const bool fwd = a < b;
      const std::uint64_t key = fwd ? (std::uint64_t(a) << 32 | b) : (std::uint64_t(b) << 32 | a);
      halves.push_back({key, fwd});
    }
  }
  std::sort(halves.begin(), halves.end(), [](const Half& x, const Half& y) { return x.key < y.key; });
  Topology t;
  for (std::size_t v = 0; v < same.size(); ++v) t.shared_corners += same[v] != v;
  for (std::size_t i = 0; i < halves.size();) {
    std::size_t j = i;
    while (j < halves.size() && halves[j].key == halves[i].key) ++j;
    const std::size_t uses = j - i;
    if (uses == 1)
      ++t.boundary_edges;
    else if (uses > 2)
      ++t.nonmanifold_edges;
    else if (halves[i].forward == halves[i + 1].forward)
      ++t.misoriented_edges;
    i = j;
  }
  return t;
}

std::vector<std::uint32_t> coincident_vertices(const Mesh& mesh) {
  const auto nv = static_cast<std::uint32_t>(mesh.local.size());
  std::vector<std::uint32_t> same(nv);
  std::vector<std::uint32_t> order;
  order.reserve(nv);
  for (std::uint32_t v = 0; v < nv; ++v) {
    same[v] = v;
    if (mesh.local[v].allFinite()) order.push_back(v);  // (NaN would break the ordering)
  }
  // Lexicographic by value (so -0 == +0), ties by index: each run of equal positions starts at
  // its lowest index.
  auto less = [&](std::uint32_t i, std::uint32_t j) {
    const Vec3 &a = mesh.local[i], &b = mesh.local[j];
    for (int k = 0; k < 3; ++k)
      if (a[k] != b[k]) return a[k] < b[k];
    return i < j;
  };
  std::sort(order.begin(), order.end(), less);
  for (std::size_t i = 1; i < order.size(); ++i)
    if (mesh.local[order[i]] == mesh.local[order[i - 1]]) same[order[i]] = same[order[i - 1]];
  return same;
}

std::vector<std::uint32_t> Mesh::degenerate_faces() const {
  // Zero area up to rounding: |e1 x e2| <= 8 eps |e1||e2| (the sine of the corner angle is below
  // ~1.8e-15, i.e. the three vertices are collinear to within the precision of their doubles).
  // Scale-free by construction.
  std::vector<std::uint32_t> out;
  for (std::uint32_t i = 0; i < faces.size(); ++i) {
    const Tri& f = faces[i];
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) {
      out.push_back(i);
      continue;
    }
    const Vec3 e1 = local[f[1]] - local[f[0]], e2 = local[f[2]] - local[f[0]];
    const double lim = 8 * DBL_EPSILON * e1.norm() * e2.norm();
    if (!(e1.cross(e2).norm() > lim)) out.push_back(i);
  }
  return out;
}

void Mesh::recentre() {
  const Box b = local_bounds();
  if (b.empty()) return;
  // Snap the new centre to a grid of 2^k mm with 2^k near a quarter of the extent. When the body
  // sits far from the frame's origin, every coordinate's ulp divides 2^k, so v - centre is exact;
  // near the origin the subtraction may round by at most an ulp of the extent.
  const double extent = (b.hi - b.lo).maxCoeff();
  Vec3 c = b.centre();
  if (extent > 0 && std::isfinite(extent)) {
    const double grid = std::ldexp(1.0, std::ilogb(extent) - 2);
    for (int i = 0; i < 3; ++i) c[i] = std::round(c[i] / grid) * grid;
  }
  for (Vec3& p : local) p -= c;
  origin += c;
}

void Mesh::scale(double s) {
  for (Vec3& p : local) p *= s;
  origin *= s;
}

Status Mesh::validate() const {
  if (faces.empty()) return fail(name, ": no triangles");
  for (std::size_t i = 0; i < local.size(); ++i) {
    const Vec3 p = origin + local[i];
    if (!local[i].allFinite() || !p.allFinite())
      return fail(name, ": vertex ", i, ": coordinate is NaN or infinite (", p.x(), ", ", p.y(), ", ", p.z(), ")");
    // Distances are computed from squared norms: a finite coordinate past ~1e154 mm overflows them.
    if (!std::isfinite(p.squaredNorm()))
      return fail(name, ": vertex ", i, ": coordinate too large (", p.x(), ", ", p.y(), ", ", p.z(),
                  "): its squared norm overflows a double");
  }
  for (std::size_t i = 0; i < faces.size(); ++i)
    for (int k = 0; k < 3; ++k)
      if (faces[i][k] >= local.size())
        return fail(name, ": face ", i, ": vertex index ", faces[i][k], " out of range [0, ", local.size(), ")");
  return Ok{};
}

void WordHash::bytes(const void* p, std::size_t n) {
  const auto* c = static_cast<const unsigned char*>(p);
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    std::uint64_t w;
    std::memcpy(&w, c + i, 8);
    word(w);
  }
  std::uint64_t w = 0;
  std::memcpy(&w, c + i, n - i);
  word(w ^ (static_cast<std::uint64_t>(n - i) << 56));
}

std::uint64_t WordHash::finish() const {
  std::uint64_t h = h_;
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdull;
  h ^= h >> 33;
  return h;
}

WordHash mesh_words(const Mesh& mesh) {
  WordHash h(0x9e3779b97f4a7c15ull ^ (mesh.local.size() * 0x100000001b3ull) ^ (mesh.faces.size() << 32));
  h.bytes(mesh.origin.data(), sizeof(double) * 3);
  if (!mesh.local.empty()) h.bytes(mesh.local.data(), mesh.local.size() * sizeof(Vec3));
  if (!mesh.faces.empty()) h.bytes(mesh.faces.data(), mesh.faces.size() * sizeof(Tri));
  return h;
}

std::uint64_t mesh_hash(const Mesh& mesh) { return mesh_words(mesh).finish(); }

Mesh make_mesh(std::string name, const std::vector<Vec3>& positions, std::vector<Tri> faces) {
  Mesh m;
  m.name = std::move(name);
  m.local = positions;
  m.faces = std::move(faces);
  m.recentre();
  return m;
}

}  // namespace st::geom
