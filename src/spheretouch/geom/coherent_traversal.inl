// SPDX-License-Identifier: BSD-3-Clause
// One round of the coherent collider (coherent.hpp), compiled once per instruction set like
// collide_traversal.inl, after it and inside the same region: it is a CollideQuery (the same
// kernels, probe transforms, batches and counters) that walks the front instead of the trees.
// No #include here: everything is defined inside the region, for its ISA.
//
// The margins. Every certificate is a distance d (mm, object frame) such that the answer cannot
// change while every probe point of the node moved less than d from where the certificate put it:
//  * a sphere gap sqrt(d2) - (r + q): the radii carry the slack that covers the float centres'
//    error (collide.cpp, top), so the true gap is at least the computed one;
//  * a box gap (face boxes, or the probe leaf's box): the boxes contain the very doubles exactly,
//    so their separation along an axis is a distance between the triangles;
//  * a separating axis a of the float filter (tri_filter's analysis): along the fixed float
//    vector a the exact projections are within the bound of the computed ones, so the exact gap
//    along a is at least gap - bound, and the distance at least (gap - bound) / |a|;
//  * intersecting: the distance from the origin to the boundary of P - O is the least h(n)/|n|
//    over its facet normals n, all among the 11 axes; h(n_exact) >= gap - bound (tri_filter), and
//    |n_exact| <= |a| + 84 u M^2 (the axis error), so min over the axes of (gap - bound) /
//    (|a| + 2^-17 M^2) is a depth: a motion smaller than it moves P - O's support by less, so the
//    origin stays inside.
// Each quotient is rounded (sqrt, division: u each), hence the final factor 1 - 2^-20.

template <>
struct CoherentQuery<ST_COLLIDE_WIDE_SIMD::Lanes> : CollideQuery<ST_COLLIDE_WIDE_SIMD::Lanes> {
  using Base = CollideQuery<ST_COLLIDE_WIDE_SIMD::Lanes>;

  // Which spheres k (k < n <= 8) of a float SoA block are apart from the sphere (qx, qy, qz; qr)
  // as this round records them, by their gap as sphere_mask computes its test,
  // sqrt(|c_k - q|^2) - (r_k + qr), NaN staying NaN (bit k of `apart`: gap > 0 in a fresh round,
  // else gap >= δ), which do not meet (gap > 0: bit k of `positive`; NaN is neither), and the
  // least gap of those apart (+inf: none), taken on the lanes.
  void classify(const float* c, std::size_t st, std::uint32_t n, float qx, float qy, float qz, float qr, float& least,
                std::uint32_t& apart, std::uint32_t& positive) const {
    const Lanes x = Lanes::broadcast(qx), y = Lanes::broadcast(qy), z = Lanes::broadcast(qz), r = Lanes::broadcast(qr);
    const Lanes zero = Lanes::broadcast(0.0f), at = Lanes::broadcast(reach_f);
    const Lanes none = Lanes::broadcast(std::numeric_limits<float>::infinity());
    apart = positive = 0;
    least = std::numeric_limits<float>::infinity();
    for (std::uint32_t k = 0; k < n; k += Lanes::width) {
      const Lanes dx = Lanes::load(c + k) - x;
      const Lanes dy = Lanes::load(c + st + k) - y;
      const Lanes dz = Lanes::load(c + 2 * st + k) - z;
      const Lanes g = sqrt(dx * dx + dy * dy + dz * dz) - (Lanes::load(c + 3 * st + k) + r);
      const auto pos = g > zero;
      const auto far = (fresh ? pos : g >= at) & decltype(pos)::first(n - k);
      positive |= pos.bits() << k;
      apart |= far.bits() << k;
      least = std::min(least, hmin(select(far, g, none)));  // the lanes selected are not NaN
    }
  }
  template <class L>
  static void store(float* out, L v) {
    std::memcpy(out, &v.v, sizeof(float) * L::width);
  }

  // One axis for the margins (see the top of this file): `sepm` gains the best proved
  // separation, `inm` keeps the least proved depth.
  [[gnu::always_inline]] static void margin_axis(WideLanes ax, WideLanes ay, WideLanes az, const TriStep& t,
                                                 WideLanes m2, WideLanes& sepm, WideLanes& inm) {
    const WideLanes* p = t.p;
    const WideLanes* o = t.o;
    const WideLanes d0 = ax * p[0] + ay * p[1] + az * p[2];
    const WideLanes d1 = ax * p[3] + ay * p[4] + az * p[5];
    const WideLanes d2 = ax * p[6] + ay * p[7] + az * p[8];
    const WideLanes e1 = ax * o[0] + ay * o[1] + az * o[2];
    const WideLanes e2 = ax * o[3] + ay * o[4] + az * o[5];
    const WideLanes zero = WideLanes::broadcast(0.0f);
    const WideLanes pmin = min(d0, min(d1, d2)), pmax = max(d0, max(d1, d2));
    const WideLanes omin = min(zero, min(e1, e2)), omax = max(zero, max(e1, e2));
    const WideLanes len = sqrt(ax * ax + ay * ay + az * az) * WideLanes::broadcast(1.0f + 0x1p-20f);
    const WideLanes sep = max(omin - pmax, pmin - omax) - t.bound;
    const WideLanes dep = min(pmax - omin, omax - pmin) - t.bound;
    sepm = max(sep / len, sepm);  // a zero axis: sep < 0, -inf or NaN, and max keeps sepm
    inm = min(dep / (len + WideLanes::broadcast(0x1p-17f) * m2), inm);
  }

  // tri_filter with margins: for the n <= kTriBatch pairs of v (as tri_filter reads them), bit i
  // of `decided` when pair i is proved apart or intersecting, of `overlap` when intersecting, and
  // margin[i] the distance it stays so (0 when undecided). `full` false: the two normals only (a
  // first pass that proves most candidates apart; it decides no intersection).
  static void tri_margins(const float (*v)[kTriBatch], std::uint32_t n, bool full, float* margin,
                          std::uint32_t& decided, std::uint32_t& overlap) {
    decided = overlap = 0;
    for (std::uint32_t j = 0; j < n; j += WideLanes::width) {
      TriStep t;
      tri_step(v, n, j, t);
      const WideLanes m2 = t.scale * t.scale;
      const WideLanes zero = WideLanes::broadcast(0.0f);
      WideLanes sepm = zero, inm = WideLanes::broadcast(std::numeric_limits<float>::infinity());
      margin_axis(t.ey[0] * t.ez[1] - t.ez[0] * t.ey[1], t.ez[0] * t.ex[1] - t.ex[0] * t.ez[1],
                  t.ex[0] * t.ey[1] - t.ey[0] * t.ex[1], t, m2, sepm, inm);
      margin_axis(t.fy[0] * t.fz[1] - t.fz[0] * t.fy[1], t.fz[0] * t.fx[1] - t.fx[0] * t.fz[1],
                  t.fx[0] * t.fy[1] - t.fy[0] * t.fx[1], t, m2, sepm, inm);
      if (full && ((sepm > zero).bits() & t.ok) != t.ok)
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b)
            margin_axis(t.ey[a] * t.fz[b] - t.ez[a] * t.fy[b], t.ez[a] * t.fx[b] - t.ex[a] * t.fz[b],
                        t.ex[a] * t.fy[b] - t.ey[a] * t.fx[b], t, m2, sepm, inm);
      // Lanes whose edge axes were skipped (all lanes apart by a normal) have inm <= -sepm < 0;
      // without `full` no lane is proved intersecting.
      const std::uint32_t sp = (sepm > zero).bits() & t.ok, in = full ? (inm > zero).bits() & t.ok : 0u;
      alignas(64) float s[WideLanes::width], d[WideLanes::width];
      store(s, sepm);
      store(d, inm);
      const std::uint32_t one = sp ^ in;
      decided |= one << j;
      overlap |= (in & ~sp) << j;
      for (int l = 0; l < WideLanes::width && j + l < n; ++l) {
        const float x = (one >> l) & 1u ? ((sp >> l) & 1u ? s[l] : d[l]) : 0.0f;
        margin[j + l] = x * (1.0f - 0x1p-20f);
      }
    }
  }

  CoherentCollider& cc;
  double reach = 0;   // δ of the entries made this round
  float reach_f = 0;  // δ rounded down to float (what entries record)
  // This round builds the front from the roots (no front yet): it descends only the sphere
  // pairs that meet, as collide() does, so it costs about what collide() does; the pairs apart by
  // less than δ become groups with their gap, and the motion of the next rounds expands them a
  // few at a time (a later walk descends what is nearer than δ).
  bool fresh = false;
  std::uint32_t round = 0;        // this round's id
  bool overflow = false;          // the pool went over max_bytes: this round is abandoned
  std::uint32_t builds_left = 0;  // leaf pairs this round may still build, in kBuildUnits (leaf())
  bool rerooting = false;         // this round walks from the roots, keeping the front's leaf pairs
  std::uint32_t leaf_count = 0;   // leaf-pair entries of the new front
  using Delta = detail::PoseDelta;
  // The filter-with-margins batch: candidates (by index in cands_) waiting for tri_margins.
  std::uint32_t m_index[kTriBatch] = {}, m_slot[kTriBatch] = {}, m_face[kTriBatch] = {};
  double m_level[kTriBatch] = {};  // ... and their entries' levels (FrontEntry::level)
  std::uint32_t m_n = 0;
  // ... and those the normals did not prove apart, with their coordinates, for all 11 axes.
  std::uint32_t h_index[kTriBatch] = {}, h_slot[kTriBatch] = {}, h_face[kTriBatch] = {};
  double h_level[kTriBatch] = {};
  std::uint32_t h_n = 0;
  alignas(64) float h_v[15][kTriBatch] = {};

  // A group's gap still open: its probe node moved less than its margin since its pose? The
  // shortcut first (coherent.hpp, top): the probe's path still below the group's `level` (exact
  // sums, however many rounds); else the node's motion bound from its pose (none once that pose is
  // no longer kept), which sets `level` anew.
  bool still_group(detail::FrontEntry& g) {
    if (path < g.level) return true;
    const double margin = g.margin;
    const double moved = node_motion(g.c, g.r, g.pose);
    if (!(margin > moved)) return false;
    g.level = until(margin - moved);
    return true;
  }
  // A group's `level` from this round, its node `room` short of using its margin up: while the
  // path from here grows by less than that, the node's motion since its pose stays below
  // its margin (at most its motion to here plus the path since: coherent.hpp, top). Rounded down
  // to a multiple of the path's quantum, and at most 2^52 of them ahead, the level is exact, as
  // the path is: so is the comparison.
  double until(double room) const {
    return path + std::min(std::floor(room * (1 - 1e-9) * cc.path_per_quantum_), 0x1p52) * cc.path_quantum_;
  }
  double path = 0;  // the probe's path at this round (CoherentCollider::path_)
  // This round's change since `pose` (kept no more than kPoses rounds).
  const Delta& delta(std::uint32_t pose) {
    const std::uint64_t key = (std::uint64_t{round} << 32) | pose;
    const Delta& hot = cc.deltas_[pose % CoherentCollider::kPoses];
    if (hot.key == key && round - pose < CoherentCollider::kPoses) [[likely]]
      return hot;
    return delta_slow(pose);
  }
  [[gnu::noinline]] const Delta& delta_slow(std::uint32_t pose) {
    static const Delta expired = [] {  // callers test the pose's age first; this only keeps it defined
      Delta d;
      d.D.setConstant(std::numeric_limits<double>::infinity());
      d.dt.setConstant(std::numeric_limits<double>::infinity());
      d.norm = d.rnd = d.whole = std::numeric_limits<double>::infinity();
      return d;
    }();
    if (round - pose >= CoherentCollider::kPoses) return expired;  // its ring slot holds a newer pose
    Delta& d = cc.deltas_[pose % CoherentCollider::kPoses];
    const detail::CertPose& cp = cc.poses_[pose % CoherentCollider::kPoses];
    ST_ASSERT(cp.round == pose, "a pose younger than kPoses rounds is still in its ring slot");
    d.D = rt.R - cp.rt.R;
    d.dt = rt.t - cp.rt.t;
    d.norm = d.D.norm();  // Frobenius >= spectral
    // apply() rounds each coordinate within ~4e-16 of the magnitude, the bound's own few
    // operations a few 1e-16 relative: 1e-12 of both magnitudes covers both poses' and it.
    d.rnd = 1e-12 * (cc.poses_[round % CoherentCollider::kPoses].mag + cp.mag) + 1e-300;
    d.key = (std::uint64_t{round} << 32) | pose;
    d.whole = sphere_motion(d, PT.nodes[0].centre, PT.nodes[0].radius);
    return d;
  }
  // Bound on how far any point of the sphere (c, r) (probe-local) moved between the pose of `d`
  // and this round: |D c + dt| + ||D||_F r, widened for the rounding of both apply()s and its own.
  static double sphere_motion(const Delta& d, const float* c, float r) {
    const Vec3 x(c[0], c[1], c[2]);
    return ((d.D * x + d.dt).norm() + d.norm * double(r)) * (1 + 1e-9) + d.rnd;
  }
  // A front entry for (p, o), made at this round's pose, with p's sphere.
  detail::FrontEntry entry(std::uint8_t kind, std::uint32_t p, std::uint32_t o) const {
    detail::FrontEntry e;
    e.p = p, e.o = o, e.pose = e.anchor = round, e.kind = kind;
    const SphereNode& h = PT.nodes[p];
    e.c[0] = h.centre[0], e.c[1] = h.centre[1], e.c[2] = h.centre[2], e.r = h.radius;
    return e;
  }

  // The pool in bytes (what max_bytes bounds).
  std::size_t pool_bytes() const { return cc.pool_bytes(cc.next_front_.size()); }
  void add_group(std::uint8_t kind, std::uint32_t p, std::uint32_t o, std::uint32_t mask, float gap) {
    detail::FrontEntry e = entry(kind, p, o);
    e.arg = mask;
    e.margin = gap * (1.0f - 0x1p-20f);
    e.level = until(e.margin);
    push_group(e);
  }
  // Appends a group to the store, and its level to the scan's (CoherentCollider::glevel_).
  void push_group(const detail::FrontEntry& g) {
    cc.groups_.push_back(g);
    cc.glevel_.push_back(g.level);
  }

  // A leaf pair's refresh point: a fraction of δ in [3/4, 1) that differs between leaf pairs.
  static std::uint8_t stagger(std::uint32_t p, std::uint32_t o) {
    return static_cast<std::uint8_t>((p * 0x9e3779b1u ^ o * 0x85ebca77u) >> 24);
  }
  static float widen_below(float x, double by) { return float_below(double(x) - by); }
  static float widen_above(float x, double by) { return float_above(double(x) + by); }

  // Leaf pair (p, o) at this pose: its candidates within δ with their certificates (or the pair
  // apart, with its gap, when its boxes are farther than δ). Emits the intersecting pairs. `old`:
  // the entry this refreshes, whose candidates keep their certificates where these still hold.
  // What it cost against a round's budget of builds (leaf()): 0 when the leaf boxes settled it,
  // 1 when its face boxes gathered no candidate, kBuildUnits when it has candidates.
  std::uint32_t build_leaf(std::uint32_t p, std::uint32_t o, const detail::FrontEntry* old = nullptr) {
    const SphereNode& hp = PT.nodes[p];
    const SphereNode& ho = OT.nodes[o];
    ++res.stats.leaf_pairs;
    if (old) cc.garbage_ += old->count;  // its candidates: replaced below, or not needed (apart)
    const std::array<float, 8>& u = probe_leaf(p);
    {  // the probe leaf's box against the object leaf's sphere: apart by more than δ?
      const float* os = sc.osph_.data();
      const std::size_t so = sc.nstride_o_;
      float d2 = 0;
      for (int k = 0; k < 3; ++k) {
        const float c = os[k * so + o];
        const float d = std::max(0.0f, std::max(u[k] - c, c - u[3 + k]));
        d2 += d * d;
      }
      const float gap = std::sqrt(d2) - (os[3 * so + o] + slack);
      if (gap >= reach_f) {
        add_group(detail::kPairApart, p, o, 0, gap);
        return 0;
      }
    }
    {  // the probe leaf's box against the object leaf's box
      const std::array<float, 8>& v = sc.obox_[o];
      float gap = 0;
      for (int k = 0; k < 3; ++k) gap = std::max(gap, std::max(v[k] - u[3 + k], u[k] - v[3 + k]));
      if (gap >= reach_f) {
        add_group(detail::kPairApart, p, o, 0, gap);
        return 0;
      }
    }
    detail::FrontEntry e = entry(detail::kLeafPair, p, o);
    e.margin = reach_f;
    // The candidates are appended to cands_ (the old entry's, if any, become garbage: the pool is
    // compacted at the end of a round when more than half of it is).
    e.arg = static_cast<std::uint32_t>(cc.cands_.size());
    e.theta = stagger(p, o);
    float w[6];
    for (int k = 0; k < 3; ++k) w[k] = widen_below(u[k], reach), w[3 + k] = widen_above(u[3 + k], reach);
    std::uint32_t prev = old ? old->arg : 0;  // indices: cands_ grows below
    const std::uint32_t prev_end = old ? old->arg + old->count : 0;
    // The old entry's candidates hold while the leaf moved less than their margins from its
    // anchor: one kept holds from this pose while it moves less than what is left (coherent.hpp, top).
    const double moved_old = old ? node_motion(hp.centre, hp.radius, old->anchor) : 0.0;
    // ... the margins as stored (FrontEntry::level added) against that motion and the level.
    const double charged_old = old ? (moved_old + old->level) * (1 + 1e-12) : 0.0;
    const FaceBox* ob = OT.face_boxes.data() + ho.first;
    float ou[6];
    const std::uint64_t mo = face_box_mask(ob, ho.count, w, ou);
    if (mo != 0) {
      for (int k = 0; k < 3; ++k) ou[k] = widen_below(ou[k], reach), ou[3 + k] = widen_above(ou[3 + k], reach);
      probe_faces(p);
      const std::uint64_t mp = probe_mask(hp.first, hp.count, ou);
      const float* pb = sc.pbox_.data();
      const std::size_t st = sc.pstride_;
      for (std::uint64_t m = mo; mp != 0 && m != 0; m &= m - 1) {
        const unsigned j = static_cast<unsigned>(std::countr_zero(m));
        const FaceBox& fb = ob[j];
        const float b[6] = {widen_below(fb.lo[0], reach), widen_below(fb.lo[1], reach), widen_below(fb.lo[2], reach),
                            widen_above(fb.hi[0], reach), widen_above(fb.hi[1], reach), widen_above(fb.hi[2], reach)};
        const std::uint32_t of = OT.face_order[ho.first + j];
        for (std::uint64_t mf = probe_mask(hp.first, hp.count, b) & mp; mf != 0; mf &= mf - 1) {
          const std::uint32_t slot = hp.first + static_cast<unsigned>(std::countr_zero(mf));
          // Apart boxes: their gap is the certificate, no test needed.
          float gap = 0;
          for (int k = 0; k < 3; ++k)
            gap = std::max(gap, std::max(fb.lo[k] - pb[(3 + k) * st + slot], pb[k * st + slot] - fb.hi[k]));
          const auto at = static_cast<std::uint32_t>(cc.cands_.size());
          cc.cands_.push_back({slot, of, gap * (1.0f - 0x1p-20f), 0, static_cast<std::uint8_t>(j)});
          if (gap > 0) continue;
          // The same pair in the entry refreshed, its certificate still good: kept.
          auto before = [&](const detail::Candidate& c) { return c.j < j || (c.j == j && c.slot < slot); };
          while (prev != prev_end && before(cc.cands_[prev])) ++prev;
          if (prev != prev_end && cc.cands_[prev].j == j && cc.cands_[prev].slot == slot &&
              double(cc.cands_[prev].margin) > charged_old) {
            detail::Candidate kept = cc.cands_[prev];
            kept.margin = std::max(0.0f, float_below(double(kept.margin) - charged_old));
            cc.cands_.back() = kept;
            ++cc.stats_.reused;
            check_decision(slot, of, kept.hit != 0);
            if (kept.hit) emit(PT.face_order[slot], of);
            continue;
          }
          ++res.stats.tri_pairs;
          m_index[m_n] = at, m_slot[m_n] = slot, m_face[m_n] = of, m_level[m_n] = 0;
          if (++m_n == kTriBatch) flush_margins();
        }
      }
    }
    e.count = static_cast<std::uint16_t>(cc.cands_.size() - e.arg);
    // No candidate: every face box of the pair is more than δ from every other widened by δ (a
    // box separation is a distance), so the pair is apart by more than δ, as if its leaf boxes
    // were: a group (checked in place each round, expanded when the motion uses δ up) instead of
    // a leaf-pair entry to visit, copy and refresh. At light contact most leaf pairs of the front
    // are such (207 of 325 a round on the 98-contact armadillo_L2 slide). Its gap is taken as a
    // fraction of δ that differs between pairs, as a leaf pair's refresh point: pairs built in
    // the same rounds would otherwise all be expanded in one.
    if (e.count == 0) {
      add_group(detail::kPairApart, p, o, 0, reach_f * float(768 + e.theta) / 1024.0f);
      return 1;
    }
    cc.next_front_.push_back(e);
    ++leaf_count;
    return kBuildUnits;
  }
  static constexpr std::uint32_t kBuildUnits = 4;

  // Leaf pair (p, o) reached this round, to be (re)built: built while this round's budget lasts;
  // else answered by collide()'s own leaf stage and kept for a later round (`old`, an entry due
  // for its refresh, unchanged with its candidates; a new pair as kLeafPending). So a round after
  // a rebuild, or one where many leaf pairs fall due at once, costs little more than collide().
  // `spheres`: what this round's walk found of the pair's spheres (apart: no leaf stage needed;
  // meeting: no need to test them again), unknown for an entry of the front.
  enum class Spheres : std::uint8_t { unknown, apart, meet };
  void leaf(std::uint32_t p, std::uint32_t o, const detail::FrontEntry* old, Spheres spheres = Spheres::unknown) {
    if (builds_left > 0) {
      // A pair its leaf boxes settle costs little; one whose face boxes gathered nothing, a
      // quarter of one with candidates (a round after a rebuild would otherwise gather every
      // empty pair of the front at once).
      const std::uint32_t used = build_leaf(p, o, old);
      builds_left -= std::min(used, builds_left);
      return;
    }
    if (old) {
      cc.next_front_.push_back(*old);
    } else {
      cc.next_front_.push_back(entry(detail::kLeafPending, p, o));
    }
    ++leaf_count;
    ++cc.stats_.deferred;
    // collide() reaches a leaf pair only when its spheres meet; the front also keeps those within
    // δ, whose faces cannot meet: the same sphere test first spares them the leaf stage (and the
    // probe leaf's transform). The walk has just made it (split()): its answer stands. Where the
    // float rounding of the gap and of collide()'s squared test could disagree at a touching pair,
    // the leaf stage runs on spheres that barely miss: it finds no face pair there (the spheres
    // enclose the faces), so the pairs stay collide()'s.
    if (spheres == Spheres::apart) return;
    if (spheres == Spheres::meet) return leaf_leaf(p, o);
    put_probe_sphere(p);
    const float* ps = sc.psph_.data();
    const std::size_t sp = sc.nstride_p_;
    if (sphere_mask(sc.osph_.data() + o, sc.nstride_o_, 1, ps[p], ps[sp + p], ps[2 * sp + p], ps[3 * sp + p]) != 0)
      leaf_leaf(p, o);
  }

  // The candidates waiting for their margins: the filter with margins, the exact test for the
  // undecided (margin 0: tested again every round).
  void flush_margins() {
    if (m_n == 0) return;
    alignas(64) float v[15][kTriBatch];
    prep_tris(m_slot, m_face, m_n, v);
    float margin[kTriBatch];
    std::uint32_t apart = 0, overlap = 0;
    tri_margins(v, m_n, false, margin, apart, overlap);
    for (std::uint32_t i = 0; i < m_n; ++i) {
      if ((apart >> i) & 1u) {
        check_decision(m_slot[i], m_face[i], false);
        certify(m_index[i], margin[i], false, m_level[i]);
        continue;
      }
      h_index[h_n] = m_index[i], h_slot[h_n] = m_slot[i], h_face[h_n] = m_face[i], h_level[h_n] = m_level[i];
      for (int r = 0; r < 15; ++r) h_v[r][h_n] = v[r][i];
      if (++h_n == kTriBatch) flush_hard();
    }
    m_n = 0;
  }
  // The hard candidates through all 11 axes; the undecided through the exact test (margin 0).
  void flush_hard() {
    if (h_n == 0) return;
    pad_lanes(h_v, h_n);
    float margin[kTriBatch];
    std::uint32_t decided = 0, overlap = 0;
    tri_margins(h_v, h_n, true, margin, decided, overlap);
    for (std::uint32_t i = 0; i < h_n; ++i) {
      bool hit;
      if ((decided >> i) & 1u) {
        hit = (overlap >> i) & 1u;
        check_decision(h_slot[i], h_face[i], hit);
      } else {
        hit = exact_pair(h_slot[i], h_face[i]);
        margin[i] = 0;
      }
      certify(h_index[i], margin[i], hit, h_level[i]);
      if (hit) emit(PT.face_order[h_slot[i]], h_face[i]);
    }
    h_n = 0;
  }
  // Candidate `at` found (not) intersecting at this pose, its answer good while the leaf moves
  // less than `margin` from here (its entry's anchor is this pose), stored with its entry's
  // `level` added (FrontEntry::level), rounded down.
  void certify(std::uint32_t at, float margin, bool hit, double level) {
    detail::Candidate& c = cc.cands_[at];
    c.margin = level == 0 ? margin : float_below(double(margin) + level);
    c.hit = hit;
  }

  // How far a probe node's sphere (c, r) moved since `pose`: the tighter of the whole probe's
  // bound and its own (infinite for a pose no longer kept).
  double node_motion(const float* c, float r, std::uint32_t pose) {
    if (round - pose >= CoherentCollider::kPoses) return std::numeric_limits<double>::infinity();
    const Delta& d = delta(pose);
    return std::min(d.whole, sphere_motion(d, c, r));
  }
  // A cached leaf pair, its leaf `moved` (a bound) since the entry's anchor: the candidates whose
  // certificate holds give their answer, the others are tested at this pose and certified anew,
  // and then the anchor moves here (coherent.hpp, top). The leaf pair's own certificate, for the
  // face pairs that are not candidates, stays the entry's.
  void reuse_leaf(const detail::FrontEntry& e, double moved) {
    cc.next_front_.push_back(e);  // its candidates stay where they are
    ++leaf_count;
    detail::Candidate* c = cc.cands_.data() + e.arg;  // nothing is appended to cands_ here
    bool prepared = false;
    double base = e.level;
    if (base > 16.0 * e.margin) {                  // jitter can charge a level without end: stored near it, the
      for (std::uint32_t k = 0; k < e.count; ++k)  // margins would lose their low bits
        c[k].margin = std::max(0.0f, float_below(double(c[k].margin) - base));
      base = cc.next_front_.back().level = 0;
    }
    // A float at or above the bound (the margins are stored with the entry's level added): a
    // margin above it is above the bound.
    const float bound = float_above(moved + base);
    // When the anchor moves here, what the answers kept lose is charged to the level instead of
    // each margin (FrontEntry::level), rounded up; the retested are stored with it.
    const double level = (base + moved) * (1 + 1e-12);
    std::uint32_t retested = 0;
    for (std::uint32_t i = 0; i < e.count; ++i) {
      if (c[i].margin > bound) {
        if (c[i].hit) emit(PT.face_order[c[i].slot], c[i].face);
        check_decision(c[i].slot, c[i].face, c[i].hit != 0, prepared, e.p);
        continue;
      }
      if (retested++ == 0) {  // the anchor moves here: the answers taken so far keep what is left
        cc.next_front_.back().anchor = round;
        cc.next_front_.back().level = level;
        if (!prepared) probe_leaf(e.p), prepared = true;
      }
      ++res.stats.tri_pairs;
      m_index[m_n] = e.arg + i, m_slot[m_n] = c[i].slot, m_face[m_n] = c[i].face, m_level[m_n] = level;
      if (++m_n == kTriBatch) flush_margins();
    }
    cc.stats_.reused += e.count - retested;
    cc.stats_.retested += retested;
  }
  // Checking mode: a reused answer against the exact test at this pose (the leaf transformed first).
  void check_decision([[maybe_unused]] std::uint32_t slot, [[maybe_unused]] std::uint32_t of, [[maybe_unused]] bool hit,
                      [[maybe_unused]] bool& prepared, [[maybe_unused]] std::uint32_t p) {
#if defined(ST_CHECKS)
    if (!prepared) probe_leaf(p), prepared = true;
    ST_ASSERT(hit == overlaps(slot, of), "a certified answer is the exact test's at this pose");
#endif
  }
  using Base::check_decision;

  // Children of (p, o) on one side, those in `mask`, tested at this pose: those nearer than δ are
  // pushed for the walk, the others make one group with their least gap.
  void split(std::uint32_t p, std::uint32_t o, bool probe_side, std::uint32_t mask,
             std::pair<std::uint32_t, std::uint32_t>* stack, std::uint32_t& n) {
    const float* ps = sc.psph_.data();
    const float* os = sc.osph_.data();
    const std::size_t sp = sc.nstride_p_, so = sc.nstride_o_;
    const SphereNode& h = probe_side ? PT.nodes[p] : OT.nodes[o];
    float least = 0;
    std::uint32_t apart = 0, positive = 0;  // NaN is near: never certified
    if (probe_side) {
      probe_children(p);
      classify(ps + h.first, sp, h.count, os[o], os[so + o], os[2 * so + o], os[3 * so + o], least, apart, positive);
    } else {
      classify(os + h.first, so, h.count, ps[p], ps[sp + p], ps[2 * sp + p], ps[3 * sp + p], least, apart, positive);
    }
    res.stats.node_pairs += static_cast<std::uint32_t>(std::popcount(mask));
    apart &= mask;
    std::uint32_t near = mask & ~apart;
    // The group's margin: the least gap of all the children apart, those outside `mask` (an
    // expanded group's subset) included: at most the least of its own, so a margin that holds.
    if (apart != 0) add_group(probe_side ? detail::kProbeChildren : detail::kObjectChildren, p, o, apart, least);
    // As push_children, with kSpheresApart on the object node of a pair whose spheres do not
    // meet (gap > 0: the true gap is at least the computed one), which collide() would not visit.
    for (; near != 0; near &= ~(1u << (31 - std::countl_zero(near)))) {
      const unsigned k = 31 - static_cast<unsigned>(std::countl_zero(near));
      const std::uint32_t c = h.first + k, apart_flag = (positive >> k) & 1u ? kSpheresApart : 0u;
      stack[n++] = probe_side ? std::pair{c, o | apart_flag} : std::pair{p, c | apart_flag};
    }
    ST_ASSERT(n <= sc.stack_cap_, "walk_front leaves room for kMaxChildren before each split");
  }
  // On a stacked pair's object node: the pair's spheres are apart (split()). Object trees have
  // far fewer than 2^31 nodes (SphereTree's indices and the memory they take).
  static constexpr std::uint32_t kSpheresApart = 1u << 31;

  // The walk of collide() from the pairs on the stack, recording the front as it goes.
  void walk_front(std::pair<std::uint32_t, std::uint32_t>* stack, std::uint32_t n) {
    while (n > 0 && !res.stats.pair_limit_hit && !overflow) {
      if (opt.max_work != UINT64_MAX) [[unlikely]] {
        res.stats.exact_evals = detail::exact_evaluations - evals0;
        if (res.stats.work() > opt.max_work) {
          res.stats.work_limit_hit = true;
          return;
        }
      }
      // Plain names, not a structured binding: the lambdas below capture them (clang 14 cannot).
      const std::uint32_t p = stack[n - 1].first, o = stack[n - 1].second & ~kSpheresApart;
      const Spheres spheres = (stack[n - 1].second & kSpheresApart) != 0 ? Spheres::apart : Spheres::meet;
      --n;
      const SphereNode& hp = PT.nodes[p];
      const SphereNode& ho = OT.nodes[o];
      const bool tp = hp.leaf, to = ho.leaf;
      if (tp && to) {
        const detail::FrontEntry* known = rerooting ? known_leaf(p, o) : nullptr;
        if (!known)
          counted(o, [&] { leaf(p, o, nullptr, spheres); });
        else if (known->kind == detail::kLeafPair || known->kind == detail::kLeafPending)
          counted(o, [&] { visit_leaf(*known); });
        else if (detail::FrontEntry g = *known; still_group(g))  // a leaf pair its boxes proved apart
          push_group(g);
        else
          counted(o, [&] { leaf(p, o, nullptr, spheres); });
        continue;
      }
      if (n + kMaxChildren > sc.stack_cap_) [[unlikely]] {
        ++res.stats.truncated;
        return;
      }
      const bool object_side = !to && (tp || ho.radius >= s * hp.radius);
      split(p, o, !object_side, (1u << (object_side ? ho.count : hp.count)) - 1u, stack, n);
    }
  }

  // A group whose gap the motion used up: its pairs tested again at this pose.
  void expand(const detail::FrontEntry& e) {
    ++cc.stats_.expansions;
    auto* stack = sc.stack_.data();
    std::uint32_t n = 0;
    if (e.kind == detail::kPairApart) {
      put_probe_sphere(e.p);
      const float* ps = sc.psph_.data();
      const std::size_t sp = sc.nstride_p_;
      float gap;
      std::uint32_t apart = 0, positive = 0;
      classify(sc.osph_.data() + e.o, sc.nstride_o_, 1, ps[e.p], ps[sp + e.p], ps[2 * sp + e.p], ps[3 * sp + e.p], gap,
               apart, positive);
      res.stats.node_pairs += 1;
      if (apart & 1u) return add_group(detail::kPairApart, e.p, e.o, 0, gap);
      stack[n++] = {e.p, e.o | (positive & 1u ? kSpheresApart : 0u)};  // flagged as split() flags
    } else {
      if (e.kind == detail::kObjectChildren) put_probe_sphere(e.p);
      split(e.p, e.o, e.kind == detail::kProbeChildren, e.arg, stack, n);
    }
    walk_front(stack, n);
  }

  // A leaf pair's handling `f`, its work charged to the object leaf o as collide() charges it
  // (CollideConfig::node_work; a reused answer costs nothing).
  template <class F>
  void counted(std::uint32_t o, F&& f) {
    if (!opt.node_work) [[likely]]
      return f();
    const std::uint64_t tris = res.stats.tri_pairs;
    f();
    opt.node_work->charge_leaf_pair(o, res.stats.tri_pairs - tris);
  }
  // A leaf-pair entry of the front: built when pending, refreshed when due, else reused.
  void visit_leaf(const detail::FrontEntry& e) {
    if (e.kind == detail::kLeafPending) {
      leaf(e.p, e.o, nullptr);
      return;
    }
    const double moved = node_motion(e.c, e.r, e.pose);
    if (!(double(e.margin * float(768 + e.theta) / 1024.0f) > moved)) {
      ++cc.stats_.refreshes;
      leaf(e.p, e.o, &e);
    } else {
      reuse_leaf(e, e.anchor == e.pose ? moved : node_motion(e.c, e.r, e.anchor));
    }
  }
  // Re-rooting: the old front's entry for leaf pair (p, o), if it has one (a leaf-pair entry of
  // front_, or a group of old_groups_: kOldGroup marks those indices).
  static constexpr std::uint32_t kOldGroup = 1u << 31;
  const detail::FrontEntry* known_leaf(std::uint32_t p, std::uint32_t o) const {
    const std::uint64_t key = (std::uint64_t{p} << 32) | o;
    const auto it = std::lower_bound(cc.leaf_index_.begin(), cc.leaf_index_.end(), std::pair{key, 0u});
    if (it == cc.leaf_index_.end() || it->first != key) return nullptr;
    return it->second & kOldGroup ? &cc.old_groups_[it->second & ~kOldGroup] : &cc.front_[it->second];
  }

  // The round: every entry of the front kept, refreshed or expanded (or, the first round, the
  // roots expanded). When the front has doubled since it was last walked from the roots, that
  // walk is done again instead (its leaf pairs' entries kept, matched by (p, o)): a front only
  // refines as the probe moves, and the fine apart pairs it leaves behind would otherwise pile
  // up. False when the pool went over max_bytes (the caller runs collide()).
  bool run() {
    std::uint64_t scanned = 0;
    cc.next_front_.clear();
    const std::size_t limit = cc.config_.max_bytes;
    auto expand_root = [&](std::uint32_t r) { expand(entry(detail::kPairApart, 0, r)); };
    {  // the path (coherent.hpp, top): the whole probe's bound from the last cached pose added,
       // rounded up to a multiple of the quantum, one at least (a power of two: the scalings and
       // the rounding are exact, and so is the sum below 2^52 quanta; a bound small enough to
       // underflow in quanta still counts one)
      const double q = cc.path_quantum_;
      const std::uint32_t prev = cc.last_cached_;
      const double step = prev != ~0u && round - prev < CoherentCollider::kPoses
                              ? std::max(1.0, std::ceil(delta(prev).whole * cc.path_per_quantum_)) * q
                              : std::numeric_limits<double>::infinity();  // none kept: a gap
      path = cc.path_ + step;
      if (!(path < 0x1p52 * q)) {  // a gap, or the sums about to be inexact: no level holds across
        path = 0;
        for (std::size_t i = 0; i < cc.groups_.size(); ++i)
          if (cc.groups_[i].kind != detail::kDead)
            cc.groups_[i].level = cc.glevel_[i] = -std::numeric_limits<double>::infinity();
      }
      cc.path_ = path;
      cc.last_cached_ = round;
    }
    if (rerooting) {  // every group is made again by the walk; the leaf pairs' entries are looked up
      ++cc.stats_.reroots;
      cc.old_groups_.clear();
      cc.old_groups_.swap(cc.groups_);
      cc.glevel_.clear();
      cc.dead_ = 0;
      cc.leaf_index_.clear();
      for (std::uint32_t i = 0; i < cc.front_.size(); ++i) {
        const detail::FrontEntry& e = cc.front_[i];
        cc.leaf_index_.emplace_back((std::uint64_t{e.p} << 32) | e.o, i);
      }
      for (std::uint32_t i = 0; i < cc.old_groups_.size(); ++i) {
        const detail::FrontEntry& e = cc.old_groups_[i];
        if (e.kind == detail::kPairApart && PT.nodes[e.p].leaf && OT.nodes[e.o].leaf)
          cc.leaf_index_.emplace_back((std::uint64_t{e.p} << 32) | e.o, i | kOldGroup);
      }
      std::sort(cc.leaf_index_.begin(), cc.leaf_index_.end());
    }
    if (!cc.have_front_ || rerooting) {
      if (!rerooting) ++cc.stats_.rebuilds, fresh = true;
      if (!opt.restrict_object) {
        expand_root(0);
      } else {
        for (const std::uint32_t r : opt.object_roots)
          if (r < OT.num_nodes()) expand_root(r);
      }
    } else {
      // Whether the round stops here: a limit hit, the pool over max_bytes, or the work budget
      // spent (it counts what this round does: each entry looked at and each answer taken from
      // a certificate is a unit, besides the tests it runs: CollideStats::work()).
      auto cut = [&](std::uint64_t units) {
        if (res.stats.pair_limit_hit || res.stats.work_limit_hit || res.stats.truncated != 0) return true;
        scanned += units;
        if (opt.max_work != UINT64_MAX) [[unlikely]] {
          res.stats.exact_evals = detail::exact_evaluations - evals0;
          if (res.stats.work() + scanned > opt.max_work) {
            res.stats.work_limit_hit = true;
            return true;
          }
        }
        overflow = pool_bytes() > limit;
        return overflow;
      };
      for (const detail::FrontEntry& e : cc.front_) {  // the leaf pairs
        if (cut(1 + e.count)) break;
        counted(e.o, [&] { visit_leaf(e); });
      }
      // The groups, in place: the groups the expansions append are at this pose (not looked at).
      // Without a work budget a group still valid needs no check of the limits (nothing grew).
      const bool budgeted = opt.max_work != UINT64_MAX;
      // The scan reads the groups' levels (8 bytes a group), the group itself only when the path
      // has passed its level.
      const std::size_t groups = cc.groups_.size();
      const double path_now = path;  // in a register: the loop stores through pointers
      for (std::size_t i = 0; i < groups; ++i) {
        if (path_now < cc.glevel_[i]) {  // still_group()'s shortcut (a dead group's level is +inf)
          if (budgeted && cc.groups_[i].kind != detail::kDead && cut(1)) break;
          continue;
        }
        detail::FrontEntry& g = cc.groups_[i];
        const bool valid = still_group(g);
        if ((budgeted || !valid) && cut(1)) break;
        if (valid) {
          cc.glevel_[i] = g.level;
          continue;
        }
        const detail::FrontEntry e = g;  // expand() appends to groups_
        g.kind = detail::kDead;
        cc.glevel_[i] = std::numeric_limits<double>::infinity();
        ++cc.dead_;
        expand(e);
      }
    }
    flush_margins();
    flush_hard();
    flush_tris();
    flush_full();
    if (pool_bytes() > limit) overflow = true;
    res.stats.exact_evals = detail::exact_evaluations - evals0;
    cc.leaf_entries_ = leaf_count;
    if (rerooting) {  // the old leaf pairs not reached again left their candidates behind
      std::size_t live = 0;
      for (const detail::FrontEntry& e : cc.next_front_) live += e.kind == detail::kLeafPair ? e.count : 0;
      cc.garbage_ = cc.cands_.size() - live;
    }
    return !overflow;
  }
};
