// SPDX-License-Identifier: BSD-3-Clause
// orient_faces() (orient.hpp): a walk over the manifold edges, then each part turned as a whole.
#include <spheretouch/geom/orient.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace st::inline SPHERETOUCH_ABI::geom {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Vertices of a closed part whose winding numbers about another decide whether it lies inside it.
constexpr std::size_t kNestSamples = 16;

// Faces joined across manifold edges, as compressed rows: face f's neighbours are
// next[first[f] .. first[f + 1]), with `same` set where both faces traverse the edge the same
// way (one of them must be flipped for the two to agree). `boundary[f]`: f has an edge no other
// face uses. The edges used by three or more faces (or twice by one face), each as the run
// shared_faces[shared_at[k] .. shared_at[k + 1]) of the faces that use it.
struct Adjacency {
  std::vector<std::uint32_t> first, next;
  std::vector<std::uint8_t> same, boundary;
  std::vector<std::uint32_t> shared_at{0}, shared_faces;
};

Adjacency adjacency(const Mesh& mesh) {
  struct Half {
    std::uint64_t key;
    std::uint32_t face;
    bool forward;
  };
  const auto nf = static_cast<std::uint32_t>(mesh.faces.size());
  const std::vector<std::uint32_t> same_at = coincident_vertices(mesh);  // a soup's corners joined
  std::vector<Half> halves;
  halves.reserve(std::size_t(nf) * 3);
  for (std::uint32_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = same_at[mesh.faces[f][k]], b = same_at[mesh.faces[f][(k + 1) % 3]];
      if (a == b) continue;  // a repeated vertex: no edge
      const bool fwd = a < b;
      halves.push_back({fwd ? (std::uint64_t(a) << 32 | b) : (std::uint64_t(b) << 32 | a), f, fwd});
    }
  std::sort(halves.begin(), halves.end(),
            [](const Half& x, const Half& y) { return x.key != y.key ? x.key < y.key : x.face < y.face; });
  Adjacency g;
  g.boundary.assign(nf, 0);
  struct Link {
    std::uint32_t face, other;
    std::uint8_t same;
  };
  std::vector<Link> links;
  for (std::size_t i = 0; i < halves.size();) {
    std::size_t j = i;
    while (j < halves.size() && halves[j].key == halves[i].key) ++j;
    if (j - i == 2 && halves[i].face != halves[i + 1].face) {
      const std::uint8_t same = halves[i].forward == halves[i + 1].forward;
      links.push_back({halves[i].face, halves[i + 1].face, same});
      links.push_back({halves[i + 1].face, halves[i].face, same});
    } else if (j - i == 1) {
      g.boundary[halves[i].face] = 1;
    } else {
      for (std::size_t k = i; k < j; ++k) g.shared_faces.push_back(halves[k].face);
      g.shared_at.push_back(static_cast<std::uint32_t>(g.shared_faces.size()));
    }
    i = j;
  }
  g.first.assign(std::size_t(nf) + 1, 0);
  for (const Link& l : links) ++g.first[l.face + 1];
  for (std::uint32_t f = 0; f < nf; ++f) g.first[f + 1] += g.first[f];
  g.next.resize(links.size());
  g.same.resize(links.size());
  std::vector<std::uint32_t> fill(g.first.begin(), g.first.end() - 1);
  for (const Link& l : links) {
    g.next[fill[l.face]] = l.other;
    g.same[fill[l.face]++] = l.same;
  }
  return g;
}

// The face's corners with its winding as `flip` says.
struct Corners {
  Vec3 a, b, c;
};
Corners corners(const Mesh& m, std::uint32_t f, bool flip) {
  const Tri& t = m.faces[f];
  return flip ? Corners{m.local[t[0]], m.local[t[2]], m.local[t[1]]}
              : Corners{m.local[t[0]], m.local[t[1]], m.local[t[2]]};
}

// Signed solid angle of triangle (a, b, c) seen from the origin (Van Oosterom and Strackee).
double solid_angle(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double la = a.norm(), lb = b.norm(), lc = c.norm();
  const double num = a.dot(b.cross(c));
  const double den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
  return 2 * std::atan2(num, den);
}

// The edge-connected parts of a mesh and what orient_faces() needs of each: a face's part and
// whether the walk flipped it against its part's first face; per part its first face, the area
// wound as in the file and against it, the signed volume as the walk left it (about the part's
// bounds' centre, for precision), its bounds and whether it is closed.
struct Parts {
  std::vector<std::uint32_t> part, first;
  std::vector<std::uint8_t> flip, closed;
  std::vector<double> kept, against, volume6;
  std::vector<Box> bounds;
  std::size_t unorientable_edges = 0;
  std::size_t count() const { return first.size(); }
};

Parts find_parts(const Mesh& mesh) {
  Parts ps;
  const auto nf = static_cast<std::uint32_t>(mesh.faces.size());
  const Adjacency g = adjacency(mesh);

  // The walk: part of each face, and whether it disagrees with its part's first face.
  constexpr std::uint32_t kNone = UINT32_MAX;
  std::vector<std::uint32_t>& part = ps.part;
  std::vector<std::uint8_t>& flip = ps.flip;
  part.assign(nf, kNone);
  flip.assign(nf, 0);
  std::vector<std::uint32_t> queue;
  std::vector<std::uint8_t> part_open;
  for (std::uint32_t s = 0; s < nf; ++s) {
    if (part[s] != kNone) continue;
    const auto id = static_cast<std::uint32_t>(ps.first.size());
    ps.first.push_back(s);
    part_open.push_back(0);
    part[s] = id;
    queue.assign(1, s);
    for (std::size_t q = 0; q < queue.size(); ++q) {
      const std::uint32_t f = queue[q];
      part_open[id] |= g.boundary[f];
      for (std::uint32_t k = g.first[f]; k < g.first[f + 1]; ++k) {
        const std::uint32_t n = g.next[k];
        const std::uint8_t want = flip[f] ^ g.same[k];
        if (part[n] == kNone) {
          part[n] = id;
          flip[n] = want;
          queue.push_back(n);
        } else if (flip[n] != want && f < n) {
          ++ps.unorientable_edges;
        }
      }
    }
  }
  const std::size_t parts = ps.count();
  // An edge that more faces share leaves open each part that uses it an odd number of times
  // (two cubes that meet along an edge: each uses it twice, and each is closed).
  {
    std::vector<std::uint32_t> users;
    for (std::size_t k = 0; k + 1 < g.shared_at.size(); ++k) {
      users.clear();
      for (std::uint32_t i = g.shared_at[k]; i < g.shared_at[k + 1]; ++i) users.push_back(part[g.shared_faces[i]]);
      std::sort(users.begin(), users.end());
      for (std::size_t i = 0; i < users.size();) {
        std::size_t j = i;
        while (j < users.size() && users[j] == users[i]) ++j;
        if ((j - i) % 2 == 1) part_open[users[i]] = 1;
        i = j;
      }
    }
  }
  ps.kept.assign(parts, 0);
  ps.against.assign(parts, 0);
  ps.volume6.assign(parts, 0);
  ps.bounds.assign(parts, Box{});
  for (std::uint32_t f = 0; f < nf; ++f)
    for (std::uint32_t v : mesh.faces[f]) ps.bounds[part[f]].grow(mesh.local[v]);
  for (std::uint32_t f = 0; f < nf; ++f) {
    const Corners c = corners(mesh, f, flip[f]);
    const Vec3 o = ps.bounds[part[f]].centre();
    const double area = (c.b - c.a).cross(c.c - c.a).norm();
    (flip[f] ? ps.against : ps.kept)[part[f]] += area;
    ps.volume6[part[f]] += (c.a - o).dot((c.b - o).cross(c.c - o));
  }
  // A closed part whose volume is lost in rounding (a flat closed sheet) has no inside either.
  ps.closed.assign(parts, 0);
  for (std::size_t p = 0; p < parts; ++p) {
    const double d = ps.bounds[p].diagonal();
    ps.closed[p] = !part_open[p] && std::abs(ps.volume6[p]) > 1e-9 * d * d * d;
  }
  return ps;
}

}  // namespace

OrientReport orient_faces(Mesh& mesh) {
  OrientReport rep;
  const auto nf = static_cast<std::uint32_t>(mesh.faces.size());
  if (nf == 0) return rep;
  const Parts ps = find_parts(mesh);
  const std::size_t parts = ps.count();
  rep.parts = parts;
  rep.unorientable_edges = ps.unorientable_edges;
  for (std::size_t p = 0; p < parts; ++p) rep.closed_parts += ps.closed[p];

  // Nesting: how many other closed parts hold each closed part (either winding). Part p is inside
  // q when its bounds are and every one of up to kNestSamples of its vertices (its first, its
  // extremes along each axis, others spread over its faces) has a winding number about q over
  // 1/2. Parts that overlap without nesting (an assembly's closed parts pushed into each other,
  // a mesh's shells that intersect) have vertices on both sides: neither is a cavity.
  std::vector<std::uint32_t> faces_of(nf);  // faces grouped by part
  std::vector<std::uint32_t> part_at(parts + 1, 0);
  for (std::uint32_t f = 0; f < nf; ++f) ++part_at[ps.part[f] + 1];
  for (std::size_t p = 0; p < parts; ++p) part_at[p + 1] += part_at[p];
  {
    std::vector<std::uint32_t> at(part_at.begin(), part_at.end() - 1);
    for (std::uint32_t f = 0; f < nf; ++f) faces_of[at[ps.part[f]]++] = f;
  }
  std::vector<std::uint32_t> closed_list;
  for (std::uint32_t p = 0; p < parts; ++p)
    if (ps.closed[p]) closed_list.push_back(p);
  auto holds = [](const Box& outer, const Box& inner) {
    return (inner.lo.array() > outer.lo.array()).all() && (inner.hi.array() < outer.hi.array()).all();
  };
  std::size_t visits = 0;
  std::vector<std::uint8_t> odd(parts, 0);
  std::vector<Vec3> samples;
  for (const std::uint32_t p : closed_list) {
    bool inside_odd = false, skipped = false;
    samples.clear();
    for (const std::uint32_t q : closed_list) {
      if (q == p || !holds(ps.bounds[q], ps.bounds[p])) continue;
      if (samples.empty()) {  // p's sample vertices (first corners of its faces), made once it may be nested
        const std::uint32_t* pf = faces_of.data() + part_at[p];
        const std::uint32_t n = part_at[p + 1] - part_at[p];
        auto at = [&](std::uint32_t k) -> const Vec3& { return mesh.local[mesh.faces[pf[k]][0]]; };
        std::vector<std::uint32_t> picks(7, 0);  // the first, then the least and greatest along x, y, z
        for (std::uint32_t k = 1; k < n; ++k)
          for (int a = 0; a < 3; ++a) {
            if (at(k)[a] < at(picks[1 + 2 * a])[a]) picks[1 + 2 * a] = k;
            if (at(k)[a] > at(picks[2 + 2 * a])[a]) picks[2 + 2 * a] = k;
          }
        for (std::uint32_t i = 1; picks.size() < kNestSamples; ++i)  // spread over the rest
          picks.push_back(std::uint32_t(std::uint64_t(n) * i / (kNestSamples - 6)));
        std::sort(picks.begin(), picks.end());
        picks.erase(std::unique(picks.begin(), picks.end()), picks.end());
        for (std::uint32_t k : picks) samples.push_back(at(k));
      }
      const std::size_t n = part_at[q + 1] - part_at[q];
      if (visits + n * samples.size() > kMaxNestingTests) {
        skipped = true;
        break;
      }
      bool all_inside = true;
      for (const Vec3& x : samples) {
        visits += n;
        double omega = 0;
        for (std::uint32_t k = part_at[q]; k < part_at[q + 1]; ++k) {
          const Corners c = corners(mesh, faces_of[k], ps.flip[faces_of[k]]);
          omega += solid_angle(c.a - x, c.b - x, c.c - x);
        }
        if (!(std::abs(omega) > 2 * kPi)) {  // |w| = |Ω| / 4π <= 1/2: outside q
          all_inside = false;
          break;
        }
      }
      if (all_inside) inside_odd = !inside_odd;
    }
    if (skipped) {
      ++rep.nesting_skipped;
      continue;
    }
    odd[p] = inside_odd;
  }

  // Each part turned as a whole where it should be.
  std::vector<std::uint8_t> turn(parts, 0);
  for (std::size_t p = 0; p < parts; ++p) {
    if (ps.closed[p]) {
      turn[p] = (ps.volume6[p] > 0) == bool(odd[p]);  // outward unless a cavity
      rep.cavities += odd[p];
    } else {
      turn[p] = ps.against[p] > ps.kept[p];  // the file's majority, by area
    }
    // Inside out in the file: most of the area of a closed part flipped here.
    const double flipped = turn[p] ? ps.kept[p] : ps.against[p], unchanged = ps.kept[p] + ps.against[p] - flipped;
    rep.inverted_parts += ps.closed[p] && flipped > unchanged;
  }
  for (std::uint32_t f = 0; f < nf; ++f)
    if (ps.flip[f] ^ turn[ps.part[f]]) {
      std::swap(mesh.faces[f][1], mesh.faces[f][2]);
      ++rep.flipped;
    }
  return rep;
}

std::vector<std::uint8_t> open_part_faces(const Mesh& mesh) {
  std::vector<std::uint8_t> open(mesh.faces.size(), 0);
  if (mesh.faces.empty()) return open;
  const Parts ps = find_parts(mesh);
  for (std::size_t f = 0; f < open.size(); ++f) {
    const Tri& t = mesh.faces[f];
    const bool point = mesh.local[t[0]] == mesh.local[t[1]] && mesh.local[t[1]] == mesh.local[t[2]];
    open[f] = !ps.closed[ps.part[f]] && !point;  // (a point has no side to take)
  }
  return open;
}

std::string describe_winding(const OrientReport& r) {
  std::string out;
  auto add = [&out](const std::string& s) { out += (out.empty() ? "" : "; ") + s; };
  if (r.flipped > 0) {
    std::string s =
        std::to_string(r.flipped) + (r.flipped == 1 ? " face" : " faces") + " flipped to wind consistently and outward";
    if (r.inverted_parts > 0)
      s += " (" + std::to_string(r.inverted_parts) +
           (r.inverted_parts == 1 ? " closed part was" : " closed parts were") + " inside out)";
    add(s);
  }
  if (r.cavities > 0)
    add(std::to_string(r.cavities) + (r.cavities == 1 ? " closed part is a cavity" : " closed parts are cavities") +
        " (wound inward)");
  if (const std::size_t open = r.parts - r.closed_parts; open > 0)
    add(std::to_string(open) + (open == 1 ? " open part" : " open parts") +
        " (no inside: a contact takes the side the probe comes from)");
  if (r.unorientable_edges > 0)
    add(std::to_string(r.unorientable_edges) + " edges cannot agree (a non-orientable part)");
  if (r.nesting_skipped > 0)
    add(std::to_string(r.nesting_skipped) + " closed parts wound outward without a nesting test (too many)");
  return out;
}

}  // namespace st::geom
