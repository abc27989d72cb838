// The patch contact model (definitions in contact.hpp): FD from the vector area of the object
// surface inside the probe, computed from the pairs' intersection segments (Stokes), PD as the
// directional penetration depth along FD over both bodies (a steepest-ascent climb over each
// body's vertices from the colliding pairs, exit distances found by walking over the other
// body's facing faces, edge crossings near the top), history for thin features, and a held
// plane when the probe has passed through a feature it entered.
//
// References: the vector area of a surface patch is ½∮x×dx over its boundary (Stokes); the
// gradient of the intersection volume of two bodies with respect to a translation is the vector
// area of the part of one body's surface inside the other (Faure et al. 2008, "Image-based
// collision detection and response between arbitrary volume objects", SCA, use the same
// volume-gradient direction); directional penetration depth along a fixed direction follows
// Kim, Lin & Manocha 2002 ("Fast penetration depth estimation using rasterization hardware and
// hierarchical refinement"), here on the contact patch only.
#include "geom/contact_patch.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace st::geom {

// ---------------------------------------------------------------------------------------------
// Vertex adjacency.

VertexFaces VertexFaces::build(const Mesh& mesh) {
  VertexFaces a;
  const std::size_t nv = mesh.local.size();
  a.first.assign(nv + 1, 0);
  for (const Tri& t : mesh.faces)
    for (std::uint32_t v : t)
      if (v < nv) ++a.first[v + 1];
  for (std::size_t v = 0; v < nv; ++v) a.first[v + 1] += a.first[v];
  a.faces.resize(a.first[nv]);
  std::vector<std::uint32_t> fill(a.first.begin(), a.first.end() - 1);
  for (std::uint32_t f = 0; f < mesh.faces.size(); ++f)
    for (std::uint32_t v : mesh.faces[f])
      if (v < nv) a.faces[fill[v]++] = f;
  return a;
}

// ---------------------------------------------------------------------------------------------
// Surface walk.

void SurfaceWalk::set_direction(const Vec3& dir) {
  d = dir;
  // Any orthonormal basis of the plane ⊥ d with u × w = d.
  const Vec3 helper = std::abs(d.x()) < 0.6 ? Vec3::UnitX() : (std::abs(d.y()) < 0.6 ? Vec3::UnitY() : Vec3::UnitZ());
  u = d.cross(helper).normalized();
  w = d.cross(u);
}

Vec3 SurfaceWalk::at(std::uint32_t v) { return patch ? patch->probe_point(v, *mesh) : mesh->local[v]; }

std::uint32_t SurfaceWalk::across(std::uint32_t f, std::uint32_t a, std::uint32_t b) const {
  for (std::uint32_t k = vf->first[a]; k < vf->first[a + 1]; ++k) {
    const std::uint32_t g = vf->faces[k];
    if (g == f) continue;
    const Tri& t = mesh->faces[g];
    if (t[0] == b || t[1] == b || t[2] == b) return g;
  }
  return UINT32_MAX;
}

bool SurfaceWalk::exit(const Vec3& x, std::uint32_t& face, double& dist, int max_steps) {
  const std::size_t nv = mesh->local.size();
  const double qu = x.dot(u), qw = x.dot(w), qh = x.dot(d);
  std::uint32_t f = face, prev = UINT32_MAX;
  for (int step = 0; step < max_steps && f != UINT32_MAX; ++step) {
    const Tri& t = mesh->faces[f];
    if (t[0] >= nv || t[1] >= nv || t[2] >= nv) return false;
    const Vec3 a = at(t[0]), b = at(t[1]), c = at(t[2]);
    const double au = a.dot(u), aw = a.dot(w), bu = b.dot(u), bw = b.dot(w), cu = c.dot(u), cw = c.dot(w);
    const double e1u = bu - au, e1w = bw - aw, e2u = cu - au, e2w = cw - aw;
    // det = (b−a)×(c−a)·d (u × w = d): the projected area, > 0 when the face faces d. Only faces
    // turned less than acos(kFrontCos) from d are walked (never a silhouette or a back face).
    const double det = e1u * e2w - e2u * e1w;
    if (!(det > 0) || det * det <= kFrontCos * kFrontCos * (b - a).cross(c - a).squaredNorm()) return false;
    const double pu = qu - au, pw = qw - aw;
    const double b1 = (pu * e2w - e2u * pw) / det, b2 = (e1u * pw - pu * e1w) / det, b0 = 1 - b1 - b2;
    constexpr double kTol = 1e-9;  // closed triangles: a point over a shared edge is found from either side
    if (b0 >= -kTol && b1 >= -kTol && b2 >= -kTol) {
      face = f;
      const double h = b0 * a.dot(d) + b1 * b.dot(d) + b2 * c.dot(d);
      dist = h - qh;
      return true;
    }
    // Cross the edge facing the point (opposite the most negative coordinate), never straight
    // back; the second most negative if that one leads back.
    const double bc[3] = {b0, b1, b2};
    int i0 = 0;
    if (bc[1] < bc[i0]) i0 = 1;
    if (bc[2] < bc[i0]) i0 = 2;
    std::uint32_t next = across(f, t[(i0 + 1) % 3], t[(i0 + 2) % 3]);
    if (next == prev && next != UINT32_MAX) {
      const int j1 = (i0 + 1) % 3, j2 = (i0 + 2) % 3;
      const int i1 = bc[j1] < bc[j2] ? j1 : j2;
      next = bc[i1] < -kTol ? across(f, t[(i1 + 1) % 3], t[(i1 + 2) % 3]) : UINT32_MAX;
    }
    prev = f;
    f = next;
  }
  return false;
}

// ---------------------------------------------------------------------------------------------
// The model.

namespace {

/// Where triangle (p0, p1, p2), with signed distances d[] to the other triangle's plane, crosses
/// that plane, as an interval [t0, t1] of x·L along the line direction L (the points x0, x1 at its
/// ends). False when it does not cross (all distances of one strict sign) or lies
/// in the plane.
//
/// A vertex exactly on the plane (d = 0) counts as on its positive side (a symbolic perturbation,
/// as in Edelsbrunner & Mücke's simulation of simplicity): the decision depends on the vertex and
/// the plane only, so two faces sharing an edge that lies in the plane agree, and the curve is
/// counted once instead of twice or not at all.
bool crossing(const Vec3* p[3], const double d[3], const Vec3& L, double& t0, double& t1, Vec3& x0, Vec3& x1) {
  const bool neg[3] = {d[0] < 0, d[1] < 0, d[2] < 0};
  if ((neg[0] && neg[1] && neg[2]) || (!neg[0] && !neg[1] && !neg[2])) return false;
  int n = 0;
  Vec3 pts[2];
  for (int i = 0; i < 3; ++i) {
    const int j = (i + 1) % 3;
    if (neg[i] != neg[j] && n < 2) {
      const double s = d[i] / (d[i] - d[j]);  // d[j] = 0 gives the vertex itself
      pts[n++] = *p[i] + s * (*p[j] - *p[i]);
    }
  }
  if (n < 2) return false;
  t0 = std::numeric_limits<double>::infinity();
  t1 = -t0;
  for (int k = 0; k < n; ++k) {
    const double t = pts[k].dot(L);
    if (t < t0) t0 = t, x0 = pts[k];
    if (t > t1) t1 = t, x1 = pts[k];
  }
  return true;
}

/// Intersection segment [s0, s1] of object triangle a (unit normal na) and probe triangle b (unit
/// normal nb), oriented along na × nb (the boundary of the object surface inside the probe runs
/// that way, with the inside on its left seen from outside). False when there is no segment.
bool segment(const Vec3* a[3], const Vec3& na, const Vec3* b[3], const Vec3& nb, Vec3& s0, Vec3& s1) {
  const Vec3 L = na.cross(nb);                   // unit normals: |L| = sin of the angle between the planes
  if (!(L.squaredNorm() > 1e-24)) return false;  // parallel planes: touching or coplanar, no curve
  double db[3], da[3];
  for (int k = 0; k < 3; ++k) db[k] = na.dot(*b[k] - *a[0]);
  for (int k = 0; k < 3; ++k) da[k] = nb.dot(*a[k] - *b[0]);
  double ta0, ta1, tb0, tb1;
  Vec3 xa0, xa1, xb0, xb1;
  if (!crossing(a, da, L, ta0, ta1, xa0, xa1) || !crossing(b, db, L, tb0, tb1, xb0, xb1)) return false;
  const double lo = std::max(ta0, tb0), hi = std::min(ta1, tb1);
  if (!(hi > lo)) return false;  // a point or nothing: no length, no area
  s0 = ta0 >= tb0 ? xa0 : xb0;
  s1 = ta1 <= tb1 ? xa1 : xb1;
  return true;
}

/// Vector area below this fraction of the colliding object faces' area is noise, not a direction.
constexpr double kTinyArea = 1e-9;

/// Colliding pairs up to which every pair's edges are crossed with each other along FD (edge–edge
/// depth): 64 pairs × 9 edge crossings stay within a few microseconds.
constexpr std::size_t kRefineAllPairs = 64;
/// Colliding pairs sampled as starts of the depth climb (plus last round's deepest vertex): the
/// climb from any inside vertex of a contact region reaches its deepest point, so a few dozen
/// starts spread over the pairs find every region that is not tiny.
constexpr std::size_t kSeedPairs = 8;
/// Colliding pairs' vertices lowest along the exit direction tried as climb starts.
constexpr int kLowSeeds = 8;
/// Fans visited when following a ridge from the deepest vertex (each ~2 edge lengths on).
constexpr int kRidgeSteps = 8;
/// A ridge is followed further only while each fan adds more than this to the depth, mm (a
/// smooth surface gives ever smaller gains).
constexpr double kRidgeGainMm = 1e-4;
/// Rounds between searches for new contact regions while the remembered ones still hold.
constexpr std::uint32_t kDiscoverEvery = 4;
/// Steps a walk may take from its start face: neighbouring vertices land within a face or two of
/// each other; a longer walk means the point is not over the patch.
constexpr int kMaxWalkSteps = 16;

/// Unit normal n of a triangle and its unnormalised normal cr = (b−a)×(c−a); false when
/// degenerate (kDegenerateRel) or non-finite.
bool unit_normal(const Vec3& a, const Vec3& b, const Vec3& c, Vec3& n, Vec3& cr) {
  cr = (b - a).cross(c - a);
  const double longest2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  const double len = cr.norm();
  if (!std::isfinite(len) || !(len > kDegenerateRel * longest2)) return false;
  n = cr / len;
  return true;
}

}  // namespace

void ContactBuilder::Patch::BodyState::reset(const Mesh& m) {
  vf = VertexFaces::build(m);
  mesh = &m;
  nv = m.local.size();
  nf = m.faces.size();
  visit_stamp.assign(nv, 0);
  path_stamp.assign(nv, 0);
  depth.assign(nv, 0);
  exit_face.assign(nv, UINT32_MAX);
  face_stamp.assign(nf, 0);
  face_slot.assign(nf, 0);
  memory = {};
  face_normals.clear();
}

void ContactBuilder::Patch::BodyState::compute_face_normals() {
  face_normals.assign(nf, Vec3::Zero());
  Vec3 n, cr;
  for (std::size_t f = 0; f < nf; ++f) {
    const Tri& t = mesh->faces[f];
    if (t[0] < nv && t[1] < nv && t[2] < nv && unit_normal(mesh->local[t[0]], mesh->local[t[1]], mesh->local[t[2]], n, cr))
      face_normals[f] = n;
  }
}

void ContactBuilder::Patch::BodyState::clear_stamps() {
  std::fill(visit_stamp.begin(), visit_stamp.end(), 0);
  std::fill(face_stamp.begin(), face_stamp.end(), 0);
}

std::size_t ContactBuilder::Patch::BodyState::bytes() const {
  return vf.bytes() +
         (visit_stamp.capacity() + path_stamp.capacity() + exit_face.capacity() + face_stamp.capacity() +
          face_slot.capacity() + faces.capacity()) *
             4 +
         depth.capacity() * sizeof(double) + (normals.capacity() + face_normals.capacity()) * sizeof(Vec3);
}

void ContactBuilder::Patch::prepare(const Mesh& probe, const Mesh& object) {
  if (!probe_s.sized_for(probe)) {
    probe_s.reset(probe);
    probe_s.compute_face_normals();
    probe_world.assign(probe_s.nv, Vec3::Zero());
    probe_xform_stamp.assign(probe_s.nv, 0);
    epoch = 0;
  }
  if (!object_s.sized_for(object)) {
    object_s.reset(object);
    epoch = 0;
  }
}

void ContactBuilder::Patch::reset() {
  have_prev = false;
  prev_n.setZero();
  held_valid = false;
  probe_s.memory = {};
  object_s.memory = {};
}

std::size_t ContactBuilder::Patch::bytes() const {
  return probe_s.bytes() + object_s.bytes() + (probe_world.capacity() + curve.capacity()) * sizeof(Vec3) +
         (probe_xform_stamp.capacity() + climb.capacity()) * 4 + valid.capacity() * sizeof(ContactPair);
}

const Vec3& ContactBuilder::Patch::probe_point(std::uint32_t v, const Mesh& probe) {
  if (probe_xform_stamp[v] != epoch) {
    probe_xform_stamp[v] = epoch;
    probe_world[v] = rot * probe.local[v] + shift;
  }
  return probe_world[v];
}

ContactBuilder::Patch::Deepest ContactBuilder::Patch::side(bool probe_side, const Vec3& d, const Mesh& probe,
                                                           const Mesh& object) {
  Deepest best;
  BodyState& T = probe_side ? probe_s : object_s;  // the body whose points may be inside
  BodyState& S = probe_side ? object_s : probe_s;  // the body whose faces they leave through
  const Mesh& test = *T.mesh;
  const Mesh& surface = *S.mesh;
  const VertexFaces& test_vf = T.vf;
  std::vector<std::uint32_t>& visit = T.visit_stamp;
  std::vector<double>& depth = T.depth;
  std::vector<std::uint32_t>& exitf = T.exit_face;
  Memory& memory = T.memory;
  const std::size_t test_nv = T.nv;
  auto test_pos = [&](std::uint32_t v) -> Vec3 { return probe_side ? probe_point(v, probe) : object.local[v]; };
  SurfaceWalk walk;
  walk.mesh = &surface;
  walk.vf = &S.vf;
  walk.patch = probe_side ? nullptr : this;
  walk.set_direction(d);

  std::vector<std::uint32_t>& path = T.path_stamp;

  // Exit distance of a vertex, walking from a face near it; once per vertex and round.
  std::uint32_t evaluated = 0;
  auto eval = [&](std::uint32_t v, std::uint32_t hint) -> double {
    if (visit[v] == epoch) return depth[v];
    visit[v] = epoch;
    depth[v] = -std::numeric_limits<double>::infinity();
    exitf[v] = UINT32_MAX;
    if (hint == UINT32_MAX) return depth[v];
    if (++evaluated > config.max_inside_vertices) {
      best.capped = true;
      return depth[v];
    }
    std::uint32_t f = hint;
    double dist = 0;
    if (!walk.exit(test_pos(v), f, dist, kMaxWalkSteps)) return depth[v];
    depth[v] = dist;
    exitf[v] = f;
    if (dist > 0) {
      ++best.inside;
      if (dist > best.depth) {
        best.depth = dist;
        best.vertex = v;
        best.face = f;
      }
    }
    return dist;
  };
  // Ascent over the vertex graph: the exit distance grows toward the deepest point, so the work
  // is the length of the climb, not the number of vertices inside. Neighbours are tried in the
  // order of their height along -d (the cheap part of the exit distance: exact over a flat
  // surface), and the climb moves to the first that is deeper; it stops at a local maximum, or
  // where it comes next to the path of an earlier climb (from there on that climb's result stands).
  std::uint32_t maxima[Memory::kSize];
  double maxima_depth[Memory::kSize];
  int n_maxima = 0;
  if (climb_serial > 0xF0000000u) {  // serials about to wrap: forget every path (once per ~4e9 climbs)
    std::fill(probe_s.path_stamp.begin(), probe_s.path_stamp.end(), 0);
    std::fill(object_s.path_stamp.begin(), object_s.path_stamp.end(), 0);
    climb_serial = 0;
  }
  const std::uint32_t round_first = climb_serial + 1;
  auto climb_from = [&](std::uint32_t v) {
    if (path[v] >= round_first) return;
    const std::uint32_t serial = ++climb_serial;
    for (;;) {
      path[v] = serial;
      std::uint32_t cand[32];
      double key[32];
      int n = 0;
      for (std::uint32_t k = test_vf.first[v]; k < test_vf.first[v + 1]; ++k)
        for (std::uint32_t u : test.faces[test_vf.faces[k]]) {
          if (u == v || u >= test_nv || n == 32) continue;
          bool dup = false;
          for (int i = 0; i < n; ++i) dup |= cand[i] == u;
          if (dup) continue;
          cand[n] = u;
          key[n++] = -test_pos(u).dot(d);
        }
      for (int i = 1; i < n; ++i)  // insertion sort, deepest along -d first (n is ~6)
        for (int j = i; j > 0 && key[j] > key[j - 1]; --j)
          std::swap(key[j], key[j - 1]), std::swap(cand[j], cand[j - 1]);
      std::uint32_t next = UINT32_MAX;
      bool joined = false;
      for (int i = 0; i < n && next == UINT32_MAX; ++i) {
        joined |= path[cand[i]] >= round_first && path[cand[i]] != serial;
        if (eval(cand[i], exitf[v]) > depth[v]) next = cand[i];
      }
      if (best.capped) return;
      // A vertex higher than all its neighbours may still sit below a ridge or plateau between
      // vertices: look one ring further before calling it the deepest (other maxima are only
      // kept for next round's starts, they need not be exact).
      for (int i = 0; i < n && next == UINT32_MAX && depth[v] >= best.depth; ++i) {
        const std::uint32_t c = cand[i];
        if (exitf[c] == UINT32_MAX) continue;
        for (std::uint32_t k = test_vf.first[c]; k < test_vf.first[c + 1] && next == UINT32_MAX; ++k)
          for (std::uint32_t u : test.faces[test_vf.faces[k]])
            if (u != v && u < test_nv && eval(u, exitf[c]) > depth[v]) {
              next = u;
              break;
            }
      }
      if (next == UINT32_MAX) {  // a local maximum: remember it (deepest first)
        int i = n_maxima < Memory::kSize ? n_maxima++ : Memory::kSize - 1;
        if (i == Memory::kSize - 1 && n_maxima == Memory::kSize && maxima_depth[i] >= depth[v]) return;
        maxima[i] = v;
        maxima_depth[i] = depth[v];
        for (; i > 0 && maxima_depth[i] > maxima_depth[i - 1]; --i)
          std::swap(maxima[i], maxima[i - 1]), std::swap(maxima_depth[i], maxima_depth[i - 1]);
        return;
      }
      // Next to an earlier climb's path: that climb has been up this slope already.
      if (joined) return;
      v = next;
    }
  };
  // Starts: last round's local maxima (from the faces they left through); the colliding pairs'
  // vertices lowest along d (over a flat surface the deepest; from the pair's face on the other
  // side); and a sample of the pairs whose offset turns every round, so a separate contact region
  // that neither found is found within a few rounds.
  climb.clear();
  bool remembered = false;
  for (int i = 0; i < Memory::kSize; ++i) {
    const std::uint32_t v = memory.vertex[i];
    if (v < test_nv && memory.face[i] < surface.faces.size() && eval(v, memory.face[i]) > 0) {
      climb_from(v);
      remembered = true;
    }
  }
  // While the remembered maxima hold, new regions are looked for every kDiscoverEvery rounds
  // (a region starts at depth 0, so one found a few rounds late has not grown much).
  const bool discover = !remembered || epoch % kDiscoverEvery == 0;
  std::uint32_t low_v[kLowSeeds], low_f[kLowSeeds];
  double low_key[kLowSeeds];
  int n_low = 0;
  const std::span<const ContactPair> seed_pairs =
      discover ? std::span<const ContactPair>(valid) : std::span<const ContactPair>();
  for (const ContactPair& p : seed_pairs) {
    const std::uint32_t tf = probe_side ? p.probe : p.object, sf = probe_side ? p.object : p.probe;
    for (std::uint32_t v : test.faces[tf]) {
      if (v >= test_nv) continue;
      const double key = -test_pos(v).dot(d);
      if (n_low == kLowSeeds && key <= low_key[n_low - 1]) continue;
      bool dup = false;
      for (int i = 0; i < n_low; ++i) dup |= low_v[i] == v;
      if (dup) continue;
      int i = n_low < kLowSeeds ? n_low++ : kLowSeeds - 1;
      low_v[i] = v, low_f[i] = sf, low_key[i] = key;
      for (; i > 0 && low_key[i] > low_key[i - 1]; --i)
        std::swap(low_v[i], low_v[i - 1]), std::swap(low_f[i], low_f[i - 1]), std::swap(low_key[i], low_key[i - 1]);
    }
  }
  for (int i = 0; i < n_low; ++i)
    if (visit[low_v[i]] != epoch && eval(low_v[i], low_f[i]) > 0) climb.push_back(low_v[i]);
  const std::size_t stride = std::max<std::size_t>(1, valid.size() / kSeedPairs);
  for (std::size_t i = (epoch / kDiscoverEvery) % stride; discover && i < valid.size(); i += stride) {
    const ContactPair& p = valid[i];
    const std::uint32_t tf = probe_side ? p.probe : p.object, sf = probe_side ? p.object : p.probe;
    for (std::uint32_t v : test.faces[tf])
      if (v < test_nv && visit[v] != epoch && eval(v, sf) > 0) climb.push_back(v);
  }
  std::sort(climb.begin(), climb.end(), [&](std::uint32_t a, std::uint32_t b) { return depth[a] > depth[b]; });
  for (std::uint32_t v : climb) climb_from(v);
  const std::uint32_t deepest_vertex = best.vertex;
  memory = Memory{};
  for (int i = 0; i < n_maxima; ++i) {
    memory.vertex[i] = maxima[i];
    memory.face[i] = exitf[maxima[i]];
  }
  if (deepest_vertex != UINT32_MAX) best.point = test_pos(deepest_vertex);

  // Between vertices: the maximum of two piecewise-linear heights lies on a vertex of their
  // overlay, so also try where edges of this side cross the other side's edges along d: around
  // the deepest vertex, and over every colliding pair when the patch is small or no vertex is
  // inside (a convex edge of one body pressed into a face of the other between its vertices).
  std::uint32_t won_a = UINT32_MAX, won_b = UINT32_MAX;  // the test edge whose crossing won last
  auto refine_edge = [&](std::uint32_t ia, std::uint32_t ib, std::uint32_t sface) {
    const Vec3 a = test_pos(ia), b = test_pos(ib);
    const Tri& t = surface.faces[sface];
    const double au = a.dot(walk.u), aw = a.dot(walk.w), ru = b.dot(walk.u) - au, rw = b.dot(walk.w) - aw;
    for (int e = 0; e < 3; ++e) {
      if (t[e] >= surface.local.size() || t[(e + 1) % 3] >= surface.local.size()) return;
      const Vec3 p0 = walk.at(t[e]), p1 = walk.at(t[(e + 1) % 3]);
      const double su = p1.dot(walk.u) - p0.dot(walk.u), sw = p1.dot(walk.w) - p0.dot(walk.w);
      const double den = ru * sw - rw * su;
      if (!(std::abs(den) > 0)) continue;  // parallel
      const double qu = p0.dot(walk.u) - au, qw = p0.dot(walk.w) - aw;
      const double s = (qu * sw - qw * su) / den, r = (qu * rw - qw * ru) / den;
      if (s < 0 || s > 1 || r < 0 || r > 1) continue;
      const Vec3 x = a + s * (b - a);
      std::uint32_t f = sface;
      double dist = 0;
      if (walk.exit(x, f, dist, 4) && dist > best.depth) {
        best.depth = dist;
        best.point = x;
        best.face = f;
        best.vertex = UINT32_MAX;  // an edge point
        won_a = ia, won_b = ib;
      }
    }
  };
  // Every edge of the faces around vertex c against the faces its neighbourhood leaves through.
  auto refine_around = [&](std::uint32_t c) {
    std::uint32_t near[8];
    int n_near = 0;
    auto add_near = [&](std::uint32_t f) {
      if (f == UINT32_MAX || n_near == 8) return;
      for (int i = 0; i < n_near; ++i)
        if (near[i] == f) return;
      near[n_near++] = f;
    };
    add_near(exitf[c]);
    for (std::uint32_t k = test_vf.first[c]; k < test_vf.first[c + 1]; ++k)
      for (std::uint32_t u : test.faces[test_vf.faces[k]])
        if (u < test_nv) {
          eval(u, exitf[c]);
          add_near(exitf[u]);
        }
    // Over one face of the other side both heights are linear: no crossing can beat the vertices.
    if (n_near < 2) return;
    for (std::uint32_t k = test_vf.first[c]; k < test_vf.first[c + 1]; ++k) {
      const Tri& t = test.faces[test_vf.faces[k]];
      if (t[0] >= test_nv || t[1] >= test_nv || t[2] >= test_nv) continue;
      for (int e = 0; e < 3; ++e)
        for (int i = 0; i < n_near; ++i) refine_edge(t[e], t[(e + 1) % 3], near[i]);
    }
  };
  if (deepest_vertex != UINT32_MAX) {
    // Along a ridge (a convex edge of the other body seen along d), the deepest point moves
    // between vertices: follow the winning crossings from fan to fan while they improve.
    std::uint32_t c = deepest_vertex;
    for (int it = 0; it < kRidgeSteps; ++it) {
      const double before = best.depth;
      refine_around(c);
      if (!(best.depth > before + kRidgeGainMm) || won_a == UINT32_MAX) break;
      const std::uint32_t next = (won_a == c || (won_b != c && depth[won_b] > depth[won_a])) ? won_b : won_a;
      if (next == c || next >= test_nv || exitf[next] == UINT32_MAX) break;
      c = next;
    }
    if (c != deepest_vertex) {  // start next round's climb where the ridge search ended
      memory.vertex[0] = c;
      memory.face[0] = exitf[c];
    }
  }
  if (deepest_vertex == UINT32_MAX || valid.size() <= kRefineAllPairs) {
    for (const ContactPair& p : valid) {
      const std::uint32_t tf = probe_side ? p.probe : p.object, sf = probe_side ? p.object : p.probe;
      const Tri& t = test.faces[tf];
      if (t[0] >= test_nv || t[1] >= test_nv || t[2] >= test_nv) continue;
      for (int e = 0; e < 3; ++e) refine_edge(t[e], t[(e + 1) % 3], sf);
    }
  }
  return best;
}

ContactModel ContactBuilder::Patch::build(const Mesh& probe, const Mesh& object, const Pose& pose,
                                          std::span<const ContactPair> pairs) {
  prepare(probe, object);
  if (++epoch == 0) {  // stamps wrapped: clear them once every 2^32 rounds
    std::fill(probe_xform_stamp.begin(), probe_xform_stamp.end(), 0);
    probe_s.clear_stamps();
    object_s.clear_stamps();
    epoch = 1;
  }
  ContactModel m;
  m.pose = to_pod(pose);
  m.pairs = static_cast<std::uint32_t>(std::min<std::size_t>(pairs.size(), UINT32_MAX));
  const bool pose_ok = pose.matrix().allFinite();
  if (!pose_ok) m.flags |= kBadInput;

  valid.clear();
  probe_s.faces.clear();
  object_s.faces.clear();
  for (const ContactPair& p : pairs) {
    if (p.probe >= probe.faces.size() || p.object >= object.faces.size()) {
      ++m.skipped_pairs;
      continue;
    }
    valid.push_back(p);
    if (probe_s.face_stamp[p.probe] != epoch) {
      probe_s.face_stamp[p.probe] = epoch;
      probe_s.face_slot[p.probe] = std::uint32_t(probe_s.faces.size());
      probe_s.faces.push_back(p.probe);
    }
    if (object_s.face_stamp[p.object] != epoch) {
      object_s.face_stamp[p.object] = epoch;
      object_s.face_slot[p.object] = std::uint32_t(object_s.faces.size());
      object_s.faces.push_back(p.object);
    }
  }
  if (m.skipped_pairs) m.flags |= kBadInput;
  m.probe_faces = static_cast<std::uint32_t>(probe_s.faces.size());
  m.object_faces = static_cast<std::uint32_t>(object_s.faces.size());
  m.contacts = m.probe_faces + m.object_faces;
  if (!pose_ok) {
    reset();
    return m;
  }

  // Probe vertices in object-local coordinates, each transformed once per round:
  // x = R·local + (R·probe.origin + t - object.origin) (no large offsets in the sum).
  rot = pose.linear();
  shift = rot * probe.origin + pose.translation() - object.origin;
  const Eigen::Matrix3d& R = rot;
  auto tri_ok = [](const Tri& t, std::size_t nv) { return t[0] < nv && t[1] < nv && t[2] < nv; };

  // Unit normals of the colliding faces, once per face (zero: degenerate, no direction); the
  // probe's are rotated into the object frame. Degenerate object faces count as contacts but
  // give no direction.
  Vec3 n_faces = Vec3::Zero();  // Σ unnormalised normals: 2 × the area-weighted mean normal (fallback)
  double n_faces_abs = 0;       // Σ of their lengths
  Vec3 nf, cr;
  object_s.normals.resize(object_s.faces.size());
  for (std::size_t i = 0; i < object_s.faces.size(); ++i) {
    const Tri& t = object.faces[object_s.faces[i]];
    object_s.normals[i].setZero();
    if (!tri_ok(t, object_s.nv) || !unit_normal(object.local[t[0]], object.local[t[1]], object.local[t[2]], nf, cr)) {
      ++m.degenerate_faces;
      continue;
    }
    object_s.normals[i] = nf;
    n_faces += cr;
    n_faces_abs += cr.norm();
  }
  if (m.degenerate_faces) m.flags |= kDegenerateSkipped;
  probe_s.normals.resize(probe_s.faces.size());
  for (std::size_t i = 0; i < probe_s.faces.size(); ++i) {
    const Tri& t = probe.faces[probe_s.faces[i]];
    probe_s.normals[i].setZero();
    if (!tri_ok(t, probe_s.nv)) continue;
    for (std::uint32_t v : t) (void)probe_point(v, probe);            // transform each vertex once, in face order
    probe_s.normals[i] = R * probe_s.face_normals[probe_s.faces[i]];  // zero stays zero (degenerate)
  }

  // The vector area of the object surface inside the probe, from the intersection curve:
  // A = ½ Σ (s0 − o) × (s1 − o) over the pairs' segments (o: any point; near the patch for
  // rounding). Split into the part on faces not turned away from the previous FD (front) and all.
  Vec3 origin = Vec3::Zero();
  if (!valid.empty() && tri_ok(object.faces[valid.front().object], object_s.nv))
    origin = object.local[object.faces[valid.front().object][0]];
  Vec3 a_all = Vec3::Zero(), a_front = Vec3::Zero();
  double abs_all = 0, abs_front = 0;
  bool any_front_face = false;
  curve.clear();
  Vec3 s0, s1;
  for (const ContactPair& p : valid) {
    const Tri& to = object.faces[p.object];
    const Tri& tp = probe.faces[p.probe];
    if (!tri_ok(to, object_s.nv) || !tri_ok(tp, probe_s.nv)) continue;
    const Vec3& na = object_s.normals[object_s.face_slot[p.object]];
    const Vec3& nb = probe_s.normals[probe_s.face_slot[p.probe]];
    if (na.squaredNorm() == 0 || nb.squaredNorm() == 0) continue;  // degenerate: no direction
    const Vec3* a[3] = {&object.local[to[0]], &object.local[to[1]], &object.local[to[2]]};
    const bool front = have_prev && na.dot(prev_n) > kBackCos;
    any_front_face |= front;
    const Vec3* b[3] = {&probe_world[tp[0]], &probe_world[tp[1]], &probe_world[tp[2]]};  // transformed above
    if (!segment(a, na, b, nb, s0, s1)) continue;
    const Vec3 piece = 0.5 * (s0 - origin).cross(s1 - origin);
    const double piece_abs = piece.norm();
    a_all += piece;
    abs_all += piece_abs;
    if (front) {
      a_front += piece;
      abs_front += piece_abs;
    }
    curve.push_back(s0);
    curve.push_back(s1);
  }

  // FD: the front part of the curve while contact continues (thin plates, wedges), all of it at
  // first contact; then the fallbacks.
  Vec3 n = Vec3::Zero();
  bool in_contact = !valid.empty() && m.degenerate_faces < m.object_faces;
  if (in_contact && have_prev && !any_front_face) in_contact = false;  // only back faces: past a thin feature
  if (in_contact) {
    const Vec3& a = have_prev ? a_front : a_all;
    const double abs_sum = have_prev ? abs_front : abs_all;
    const double a_norm = a.norm();
    // A curve of (nearly) no area is rounding noise (faces touching at a vertex or an edge): its
    // direction is arbitrary. kTinyArea of the colliding faces' area is far below any real
    // penetration (a ball pressed 1e-6 of its radius already has ~1e-5 of its face area inside).
    const bool tiny = !(a_norm > kTinyArea * 0.5 * n_faces_abs);
    if (abs_sum > 0 && a_norm > kCancelRatio * abs_sum && std::isfinite(a_norm) && !tiny) {
      n = a / a_norm;
    } else {
      m.flags |= kNormalFallback;
      if (abs_sum > 0 && !tiny) m.flags |= kNormalsDisagree;
      if (have_prev)
        n = prev_n;
      else if (n_faces.norm() > kCancelRatio * n_faces_abs)
        n = n_faces.normalized();
      else
        in_contact = false;
    }
  }

  if (!in_contact) {
    // Held contact: the probe has passed through a feature it entered (or only touches the
    // feature's far side): keep the last plane while the tracked point is below it and over
    // the patch's footprint.
    if (held_valid) {
      const Vec3 x = R * held_tracked + shift;
      const Vec3 rel = x - held_point;
      const double depth = -rel.dot(held_n);
      const double lateral = (rel + depth * held_n).norm();
      if (depth > 0 && lateral <= held_radius + config.hold_margin_mm) {
        m.flags |= kInContact | kHeld | kNormalFallback;
        m.force_dir = to_pod(held_n);
        m.penetration_mm = depth;
        m.probe_point = to_pod(held_tracked + probe.origin);
        m.plane_point = to_pod(held_point + object.origin);
        m.contact_point = to_pod(x + depth * held_n + object.origin);
        have_prev = true;
        prev_n = held_n;
        return m;
      }
    }
    reset();
    return m;
  }
  if (curve.empty()) {  // touching or coplanar only: the footprint is the colliding faces
    for (std::uint32_t f : object_s.faces)
      if (tri_ok(object.faces[f], object_s.nv))
        for (std::uint32_t v : object.faces[f]) curve.push_back(object.local[v]);
  }

  // PD: directional penetration depth along n, both ways: probe points inside the object leave
  // along +n through the object's faces that face +n; object points inside the probe leave along
  // −n through the probe's faces that face −n.
  const Deepest dp = side(true, n, probe, object);
  const Deepest dobj = side(false, -n, probe, object);
  m.inside_probe_vertices = dp.inside;
  m.inside_object_vertices = dobj.inside;
  if (dp.capped || dobj.capped) m.flags |= kInsideCapped;
  m.flags |= kInContact;
  m.force_dir = to_pod(n);

  // The point PD is measured at, fixed on the probe, and the plane through the surface there.
  Vec3 tracked_local, plane_pt;  // probe-local point, object-local plane point
  if (dp.depth > 0 && dp.depth >= dobj.depth) {
    m.penetration_mm = dp.depth;
    m.deepest_probe_vertex = dp.vertex;
    m.nearest_object_face = dp.face;
    tracked_local = R.transpose() * (dp.point - shift);
    plane_pt = dp.point + dp.depth * n;
  } else if (dobj.depth > 0) {
    // An object point is deepest: the probe point is where it leaves the probe (along −n), a
    // point fixed on the probe; the plane passes through the object point.
    m.penetration_mm = dobj.depth;
    const Vec3 e = dobj.point - dobj.depth * n;
    tracked_local = R.transpose() * (e - shift);
    plane_pt = dobj.point;
  } else {
    // Touching, or edges crossing with every vertex outside: PD = 0, the plane through the
    // colliding probe vertex lowest along n (pressing on raises the depth from 0).
    m.penetration_mm = 0;
    double lowest = std::numeric_limits<double>::infinity();
    std::uint32_t lv = UINT32_MAX;
    for (std::uint32_t f : probe_s.faces)
      for (std::uint32_t v : probe.faces[f])
        if (v < probe_s.nv && probe_point(v, probe).dot(n) < lowest) lowest = probe_point(v, probe).dot(n), lv = v;
    if (lv == UINT32_MAX) {  // only faces with out-of-range vertices: nothing to render
      reset();
      m.flags &= ~kInContact;
      m.force_dir = {};
      return m;
    }
    m.deepest_probe_vertex = lv;
    tracked_local = probe.local[lv];
    plane_pt = probe_point(lv, probe);
  }
  m.probe_point = to_pod(tracked_local + probe.origin);
  m.plane_point = to_pod(plane_pt + object.origin);
  m.contact_point = m.plane_point;

  // Held-contact footprint: how far the intersection curve reaches from the plane point.
  double radius2 = 0;
  for (const Vec3& x : curve) {
    const Vec3 rel = x - plane_pt;
    radius2 = std::max(radius2, (rel - rel.dot(n) * n).squaredNorm());
  }
  const double radius = std::sqrt(radius2);
  have_prev = true;
  prev_n = n;
  held_valid = true;
  held_n = n;
  held_point = plane_pt;
  held_tracked = tracked_local;
  held_radius = radius;
  return m;
}

}  // namespace st::geom
