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
#include <utility>

#include "geom/check.hpp"
#include "geom/contact_segments.hpp"
#include "geom/surface_walk.hpp"

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
// The model.

namespace {

/// Faces grouped afresh (not from the last grouping) when more than 1 in this many are new since
/// then: joining a new face looks at the ~18 faces around its corners, a fresh grouping at the
/// 3 corners of every face.
constexpr std::uint32_t kFreshGrouping = 6;
constexpr std::uint32_t kNoGroup = UINT32_MAX;

/// BodyState::use: what a colliding face's record gives the segments.
constexpr std::uint8_t kNoDirection = 0;  ///< degenerate or bad vertex indices: no segment
constexpr std::uint8_t kUsable = 1;       ///< a unit normal
constexpr std::uint8_t kFront = 2;        ///< and (object faces) not turned away from the previous FD

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
/// A remembered maximum less than this share as deep as the deepest point found so far is not
/// climbed in every round (see Patch::side).
constexpr double kShallowShare = 0.5;
/// The patrol (Patch::side): one climb at a time from a pair of the whole patch, at most this
/// many steps per search for new regions, continued in the next search from where it stopped.
/// A climb from a region's rim to its peak takes ~50 steps at a 21 mm deep press of hand_L2 on
/// the elephant, ~1.5 µs each (vertices no recent round touched, the caches swept by the
/// collision round): 2 per side keep a search's cost to ~6 µs and finish such a climb within
/// ~25 searches (~100 rounds).
constexpr int kPatrolSteps = 2;
/// Golden-ratio step of the pairs the patrol starts from: the k-th climb starts from pair
/// ⌊frac(k·φ)·n⌋ of n, so successive ones spread evenly over the patch whatever n is.
constexpr double kPatrolStep = 0.6180339887498949;
/// Steps the held contact's walk may take from last round's face: a slide of a few face widths a
/// round (fast motion over a fine mesh).
constexpr int kMaxHoldSteps = 256;
/// Steps a walk may take from its start face: neighbouring vertices land within a face or two of
/// each other; a longer walk means the point is not over the patch.
constexpr int kMaxWalkSteps = 16;

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

void ContactBuilder::Patch::BodyState::reset(const Mesh& m) {
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

void ContactBuilder::Patch::BodyState::clear_store() {
  store.clear();
  store_seen.clear();
  store_free.clear();
  entry.clear();
  prev_entry.clear();
  to_fill.clear();
  fixed_epoch = 0;
}

void ContactBuilder::Patch::BodyState::compute_face_normals() {
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

// Inlined into the pairs' loop (Patch::take_pairs, its only caller), run for every colliding face: as little as
// possible besides the mark (read at random, a cache miss), so that many are in flight at once.
[[gnu::always_inline]] inline std::uint32_t ContactBuilder::Patch::BodyState::see(std::uint32_t f, std::uint32_t epoch) {
  Mark& mark = face_mark[f];
  if (mark.stamp != epoch) {
    const bool again = fixed_epoch != 0 && fixed_epoch == epoch - 1 && mark.stamp == epoch - 1;
    entry.push_back(again ? mark.slot : UINT32_MAX);  // last round's slot for now (settle)
    mark = {epoch, static_cast<std::uint32_t>(faces.size())};
    faces.push_back(f);
  }
  return mark.slot;
}

void ContactBuilder::Patch::BodyState::begin_round() {
  faces.clear();
  to_fill.clear();
  std::swap(entry, prev_entry);
  entry.clear();
}

void ContactBuilder::Patch::BodyState::settle(std::uint32_t epoch) {
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

void ContactBuilder::Patch::BodyState::fill_new() {
  for (std::uint32_t slot : to_fill) make_fixed(fixed(slot), faces[slot]);
}

void ContactBuilder::Patch::BodyState::cover_all() {
  for (std::uint32_t slot = 0; slot < faces.size(); ++slot) {
    Fixed& fx = fixed(slot);
    if (fx.covered) continue;
    fx.covered = true;
    if (!fx.bad_index)
      for (std::uint32_t v : fx.vid) ++cover_count[v];
  }
}

void ContactBuilder::Patch::BodyState::make_fixed(Fixed& fx, std::uint32_t f) const {
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

void ContactBuilder::Patch::BodyState::clear_stamps() {
  std::fill(visit_stamp.begin(), visit_stamp.end(), 0);
  std::fill(cover_count.begin(), cover_count.end(), 0);  // the store is emptied below
  std::fill(face_mark.begin(), face_mark.end(), Mark{});
  clear_store();
}

std::size_t ContactBuilder::Patch::BodyState::bytes() const {
  return vf.bytes() +
         (visit_stamp.capacity() + path_stamp.capacity() + exit_face.capacity() + cover_count.capacity() +
          2 * face_mark.capacity() + faces.capacity() + group_parent.capacity() + 2 * group_table.capacity() +
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

std::uint32_t ContactBuilder::Patch::group_faces(BodyState& T) {
  const auto n_slots = static_cast<std::uint32_t>(T.faces.size());
  std::vector<std::uint32_t>& label = T.group_label;
  std::vector<std::uint32_t>& parent = T.group_parent;  // union-find over labels
  std::vector<std::uint32_t>& remap = T.group_remap;
  label.assign(n_slots, kNoGroup);
  parent.clear();
  auto root = [&](std::uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  auto unite = [&](std::uint32_t a, std::uint32_t b) {
    a = root(a), b = root(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  };
  auto fresh = [&] {
    parent.push_back(static_cast<std::uint32_t>(parent.size()));
    return parent.back();
  };
  // The faces that were grouped last time keep their groups (renumbered from 0).
  remap.assign(T.n_groups, kNoGroup);
  std::uint32_t n_new = 0;
  for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
    const std::uint32_t g = T.fixed(slot).group;
    if (g >= T.n_groups) {
      ++n_new;
      continue;
    }
    if (remap[g] == kNoGroup) remap[g] = fresh();
    label[slot] = remap[g];
  }
  if (std::uint64_t(n_new) * kFreshGrouping > n_slots) {
    // Group every face afresh: union-find over the slots, each vertex remembering the first slot
    // it was seen in, in a small hash table (scratch, stays in cache; a per-vertex array would be
    // read at random over the whole mesh).
    parent.resize(n_slots);
    for (std::uint32_t i = 0; i < n_slots; ++i) parent[i] = label[i] = i;
    std::vector<std::uint64_t>& table = T.group_table;  // (vertex + 1) << 32 | slot; 0 = empty
    std::size_t size = 64;
    while (size < 6 * std::size_t(n_slots)) size *= 2;  // at most half full
    table.assign(size, 0);
    for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
      if (T.fixed(slot).bad_index) continue;
      for (std::uint32_t v : T.fixed(slot).vid) {
        const std::uint64_t key = std::uint64_t(v) + 1;
        for (std::size_t h = (v * 0x9E3779B97F4A7C15ull) >> 40 & (size - 1);; h = (h + 1) & (size - 1)) {
          if (table[h] == 0) {
            table[h] = key << 32 | slot;
            break;
          }
          if (table[h] >> 32 == key) {
            unite(std::uint32_t(table[h]), slot);
            break;
          }
        }
      }
    }
  } else {
    // A face new since then joins the colliding faces around its vertices (found through the
    // mesh's vertex-face lists and this round's face marks); alone, it starts a group.
    for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
      if (label[slot] != kNoGroup) continue;
      if (!T.fixed(slot).bad_index)
        for (std::uint32_t v : T.fixed(slot).vid)
          for (std::uint32_t k = T.vf.first[v]; k < T.vf.first[v + 1]; ++k) {
            const BodyState::Mark& mk = T.face_mark[T.vf.faces[k]];
            if (mk.stamp != epoch || mk.slot == slot || label[mk.slot] == kNoGroup) continue;
            if (label[slot] == kNoGroup)
              label[slot] = label[mk.slot];
            else
              unite(label[slot], label[mk.slot]);
          }
      if (label[slot] == kNoGroup) label[slot] = fresh();
    }
  }
  // Dense labels, kept with the faces for the next grouping.
  remap.assign(parent.size(), kNoGroup);
  std::uint32_t n = 0;
  for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
    const std::uint32_t r = root(label[slot]);
    if (remap[r] == kNoGroup) remap[r] = n++;
    T.fixed(slot).group = label[slot] = remap[r];
  }
  T.n_groups = n;
  return n;
}

std::uint32_t ContactBuilder::Patch::new_groups(BodyState& T) {
  const auto n_slots = static_cast<std::uint32_t>(T.faces.size());
  std::vector<std::uint32_t>& label = T.group_label;
  std::vector<std::uint32_t>& parent = T.group_parent;     // union-find over the new faces' slots
  std::vector<std::uint8_t>& attached = T.group_attached;  // per slot: its set shares a vertex with a covered face
  label.assign(n_slots, 0);
  parent.resize(n_slots);
  attached.assign(n_slots, 0);
  auto root = [&](std::uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  // A new face touches a covered one where its vertex has a covered colliding face around it
  // (T.cover_count); new faces sharing a vertex join (per vertex, this call's stamp and the
  // first new face's slot).
  std::vector<std::uint64_t>& mark = T.vertex_mark;
  if (++T.vertex_stamp == 0) {
    std::fill(mark.begin(), mark.end(), 0);
    T.vertex_stamp = 1;
  }
  const std::uint64_t stamp = std::uint64_t(T.vertex_stamp) << 32;
  for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
    const BodyState::Fixed& fx = T.fixed(slot);
    parent[slot] = slot;
    if (fx.covered || fx.bad_index) continue;
    for (std::uint32_t v : fx.vid) {
      if (T.cover_count[v] > 0) attached[slot] = 1;
      const std::uint64_t m = mark[v];
      if ((m >> 32) != T.vertex_stamp) {
        mark[v] = stamp | slot;
      } else {
        const std::uint32_t a = root(slot), b = root(std::uint32_t(m));
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
    }
  }
  // Labels: 0 the covered faces (and those with bad indices), 1 + n for the n-th set of new faces.
  std::vector<std::uint32_t>& remap = T.group_remap;
  remap.assign(n_slots, kNoGroup);
  std::uint32_t n = 1;
  for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
    const BodyState::Fixed& fx = T.fixed(slot);
    if (fx.covered || fx.bad_index) continue;
    const std::uint32_t r = root(slot);
    if (remap[r] == kNoGroup) remap[r] = n++;
    label[slot] = remap[r];
    if (attached[slot]) attached[r] = 1;
  }
  std::vector<std::uint8_t>& open = T.group_open;
  open.assign(n, 0);
  for (std::uint32_t slot = 0; slot < n_slots; ++slot)
    if (label[slot] != 0) open[label[slot]] = attached[root(slot)] ? 0 : 1;
  return n;
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
    // Past the surface's edge (or a turn of more than ~85°): held within hold_margin_mm of the
    // last face walked, its plane extended.
    if (last == UINT32_MAX || !walk.near_face(x, last, config.hold_margin_mm, depth)) return false;
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
  have_prev = true;
  prev_n = held_n;
  return true;
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

  // Exit distance of a vertex, walking from a face near it; once per vertex and round. The walk
  // starts from the face the vertex left through last round when it was evaluated then (the
  // probe moves little in a round: the walk takes no step), and from `hint`, a face near it,
  // when there is none or that walk fails (the face has turned away from d since).
  std::uint32_t evaluated = 0;
  auto eval = [&](std::uint32_t v, std::uint32_t hint) -> double {
    if (visit[v] == epoch) return depth[v];
    const std::uint32_t own = visit[v] == epoch - 1 ? exitf[v] : UINT32_MAX;
    visit[v] = epoch;
    depth[v] = -std::numeric_limits<double>::infinity();
    exitf[v] = UINT32_MAX;
    if (hint == UINT32_MAX) return depth[v];
    if (++evaluated > config.max_inside_vertices) {
      best.capped = true;
      return depth[v];
    }
    const Vec3 x = test_pos(v);
    std::uint32_t f = own;
    double dist = 0;
    if (own == UINT32_MAX || !walk.exit(x, f, dist, kMaxWalkSteps)) {
      f = hint;
      if (own == hint || !walk.exit(x, f, dist, kMaxWalkSteps)) return depth[v];
    }
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
  // Known for the next searches for new regions: local maxima found beyond the kSize deepest,
  // and a vertex of each group this search climbed from (its region is not new any more).
  std::uint32_t known[Memory::kKnown];
  int n_known = 0;
  auto drop = [&](std::uint32_t v) {
    if (n_known < Memory::kKnown) known[n_known++] = v;
  };
  if (climb_serial > 0xF0000000u) {  // serials about to wrap: forget every path (once per ~4e9 climbs)
    std::fill(probe_s.path_stamp.begin(), probe_s.path_stamp.end(), 0);
    std::fill(object_s.path_stamp.begin(), object_s.path_stamp.end(), 0);
    climb_serial = 0;
  }
  const std::uint32_t round_first = climb_serial + 1;
  // Remembers a local maximum (deepest first). Full: the shallowest gives way, or v is not kept.
  // (Only a slot already filled is compared: the old test read the last slot on the way to
  // filling it, uninitialised.)
  auto remember = [&](std::uint32_t v) {
    if (n_maxima == Memory::kSize && maxima_depth[Memory::kSize - 1] >= depth[v]) {
      drop(v);
      return;
    }
    if (n_maxima == Memory::kSize) drop(maxima[Memory::kSize - 1]);
    int i = n_maxima < Memory::kSize ? n_maxima++ : Memory::kSize - 1;
    maxima[i] = v;
    maxima_depth[i] = depth[v];
    for (; i > 0 && maxima_depth[i] > maxima_depth[i - 1]; --i)
      std::swap(maxima[i], maxima[i - 1]), std::swap(maxima_depth[i], maxima_depth[i - 1]);
  };
  // Returns where it stopped when it took max_steps steps without reaching a maximum or an
  // earlier path (UINT32_MAX: it ended).
  auto climb_from = [&](std::uint32_t v, int max_steps = std::numeric_limits<int>::max()) -> std::uint32_t {
    if (path[v] >= round_first) return UINT32_MAX;
    const std::uint32_t serial = ++climb_serial;
    for (int step = 0;; ++step) {
      if (step == max_steps) return v;
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
      if (best.capped) return UINT32_MAX;
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
      if (next == UINT32_MAX) {  // a local maximum
        remember(v);
        return UINT32_MAX;
      }
      // Next to an earlier climb's path: that climb has been up this slope already.
      if (joined) return UINT32_MAX;
      v = next;
    }
  };
  // Starts: last round's local maxima (from the faces they left through); the colliding pairs'
  // vertices lowest along d (over a flat surface the deepest; from the pair's face on the other
  // side); and a sample of the pairs whose offset turns every round, so a separate contact region
  // that neither found is found within a few rounds.
  //
  // A remembered maximum other than the deepest is climbed every round only while it is at least
  // kShallowShare as deep as the deepest point found so far (it could set PD); a shallower one
  // is kept as it is (its depth there still read every round) and climbed in a round that looks
  // for new regions (every kDiscoverEvery-th: the extra work then falls in rounds that have some
  // anyway, and the typical round's cost stays down), one of them in each such round in turn.
  climb.clear();
  bool remembered = false;
  const bool discover_round = epoch % kDiscoverEvery == 0;
  const int shallow_turn = 1 + int(epoch / kDiscoverEvery % (Memory::kSize - 1));
  bool lost = memory.lost;
  for (int i = 0; i < Memory::kSize; ++i) {
    const std::uint32_t v = memory.vertex[i];
    if (v < test_nv && memory.face[i] < surface.faces.size() && eval(v, memory.face[i]) > 0) {
      if (i == 0 || (discover_round && i == shallow_turn) || depth[v] >= kShallowShare * best.depth)
        climb_from(v);
      else if (path[v] < round_first)  // not on a path of this round (a climb's maximum is remembered there)
        remember(v);
      remembered = true;
    } else if (v != UINT32_MAX) {
      lost = true;
    }
  }
  // While the remembered maxima hold, new regions are looked for every kDiscoverEvery rounds
  // (a region starts at depth 0, so one found a few rounds late has not grown much): climbs
  // start from the colliding pairs' vertices lowest along d (over a flat surface the deepest)
  // and from a sample of the pairs whose offset turns every round. With nothing remembered from
  // the whole patch; otherwise only from the regions not followed yet. This body's colliding
  // faces fall into groups connected through shared vertices (a ring around each region the
  // other body entered). A new region brings faces that began colliding since the last search
  // (not `covered`): a group with none that a search has seen is a new region (new_groups).
  // Only once a remembered maximum has been lost (its region may be followed no more) are all
  // faces grouped (group_faces) and each group's extent across d checked for one of this
  // round's maxima (or a vertex known from the last searches) instead. With no new face and
  // nothing lost there is nothing to group. What this misses (a region that split from a
  // followed group, or a second peak inside one) is found by the patrol: one climb at a time
  // from a pair of the whole patch, a different pair each time (kPatrolStep), kPatrolSteps steps
  // per search and continued in the next. (A search over the whole patch at once cost ~10x a
  // round at ~1,000 contacts, its climbs from the rim mostly retracing the remembered ones.)
  const bool discover = !remembered || discover_round;
  const bool full = !remembered;
  std::vector<std::uint32_t>& open = seed_pairs;  // indices into valid
  open.clear();
  if (discover && full) {
    for (std::uint32_t i = 0; i < valid.size(); ++i) open.push_back(i);
  } else if (discover) {
    const auto n_slots = static_cast<std::uint32_t>(T.faces.size());
    bool any_new = false;
    for (std::uint32_t slot = 0; slot < n_slots && !any_new; ++slot) any_new = !T.fixed(slot).covered;
    if (any_new || lost) {
      const std::uint32_t n_groups = lost ? group_faces(T) : new_groups(T);
      const std::vector<std::uint32_t>& label = T.group_label;
      std::vector<std::uint32_t>& first = T.group_first;  // per group: a face of it (its first slot)
      first.assign(n_groups, UINT32_MAX);
      std::vector<std::uint8_t>& group_open = T.group_open;  // per group: a region not followed
      if (!lost) {                                           // new_groups said which are open
        for (std::uint32_t slot = 0; slot < n_slots; ++slot)
          if (first[label[slot]] == UINT32_MAX) first[label[slot]] = slot;
      } else {
        group_open.assign(n_groups, 1);
        // Each group's extent across d (from the records, in the common frame); open: none of
        // this round's maxima, nor a vertex known from the last searches, lies in it.
        const Vec3 uc = dir_to_common(walk.u), wc = dir_to_common(walk.w);
        std::vector<double>& box = T.group_box;  // per group: lo_u, hi_u, lo_w, hi_w
        box.resize(4 * std::size_t(n_groups));
        for (std::uint32_t g = 0; g < n_groups; ++g) {
          double* bx = &box[4 * std::size_t(g)];
          bx[0] = bx[2] = std::numeric_limits<double>::infinity(), bx[1] = bx[3] = -bx[0];
        }
        for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
          const std::uint32_t g = label[slot];
          if (first[g] == UINT32_MAX) first[g] = slot;
          if (T.use[slot] == kNoDirection) continue;  // no record (a moved one is not filled when degenerate)
          double* bx = &box[4 * std::size_t(g)];
          for (const Vec3& x : common_rec(T, slot).v) {
            const double xu = x.dot(uc), xw = x.dot(wc);
            bx[0] = std::min(bx[0], xu), bx[1] = std::max(bx[1], xu), bx[2] = std::min(bx[2], xw),
            bx[3] = std::max(bx[3], xw);
          }
        }
        for (std::uint32_t g = 0; g < n_groups; ++g) {
          const double* bx = &box[4 * std::size_t(g)];
          auto inside = [&](std::uint32_t v) {
            const Vec3 x = to_common(test_pos(v));
            const double xu = x.dot(uc), xw = x.dot(wc);
            return xu >= bx[0] && xu <= bx[1] && xw >= bx[2] && xw <= bx[3];
          };
          bool followed = false;
          for (int i = 0; i < n_maxima && !followed; ++i) followed = inside(maxima[i]);
          for (int i = 0; i < Memory::kKnown && !followed; ++i)
            followed = memory.known[i] < test_nv && inside(memory.known[i]);
          group_open[g] = followed ? 0 : 1;
        }
      }
      bool any_open = false;
      for (std::uint32_t g = 0; g < n_groups; ++g) {
        if (!group_open[g]) continue;
        any_open = true;
        if (!T.fixed(first[g]).bad_index) drop(T.fixed(first[g]).vid[0]);
      }
      for (std::uint32_t i = 0; i < valid.size() && any_open; ++i)
        if (group_open[label[valid_slots[i][probe_side ? 1 : 0]]]) open.push_back(i);
    }
  }
  std::uint32_t low_v[kLowSeeds], low_f[kLowSeeds];
  double low_key[kLowSeeds];
  int n_low = 0;
  for (std::uint32_t pi : open) {
    const ContactPair& p = valid[pi];
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
  const std::size_t stride = std::max<std::size_t>(1, open.size() / kSeedPairs);
  for (std::size_t i = (epoch / kDiscoverEvery) % stride; i < open.size(); i += stride) {
    const ContactPair& p = valid[open[i]];
    const std::uint32_t tf = probe_side ? p.probe : p.object, sf = probe_side ? p.object : p.probe;
    for (std::uint32_t v : test.faces[tf])
      if (v < test_nv && visit[v] != epoch && eval(v, sf) > 0) climb.push_back(v);
  }
  const bool searched = !climb.empty();  // climbs from regions not followed (their groups now known)
  std::sort(climb.begin(), climb.end(), [&](std::uint32_t a, std::uint32_t b) { return depth[a] > depth[b]; });
  for (std::uint32_t v : climb) climb_from(v);
  // The patrol: its climb goes on from where it stopped while that vertex is still inside, else
  // a new one starts from the deepest inside vertex of the next pair.
  std::uint32_t patrol = UINT32_MAX, patrol_face = UINT32_MAX, patrol_k = memory.patrol_k;
  if (discover && !full && !valid.empty()) {
    std::uint32_t v = memory.patrol;
    if (!(v < test_nv && memory.patrol_face < surface.faces.size() && eval(v, memory.patrol_face) > 0)) {
      const double k = patrol_k++;
      const std::size_t i =
          std::min(valid.size() - 1, std::size_t((k * kPatrolStep - std::floor(k * kPatrolStep)) * double(valid.size())));
      const std::uint32_t tf = probe_side ? valid[i].probe : valid[i].object;
      const std::uint32_t sf = probe_side ? valid[i].object : valid[i].probe;
      v = UINT32_MAX;
      for (std::uint32_t u : test.faces[tf])
        if (u < test_nv && eval(u, sf) > 0 && (v == UINT32_MAX || depth[u] > depth[v])) v = u;
    }
    if (v != UINT32_MAX) patrol = climb_from(v, kPatrolSteps);
    if (patrol != UINT32_MAX) patrol_face = exitf[patrol];
  } else {  // kept through the rounds between searches
    patrol = memory.patrol;
    patrol_face = memory.patrol_face;
  }
  const std::uint32_t deepest_vertex = best.vertex;
  const Memory last = memory;
  memory = Memory{};
  for (int i = 0; i < n_maxima; ++i) {
    memory.vertex[i] = maxima[i];
    memory.face[i] = exitf[maxima[i]];
  }
  memory.patrol = patrol;
  memory.patrol_face = patrol_face;
  memory.patrol_k = patrol_k;
  if (discover) {  // every colliding face has now been seen by a search; what was lost, looked for
    T.cover_all();
    lost = false;
  }
  memory.lost = lost;
  // What the last search that climbed from regions not followed knew.
  if (!searched)
    std::copy(std::begin(last.known), std::end(last.known), std::begin(memory.known));
  else
    std::copy(known, known + n_known, std::begin(memory.known));
  if (deepest_vertex != UINT32_MAX) best.point = test_pos(deepest_vertex);

  // Between vertices: the maximum of two piecewise-linear heights lies on a vertex of their
  // overlay, so also try where edges of this side cross the other side's edges along d: around
  // the deepest vertex, and over every colliding pair when the patch is small or no vertex is
  // inside (a convex edge of one body pressed into a face of the other between its vertices).
  std::uint32_t won_a = UINT32_MAX, won_b = UINT32_MAX;  // the test edge whose crossing won last
  // A surface face seen along d: its corners in the plane ⊥ d and their heights.
  struct Seen {
    std::uint32_t face;
    double pu[3], pw[3], ph[3];
  };
  // False when the face has a bad index or does not face d (a walk would not cross it).
  auto see = [&](std::uint32_t f, Seen& sn) {
    const Tri& t = surface.faces[f];
    const std::size_t surface_nv = surface.local.size();
    if (t[0] >= surface_nv || t[1] >= surface_nv || t[2] >= surface_nv) return false;
    const Vec3 p[3] = {walk.at(t[0]), walk.at(t[1]), walk.at(t[2])};
    sn.face = f;
    for (int k = 0; k < 3; ++k) sn.pu[k] = p[k].dot(walk.u), sn.pw[k] = p[k].dot(walk.w), sn.ph[k] = p[k].dot(walk.d);
    return SurfaceWalk::facing(
        (sn.pu[1] - sn.pu[0]) * (sn.pw[2] - sn.pw[0]) - (sn.pu[2] - sn.pu[0]) * (sn.pw[1] - sn.pw[0]), p[0], p[1], p[2]);
  };
  // Where test edge (ia, ib) crosses the edges of seen faces along d. A crossing lies on an edge
  // of a surface face that faces d, so the surface's height there is the edge's (no walk needed).
  auto refine_edge = [&](std::uint32_t ia, std::uint32_t ib, const Seen* seen, int n_seen) {
    const Vec3 a = test_pos(ia), b = test_pos(ib);
    const double au = a.dot(walk.u), aw = a.dot(walk.w), ah = a.dot(walk.d);
    const double ru = b.dot(walk.u) - au, rw = b.dot(walk.w) - aw, rh = b.dot(walk.d) - ah;
    for (int i = 0; i < n_seen; ++i) {
      const Seen& sn = seen[i];
      for (int e = 0; e < 3; ++e) {
        const int j = e == 2 ? 0 : e + 1;
        const double su = sn.pu[j] - sn.pu[e], sw = sn.pw[j] - sn.pw[e];
        const double den = ru * sw - rw * su;
        if (!(std::abs(den) > 0)) continue;  // parallel
        const double qu = sn.pu[e] - au, qw = sn.pw[e] - aw, inv = 1 / den;
        const double sa = (qu * sw - qw * su) * inv, r = (qu * rw - qw * ru) * inv;
        if (sa < 0 || sa > 1 || r < 0 || r > 1) continue;
        const double dist = (sn.ph[e] + r * (sn.ph[j] - sn.ph[e])) - (ah + sa * rh);
        if (dist > best.depth) {
          best.depth = dist;
          best.point = a + sa * (b - a);
          best.face = sn.face;
          best.vertex = UINT32_MAX;  // an edge point
          won_a = ia, won_b = ib;
        }
      }
    }
  };
  // Every edge of the faces around vertex c (once) against the faces its neighbourhood leaves
  // through.
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
    Seen seen[8];
    int n_seen = 0;
    for (int i = 0; i < n_near; ++i) n_seen += see(near[i], seen[n_seen]) ? 1 : 0;
    std::uint32_t done_a[48], done_b[48];  // edges crossed already (each is shared by two faces)
    int n_done = 0;
    for (std::uint32_t k = test_vf.first[c]; k < test_vf.first[c + 1]; ++k) {
      const Tri& t = test.faces[test_vf.faces[k]];
      if (t[0] >= test_nv || t[1] >= test_nv || t[2] >= test_nv) continue;
      for (int e = 0; e < 3; ++e) {
        const std::uint32_t ia = t[e], ib = t[e == 2 ? 0 : e + 1];
        bool done = false;
        for (int i = 0; i < n_done && !done; ++i) done = done_a[i] == ib && done_b[i] == ia;
        if (done) continue;
        if (n_done < 48) done_a[n_done] = ia, done_b[n_done++] = ib;
        refine_edge(ia, ib, seen, n_seen);
      }
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
      Seen sn;
      if (t[0] >= test_nv || t[1] >= test_nv || t[2] >= test_nv || !see(sf, sn)) continue;
      for (int e = 0; e < 3; ++e) refine_edge(t[e], t[(e + 1) % 3], &sn, 1);
    }
  }
  return best;
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
  if (penetration(probe, object, n, m, tracked_local, face)) keep_contact(n, tracked_local, face);
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
  // where it is (BodyState::see, settle). Returns the face's slot. The face of the pair before
  // is answered without reading its mark: the collision core lists a leaf pair's pairs
  // together, so about half the pairs repeat the object face of the pair before them (the
  // marks, over the whole mesh, are read at random).
  struct Last {
    std::uint32_t face = UINT32_MAX, slot = 0;
  } last_probe, last_object;
  auto first_sight = [&](BodyState & b, Last & last, std::uint32_t f) __attribute__((always_inline)) {
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
    const BodyState::Fixed& fx = object_s.fixed(i);
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
    const BodyState::Fixed& fx = probe_s.fixed(i);
    probe_s.use[i] = kNoDirection;
    if (fx.bad_index) continue;
    if (!probe_frame) move(fx.rec, probe_s.recs[i]);
    probe_s.use[i] = fx.rec.n.squaredNorm() == 0 ? kNoDirection : kUsable;
  }
  probe_s.fixed_epoch = epoch;
  return faces;
}

ContactBuilder::Patch::CurveArea ContactBuilder::Patch::vector_area() {
  // The vector area of the object surface inside the probe, from the intersection curve:
  // A = ½ Σ (s0 − o) × (s1 − o) over the pairs' segments, four pairs at a time (segments4), in
  // the common frame (turned into the object's after): while contact continues, only the part on
  // faces not turned away from the previous FD (front); at first contact all of it.
  CurveArea out;
  SegmentAreaSum sums(curve_point());
  const BodyState::Fixed* object_store = object_s.store.data();
  const BodyState::Fixed* probe_store = probe_s.store.data();
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

bool ContactBuilder::Patch::penetration(const Mesh& probe, const Mesh& object, const Vec3& n, ContactModel& m,
                                        Vec3& tracked_local, std::uint32_t& face) {
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
