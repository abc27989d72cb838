// SPDX-License-Identifier: BSD-3-Clause
// The patch contact model's depth search (DepthSearch, contact_depth.hpp): one side's directional
// penetration depth along FD, after Kim, Lin & Manocha 2002 ("Fast penetration depth estimation
// using rasterization hardware and hierarchical refinement"), here on the contact patch only: a
// steepest-ascent climb over one body's vertices from the colliding pairs, exit distances found by
// walking over the other body's facing faces, edge crossings near the top.
#include <spheretouch/geom/contact_depth.hpp>

#include <algorithm>
#include <cmath>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/contact_patch.hpp>
#include <spheretouch/geom/contact_regions.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

namespace {

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
/// climbed in every round (see climb_remembered()).
constexpr double kShallowShare = 0.5;
/// The patrol (patrol()): one climb at a time from a pair of the whole patch, at most this
/// many steps per search for new regions, continued in the next search from where it stopped.
/// A climb from a region's rim to its peak takes ~50 steps at a 21 mm deep press of hand_L2 on
/// the elephant, ~1.5 µs each (vertices no recent round touched, the caches swept by the
/// collision round): 2 per side keep a search's cost to ~6 µs and finish such a climb within
/// ~25 searches (~100 rounds).
constexpr int kPatrolSteps = 2;
/// Golden-ratio step of the pairs the patrol starts from: the k-th climb starts from pair
/// ⌊frac(k·φ)·n⌋ of n, so successive ones spread evenly over the patch whatever n is.
constexpr double kPatrolStep = 0.6180339887498949;
/// Steps a walk may take from its start face: neighbouring vertices land within a face or two of
/// each other; a longer walk means the point is not over the patch.
constexpr int kMaxWalkSteps = 16;

}  // namespace

DepthSearch::DepthSearch(ContactBuilder::Patch& patch, bool probe_side, const Vec3& d)
    : patch_(patch),
      probe_side_(probe_side),
      T_(probe_side ? patch.probe_s : patch.object_s),
      S_(probe_side ? patch.object_s : patch.probe_s),
      test_(*T_.mesh),
      surface_(*S_.mesh),
      test_vf_(T_.vf),
      test_nv_(T_.nv),
      epoch_(patch.epoch),
      d_(d),
      visit_(T_.visit_stamp),
      depth_(T_.depth),
      exitf_(T_.exit_face),
      path_(T_.path_stamp),
      memory_(T_.memory) {
  walk_.mesh = &surface_;
  walk_.vf = &S_.vf;
  walk_.patch = probe_side ? nullptr : &patch;
  walk_.set_direction(d);
}

// Starts: last round's local maxima (from the faces they left through); the colliding pairs'
// vertices lowest along d (over a flat surface the deepest; from the pair's face on the other
// side); and a sample of the pairs whose offset turns every round, so a separate contact region
// that neither found is found within a few rounds (open_pairs()).
Deepest DepthSearch::run() {
  ST_ASSERT(round_first_ == 0, "a search runs once");
  if (patch_.climb_serial > 0xF0000000u) {  // serials about to wrap: forget every path (once per ~4e9 climbs)
    std::fill(patch_.probe_s.path_stamp.begin(), patch_.probe_s.path_stamp.end(), 0);
    std::fill(patch_.object_s.path_stamp.begin(), patch_.object_s.path_stamp.end(), 0);
    patch_.climb_serial = 0;
  }
  round_first_ = patch_.climb_serial + 1;
  patch_.climb.clear();
  const bool discover_round = epoch_ % kDiscoverEvery == 0;
  lost_ = memory_.lost;
  const bool remembered = climb_remembered(discover_round);
  const bool discover = !remembered || discover_round;
  const bool full = !remembered;
  open_pairs(discover, full);
  const bool searched = climb_from_pairs();  // climbs from regions not followed (their groups now known)
  patrol(discover, full);
  const std::uint32_t deepest_vertex = best_.vertex;
  keep_memory(discover, searched);
  if (deepest_vertex != UINT32_MAX) best_.point = test_pos(deepest_vertex);

  // Between vertices: the maximum of two piecewise-linear heights lies on a vertex of their
  // overlay, so also try where edges of this side cross the other side's edges along d: around
  // the deepest vertex, and over every colliding pair when the patch is small or no vertex is
  // inside (a convex edge of one body pressed into a face of the other between its vertices).
  if (deepest_vertex != UINT32_MAX) follow_ridge(deepest_vertex);
  if (deepest_vertex == UINT32_MAX || patch_.valid.size() <= kRefineAllPairs) refine_pairs();
  ST_ASSERT(best_.depth >= 0 && std::isfinite(best_.depth), "the depth is finite and >= 0 (0: none inside)");
  ST_ASSERT(best_.depth == 0 || best_.face < surface_.faces.size(), "a point inside leaves through a surface face");
  ST_ASSERT(best_.vertex == UINT32_MAX || best_.vertex < test_nv_, "the deepest vertex is a vertex of the test body");
  return best_;
}

Vec3 DepthSearch::test_pos(std::uint32_t v) { return probe_side_ ? patch_.probe_point(v, test_) : test_.local[v]; }

// Exit distance of a vertex, walking from a face near it; once per vertex and round. The walk
// starts from the face the vertex left through last round when it was evaluated then (the
// probe moves little in a round: the walk takes no step), and from `hint`, a face near it,
// when there is none or that walk fails (the face has turned away from d since).
double DepthSearch::eval(std::uint32_t v, std::uint32_t hint) {
  ST_ASSERT(v < test_nv_, "a vertex of the test body");
  if (visit_[v] == epoch_) return depth_[v];
  const std::uint32_t own = visit_[v] == epoch_ - 1 ? exitf_[v] : UINT32_MAX;
  visit_[v] = epoch_;
  depth_[v] = -std::numeric_limits<double>::infinity();
  exitf_[v] = UINT32_MAX;
  if (hint == UINT32_MAX) return depth_[v];
  ST_ASSERT(hint < surface_.faces.size(), "the hint is a surface face");
  if (++evaluated_ > patch_.config.max_inside_vertices) {
    best_.capped = true;
    return depth_[v];
  }
  const Vec3 x = test_pos(v);
  std::uint32_t f = own;
  double dist = 0;
  if (own == UINT32_MAX || !walk_.exit(x, f, dist, kMaxWalkSteps)) {
    f = hint;
    if (own == hint || !walk_.exit(x, f, dist, kMaxWalkSteps)) return depth_[v];
  }
  depth_[v] = dist;
  exitf_[v] = f;
  if (dist > 0) {
    ++best_.inside;
    if (dist > best_.depth) {
      best_.depth = dist;
      best_.vertex = v;
      best_.face = f;
    }
  }
  return dist;
}

// Known for the next searches for new regions: local maxima found beyond the kSize deepest, and a
// vertex of each group this search climbed from (its region is not new any more).
void DepthSearch::drop(std::uint32_t v) {
  if (n_known_ < DepthMemory::kKnown) known_[n_known_++] = v;
}

// Remembers a local maximum (deepest first). Full: the shallowest gives way, or v is not kept.
// (Only a slot already filled is compared: the old test read the last slot on the way to
// filling it, uninitialised.)
void DepthSearch::remember(std::uint32_t v) {
  if (n_maxima_ == DepthMemory::kSize && maxima_depth_[DepthMemory::kSize - 1] >= depth_[v]) {
    drop(v);
    return;
  }
  if (n_maxima_ == DepthMemory::kSize) drop(maxima_[DepthMemory::kSize - 1]);
  int i = n_maxima_ < DepthMemory::kSize ? n_maxima_++ : DepthMemory::kSize - 1;
  maxima_[i] = v;
  maxima_depth_[i] = depth_[v];
  for (; i > 0 && maxima_depth_[i] > maxima_depth_[i - 1]; --i)
    std::swap(maxima_[i], maxima_[i - 1]), std::swap(maxima_depth_[i], maxima_depth_[i - 1]);
}

// Ascent over the vertex graph: the exit distance grows toward the deepest point, so the work
// is the length of the climb, not the number of vertices inside. Neighbours are tried in the
// order of their height along -d (the cheap part of the exit distance: exact over a flat
// surface), and the climb moves to the first that is deeper; it stops at a local maximum, or
// where it comes next to the path of an earlier climb (from there on that climb's result stands).
// Returns where it stopped when it took max_steps steps without reaching a maximum or an
// earlier path (UINT32_MAX: it ended).
std::uint32_t DepthSearch::climb_from(std::uint32_t v, int max_steps) {
  if (path_[v] >= round_first_) return UINT32_MAX;
  const std::uint32_t serial = ++patch_.climb_serial;
  for (int step = 0;; ++step) {
    if (step == max_steps) return v;
    path_[v] = serial;
    std::uint32_t cand[32];
    double key[32];
    int n = 0;
    for (std::uint32_t k = test_vf_.first[v]; k < test_vf_.first[v + 1]; ++k)
      for (std::uint32_t u : test_.faces[test_vf_.faces[k]]) {
        if (u == v || u >= test_nv_ || n == 32) continue;
        bool dup = false;
        for (int i = 0; i < n; ++i) dup |= cand[i] == u;
        if (dup) continue;
        cand[n] = u;
        key[n++] = -test_pos(u).dot(d_);
      }
    for (int i = 1; i < n; ++i)  // insertion sort, deepest along -d first (n is ~6)
      for (int j = i; j > 0 && key[j] > key[j - 1]; --j) std::swap(key[j], key[j - 1]), std::swap(cand[j], cand[j - 1]);
    std::uint32_t next = UINT32_MAX;
    bool joined = false;
    for (int i = 0; i < n && next == UINT32_MAX; ++i) {
      joined |= path_[cand[i]] >= round_first_ && path_[cand[i]] != serial;
      if (eval(cand[i], exitf_[v]) > depth_[v]) next = cand[i];
    }
    if (best_.capped) return UINT32_MAX;
    // A vertex higher than all its neighbours may still sit below a ridge or plateau between
    // vertices: look one ring further before calling it the deepest (other maxima are only
    // kept for next round's starts, they need not be exact).
    for (int i = 0; i < n && next == UINT32_MAX && depth_[v] >= best_.depth; ++i) {
      const std::uint32_t c = cand[i];
      if (exitf_[c] == UINT32_MAX) continue;
      for (std::uint32_t k = test_vf_.first[c]; k < test_vf_.first[c + 1] && next == UINT32_MAX; ++k)
        for (std::uint32_t u : test_.faces[test_vf_.faces[k]])
          if (u != v && u < test_nv_ && eval(u, exitf_[c]) > depth_[v]) {
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
}

// Climbs from last round's local maxima; true when one is still inside. A remembered maximum
// other than the deepest is climbed every round only while it is at least kShallowShare as deep
// as the deepest point found so far (it could set PD); a shallower one is kept as it is (its
// depth there still read every round) and climbed in a round that looks for new regions (every
// kDiscoverEvery-th: the extra work then falls in rounds that have some anyway, and the typical
// round's cost stays down), one of them in each such round in turn.
bool DepthSearch::climb_remembered(bool discover_round) {
  bool remembered = false;
  const int shallow_turn = 1 + int(epoch_ / kDiscoverEvery % (DepthMemory::kSize - 1));
  for (int i = 0; i < DepthMemory::kSize; ++i) {
    const std::uint32_t v = memory_.vertex[i];
    if (v < test_nv_ && memory_.face[i] < surface_.faces.size() && eval(v, memory_.face[i]) > 0) {
      if (i == 0 || (discover_round && i == shallow_turn) || depth_[v] >= kShallowShare * best_.depth)
        climb_from(v);
      else if (path_[v] < round_first_)  // not on a path of this round (a climb's maximum is remembered there)
        remember(v);
      remembered = true;
    } else if (v != UINT32_MAX) {
      lost_ = true;
    }
  }
  return remembered;
}

// The pairs a search for new regions climbs from (patch.seed_pairs, indices into patch.valid).
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
void DepthSearch::open_pairs(bool discover, bool full) {
  std::vector<std::uint32_t>& open = patch_.seed_pairs;  // indices into valid
  open.clear();
  if (discover && full) {
    for (std::uint32_t i = 0; i < patch_.valid.size(); ++i) open.push_back(i);
    return;
  }
  if (!discover) return;
  const auto n_slots = static_cast<std::uint32_t>(T_.faces.size());
  bool any_new = false;
  for (std::uint32_t slot = 0; slot < n_slots && !any_new; ++slot) any_new = !T_.fixed(slot).covered;
  if (!any_new && !lost_) return;
  const std::uint32_t n_groups = group_regions();
  const std::vector<std::uint32_t>& label = T_.group_label;
  const std::vector<std::uint32_t>& first = T_.group_first;
  const std::vector<std::uint8_t>& group_open = T_.group_open;
  bool any_open = false;
  for (std::uint32_t g = 0; g < n_groups; ++g) {
    if (!group_open[g]) continue;
    ST_ASSERT(first[g] < T_.faces.size(), "an open group has a face (new_groups' label 0 may have none)");
    any_open = true;
    if (!T_.fixed(first[g]).bad_index) drop(T_.fixed(first[g]).vid[0]);
  }
  for (std::uint32_t i = 0; i < patch_.valid.size() && any_open; ++i)
    if (group_open[label[patch_.valid_slots[i][probe_side_ ? 1 : 0]]]) open.push_back(i);
}

// Groups this body's colliding faces (T.group_label), each group's first slot (T.group_first)
// and which are open (T.group_open: a region not followed); returns the group count.
std::uint32_t DepthSearch::group_regions() {
  const auto n_slots = static_cast<std::uint32_t>(T_.faces.size());
  const std::uint32_t n_groups = lost_ ? group_faces(T_, epoch_) : new_groups(T_);
  const std::vector<std::uint32_t>& label = T_.group_label;
  std::vector<std::uint32_t>& first = T_.group_first;  // per group: a face of it (its first slot)
  first.assign(n_groups, UINT32_MAX);
  for (std::uint32_t slot = 0; slot < n_slots; ++slot)
    if (first[label[slot]] == UINT32_MAX) first[label[slot]] = slot;
  if (lost_) mark_followed(n_groups);  // else new_groups said which are open
  return n_groups;
}

// Each group's extent across d (from the records, in the common frame); open: none of this
// round's maxima, nor a vertex known from the last searches, lies in it.
void DepthSearch::mark_followed(std::uint32_t n_groups) {
  const auto n_slots = static_cast<std::uint32_t>(T_.faces.size());
  const std::vector<std::uint32_t>& label = T_.group_label;
  std::vector<std::uint8_t>& group_open = T_.group_open;
  group_open.assign(n_groups, 1);
  const Vec3 uc = patch_.dir_to_common(walk_.u), wc = patch_.dir_to_common(walk_.w);
  std::vector<double>& box = T_.group_box;  // per group: lo_u, hi_u, lo_w, hi_w
  box.resize(4 * std::size_t(n_groups));
  for (std::uint32_t g = 0; g < n_groups; ++g) {
    double* bx = &box[4 * std::size_t(g)];
    bx[0] = bx[2] = std::numeric_limits<double>::infinity(), bx[1] = bx[3] = -bx[0];
  }
  for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
    if (T_.use[slot] == kNoDirection) continue;  // no record (a moved one is not filled when degenerate)
    double* bx = &box[4 * std::size_t(label[slot])];
    for (const Vec3& x : patch_.common_rec(T_, slot).v) {
      const double xu = x.dot(uc), xw = x.dot(wc);
      bx[0] = std::min(bx[0], xu), bx[1] = std::max(bx[1], xu), bx[2] = std::min(bx[2], xw), bx[3] = std::max(bx[3], xw);
    }
  }
  for (std::uint32_t g = 0; g < n_groups; ++g) {
    const double* bx = &box[4 * std::size_t(g)];
    bool followed = false;
    for (int i = 0; i < n_maxima_ && !followed; ++i) followed = in_extent(maxima_[i], bx, uc, wc);
    for (int i = 0; i < DepthMemory::kKnown && !followed; ++i)
      followed = memory_.known[i] < test_nv_ && in_extent(memory_.known[i], bx, uc, wc);
    group_open[g] = followed ? 0 : 1;
  }
}

// Whether vertex v, seen along d, lies in a group's extent bx (lo_u, hi_u, lo_w, hi_w; uc, wc:
// the plane ⊥ d in the common frame).
bool DepthSearch::in_extent(std::uint32_t v, const double* bx, const Vec3& uc, const Vec3& wc) {
  const Vec3 x = patch_.to_common(test_pos(v));
  const double xu = x.dot(uc), xw = x.dot(wc);
  return xu >= bx[0] && xu <= bx[1] && xw >= bx[2] && xw <= bx[3];
}

// Climbs from the open pairs (patch.seed_pairs): their vertices lowest along d, and a sample of
// them whose offset turns every round; true when a climb started from them.
bool DepthSearch::climb_from_pairs() {
  const std::vector<std::uint32_t>& open = patch_.seed_pairs;
  const std::vector<ContactPair>& valid = patch_.valid;
  std::vector<std::uint32_t>& climb = patch_.climb;
  std::uint32_t low_v[kLowSeeds], low_f[kLowSeeds];
  double low_key[kLowSeeds];
  int n_low = 0;
  for (std::uint32_t pi : open) {
    const ContactPair& p = valid[pi];
    const std::uint32_t tf = probe_side_ ? p.probe : p.object, sf = probe_side_ ? p.object : p.probe;
    for (std::uint32_t v : test_.faces[tf]) {
      if (v >= test_nv_) continue;
      const double key = -test_pos(v).dot(d_);
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
    if (visit_[low_v[i]] != epoch_ && eval(low_v[i], low_f[i]) > 0) climb.push_back(low_v[i]);
  const std::size_t stride = std::max<std::size_t>(1, open.size() / kSeedPairs);
  for (std::size_t i = (epoch_ / kDiscoverEvery) % stride; i < open.size(); i += stride) {
    const ContactPair& p = valid[open[i]];
    const std::uint32_t tf = probe_side_ ? p.probe : p.object, sf = probe_side_ ? p.object : p.probe;
    for (std::uint32_t v : test_.faces[tf])
      if (v < test_nv_ && visit_[v] != epoch_ && eval(v, sf) > 0) climb.push_back(v);
  }
  const bool searched = !climb.empty();
  std::sort(climb.begin(), climb.end(), [&](std::uint32_t a, std::uint32_t b) { return depth_[a] > depth_[b]; });
  for (std::uint32_t v : climb) climb_from(v);
  return searched;
}

// The patrol (in a search for new regions that is not over the whole patch): its climb goes on
// from where it stopped while that vertex is still inside, else a new one starts from the deepest
// inside vertex of the next pair. Its state is kept in the memory (unchanged between searches).
void DepthSearch::patrol(bool discover, bool full) {
  const std::vector<ContactPair>& valid = patch_.valid;
  if (!(discover && !full && !valid.empty())) return;
  std::uint32_t v = memory_.patrol;
  if (!(v < test_nv_ && memory_.patrol_face < surface_.faces.size() && eval(v, memory_.patrol_face) > 0)) {
    const double k = memory_.patrol_k++;
    const std::size_t i =
        std::min(valid.size() - 1, std::size_t((k * kPatrolStep - std::floor(k * kPatrolStep)) * double(valid.size())));
    const std::uint32_t tf = probe_side_ ? valid[i].probe : valid[i].object;
    const std::uint32_t sf = probe_side_ ? valid[i].object : valid[i].probe;
    v = UINT32_MAX;
    for (std::uint32_t u : test_.faces[tf])
      if (u < test_nv_ && eval(u, sf) > 0 && (v == UINT32_MAX || depth_[u] > depth_[v])) v = u;
  }
  const std::uint32_t stop = v != UINT32_MAX ? climb_from(v, kPatrolSteps) : UINT32_MAX;
  memory_.patrol = stop;
  memory_.patrol_face = stop != UINT32_MAX ? exitf_[stop] : UINT32_MAX;
}

// The test body's memory for the next round: this search's maxima, the patrol, what was lost,
// and what the last search that climbed from regions not followed knew.
void DepthSearch::keep_memory(bool discover, bool searched) {
  const DepthMemory last = memory_;
  memory_ = DepthMemory{};
  for (int i = 0; i < n_maxima_; ++i) {
    ST_ASSERT(i == 0 || maxima_depth_[i - 1] >= maxima_depth_[i], "maxima are kept deepest first");
    memory_.vertex[i] = maxima_[i];
    memory_.face[i] = exitf_[maxima_[i]];
  }
  memory_.patrol = last.patrol;
  memory_.patrol_face = last.patrol_face;
  memory_.patrol_k = last.patrol_k;
  if (discover) {  // every colliding face has now been seen by a search; what was lost, looked for
    T_.cover_all();
    lost_ = false;
  }
  memory_.lost = lost_;
  if (!searched)
    std::copy(std::begin(last.known), std::end(last.known), std::begin(memory_.known));
  else
    std::copy(known_, known_ + n_known_, std::begin(memory_.known));
}

// False when the face has a bad index or does not face d (a walk would not cross it).
bool DepthSearch::see(std::uint32_t f, Seen& sn) {
  const Tri& t = surface_.faces[f];
  const std::size_t surface_nv = surface_.local.size();
  if (t[0] >= surface_nv || t[1] >= surface_nv || t[2] >= surface_nv) return false;
  const Vec3 p[3] = {walk_.at(t[0]), walk_.at(t[1]), walk_.at(t[2])};
  sn.face = f;
  for (int k = 0; k < 3; ++k) sn.pu[k] = p[k].dot(walk_.u), sn.pw[k] = p[k].dot(walk_.w), sn.ph[k] = p[k].dot(walk_.d);
  return SurfaceWalk::facing(
      (sn.pu[1] - sn.pu[0]) * (sn.pw[2] - sn.pw[0]) - (sn.pu[2] - sn.pu[0]) * (sn.pw[1] - sn.pw[0]), p[0], p[1], p[2]);
}

// Where test edge (ia, ib) crosses the edges of seen faces along d. A crossing lies on an edge
// of a surface face that faces d, so the surface's height there is the edge's (no walk needed).
void DepthSearch::refine_edge(std::uint32_t ia, std::uint32_t ib, const Seen* seen, int n_seen) {
  const Vec3 a = test_pos(ia), b = test_pos(ib);
  const double au = a.dot(walk_.u), aw = a.dot(walk_.w), ah = a.dot(walk_.d);
  const double ru = b.dot(walk_.u) - au, rw = b.dot(walk_.w) - aw, rh = b.dot(walk_.d) - ah;
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
      if (dist > best_.depth && inside_below_edge(sn, e)) {
        best_.depth = dist;
        best_.point = a + sa * (b - a);
        best_.face = sn.face;
        best_.vertex = UINT32_MAX;  // an edge point
        won_a_ = ia, won_b_ = ib;
      }
    }
  }
}

bool DepthSearch::inside_below_edge(const Seen& sn, int e) {
  // Locally at the edge the solid is the intersection of the two faces' half-spaces (a convex
  // edge) or their union (a concave one). A point x straight below the edge along d is under the
  // seen face's plane (it faces d); it is under the other face's plane too when that face faces
  // d. Otherwise only a concave edge keeps x inside.
  const Tri& t = surface_.faces[sn.face];
  const std::uint32_t a = t[e], b = t[e == 2 ? 0 : e + 1], c = t[e == 0 ? 2 : e - 1];
  const std::uint32_t g = walk_.across(sn.face, a, b);
  if (g == UINT32_MAX) return true;  // an open boundary: nothing to tell by
  const Tri& tg = surface_.faces[g];
  const std::uint32_t opposite = tg[0] != a && tg[0] != b ? tg[0] : (tg[1] != a && tg[1] != b ? tg[1] : tg[2]);
  const Vec3 pa = walk_.at(a), pb = walk_.at(b), pc = walk_.at(c), po = walk_.at(opposite);
  // g runs the shared edge b → a, so its outward normal is (a − b) × (o − b) = −(b − a) × (o − a).
  const Vec3 ng = -(pb - pa).cross(po - pa);
  const Vec3 nf = (pb - pa).cross(pc - pa);  // the seen face's outward normal (unnormalised)
  if (ng.dot(walk_.d) > 0) return true;      // g faces d: x is under both planes
  return (po - pa).dot(nf) > 0;              // a concave edge: g's far vertex above the seen face's plane
}

// Every edge of the faces around vertex c (once) against the faces its neighbourhood leaves
// through.
void DepthSearch::refine_around(std::uint32_t c) {
  struct {  // the faces the neighbourhood leaves through, each once
    std::uint32_t f[8];
    int n = 0;
    void add(std::uint32_t g) {
      if (g == UINT32_MAX || n == 8) return;
      for (int i = 0; i < n; ++i)
        if (f[i] == g) return;
      f[n++] = g;
    }
  } near;
  near.add(exitf_[c]);
  for (std::uint32_t k = test_vf_.first[c]; k < test_vf_.first[c + 1]; ++k)
    for (std::uint32_t u : test_.faces[test_vf_.faces[k]])
      if (u < test_nv_) {
        eval(u, exitf_[c]);
        near.add(exitf_[u]);
      }
  // Over one face of the other side both heights are linear: no crossing can beat the vertices.
  if (near.n < 2) return;
  Seen seen[8];
  int n_seen = 0;
  for (int i = 0; i < near.n; ++i) n_seen += see(near.f[i], seen[n_seen]) ? 1 : 0;
  std::uint32_t done_a[48], done_b[48];  // edges crossed already (each is shared by two faces)
  int n_done = 0;
  for (std::uint32_t k = test_vf_.first[c]; k < test_vf_.first[c + 1]; ++k) {
    const Tri& t = test_.faces[test_vf_.faces[k]];
    if (t[0] >= test_nv_ || t[1] >= test_nv_ || t[2] >= test_nv_) continue;
    for (int e = 0; e < 3; ++e) {
      const std::uint32_t ia = t[e], ib = t[e == 2 ? 0 : e + 1];
      bool done = false;
      for (int i = 0; i < n_done && !done; ++i) done = done_a[i] == ib && done_b[i] == ia;
      if (done) continue;
      if (n_done < 48) done_a[n_done] = ia, done_b[n_done++] = ib;
      refine_edge(ia, ib, seen, n_seen);
    }
  }
}

// Along a ridge (a convex edge of the other body seen along d), the deepest point moves between
// vertices: follow the winning crossings from fan to fan while they improve.
void DepthSearch::follow_ridge(std::uint32_t deepest_vertex) {
  std::uint32_t c = deepest_vertex;
  for (int it = 0; it < kRidgeSteps; ++it) {
    const double before = best_.depth;
    refine_around(c);
    if (!(best_.depth > before + kRidgeGainMm) || won_a_ == UINT32_MAX) break;
    const std::uint32_t next = (won_a_ == c || (won_b_ != c && depth_[won_b_] > depth_[won_a_])) ? won_b_ : won_a_;
    if (next == c || next >= test_nv_ || exitf_[next] == UINT32_MAX) break;
    c = next;
  }
  if (c != deepest_vertex) {  // start next round's climb where the ridge search ended
    memory_.vertex[0] = c;
    memory_.face[0] = exitf_[c];
  }
}

// Every colliding pair's test edges against its surface face.
void DepthSearch::refine_pairs() {
  for (const ContactPair& p : patch_.valid) {
    const std::uint32_t tf = probe_side_ ? p.probe : p.object, sf = probe_side_ ? p.object : p.probe;
    const Tri& t = test_.faces[tf];
    Seen sn;
    if (t[0] >= test_nv_ || t[1] >= test_nv_ || t[2] >= test_nv_ || !see(sf, sn)) continue;
    for (int e = 0; e < 3; ++e) refine_edge(t[e], t[(e + 1) % 3], &sn, 1);
  }
}

}  // namespace st::geom
