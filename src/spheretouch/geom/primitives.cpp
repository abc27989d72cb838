// SPDX-License-Identifier: BSD-3-Clause
// Generated closed meshes. Vertex sharing is exact (indices), so the results are watertight.
#include <spheretouch/geom/primitives.hpp>

#include <cmath>
#include <map>
#include <numbers>

namespace st::inline SPHERETOUCH_ABI::geom {

Mesh make_icosphere(double radius_mm, int frequency) {
  const double p = (1 + std::sqrt(5.0)) / 2;  // golden ratio
  const Vec3 ico[12] = {{-1, p, 0},  {1, p, 0},  {-1, -p, 0}, {1, -p, 0}, {0, -1, p},  {0, 1, p},
                        {0, -1, -p}, {0, 1, -p}, {p, 0, -1},  {p, 0, 1},  {-p, 0, -1}, {-p, 0, 1}};
  const int tri[20][3] = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                          {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                          {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  const int n = std::max(1, frequency);
  std::vector<Vec3> pos;
  std::vector<Tri> faces;
  // Points on shared edges and corners are keyed by their barycentric lattice coordinates over
  // the icosahedron's vertex ids, so neighbouring faces reuse them exactly.
  std::map<std::array<int, 6>, std::uint32_t> ids;
  auto vertex = [&](int a, int b, int c, int i, int j, int k) {  // weights i,j,k over vertices a,b,c; i+j+k = n
    std::array<std::pair<int, int>, 3> w{{{a, i}, {b, j}, {c, k}}};
    std::sort(w.begin(), w.end());
    std::array<int, 6> key{};
    int m = 0;
    for (auto& [id, wt] : w)
      if (wt) {
        key[m++] = id;
        key[m++] = wt;
      }
    auto [it, fresh] = ids.try_emplace(key, static_cast<std::uint32_t>(pos.size()));
    if (fresh) {
      const Vec3 q = (i * ico[a] + j * ico[b] + k * ico[c]) / n;
      pos.push_back(radius_mm * q.normalized());
    }
    return it->second;
  };
  for (const auto& t : tri) {
    for (int i = 0; i < n; ++i)
      for (int j = 0; j + i < n; ++j) {
        const int k = n - i - j;
        // Upward triangle and, where it fits, the downward one, all counter-clockwise.
        faces.push_back({vertex(t[0], t[1], t[2], k, i, j), vertex(t[0], t[1], t[2], k - 1, i + 1, j),
                         vertex(t[0], t[1], t[2], k - 1, i, j + 1)});
        if (k >= 2)
          faces.push_back({vertex(t[0], t[1], t[2], k - 1, i + 1, j), vertex(t[0], t[1], t[2], k - 2, i + 1, j + 1),
                           vertex(t[0], t[1], t[2], k - 1, i, j + 1)});
      }
  }
  return make_mesh("icosphere(r=" + std::to_string(radius_mm) + ",f=" + std::to_string(n) + ")", pos, std::move(faces));
}

Mesh make_box(const Vec3& size_mm) {
  const Vec3 h = size_mm / 2;
  std::vector<Vec3> pos;
  for (int i = 0; i < 8; ++i) pos.emplace_back(i & 1 ? h.x() : -h.x(), i & 2 ? h.y() : -h.y(), i & 4 ? h.z() : -h.z());
  std::vector<Tri> f = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                        {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return make_mesh("box", pos, std::move(f));
}

Mesh make_capsule(double radius_mm, double length_mm, int segments) {
  const int seg = std::max(3, segments), rings = std::max(1, seg / 4);
  std::vector<Vec3> pos;
  std::vector<Tri> faces;
  // Rings from the bottom pole to the top pole; the two middle rings bound the cylinder.
  std::vector<std::pair<double, double>> ring;  // (z, r)
  for (int i = 1; i <= rings; ++i) {
    const double a = -std::numbers::pi / 2 + std::numbers::pi / 2 * i / rings;
    ring.emplace_back(-length_mm / 2 + radius_mm * std::sin(a), radius_mm * std::cos(a));
  }
  for (int i = 0; i < rings; ++i) {
    const double a = std::numbers::pi / 2 * i / rings;
    ring.emplace_back(length_mm / 2 + radius_mm * std::sin(a), radius_mm * std::cos(a));
  }
  pos.emplace_back(0, 0, -length_mm / 2 - radius_mm);  // bottom pole
  for (auto [z, r] : ring)
    for (int s = 0; s < seg; ++s) {
      const double a = 2 * std::numbers::pi * s / seg;
      pos.emplace_back(r * std::cos(a), r * std::sin(a), z);
    }
  const auto top = static_cast<std::uint32_t>(pos.size());
  pos.emplace_back(0, 0, length_mm / 2 + radius_mm);  // top pole: the fingertip
  auto at = [&](std::size_t r, int s) { return static_cast<std::uint32_t>(1 + r * seg + (s % seg)); };
  for (int s = 0; s < seg; ++s) faces.push_back({0, at(0, s + 1), at(0, s)});
  for (std::size_t r = 0; r + 1 < ring.size(); ++r)
    for (int s = 0; s < seg; ++s) {
      faces.push_back({at(r, s), at(r, s + 1), at(r + 1, s + 1)});
      faces.push_back({at(r, s), at(r + 1, s + 1), at(r + 1, s)});
    }
  for (int s = 0; s < seg; ++s) faces.push_back({at(ring.size() - 1, s), at(ring.size() - 1, s + 1), top});
  return make_mesh("capsule", pos, std::move(faces));
}

}  // namespace st::geom
