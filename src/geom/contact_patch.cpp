// The patch contact model (definitions in contact.hpp): FD from the vector area of the object
// surface inside the probe, computed from the pairs' intersection segments (Stokes), PD as the
// directional penetration depth along FD over both bodies' inside vertices (flood fill over mesh
// edges, exit distances from a height field of the facing faces), history for thin features and
// wedges, and a held plane when the probe has passed through a feature it entered.
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
// Height field.

void HeightField::begin(const Vec3& d) {
  d_ = d;
  // Any orthonormal basis of the plane ⊥ d (Frisvad-style choice of the helper axis).
  const Vec3 helper = std::abs(d.x()) < 0.6 ? Vec3::UnitX() : (std::abs(d.y()) < 0.6 ? Vec3::UnitY() : Vec3::UnitZ());
  u_ = d.cross(helper).normalized();
  w_ = d.cross(u_);
  faces_.clear();
}

void HeightField::add(const Vec3& a, const Vec3& b, const Vec3& c, std::uint32_t id) {
  Face f;
  const Vec3* p[3] = {&a, &b, &c};
  for (int k = 0; k < 3; ++k) {
    f.u[k] = p[k]->dot(u_);
    f.w[k] = p[k]->dot(w_);
    f.h[k] = p[k]->dot(d_);
  }
  f.id = id;
  faces_.push_back(f);
}

void HeightField::finish() {
  cell_start_.clear();
  cell_faces_.clear();
  if (faces_.empty()) return;
  double lu = std::numeric_limits<double>::infinity(), hu = -lu, lw = lu, hw = -lu, extent_sum = 0;
  for (const Face& f : faces_) {
    const auto [u0, u1] = std::minmax({f.u[0], f.u[1], f.u[2]});
    const auto [w0, w1] = std::minmax({f.w[0], f.w[1], f.w[2]});
    lu = std::min(lu, u0), hu = std::max(hu, u1), lw = std::min(lw, w0), hw = std::max(hw, w1);
    extent_sum += std::max(u1 - u0, w1 - w0);
  }
  // Cells about one face across (each face lands in a few cells), at most 128 per axis.
  const double span = std::max({hu - lu, hw - lw, 1e-300});
  double cell = std::max(extent_sum / double(faces_.size()), span / 128.0);
  if (!(cell > 0) || !std::isfinite(cell)) cell = span;
  inv_cell_ = 1.0 / cell;
  lo_u_ = lu;
  lo_w_ = lw;
  nu_ = std::clamp(int((hu - lu) * inv_cell_) + 1, 1, 129);
  nw_ = std::clamp(int((hw - lw) * inv_cell_) + 1, 1, 129);
  cell_start_.assign(std::size_t(nu_) * nw_ + 1, 0);
  auto range = [&](const Face& f, int& iu0, int& iu1, int& iw0, int& iw1) {
    const auto [u0, u1] = std::minmax({f.u[0], f.u[1], f.u[2]});
    const auto [w0, w1] = std::minmax({f.w[0], f.w[1], f.w[2]});
    iu0 = std::clamp(int((u0 - lo_u_) * inv_cell_), 0, nu_ - 1);
    iu1 = std::clamp(int((u1 - lo_u_) * inv_cell_), 0, nu_ - 1);
    iw0 = std::clamp(int((w0 - lo_w_) * inv_cell_), 0, nw_ - 1);
    iw1 = std::clamp(int((w1 - lo_w_) * inv_cell_), 0, nw_ - 1);
  };
  int iu0, iu1, iw0, iw1;
  for (const Face& f : faces_) {
    range(f, iu0, iu1, iw0, iw1);
    for (int iw = iw0; iw <= iw1; ++iw)
      for (int iu = iu0; iu <= iu1; ++iu) ++cell_start_[std::size_t(iw) * nu_ + iu + 1];
  }
  for (std::size_t i = 1; i < cell_start_.size(); ++i) cell_start_[i] += cell_start_[i - 1];
  cell_faces_.resize(cell_start_.back());
  std::vector<std::uint32_t>& fill = scratch_fill_;
  fill.assign(cell_start_.begin(), cell_start_.end() - 1);
  for (std::uint32_t k = 0; k < faces_.size(); ++k) {
    range(faces_[k], iu0, iu1, iw0, iw1);
    for (int iw = iw0; iw <= iw1; ++iw)
      for (int iu = iu0; iu <= iu1; ++iu) cell_faces_[fill[std::size_t(iw) * nu_ + iu]++] = k;
  }
}

double HeightField::exit(const Vec3& x, std::uint32_t& face) const {
  if (faces_.empty()) return -1;
  const double pu = x.dot(u_), pw = x.dot(w_), ph = x.dot(d_);
  const double fu = (pu - lo_u_) * inv_cell_, fw = (pw - lo_w_) * inv_cell_;
  if (!(fu > -1e-9 * nu_ && fw > -1e-9 * nw_ && fu < nu_ + 1e-9 * nu_ && fw < nw_ + 1e-9 * nw_)) return -1;
  const int iu = std::clamp(int(fu), 0, nu_ - 1), iw = std::clamp(int(fw), 0, nw_ - 1);
  const std::size_t c = std::size_t(iw) * nu_ + iu;
  double best = std::numeric_limits<double>::infinity();
  for (std::uint32_t k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
    const Face& f = faces_[cell_faces_[k]];
    // Barycentric coordinates in the projection; closed triangles with a relative tolerance so
    // that a point over a shared edge finds a face on either side.
    const double e1u = f.u[1] - f.u[0], e1w = f.w[1] - f.w[0], e2u = f.u[2] - f.u[0], e2w = f.w[2] - f.w[0];
    const double det = e1u * e2w - e2u * e1w;
    if (!(std::abs(det) > 0)) continue;
    const double qu = pu - f.u[0], qw = pw - f.w[0];
    const double b1 = (qu * e2w - e2u * qw) / det, b2 = (e1u * qw - qu * e1w) / det, b0 = 1 - b1 - b2;
    constexpr double kTol = 1e-9;
    if (b0 < -kTol || b1 < -kTol || b2 < -kTol) continue;
    const double h = b0 * f.h[0] + b1 * f.h[1] + b2 * f.h[2];
    const double up = h - ph;
    if (up > 0 && up < best) {
      best = up;
      face = f.id;
    }
  }
  return std::isfinite(best) ? best : -1;
}

double HeightField::refine(const Vec3& a, const Vec3& b, Vec3& at, std::uint32_t& face) const {
  if (faces_.empty()) return -1;
  const double au = a.dot(u_), aw = a.dot(w_), bu = b.dot(u_), bw = b.dot(w_);
  const int iu0 = std::clamp(int((std::min(au, bu) - lo_u_) * inv_cell_), 0, nu_ - 1);
  const int iu1 = std::clamp(int((std::max(au, bu) - lo_u_) * inv_cell_), 0, nu_ - 1);
  const int iw0 = std::clamp(int((std::min(aw, bw) - lo_w_) * inv_cell_), 0, nw_ - 1);
  const int iw1 = std::clamp(int((std::max(aw, bw) - lo_w_) * inv_cell_), 0, nw_ - 1);
  if ((iu1 - iu0 + 1) * (iw1 - iw0 + 1) > 64) return -1;  // a long edge: not a local refinement
  const double ru = bu - au, rw = bw - aw;
  double best = -1;
  for (int iw = iw0; iw <= iw1; ++iw)
    for (int iu = iu0; iu <= iu1; ++iu) {
      const std::size_t c = std::size_t(iw) * nu_ + iu;
      for (std::uint32_t k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
        const Face& f = faces_[cell_faces_[k]];
        for (int e = 0; e < 3; ++e) {
          const int e1 = (e + 1) % 3;
          const double su = f.u[e1] - f.u[e], sw = f.w[e1] - f.w[e];
          const double den = ru * sw - rw * su;
          if (!(std::abs(den) > 0)) continue;  // parallel
          const double qu = f.u[e] - au, qw = f.w[e] - aw;
          const double s = (qu * sw - qw * su) / den, t = (qu * rw - qw * ru) / den;
          if (s < 0 || s > 1 || t < 0 || t > 1) continue;
          const Vec3 x = a + s * (b - a);
          std::uint32_t fx = UINT32_MAX;
          const double d = exit(x, fx);
          if (d > best) {
            best = d;
            at = x;
            face = fx;
          }
        }
      }
    }
  return best;
}

std::size_t HeightField::bytes() const {
  return faces_.capacity() * sizeof(Face) + (cell_start_.capacity() + cell_faces_.capacity() + scratch_fill_.capacity()) * 4;
}

// ---------------------------------------------------------------------------------------------
// The model.

namespace {

void sort_unique(std::vector<std::uint32_t>& v) {
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());
}

/// Where triangle (p0, p1, p2), with signed distances d[] to the other triangle's plane, crosses
/// that plane, as an interval [t0, t1] along the unit line direction L from origin o (the points
/// x0, x1 at its ends). False when it does not cross (all distances of one strict sign) or lies
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
  const Vec3 cr = na.cross(nb);
  const double len = cr.norm();
  if (!(len > 1e-12)) return false;  // parallel planes: touching or coplanar, no curve
  const Vec3 L = cr / len;
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

/// Colliding faces up to which every edge is tried against the other side's edges (edge–edge
/// depth): 64 faces × 3 edges × a few faces per grid cell stays within a few microseconds.
constexpr std::size_t kRefineAllFaces = 64;

/// Unit normal of a triangle; false when degenerate (kDegenerateRel) or non-finite.
bool unit_normal(const Vec3& a, const Vec3& b, const Vec3& c, Vec3& n) {
  const Vec3 cr = (b - a).cross(c - a);
  const double longest2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  const double len = cr.norm();
  if (!std::isfinite(len) || !(len > kDegenerateRel * longest2)) return false;
  n = cr / len;
  return true;
}

}  // namespace

void ContactBuilder::Patch::prepare(const Mesh& probe, const Mesh& object) {
  if (probe_mesh != &probe || probe_nv != probe.local.size() || probe_nf != probe.faces.size()) {
    probe_vf = VertexFaces::build(probe);
    probe_mesh = &probe;
    probe_nv = probe.local.size();
    probe_nf = probe.faces.size();
    probe_world.assign(probe_nv, Vec3::Zero());
    probe_xform_stamp.assign(probe_nv, 0);
    probe_visit_stamp.assign(probe_nv, 0);
    probe_face_stamp.assign(probe_nf, 0);
    epoch = 0;
  }
  if (object_mesh != &object || object_nv != object.local.size() || object_nf != object.faces.size()) {
    object_vf = VertexFaces::build(object);
    object_mesh = &object;
    object_nv = object.local.size();
    object_nf = object.faces.size();
    object_visit_stamp.assign(object_nv, 0);
    object_face_stamp.assign(object_nf, 0);
    epoch = 0;
  }
}

void ContactBuilder::Patch::reset() {
  have_prev = false;
  prev_n.setZero();
  held_valid = false;
}

std::size_t ContactBuilder::Patch::bytes() const {
  return probe_vf.bytes() + object_vf.bytes() + (probe_world.capacity() + curve.capacity()) * sizeof(Vec3) +
         (probe_xform_stamp.capacity() + probe_visit_stamp.capacity() + object_visit_stamp.capacity() +
          probe_face_stamp.capacity() + object_face_stamp.capacity() + probe_faces.capacity() +
          object_faces.capacity() + queue.capacity()) * 4 +
         valid.capacity() * sizeof(ContactPair) + field.bytes();
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
  const Mesh& test = probe_side ? probe : object;        // whose points may be inside
  const Mesh& surface = probe_side ? object : probe;     // whose faces they leave through
  const VertexFaces& test_vf = probe_side ? probe_vf : object_vf;
  const VertexFaces& surf_vf = probe_side ? object_vf : probe_vf;
  std::vector<std::uint32_t>& visit = probe_side ? probe_visit_stamp : object_visit_stamp;
  std::vector<std::uint32_t>& fstamp = probe_side ? object_face_stamp : probe_face_stamp;
  const std::vector<std::uint32_t>& test_seeds = probe_side ? probe_faces : object_faces;
  const std::vector<std::uint32_t>& surf_seeds = probe_side ? object_faces : probe_faces;
  const std::size_t test_nv = probe_side ? probe_nv : object_nv, surf_nv = probe_side ? object_nv : probe_nv;
  auto test_pos = [&](std::uint32_t v) -> Vec3 { return probe_side ? probe_point(v, probe) : object.local[v]; };
  auto surf_pos = [&](std::uint32_t v) -> Vec3 { return probe_side ? object.local[v] : probe_point(v, probe); };
  auto tri_ok = [](const Tri& t, std::size_t nv) { return t[0] < nv && t[1] < nv && t[2] < nv; };

  // The faces a point can leave through: facing d, connected to the colliding ones, over the
  // contact's footprint (the intersection curve's extent seen along d).
  field.begin(d);
  double lu = std::numeric_limits<double>::infinity(), hu = -lu, lw = lu, hw = -lu;
  for (const Vec3& x : curve) {
    double u, w;
    field.project(x, u, w);
    lu = std::min(lu, u), hu = std::max(hu, u), lw = std::min(lw, w), hw = std::max(hw, w);
  }
  const double margin = 1e-6 * std::max(hu - lu, hw - lw) + 1e-9;
  lu -= margin, hu += margin, lw -= margin, hw += margin;
  queue.clear();
  for (std::uint32_t f : surf_seeds) {
    fstamp[f] = epoch;
    queue.push_back(f);
  }
  std::uint32_t budget = config.max_inside_vertices;
  Vec3 nf;
  for (std::size_t qi = 0; qi < queue.size(); ++qi) {
    const std::uint32_t f = queue[qi];
    const Tri& t = surface.faces[f];
    if (!tri_ok(t, surf_nv)) continue;
    const Vec3 a = surf_pos(t[0]), b = surf_pos(t[1]), c = surf_pos(t[2]);
    bool keep = false;
    if (unit_normal(a, b, c, nf) && nf.dot(d) > kFrontCos) {
      double u[3], w[3];
      field.project(a, u[0], w[0]);
      field.project(b, u[1], w[1]);
      field.project(c, u[2], w[2]);
      keep = std::max({u[0], u[1], u[2]}) >= lu && std::min({u[0], u[1], u[2]}) <= hu &&
             std::max({w[0], w[1], w[2]}) >= lw && std::min({w[0], w[1], w[2]}) <= hw;
      if (keep) field.add(a, b, c, f);
    }
    const bool seed = qi < surf_seeds.size();
    if (!keep && !seed) continue;
    for (std::uint32_t v : t)
      for (std::uint32_t k = surf_vf.first[v]; k < surf_vf.first[v + 1]; ++k) {
        const std::uint32_t g = surf_vf.faces[k];
        if (fstamp[g] == epoch) continue;
        fstamp[g] = epoch;
        if (budget == 0) {
          best.capped = true;
          continue;
        }
        --budget;
        queue.push_back(g);
      }
  }
  field.finish();

  // Points inside: the colliding faces' vertices, then flood fill through inside vertices.
  queue.clear();
  std::uint32_t visited = 0;
  auto visit_vertex = [&](std::uint32_t v) {
    if (v >= test_nv || visit[v] == epoch) return;
    visit[v] = epoch;
    if (++visited > config.max_inside_vertices) {
      best.capped = true;
      return;
    }
    std::uint32_t face = UINT32_MAX;
    const Vec3 x = test_pos(v);
    const double dep = field.exit(x, face);
    if (!(dep > 0)) return;
    ++best.inside;
    queue.push_back(v);
    if (dep > best.depth) {
      best.depth = dep;
      best.vertex = v;
      best.point = x;
      best.face = face;
    }
  };
  for (std::uint32_t f : test_seeds)
    for (std::uint32_t v : test.faces[f]) visit_vertex(v);
  for (std::size_t qi = 0; qi < queue.size() && !best.capped; ++qi) {
    const std::uint32_t v = queue[qi];
    for (std::uint32_t k = test_vf.first[v]; k < test_vf.first[v + 1]; ++k)
      for (std::uint32_t u : test.faces[test_vf.faces[k]]) visit_vertex(u);
  }

  // Between vertices: the maximum of two piecewise-linear heights lies on a vertex of their
  // overlay, so also try where edges of this side cross the surface's edges along d: around the
  // deepest vertex, or over every colliding face when the patch is small or no vertex is inside
  // (a convex edge of one body pressed into a face of the other between its vertices).
  Vec3 at;
  auto refine_face = [&](std::uint32_t f) {
    const Tri& t = test.faces[f];
    if (!tri_ok(t, test_nv)) return;
    for (int e = 0; e < 3; ++e) {
      std::uint32_t face = UINT32_MAX;
      const double dep = field.refine(test_pos(t[e]), test_pos(t[(e + 1) % 3]), at, face);
      if (dep > best.depth) {
        best.depth = dep;
        best.point = at;
        best.face = face;
        best.vertex = UINT32_MAX;  // an edge point
      }
    }
  };
  const std::uint32_t deepest_vertex = best.vertex;
  if (deepest_vertex == UINT32_MAX || test_seeds.size() <= kRefineAllFaces) {
    for (std::uint32_t f : test_seeds) refine_face(f);
  }
  if (deepest_vertex != UINT32_MAX)
    for (std::uint32_t k = test_vf.first[deepest_vertex]; k < test_vf.first[deepest_vertex + 1]; ++k)
      refine_face(test_vf.faces[k]);
  return best;
}

ContactModel ContactBuilder::Patch::build(const Mesh& probe, const Mesh& object, const Pose& pose,
                                          std::span<const ContactPair> pairs) {
  prepare(probe, object);
  if (++epoch == 0) {  // stamps wrapped: clear them once every 2^32 rounds
    for (auto* v : {&probe_xform_stamp, &probe_visit_stamp, &object_visit_stamp, &probe_face_stamp, &object_face_stamp})
      std::fill(v->begin(), v->end(), 0);
    epoch = 1;
  }
  ContactModel m;
  m.pose = to_pod(pose);
  m.pairs = static_cast<std::uint32_t>(std::min<std::size_t>(pairs.size(), UINT32_MAX));
  const bool pose_ok = pose.matrix().allFinite();
  if (!pose_ok) m.flags |= kBadInput;

  valid.clear();
  probe_faces.clear();
  object_faces.clear();
  for (const ContactPair& p : pairs) {
    if (p.probe >= probe.faces.size() || p.object >= object.faces.size()) {
      ++m.skipped_pairs;
      continue;
    }
    valid.push_back(p);
    probe_faces.push_back(p.probe);
    object_faces.push_back(p.object);
  }
  if (m.skipped_pairs) m.flags |= kBadInput;
  sort_unique(probe_faces);
  sort_unique(object_faces);
  m.probe_faces = static_cast<std::uint32_t>(probe_faces.size());
  m.object_faces = static_cast<std::uint32_t>(object_faces.size());
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

  // Degenerate colliding object faces count as contacts but give no direction.
  Vec3 n_faces = Vec3::Zero();  // Σ unnormalised normals: 2 × the area-weighted mean normal (fallback)
  double n_faces_abs = 0;       // Σ of their lengths
  Vec3 nf;
  for (std::uint32_t f : object_faces) {
    const Tri& t = object.faces[f];
    if (!tri_ok(t, object_nv) || !unit_normal(object.local[t[0]], object.local[t[1]], object.local[t[2]], nf)) {
      ++m.degenerate_faces;
      continue;
    }
    const Vec3 cr = (object.local[t[1]] - object.local[t[0]]).cross(object.local[t[2]] - object.local[t[0]]);
    n_faces += cr;
    n_faces_abs += cr.norm();
  }
  if (m.degenerate_faces) m.flags |= kDegenerateSkipped;

  // The vector area of the object surface inside the probe, from the intersection curve:
  // A = ½ Σ (s0 − o) × (s1 − o) over the pairs' segments (o: any point; near the patch for
  // rounding). Split into the part on faces not turned away from the previous FD (front) and all.
  Vec3 origin = Vec3::Zero();
  if (!valid.empty() && tri_ok(object.faces[valid.front().object], object_nv))
    origin = object.local[object.faces[valid.front().object][0]];
  Vec3 a_all = Vec3::Zero(), a_front = Vec3::Zero();
  double abs_all = 0, abs_front = 0;
  bool any_front_face = false;
  curve.clear();
  Vec3 na, nb, s0, s1;
  for (const ContactPair& p : valid) {
    const Tri& to = object.faces[p.object];
    const Tri& tp = probe.faces[p.probe];
    if (!tri_ok(to, object_nv) || !tri_ok(tp, probe_nv)) continue;
    const Vec3* a[3] = {&object.local[to[0]], &object.local[to[1]], &object.local[to[2]]};
    if (!unit_normal(*a[0], *a[1], *a[2], na)) continue;
    const bool front = have_prev && na.dot(prev_n) > kBackCos;
    any_front_face |= front;
    const Vec3* b[3] = {&probe_point(tp[0], probe), &probe_point(tp[1], probe), &probe_point(tp[2], probe)};
    if (!unit_normal(*b[0], *b[1], *b[2], nb)) continue;
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
    if (abs_sum > 0 && a_norm > kCancelRatio * abs_sum && std::isfinite(a_norm)) {
      n = a / a_norm;
    } else {
      m.flags |= kNormalFallback;
      if (abs_sum > 0) m.flags |= kNormalsDisagree;
      if (have_prev) n = prev_n;
      else if (n_faces.norm() > kCancelRatio * n_faces_abs) n = n_faces.normalized();
      else in_contact = false;
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
    for (std::uint32_t f : object_faces)
      if (tri_ok(object.faces[f], object_nv))
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
    for (std::uint32_t f : probe_faces)
      for (std::uint32_t v : probe.faces[f])
        if (v < probe_nv && probe_point(v, probe).dot(n) < lowest) lowest = probe_point(v, probe).dot(n), lv = v;
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
  double radius = 0;
  for (const Vec3& x : curve) {
    const Vec3 rel = x - plane_pt;
    radius = std::max(radius, (rel - rel.dot(n) * n).norm());
  }
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
