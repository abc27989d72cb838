// SPDX-License-Identifier: BSD-3-Clause
// Loop subdivision with the original weights of Loop (1987): edge point 3/8 (a+b) + 1/8 (c+d),
// vertex point (1 - n beta) v + beta sum(neighbours), beta = (5/8 - (3/8 + cos(2 pi/n)/4)^2) / n.
#include <spheretouch/geom/subdivide.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace st::inline SPHERETOUCH_ABI::geom {
namespace {

Result<Mesh> subdivide_once(const Mesh& in) {
  const std::size_t nf = in.faces.size(), nv = in.local.size();
  // Half-edges sorted by undirected key: the two uses of each manifold edge end up adjacent.
  struct Half {
    std::uint64_t key;
    std::uint32_t slot;
  };  // slot = 3 * face + corner
  std::vector<Half> halves(3 * nf);
  for (std::uint32_t f = 0; f < nf; ++f)
    for (std::uint32_t k = 0; k < 3; ++k) {
      const std::uint32_t a = in.faces[f][k], b = in.faces[f][(k + 1) % 3];
      if (a == b)
        return fail(in.name, ": face ", f, " repeats vertex ", a, " (Loop subdivision needs a manifold mesh)");
      halves[3 * f + k] = {a < b ? (std::uint64_t(a) << 32 | b) : (std::uint64_t(b) << 32 | a), 3 * f + k};
    }
  std::sort(halves.begin(), halves.end(),
            [](const Half& x, const Half& y) { return x.key != y.key ? x.key < y.key : x.slot < y.slot; });
  std::vector<std::uint32_t> twin(3 * nf);
  for (std::size_t i = 0; i < halves.size(); i += 2) {
    const auto face_of = [](std::uint32_t slot) { return slot / 3; };
    if (i + 1 >= halves.size() || halves[i + 1].key != halves[i].key)
      return fail(in.name, ": open mesh: edge (", halves[i].key >> 32, ", ", halves[i].key & 0xffffffffu, ") of face ",
                  face_of(halves[i].slot), " has only one face (Loop subdivision needs a closed mesh)");
    if (i + 2 < halves.size() && halves[i + 2].key == halves[i].key)
      return fail(in.name, ": non-manifold edge (", halves[i].key >> 32, ", ", halves[i].key & 0xffffffffu,
                  ") shared by 3 or more faces, first ", face_of(halves[i].slot));
    const std::uint32_t s0 = halves[i].slot, s1 = halves[i + 1].slot;
    if (in.faces[s0 / 3][s0 % 3] == in.faces[s1 / 3][s1 % 3])
      return fail(in.name, ": faces ", s0 / 3, " and ", s1 / 3,
                  " traverse their shared edge the same way (inconsistent orientation)");
    twin[s0] = s1;
    twin[s1] = s0;
  }
  // Edge vertices numbered by first use in face order.
  constexpr std::uint32_t kNone = ~0u;
  std::vector<std::uint32_t> edge_vertex(3 * nf, kNone);
  std::uint32_t next = static_cast<std::uint32_t>(nv);
  for (std::uint32_t s = 0; s < 3 * nf; ++s)
    if (edge_vertex[s] == kNone) edge_vertex[s] = edge_vertex[twin[s]] = next++;

  Mesh out;
  out.name = in.name;
  out.origin = in.origin;
  out.local.resize(next);
  // Edge points: 3/8 of the edge ends + 1/8 of the two opposite corners.
  for (std::uint32_t s = 0; s < 3 * nf; ++s) {
    const std::uint32_t t = twin[s];
    if (s > t) continue;
    const Tri& f = in.faces[s / 3];
    const Tri& g = in.faces[t / 3];
    const Vec3& a = in.local[f[s % 3]];
    const Vec3& b = in.local[f[(s % 3 + 1) % 3]];
    const Vec3& c = in.local[f[(s % 3 + 2) % 3]];
    const Vec3& d = in.local[g[(t % 3 + 2) % 3]];
    out.local[edge_vertex[s]] = 0.375 * (a + b) + 0.125 * (c + d);
  }
  // Vertex points: each undirected edge adds each end to the other's neighbour sum once.
  std::vector<Vec3> sum(nv, Vec3::Zero());
  std::vector<std::uint32_t> valence(nv, 0);
  for (std::uint32_t s = 0; s < 3 * nf; ++s) {
    if (s > twin[s]) continue;
    const std::uint32_t a = in.faces[s / 3][s % 3], b = in.faces[s / 3][(s % 3 + 1) % 3];
    sum[a] += in.local[b];
    sum[b] += in.local[a];
    ++valence[a];
    ++valence[b];
  }
  for (std::uint32_t v = 0; v < nv; ++v) {
    if (valence[v] == 0) {
      out.local[v] = in.local[v];
      continue;
    }  // unused vertex: left in place
    const double n = valence[v];
    const double c = 0.375 + 0.25 * std::cos(2 * std::numbers::pi / n);
    const double beta = (0.625 - c * c) / n;
    out.local[v] = (1 - n * beta) * in.local[v] + beta * sum[v];
  }
  out.faces.resize(4 * nf);
  for (std::uint32_t f = 0; f < nf; ++f) {
    const Tri& t = in.faces[f];
    const std::uint32_t m01 = edge_vertex[3 * f], m12 = edge_vertex[3 * f + 1], m20 = edge_vertex[3 * f + 2];
    out.faces[4 * f + 0] = {t[0], m01, m20};
    out.faces[4 * f + 1] = {t[1], m12, m01};
    out.faces[4 * f + 2] = {t[2], m20, m12};
    out.faces[4 * f + 3] = {m01, m12, m20};
  }
  return out;
}

}  // namespace

Result<Mesh> loop_subdivide(const Mesh& mesh, int levels) {
  if (levels < 0 || levels > 8) return fail(mesh.name, ": subdivision levels ", levels, " outside [0, 8]");
  Mesh m = mesh;
  for (int l = 0; l < levels; ++l) {
    if (m.faces.size() > (std::size_t(1) << 29)) return fail(mesh.name, ": level ", l + 1, " would exceed 2^31 faces");
    Result<Mesh> r = subdivide_once(m);
    if (!r) return r;
    m = std::move(r).value();
  }
  return m;
}

}  // namespace st::geom
