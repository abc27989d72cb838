// SPDX-License-Identifier: BSD-3-Clause
// The patch contact model (definitions in contact.hpp): FD from the vector area of the object
// surface inside the probe, computed from the pairs' intersection segments (Stokes), PD as the
// directional penetration depth along FD over both bodies (a steepest-ascent climb over each
// body's vertices from the colliding pairs, exit distances found by walking over the other
// body's facing faces, edge crossings near the top), history for thin features, and a held
// plane when the probe has passed through a feature it entered. This file is the round
// (Patch::build() and its steps) and the per-body state; the segment kernel is in
// contact_segments.cpp, the surface walk in surface_walk.cpp, the contact regions in
// contact_regions.cpp and the depth search in contact_depth.cpp.
//
// References: the vector area of a surface patch is ½∮x×dx over its boundary (Stokes); the
// gradient of the intersection volume of two bodies with respect to a translation is the vector
// area of the part of one body's surface inside the other (Faure et al. 2008, "Image-based
// collision detection and response between arbitrary volume objects", SCA, use the same
// volume-gradient direction); directional penetration depth along a fixed direction follows
// Kim, Lin & Manocha 2002 ("Fast penetration depth estimation using rasterization hardware and
// hierarchical refinement"), here on the contact patch only.
#include <spheretouch/geom/contact_patch.hpp>

#include <spheretouch/geom/contact_planes.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/contact_depth.hpp>
#include <spheretouch/geom/contact_segments.hpp>
#include <spheretouch/geom/surface_walk.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

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
// The model.

namespace {

/// Vector area below this fraction of the colliding object faces' area is noise, not a direction.
constexpr double kTinyArea = 1e-9;

/// Steps of the probe's support climb under a plane (Patch::probe_support): a fine ball's pole is
/// ~20 steps from its rim.
constexpr int kMaxSupportSteps = 256;
/// Two planar clusters face each other when each one's centroid is this far above the other's
/// plane, mm (a concave contact; rounding aside, coplanar clusters are one).
constexpr double kConcaveSlackMm = 1e-6;
/// Steps the held contact's walk may take from last round's face: a slide of a few face widths a
/// round (fast motion over a fine mesh).
constexpr int kMaxHoldSteps = 256;
/// A held contact lasts at most this fraction of the probe's bounding radius past the edge of the
/// surface it entered (Patch::hold_margin).
constexpr double kHoldMarginOfProbe = 0.25;

/// Unit normal n of a triangle, its unnormalised normal cr = (b−a)×(c−a) and |cr|; false when
/// degenerate (kDegenerateRel) or non-finite.
bool unit_normal(const Vec3& a, const Vec3& b, const Vec3& c, Vec3& n, Vec3& cr, double& len) {
  cr = (b - a).cross(c - a);
  const double longest2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  len = cr.norm();
  if (!std::isfinite(len) || !(len > kDegenerateRel * longest2)) return false;
  n = cr * (1 / len);  // one division (divisions are slow here, and this runs per colliding face)
  return true;
}

}  // namespace

void PatchBody::reset(const Mesh& m) {
  vf = VertexFaces::build(m);
  mesh = &m;
  nv = m.local.size();
  nf = m.faces.size();
  visit_stamp.assign(nv, 0);
  vertex_mark.assign(nv, 0);
  vertex_stamp = 0;
  cover_count.assign(nv, 0);
  path_stamp.assign(nv, 0);
  depth.assign(nv, 0);
  exit_face.assign(nv, UINT32_MAX);
  face_mark.assign(nf, {});
  memory = {};
  face_normals.clear();
  clear_store();
  n_groups = 0;
}

void PatchBody::clear_store() {
  store.clear();
  store_seen.clear();
  store_free.clear();
  entry.clear();
  prev_entry.clear();
  to_fill.clear();
  fixed_epoch = 0;
}

void PatchBody::compute_face_normals() {
  face_normals.assign(nf, Vec3::Zero());
  Vec3 n, cr;
  double len;
  for (std::size_t f = 0; f < nf; ++f) {
    const Tri& t = mesh->faces[f];
    if (t[0] < nv && t[1] < nv && t[2] < nv &&
        unit_normal(mesh->local[t[0]], mesh->local[t[1]], mesh->local[t[2]], n, cr, len))
      face_normals[f] = n;
  }
}

void PatchBody::begin_round() {
  faces.clear();
  to_fill.clear();
  std::swap(entry, prev_entry);
  entry.clear();
}

void PatchBody::settle(std::uint32_t epoch) {
  ST_ASSERT(entry.size() == faces.size(), "an entry per slot");
  for (std::uint32_t slot = 0; slot < entry.size(); ++slot) {
    std::uint32_t& e = entry[slot];
    if (e != UINT32_MAX) {
      ST_ASSERT(e < prev_entry.size(), "a face seen again has last round's slot");
      e = prev_entry[e];  // collided last round: its entry stays
    } else {              // new: a fresh entry, filled from the mesh with the records
      if (store_free.empty()) {
        e = static_cast<std::uint32_t>(store.size());
        store.emplace_back();
        store_seen.push_back(0);
      } else {
        e = store_free.back();
        store_free.pop_back();
      }
      store[e].covered = false;  // (filled later: a round may end before)
      to_fill.push_back(slot);
    }
    store_seen[e] = epoch;
  }
  for (std::uint32_t e : prev_entry) {  // last round's faces that collide no more
    if (store_seen[e] == epoch) continue;
    store_free.push_back(e);
    const Fixed& fx = store[e];
    if (fx.covered && !fx.bad_index)
      for (std::uint32_t v : fx.vid) {
        ST_ASSERT(cover_count[v] > 0, "a covered face was counted at its vertices");
        --cover_count[v];
      }
  }
}

void PatchBody::fill_new() {
  for (std::uint32_t slot : to_fill) make_fixed(fixed(slot), faces[slot]);
}

void PatchBody::cover_all() {
  for (std::uint32_t slot = 0; slot < faces.size(); ++slot) {
    Fixed& fx = fixed(slot);
    if (fx.covered) continue;
    fx.covered = true;
    if (!fx.bad_index)
      for (std::uint32_t v : fx.vid) ++cover_count[v];
  }
}

void PatchBody::make_fixed(Fixed& fx, std::uint32_t f) const {
  const Tri& t = mesh->faces[f];
  FaceRec& r = fx.rec;
  fx.vid = t;
  fx.group = UINT32_MAX;
  fx.covered = false;
  fx.bad_index = !(t[0] < nv && t[1] < nv && t[2] < nv);
  fx.len = 0;
  r.n.setZero();
  r.c = 0;
  if (fx.bad_index) {
    r.v[0] = r.v[1] = r.v[2] = Vec3::Zero();
    return;
  }
  for (int k = 0; k < 3; ++k) r.v[k] = mesh->local[t[k]];
  Vec3 cr;
  if (!face_normals.empty())
    r.n = face_normals[f];  // computed once per mesh (the probe's; zero: degenerate)
  else if (!unit_normal(r.v[0], r.v[1], r.v[2], r.n, cr, fx.len))
    r.n.setZero(), fx.len = 0;
  ST_ASSERT(r.n.squaredNorm() == 0 || std::abs(r.n.squaredNorm() - 1) < 1e-9, "a unit normal, or zero (degenerate)");
  r.c = r.n.dot(r.v[0]);
}

void PatchBody::clear_stamps() {
  std::fill(visit_stamp.begin(), visit_stamp.end(), 0);
  std::fill(cover_count.begin(), cover_count.end(), 0);  // the store is emptied below
  std::fill(face_mark.begin(), face_mark.end(), Mark{});
  clear_store();
}

std::size_t PatchBody::bytes() const {
  return vf.bytes() +
         (visit_stamp.capacity() + path_stamp.capacity() + exit_face.capacity() + cover_count.capacity() +
          2 * face_mark.capacity() + faces.capacity() + group_sets.capacity() + 2 * group_table.capacity() +
          group_label.capacity() + group_remap.capacity() + group_first.capacity()) *
             4 +
         (depth.capacity() + group_box.capacity() + vertex_mark.capacity()) * sizeof(double) + group_open.capacity() +
         group_attached.capacity() + recs.capacity() * sizeof(FaceRec) + use.capacity() + store.capacity() * sizeof(Fixed) +
         (store_seen.capacity() + store_free.capacity() + entry.capacity() + prev_entry.capacity() + to_fill.capacity()) * 4 +
         face_normals.capacity() * sizeof(Vec3);
}

void ContactBuilder::Patch::prepare(const Mesh& probe, const Mesh& object) {
  if (!probe_s.sized_for(probe)) {
    probe_s.reset(probe);
    probe_s.compute_face_normals();
    probe_world.assign(probe_s.nv, Vec3::Zero());
    probe_xform_stamp.assign(probe_s.nv, 0);
    epoch = 0;
    const Box b = probe.local_bounds();
    double r2 = 0;  // the probe's bounding radius about its bounds' centre, squared
    if (!b.empty())
      for (const Vec3& v : probe.local) r2 = std::max(r2, (v - b.centre()).squaredNorm());
    hold_margin = std::min(config.hold_margin_mm, kHoldMarginOfProbe * std::sqrt(r2));
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
  return probe_s.bytes() + object_s.bytes() + probe_world.capacity() * sizeof(Vec3) +
         (probe_xform_stamp.capacity() + climb.capacity() + seed_pairs.capacity()) * 4 +
         (valid.capacity() + canonical.capacity()) * sizeof(ContactPair) + valid_slots.capacity() * 8;
}

const Vec3& ContactBuilder::Patch::probe_point(std::uint32_t v, const Mesh& probe) {
  ST_ASSERT(v < probe_world.size() && v < probe.local.size(), "a vertex of the probe");
  if (probe_xform_stamp[v] != epoch) {
    probe_xform_stamp[v] = epoch;
    probe_world[v] = rot * probe.local[v] + shift;
  }
  return probe_world[v];
}

bool ContactBuilder::Patch::hold(const Mesh& probe, const Mesh& object, ContactModel& m) {
  if (!held_valid || held_face >= object.faces.size()) return false;
  // The tracked probe point (the deepest one when the contact was last rendered), object-local,
  // located under the entered surface by a walk over its faces that face held_n, from the face
  // found last round (a slide moves it a face or a few).
  const Vec3 x = rot * held_tracked + shift;
  SurfaceWalk walk;
  walk.mesh = &object;
  walk.vf = &object_s.vf;
  walk.set_direction(held_n);
  std::uint32_t face = held_face, last = held_face;
  double depth = 0;
  if (!walk.exit(x, face, depth, kMaxHoldSteps, &last)) {
    // Past the surface's edge (or a turn of more than ~85°): held within hold_margin of the last
    // face walked, its plane extended.
    if (last == UINT32_MAX || !walk.near_face(x, last, hold_margin, depth)) return false;
    face = last;
  }
  if (!(depth > 0)) return false;  // clear on the entry side
  ST_ASSERT(face < object.faces.size(), "the held face is an object face");
  held_face = face;
  const Vec3 on_surface = x + depth * held_n;
  m.flags |= kInContact | kHeld | kNormalFallback;
  m.force_dir = to_pod(held_n);
  m.penetration_mm = depth;
  m.nearest_object_face = face;
  m.probe_point = to_pod(held_tracked + probe.origin);
  m.plane_point = to_pod(on_surface + object.origin);
  m.contact_point = m.plane_point;
  m.pressure_point = m.contact_point;
  have_prev = true;
  prev_n = held_n;
  return true;
}

Vec3 ContactBuilder::Patch::curve_point() const {
  // The pairs are in canonical order, so the point is a function of the pair set (FirstSegment
  // measures from the common frame's origin, a body's centre).
  FirstSegment first;
  for (const auto& [slot_a, slot_b] : valid_slots) {
    if (first.found()) break;
    const std::uint8_t use_a = object_s.use[slot_a];
    if (use_a == kNoDirection || probe_s.use[slot_b] == kNoDirection) continue;
    if (have_prev && use_a != kFront) continue;
    first.add(&common_rec(object_s, slot_a), &common_rec(probe_s, slot_b));
  }
  first.finish();
  ST_ASSERT(first.midpoint().allFinite(), "the curve point is finite (segments of unit normals)");
  return first.midpoint();
}

double ContactBuilder::Patch::probe_support(const Mesh& probe, const Vec3& normal, double offset, std::uint32_t& vertex) {
  // The probe's deepest point under the plane x·normal = offset: a steepest ascent of
  // h(v) = offset − normal·x(v) over the probe's vertex graph, from the best vertex of the
  // colliding probe faces (exact for a convex probe: h is linear; a local maximum near the
  // contact otherwise, which is the one that matters).
  const std::size_t nv = probe_s.nv;
  double best = -std::numeric_limits<double>::infinity();
  vertex = UINT32_MAX;
  for (std::uint32_t f : probe_s.faces)
    for (std::uint32_t v : probe.faces[f])
      if (v < nv) {
        const double h = offset - normal.dot(probe_point(v, probe));
        if (h > best) best = h, vertex = v;
      }
  for (int step = 0; vertex != UINT32_MAX && step < kMaxSupportSteps; ++step) {
    std::uint32_t next = UINT32_MAX;
    for (std::uint32_t k = probe_s.vf.first[vertex]; k < probe_s.vf.first[vertex + 1]; ++k)
      for (std::uint32_t w : probe.faces[probe_s.vf.faces[k]])
        if (w < nv && w != vertex) {
          const double h = offset - normal.dot(probe_point(w, probe));
          if (h > best) best = h, next = w;
        }
    if (next == UINT32_MAX) break;
    vertex = next;
  }
  return best;
}

bool ContactBuilder::Patch::clear_planes(const Mesh& probe, Vec3& n, double& pd, Vec3& tracked_local, Vec3& plane_pt) {
  // The colliding object faces that give a direction, as planar clusters (object-local).
  PlaneClusters& pc = planes;
  pc.clear();
  for (std::uint32_t i = 0; i < object_s.faces.size() && !pc.overflow; ++i) {
    if (object_s.use[i] == kNoDirection || (have_prev && object_s.use[i] != kFront)) continue;
    const FaceRec& r = object_s.fixed(i).rec;
    pc.add(r.n, (r.v[0] + r.v[1] + r.v[2]) / 3);
  }
  if (!pc.concave(kConcaveSlackMm)) return false;
  std::array<Vec3, 4> normal{};
  std::array<double, 4> depth{};
  std::array<std::uint32_t, 4> vertex{};
  for (int i = 0; i < pc.n; ++i) {
    normal[i] = pc.c[i].normal;
    depth[i] = probe_support(probe, pc.c[i].normal, pc.c[i].offset, vertex[i]);
    if (vertex[i] == UINT32_MAX || !std::isfinite(depth[i])) return false;
  }
  bool ok = false;
  const Vec3 t = smallest_clearing(normal, depth, pc.n, ok);
  const double len = t.norm();
  if (!ok || !(len > 0) || !std::isfinite(len)) return false;
  n = t / len;
  pd = len;
  // The tracked point: the support vertex of the deepest plane that t holds tight (its depth
  // reached, to rounding); the plane model's depth there is PD at this pose.
  int k = 0;
  for (int i = 1; i < pc.n; ++i)
    if (depth[i] - normal[i].dot(t) > depth[k] - normal[k].dot(t) - 1e-12 && depth[i] > depth[k]) k = i;
  const Vec3 x = probe_point(vertex[k], probe);
  tracked_local = probe.local[vertex[k]];
  plane_pt = x + len * n;
  return true;
}

ContactModel ContactBuilder::Patch::build(const Mesh& probe, const Mesh& object, const Pose& pose,
                                          std::span<const ContactPair> pairs) {
  prepare(probe, object);
  const std::size_t given = pairs.size();
  pairs = in_order(pairs);
  next_epoch();
  ContactModel m;
  m.pose = to_pod(pose);
  m.pairs = static_cast<std::uint32_t>(std::min<std::size_t>(given, UINT32_MAX));
  const bool pose_ok = pose.matrix().allFinite();
  if (!pose_ok) m.flags |= kBadInput;
  take_pairs(probe, object, pairs, m);
  if (!pose_ok) {
    reset();
    return m;
  }
  set_pose(probe, object, pose);
  const FaceNormals faces = make_records(m);
  const CurveArea curve = vector_area();
  Vec3 n = Vec3::Zero();
  if (!force_direction(m, curve, faces, n)) {
    // Held contact: the probe has passed through a feature it entered (or only touches the
    // feature's far side): the force keeps pushing back out of the surface it entered while the
    // tracked point is under it (a surface-constrained proxy).
    if (hold(probe, object, m)) return m;
    reset();
    return m;
  }
  Vec3 tracked_local;  // the probe point PD is measured at, probe-local
  std::uint32_t face = UINT32_MAX;
  if (penetration(probe, object, n, m, tracked_local, face)) {
    keep_contact(n, tracked_local, face);
    m.pressure_point = pressure_point(object, to_eigen(m.force_dir), m.plane_point);
  }
  return m;
}

std::span<const ContactPair> ContactBuilder::Patch::in_order(std::span<const ContactPair> pairs) {
  // The model is a function of the set of pairs, not of their order (the collision core's order
  // differs from the scatter-gather merge's, and with it the worker count): pairs are taken in
  // (probe, object) order, each once. The collision paths deliver them so (a linear check);
  // others are sorted here, into scratch.
  const auto not_increasing = [](const ContactPair& a, const ContactPair& b) { return !(a < b); };
  if (std::adjacent_find(pairs.begin(), pairs.end(), not_increasing) == pairs.end()) return pairs;
  canonical.assign(pairs.begin(), pairs.end());
  std::sort(canonical.begin(), canonical.end());
  canonical.erase(std::unique(canonical.begin(), canonical.end()), canonical.end());
  return canonical;
}

void ContactBuilder::Patch::next_epoch() {
  if (++epoch == 0) {  // stamps wrapped: clear them once every 2^32 rounds
    std::fill(probe_xform_stamp.begin(), probe_xform_stamp.end(), 0);
    probe_s.clear_stamps();
    object_s.clear_stamps();
    epoch = 1;
  }
}

void ContactBuilder::Patch::take_pairs(const Mesh& probe, const Mesh& object, std::span<const ContactPair> pairs,
                                       ContactModel& m) {
  valid.clear();
  valid_slots.clear();
  // A face that collided in the last round (when its entries were filled) keeps its fixed part
  // where it is (PatchBody::see, settle). Returns the face's slot. The face of the pair before
  // is answered without reading its mark: the collision core lists a leaf pair's pairs
  // together, so about half the pairs repeat the object face of the pair before them (the
  // marks, over the whole mesh, are read at random).
  struct Last {
    std::uint32_t face = UINT32_MAX, slot = 0;
  } last_probe, last_object;
  auto first_sight = [&](PatchBody & b, Last & last, std::uint32_t f) __attribute__((always_inline)) {
    if (f != last.face) last = {f, b.see(f, epoch)};
    return last.slot;
  };
  probe_s.begin_round();
  object_s.begin_round();
  for (const ContactPair& p : pairs) {
    if (p.probe >= probe.faces.size() || p.object >= object.faces.size()) {
      ++m.skipped_pairs;
      continue;
    }
    valid.push_back(p);
    const std::uint32_t probe_slot = first_sight(probe_s, last_probe, p.probe);
    valid_slots.push_back({first_sight(object_s, last_object, p.object), probe_slot});
  }
  probe_s.settle(epoch);
  object_s.settle(epoch);
  if (m.skipped_pairs) m.flags |= kBadInput;
  m.probe_faces = static_cast<std::uint32_t>(probe_s.faces.size());
  m.object_faces = static_cast<std::uint32_t>(object_s.faces.size());
  m.contacts = m.probe_faces + m.object_faces;
}

void ContactBuilder::Patch::set_pose(const Mesh& probe, const Mesh& object, const Pose& pose) {
  // Probe vertices in object-local coordinates, each transformed once per round:
  // x = R·local + (R·probe.origin + t - object.origin) (no large offsets in the sum).
  rot = pose.linear();
  shift = rot * probe.origin + pose.translation() - object.origin;
}

ContactBuilder::Patch::FaceNormals ContactBuilder::Patch::make_records(ContactModel& m) {
  // One record per colliding face: vertices, unit normal (zero: degenerate, no direction) and
  // plane offset, in a common frame: the local frame of the body with more colliding faces, whose
  // records are then their fixed parts as they are (kept from round to round); the other body's
  // are moved into it. Degenerate object faces count as contacts but give no direction.
  const Eigen::Matrix3d& R = rot;
  probe_frame = probe_s.faces.size() > object_s.faces.size();
  // A record moved: x' = M·x + t (object-local → probe-local, or probe-local → object-local).
  const Eigen::Matrix3d M = probe_frame ? Eigen::Matrix3d(R.transpose()) : R;
  const Vec3 t = probe_frame ? Vec3(-(R.transpose() * shift)) : shift;
  auto move = [&](const FaceRec& from, FaceRec& r) {
    for (int k = 0; k < 3; ++k) r.v[k] = M * from.v[k] + t;
    r.n = M * from.n;  // zero stays zero (degenerate)
    r.c = r.n.dot(r.v[0]);
  };
  FaceNormals faces;  // Σ unnormalised normals: 2 × the area-weighted mean normal (fallback), Σ lengths
  probe_s.fill_new();
  object_s.fill_new();
  object_s.use.resize(object_s.faces.size());
  if (probe_frame) object_s.recs.resize(object_s.faces.size());
  for (std::uint32_t i = 0; i < object_s.faces.size(); ++i) {
    const PatchBody::Fixed& fx = object_s.fixed(i);
    object_s.use[i] = kNoDirection;
    if (fx.bad_index || fx.rec.n.squaredNorm() == 0) {
      ++m.degenerate_faces;
      continue;
    }
    if (probe_frame) move(fx.rec, object_s.recs[i]);
    object_s.use[i] = have_prev && fx.rec.n.dot(prev_n) > kBackCos ? kFront : kUsable;
    faces.sum += fx.len * fx.rec.n;
    faces.abs_sum += fx.len;
  }
  object_s.fixed_epoch = epoch;
  if (m.degenerate_faces) m.flags |= kDegenerateSkipped;
  probe_s.use.resize(probe_s.faces.size());
  if (!probe_frame) probe_s.recs.resize(probe_s.faces.size());
  for (std::uint32_t i = 0; i < probe_s.faces.size(); ++i) {
    const PatchBody::Fixed& fx = probe_s.fixed(i);
    probe_s.use[i] = kNoDirection;
    if (fx.bad_index) continue;
    if (!probe_frame) move(fx.rec, probe_s.recs[i]);
    probe_s.use[i] = fx.rec.n.squaredNorm() == 0 ? kNoDirection : kUsable;
  }
  probe_s.fixed_epoch = epoch;
  return faces;
}

PodVec3 ContactBuilder::Patch::pressure_point(const Mesh& object, const Vec3& n, const PodVec3& plane) const {
  // The curve's sums are in the common frame: FD goes into it, the centre comes out of it. The
  // centre's component along n depends on the fan's origin (and moves no torque: the force is
  // along n), so it is taken from the contact plane: a point on the plane, under the patch.
  const Vec3 nc = probe_frame ? Vec3(rot.transpose() * n) : n;
  Vec3 c;
  if (!curve_sums.area_centroid(nc, c)) {
    if (!(curve_sums.length() > 0)) return plane;
    c = curve_sums.centroid();
  }
  const Vec3 p = to_eigen(plane) - object.origin;  // object-local, as the centre
  Vec3 local = probe_frame ? Vec3(rot * c + shift) : c;
  local -= (local - p).dot(n) * n;
  return local.allFinite() ? to_pod(local + object.origin) : plane;
}

ContactBuilder::Patch::CurveArea ContactBuilder::Patch::vector_area() {
  // The vector area of the object surface inside the probe, from the intersection curve:
  // A = ½ Σ (s0 − o) × (s1 − o) over the pairs' segments, four pairs at a time (segments4), in
  // the common frame (turned into the object's after): while contact continues, only the part on
  // faces not turned away from the previous FD (front); at first contact all of it.
  CurveArea out;
  SegmentAreaSum sums(curve_point());
  const PatchBody::Fixed* object_store = object_s.store.data();
  const PatchBody::Fixed* probe_store = probe_s.store.data();
  const std::uint32_t* object_entry = object_s.entry.data();
  const std::uint32_t* probe_entry = probe_s.entry.data();
  const FaceRec* object_recs = object_s.recs.data();
  const FaceRec* probe_recs = probe_s.recs.data();
  for (const auto& [slot_a, slot_b] : valid_slots) {
    const std::uint8_t use_a = object_s.use[slot_a];
    if (use_a == kNoDirection || probe_s.use[slot_b] == kNoDirection) continue;  // degenerate: no direction
    const bool front = use_a == kFront;
    out.any_front_face |= front;
    if (have_prev && !front) continue;  // with history only the front part is used
    sums.add(probe_frame ? &object_recs[slot_a] : &object_store[object_entry[slot_a]].rec,
             probe_frame ? &probe_store[probe_entry[slot_b]].rec : &probe_recs[slot_b]);
  }
  sums.finish();
  out.area = sums.area();  // the front part's with history, else all of it
  if (probe_frame) out.area = rot * out.area;
  out.abs_sum = sums.abs_sum();
  curve_sums = sums;
  return out;
}

bool ContactBuilder::Patch::force_direction(ContactModel& m, const CurveArea& curve, const FaceNormals& faces, Vec3& n) {
  // FD: the front part of the curve while contact continues (thin plates, wedges), all of it at
  // first contact; then the fallbacks.
  bool in_contact = !valid.empty() && m.degenerate_faces < m.object_faces;
  if (in_contact && have_prev && !curve.any_front_face) in_contact = false;  // only back faces: past a thin feature
  if (in_contact) {
    const Vec3& a = curve.area;
    const double a_norm = a.norm();
    // A curve of (nearly) no area is rounding noise (faces touching at a vertex or an edge): its
    // direction is arbitrary. kTinyArea of the colliding faces' area is far below any real
    // penetration (a ball pressed 1e-6 of its radius already has ~1e-5 of its face area inside).
    const bool tiny = !(a_norm > kTinyArea * 0.5 * faces.abs_sum);
    if (curve.abs_sum > 0 && a_norm > kCancelRatio * curve.abs_sum && std::isfinite(a_norm) && !tiny) {
      n = a / a_norm;
    } else {
      m.flags |= kNormalFallback;
      if (curve.abs_sum > 0 && !tiny) m.flags |= kNormalsDisagree;
      if (have_prev)
        n = prev_n;
      else if (faces.sum.norm() > kCancelRatio * faces.abs_sum)
        n = faces.sum.normalized();
      else
        in_contact = false;
    }
  }
  ST_ASSERT(!in_contact || std::abs(n.squaredNorm() - 1) < 1e-9, "FD is a unit vector");
  return in_contact;
}

bool ContactBuilder::Patch::penetration(const Mesh& probe, const Mesh& object, Vec3& n, ContactModel& m,
                                        Vec3& tracked_local, std::uint32_t& face) {
  // PD: directional penetration depth along n, both ways: probe points inside the object leave
  // along +n through the object's faces that face +n; object points inside the probe leave along
  // −n through the probe's faces that face −n.
  const Deepest dp = DepthSearch(*this, true, n).run();
  const Deepest dobj = DepthSearch(*this, false, -n).run();
  m.inside_probe_vertices = dp.inside;
  m.inside_object_vertices = dobj.inside;
  if (dp.capped || dobj.capped) m.flags |= kInsideCapped;
  m.flags |= kInContact;
  m.force_dir = to_pod(n);

  // The point PD is measured at, fixed on the probe, and the plane through the surface there.
  Vec3 plane_pt;  // object-local plane point
  if (dp.depth > 0 && dp.depth >= dobj.depth) {
    m.penetration_mm = dp.depth;
    m.deepest_probe_vertex = dp.vertex;
    m.nearest_object_face = dp.face;
    tracked_local = rot.transpose() * (dp.point - shift);
    plane_pt = dp.point + dp.depth * n;
  } else if (dobj.depth > 0) {
    // An object point is deepest: the probe point is where it leaves the probe (along −n), a
    // point fixed on the probe; the plane passes through the object point.
    m.penetration_mm = dobj.depth;
    const Vec3 e = dobj.point - dobj.depth * n;
    tracked_local = rot.transpose() * (e - shift);
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
      return false;
    }
    m.deepest_probe_vertex = lv;
    tracked_local = probe.local[lv];
    plane_pt = probe_point(lv, probe);
  }
  // A concave contact (planar clusters of faces that face each other: a crease, an inner
  // corner, a pocket): the way out must clear every wall, and the smallest translation that does
  // is not along the summed normal (PD along it overestimated the way out by up to 0.11 mm in an
  // inner corner circled 0.4-3.6 mm deep). FD and PD become that translation (flag kPlanes).
  if (Vec3 nq, tq, pq; true) {
    double dq = 0;
    if (clear_planes(probe, nq, dq, tq, pq)) {
      n = nq;
      m.force_dir = to_pod(n);
      m.penetration_mm = dq;
      tracked_local = tq;
      plane_pt = pq;
      m.flags |= kPlanes;
    }
  }
  ST_ASSERT(m.penetration_mm >= 0, "PD >= 0");
  m.probe_point = to_pod(tracked_local + probe.origin);
  m.plane_point = to_pod(plane_pt + object.origin);
  m.contact_point = m.plane_point;
  face = dp.depth > 0 && dp.depth >= dobj.depth ? dp.face : UINT32_MAX;
  return true;
}

void ContactBuilder::Patch::keep_contact(const Vec3& n, const Vec3& tracked_local, std::uint32_t face) {
  // The surface a held contact is measured against: the face the deepest point leaves through,
  // or a colliding object face that faces n.
  held_face = face;
  for (std::uint32_t i = 0; held_face == UINT32_MAX && i < object_s.faces.size(); ++i)
    if (object_s.use[i] != kNoDirection && object_s.fixed(i).rec.n.dot(n) > kFrontCos) held_face = object_s.faces[i];
  ST_ASSERT(held_face == UINT32_MAX || held_face < object_s.nf, "the held face is an object face");
  have_prev = true;
  prev_n = n;
  held_valid = true;
  held_n = n;
  held_tracked = tracked_local;
}

}  // namespace st::geom
