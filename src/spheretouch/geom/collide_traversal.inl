// SPDX-License-Identifier: BSD-3-Clause
// The collision query's traversal and leaf stage (collide.cpp), compiled once per instruction set:
// collide.cpp includes this file inside each ISA's target region (simd.hpp) with ST_COLLIDE_SIMD
// naming the namespace of the node and box kernels' lanes (simd::sse2, ...) and ST_COLLIDE_WIDE_SIMD
// that of the triangle filter's (the same, except on AVX-512: 16 lanes for the triangles, 8 for
// the nodes, whose arrays are padded for 8 children, and the boxes, measured faster at 8: the
// 16-lane gathers cost more than they save at 24 faces a leaf), so each ISA gets its own
// CollideQuery specialisation, kernels included, and collide() runs the one simd::active_isa() names.
// No #include here: everything is defined inside the region, for its ISA.

template <>
struct CollideQuery<ST_COLLIDE_WIDE_SIMD::Lanes> {
  using Lanes = ST_COLLIDE_SIMD::Lanes;
  using Mask = ST_COLLIDE_SIMD::Mask;
  using WideLanes = ST_COLLIDE_WIDE_SIMD::Lanes;
  using WideMask = ST_COLLIDE_WIDE_SIMD::Mask;

  // The three filters are written once over this ISA's lanes, a step of a whole vector at a time;
  // every ISA gives the same masks.

  // Bit k (k < n <= 8) set when sphere k of a float SoA block (x at c[0], y at c[st], z at c[2 st],
  // radius at c[3 st]) meets the sphere (qx, qy, qz; qr): |c_k - q|^2 <= (r_k + qr)^2 in float.
  // Conservative by the slack in the probe radii (see the top of this file). Reads whole steps past
  // n: the SoA arrays are padded by kMaxChildren.
  static std::uint32_t sphere_mask(const float* c, std::size_t st, std::uint32_t n, float qx, float qy, float qz, float qr) {
    const Lanes x = Lanes::broadcast(qx), y = Lanes::broadcast(qy), z = Lanes::broadcast(qz), r = Lanes::broadcast(qr);
    std::uint32_t m = 0;
    for (std::uint32_t k = 0; k < n; k += Lanes::width) {
      const Lanes dx = Lanes::load(c + k) - x;
      const Lanes dy = Lanes::load(c + st + k) - y;
      const Lanes dz = Lanes::load(c + 2 * st + k) - z;
      const Lanes rr = Lanes::load(c + 3 * st + k) + r;
      m |= (dx * dx + dy * dy + dz * dz <= rr * rr).bits() << k;
    }
    return m & ((1u << n) - 1u);
  }

  // Bit i (i < n <= 64) set when box i of a float SoA block (lo x at c[i], lo y at c[st + i], ...,
  // hi z at c[5 st + i]) meets box b (lo xyz, hi xyz). Pure comparisons, exact. Reads whole steps
  // past n: the SoA arrays are padded by kMaxLeafFaces.
  static std::uint64_t soa_box_mask(const float* c, std::size_t st, std::uint32_t n, const float* b) {
    const Lanes blx = Lanes::broadcast(b[0]), bly = Lanes::broadcast(b[1]), blz = Lanes::broadcast(b[2]);
    const Lanes bhx = Lanes::broadcast(b[3]), bhy = Lanes::broadcast(b[4]), bhz = Lanes::broadcast(b[5]);
    std::uint64_t m = 0;
    for (std::uint32_t i = 0; i < n; i += Lanes::width) {
      const Mask h = (Lanes::load(c + i) <= bhx) & (Lanes::load(c + st + i) <= bhy) &
                     (Lanes::load(c + 2 * st + i) <= bhz) & (Lanes::load(c + 3 * st + i) >= blx) &
                     (Lanes::load(c + 4 * st + i) >= bly) & (Lanes::load(c + 5 * st + i) >= blz);
      m |= std::uint64_t{h.bits()} << i;
    }
    return n >= 64 ? m : m & ((std::uint64_t{1} << n) - 1);
  }

  // Bit j (j < n <= 64) set when face box fb[j] meets box b (lo xyz, hi xyz), and `ou` the union of
  // those boxes (lo xyz, hi xyz; +inf/-inf when there are none), both exact: comparisons, min and
  // max. A step's boxes are gathered from the 24-byte AoS, reading nothing past fb[n - 1]
  // (face_boxes is not padded). The union rides on the gathered lanes: a loop over the set bits
  // reading each box again was a fifth of leaf_leaf's time (~16 boxes a leaf pair in contact).
  static std::uint64_t face_box_mask(const FaceBox* fb, std::uint32_t n, const float* b, float* ou) {
    static_assert(sizeof(FaceBox) == 6 * sizeof(float), "face boxes are read as 6 packed floats");
    const Lanes blx = Lanes::broadcast(b[0]), bly = Lanes::broadcast(b[1]), blz = Lanes::broadcast(b[2]);
    const Lanes bhx = Lanes::broadcast(b[3]), bhy = Lanes::broadcast(b[4]), bhz = Lanes::broadcast(b[5]);
    const Lanes inf = Lanes::broadcast(std::numeric_limits<float>::infinity());
    const Lanes ninf = Lanes::broadcast(-std::numeric_limits<float>::infinity());
    Lanes ulx = inf, uly = inf, ulz = inf, uhx = ninf, uhy = ninf, uhz = ninf;
    const float* f = reinterpret_cast<const float*>(fb);
    std::uint64_t m = 0;
    for (std::uint32_t j = 0; j < n; j += Lanes::width) {
      const std::uint32_t live = n - j;
      const float* p = f + 6 * j;
      const Lanes lx = Lanes::gather<6>(p, live), ly = Lanes::gather<6>(p + 1, live), lz = Lanes::gather<6>(p + 2, live);
      const Lanes hx = Lanes::gather<6>(p + 3, live), hy = Lanes::gather<6>(p + 4, live),
                  hz = Lanes::gather<6>(p + 5, live);
      // Lanes past the last box are gathered as 0 and may compare true: the live mask clears them.
      const Mask h = Mask::first(live) & (lx <= bhx) & (ly <= bhy) & (lz <= bhz) & (hx >= blx) & (hy >= bly) & (hz >= blz);
      ulx = min(ulx, select(h, lx, inf)), uly = min(uly, select(h, ly, inf)), ulz = min(ulz, select(h, lz, inf));
      uhx = max(uhx, select(h, hx, ninf)), uhy = max(uhy, select(h, hy, ninf)), uhz = max(uhz, select(h, hz, ninf));
      m |= std::uint64_t{h.bits()} << j;
    }
    ou[0] = hmin(ulx), ou[1] = hmin(uly), ou[2] = hmin(ulz);
    ou[3] = hmax(uhx), ou[4] = hmax(uhy), ou[5] = hmax(uhz);
    return m;
  }

  // One candidate axis `a` of the triangle filter: P's and O's projections (lanes of 16 pairs,
  // coordinates relative to O's vertex 0, so O's own vertex 0 projects to 0). `sep` gains the lanes
  // whose gap along a exceeds the bound (disjoint, proved), `inter` keeps the lanes whose
  // projections overlap by more than the bound on both sides (see tri_filter).
  [[gnu::always_inline]] static void tri_axis(WideLanes ax, WideLanes ay, WideLanes az, const WideLanes* p,
                                              const WideLanes* o, WideLanes bound, WideMask& sep, WideMask& inter) {
    const WideLanes d0 = ax * p[0] + ay * p[1] + az * p[2];
    const WideLanes d1 = ax * p[3] + ay * p[4] + az * p[5];
    const WideLanes d2 = ax * p[6] + ay * p[7] + az * p[8];
    const WideLanes e1 = ax * o[0] + ay * o[1] + az * o[2];
    const WideLanes e2 = ax * o[3] + ay * o[4] + az * o[5];
    const WideLanes zero = WideLanes::broadcast(0.0f);
    const WideLanes pmin = min(d0, min(d1, d2)), pmax = max(d0, max(d1, d2));
    const WideLanes omin = min(zero, min(e1, e2)), omax = max(zero, max(e1, e2));
    sep = sep | ((omin - pmax) > bound) | ((pmin - omax) > bound);
    inter = inter & ((pmax - omin) > bound) & ((omax - pmin) > bound);
  }

  // The lanes of one step of a batch (v as for tri_filter, from column j): the 15 coordinates, the
  // bound, the edges and the lanes the analysis covers (live, finite, M in range).
  struct TriStep {
    WideLanes p[9], o[6], scale, bound, ex[3], ey[3], ez[3], fx[3], fy[3], fz[3];
    std::uint32_t ok;  ///< bit l: lane l may be decided
  };
  [[gnu::always_inline]] static void tri_step(const float (*v)[kTriBatch], std::uint32_t n, std::uint32_t j, TriStep& t) {
    for (int k = 0; k < 9; ++k) t.p[k] = WideLanes::load(v[k] + j);
    for (int k = 0; k < 6; ++k) t.o[k] = WideLanes::load(v[9 + k] + j);
    WideLanes m = abs(t.o[0]), sum = t.o[0];
    for (int k = 1; k < 6; ++k) m = max(m, abs(t.o[k])), sum = sum + t.o[k];
    for (int k = 0; k < 9; ++k) m = max(m, abs(t.p[k])), sum = sum + t.p[k];
    // (sum - sum) is 0 for finite coordinates, NaN if any is NaN or infinite (or the sum overflows).
    t.ok = (WideMask::first(n - j) & ((sum - sum) <= WideLanes::broadcast(0.0f)) &
            (m >= WideLanes::broadcast(0x1p-30f)) & (m <= WideLanes::broadcast(0x1p36f)))
               .bits();
    t.scale = m;
    t.bound = WideLanes::broadcast(0x1p-14f) * m * m * m;
    // Edges: P's e0 = p1 - p0, e1 = p2 - p1, e2 = p0 - p2; O's f0 = o1, f1 = o2 - o1, f2 = -o2.
    for (int k = 0; k < 3; ++k) {
      const int a = 3 * k, b = 3 * ((k + 1) % 3);
      t.ex[k] = t.p[b] - t.p[a], t.ey[k] = t.p[b + 1] - t.p[a + 1], t.ez[k] = t.p[b + 2] - t.p[a + 2];
    }
    const WideLanes zero = WideLanes::broadcast(0.0f);
    t.fx[0] = t.o[0], t.fy[0] = t.o[1], t.fz[0] = t.o[2];
    t.fx[1] = t.o[3] - t.o[0], t.fy[1] = t.o[4] - t.o[1], t.fz[1] = t.o[5] - t.o[2];
    t.fx[2] = zero - t.o[3], t.fy[2] = zero - t.o[4], t.fz[2] = zero - t.o[5];
  }
  // The two normals' axes of a step.
  [[gnu::always_inline]] static void tri_normals(const TriStep& t, WideMask& sep, WideMask& inter) {
    tri_axis(t.ey[0] * t.ez[1] - t.ez[0] * t.ey[1], t.ez[0] * t.ex[1] - t.ex[0] * t.ez[1],
             t.ex[0] * t.ey[1] - t.ey[0] * t.ex[1], t.p, t.o, t.bound, sep, inter);
    tri_axis(t.fy[0] * t.fz[1] - t.fz[0] * t.fy[1], t.fz[0] * t.fx[1] - t.fx[0] * t.fz[1],
             t.fx[0] * t.fy[1] - t.fy[0] * t.fx[1], t.p, t.o, t.bound, sep, inter);
  }

  // The first, cheap pass: bit i set when pair i is proved disjoint along one of the two normals
  // (most candidates: boxes overlapping, triangles apart). The others go to tri_filter.
  static std::uint32_t tri_apart_by_normals(const float (*v)[kTriBatch], std::uint32_t n) {
    std::uint32_t apart = 0;
    for (std::uint32_t j = 0; j < n; j += WideLanes::width) {
      TriStep t;
      tri_step(v, n, j, t);
      WideMask sep = WideMask::first(0), inter = WideMask::first(32);
      tri_normals(t, sep, inter);
      apart |= (sep.bits() & t.ok) << j;
    }
    return apart;
  }

  // The certified triangle filter: for n <= kTriBatch pairs, v[0..8][i] = probe triangle i's
  // vertices and v[9..14][i] = the object triangle's vertices 1 and 2, each minus the object
  // triangle's vertex 0, in double then rounded to float. Sets bit i of `decided` when pair i is
  // proved disjoint or proved intersecting, and then bit i of `overlap` to the answer; an
  // undecided pair goes to tri_tri_overlap.
  //
  // Why it never errs. Axes: the two normals and the nine edge crosses, as float cross products
  // of float edges. Disjoint: ANY direction along which the projections are apart separates the
  // triangles, so an axis' rounding does not matter, only that of the gap. Intersecting: the
  // origin is in P - O (closed) iff h(a) = max_P a.p - min_O a.o >= 0 for every facet normal a of
  // P - O, and for triangles those normals are among +-n_P, +-n_O, +-e_i x f_j; so both gaps of all
  // 11 axes exceeding the bound, with the bound covering the computed axis' distance from the
  // exact one, proves it. Bound, with u = 2^-24 and M = the largest |coordinate| of the 15 floats:
  // a vertex is within 1.03 u M of its exact value (one double, one float rounding); an edge within
  // 4.1 u M, |edge| <= 2M; an axis component within 48.4 u M^2 of the exact cross of exact edges,
  // |axis|_1 <= 24.1 M^2, so h moves by at most 296 u M^3 from axis error; a projection (3-term
  // float dot) is within 97.1 u M^3 of the exact axis-times-exact-vertex; a gap (two projections
  // and a subtraction) within 243 u M^3. Together 539 u M^3 < bound = 2^-14 M^3 = 1024 u M^3,
  // computed in float with three roundings (>= 1020 u M^3). Lanes with M outside [2^-30, 2^36]
  // (underflow below the bound, overflow of the products) or a non-finite coordinate are left
  // undecided, so NaN never decides anything. Separation and intersection both proved cannot
  // happen; should rounding ever claim both, the pair is left to the exact test.
  static void tri_filter(const float (*v)[kTriBatch], std::uint32_t n, std::uint32_t& decided, std::uint32_t& overlap) {
    decided = overlap = 0;
    for (std::uint32_t j = 0; j < n; j += WideLanes::width) {
      TriStep t;
      tri_step(v, n, j, t);
      WideMask sep = WideMask::first(0), inter = WideMask::first(32);
      tri_normals(t, sep, inter);
      if ((sep.bits() & t.ok) != t.ok)
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b)
            tri_axis(t.ey[a] * t.fz[b] - t.ez[a] * t.fy[b], t.ez[a] * t.fx[b] - t.ex[a] * t.fz[b],
                     t.ex[a] * t.fy[b] - t.ey[a] * t.fx[b], t.p, t.o, t.bound, sep, inter);
      const std::uint32_t sp = sep.bits() & t.ok, in = inter.bits() & t.ok;
      decided |= (sp ^ in) << j;
      overlap |= (in & ~sp) << j;
    }
  }

  const Mesh& P;
  const SphereTree& PT;
  const Mesh& O;
  const SphereTree& OT;
  const CollideConfig& opt;
  CollideScratch& sc;
  CollideResult& res;
  RelTransform rt;
  double s = 1;     // >= ||R||_2
  float slack = 0;  // absolute slack of the float sphere tests, mm (see sphere_mask)
  std::uint32_t gen = 0;
  std::uint64_t evals0 = detail::exact_evaluations;  // this thread's exact evaluations before the query
  bool exact = true;
  std::uint32_t stop = 0;  // approximate mode: layer at which nodes become terminal
  // Candidate triangle pairs waiting for the filter (probe slot, object face), flushed when full
  // and at the end of each descent.
  std::uint32_t tri_slot[kTriBatch] = {}, tri_face[kTriBatch] = {};
  std::uint32_t tri_n = 0;
  // ... and those the normals did not settle, with their coordinates, waiting for the full filter.
  std::uint32_t full_slot[kTriBatch] = {}, full_face[kTriBatch] = {};
  std::uint32_t full_n = 0;
  alignas(64) float full_v[15][kTriBatch] = {};

  // Probe node i's sphere in object-local into the float SoA: centre apply(rt, c) rounded to
  // float, radius s·r + slack.
  void put_probe_sphere(std::uint32_t i) {
    const SphereNode& h = PT.nodes[i];
    const Vec3 c = apply(rt, centre_of(h));
    float* ps = sc.psph_.data();
    const std::size_t st = sc.nstride_p_;
    for (int k = 0; k < 3; ++k) ps[k * st + i] = static_cast<float>(c[k]);
    ps[3 * st + i] = static_cast<float>(s * h.radius + slack);
  }
  // The children of probe node p, transformed once per query.
  void probe_children(std::uint32_t p) {
    if (sc.cstamp_[p] == gen) return;
    sc.cstamp_[p] = gen;
    const SphereNode& h = PT.nodes[p];
    for (std::uint32_t k = 0; k < h.count; ++k) put_probe_sphere(h.first + k);
  }

  bool terminal_p(const SphereNode& n) const { return n.leaf || (!exact && n.depth >= stop); }
  bool terminal_o(const SphereNode& n) const { return n.leaf || (!exact && n.depth >= stop); }

  // Float bounds of a double, branch-free: x ∓ |x|·2^-22 ∓ 1e-30 is at least 2^-22·|x| away from x
  // on the wide side, and float conversion moves it by at most 2^-24 of itself, so the result is
  // still on the wide side (x = 0 included: ±1e-30 is a normal float).
  static float float_below(double x) { return static_cast<float>(x - std::abs(x) * 0x1p-22 - 1e-30); }
  static float float_above(double x) { return static_cast<float>(x + std::abs(x) * 0x1p-22 + 1e-30); }

  // Leaf vertices l (n of them, component c at l[c * nv]) through rt into t (same layout), and
  // each coordinate's float bounds into lo and hi (same layout). A function of its own on
  // restrict pointers: so GCC 12 vectorizes the loop on AVX2 and AVX-512 (written inside
  // probe_leaf, it vectorized it on neither; SSE2 has no fma instruction to vectorize with).
  static void transform_leaf(const double* __restrict l, std::size_t nv, std::uint32_t n, const RelTransform& rt,
                             double* __restrict t, float* __restrict lo, float* __restrict hi) {
    const double r00 = rt.R(0, 0), r01 = rt.R(0, 1), r02 = rt.R(0, 2), t0 = rt.t[0];
    const double r10 = rt.R(1, 0), r11 = rt.R(1, 1), r12 = rt.R(1, 2), t1 = rt.t[1];
    const double r20 = rt.R(2, 0), r21 = rt.R(2, 1), r22 = rt.R(2, 2), t2 = rt.t[2];
    for (std::uint32_t i = 0; i < n; ++i) {
      const double x = l[i], y = l[nv + i], z = l[2 * nv + i];
      const double a = std::fma(r00, x, std::fma(r01, y, std::fma(r02, z, t0)));
      const double b = std::fma(r10, x, std::fma(r11, y, std::fma(r12, z, t1)));
      const double c = std::fma(r20, x, std::fma(r21, y, std::fma(r22, z, t2)));
      t[i] = a, t[nv + i] = b, t[2 * nv + i] = c;
      lo[i] = float_below(a), lo[nv + i] = float_below(b), lo[2 * nv + i] = float_below(c);
      hi[i] = float_above(a), hi[nv + i] = float_above(b), hi[2 * nv + i] = float_above(c);
    }
  }

  // Probe leaf p transformed (its vertices' doubles into ptx_, their float bounds into vbnd_) and
  // its box: the union of its face boxes, which is the least / greatest bound over its vertices
  // (every vertex of a leaf's range belongs to one of its faces). Once per query; the face boxes
  // themselves wait for probe_faces(): a leaf pair that the leaf boxes settle never needs them.
  const std::array<float, 8>& probe_leaf(std::uint32_t p) {
    std::array<float, 8>& u = sc.lbox_[p];
    if (sc.lstamp_[p] == gen) return u;
    sc.lstamp_[p] = gen;
    ++res.stats.probe_leaves;
    const auto [v0, v1] = sc.lvrange_[p];
    const std::uint32_t n = v1 - v0;
    ST_ASSERT(n <= 3 * kMaxLeafFaces, "a leaf's distinct vertices are at most three a face");
    // The very doubles tri_tri_overlap will see: apply(rt, v) of the same local vertices, each
    // coordinate fma(R_i0, x, fma(R_i1, y, fma(R_i2, z, t_i))) as apply() computes it (an fma is
    // rounded once, so a vector fma gives the same bits), and each coordinate's float bounds.
    const std::size_t nv = sc.nverts_;
    float* lo = sc.vbnd_.data() + v0;
    float* hi = lo + 3 * nv;
    transform_leaf(sc.lverts_.data() + v0, nv, n, rt, sc.ptx_.data() + v0, lo, hi);
    for (int k = 0; k < 3; ++k) bounds_union(lo + k * nv, hi + k * nv, n, u[k], u[3 + k]);
    u[6] = 0;  // face boxes not made yet
    return u;
  }

  // The least of lo[0, n) and the greatest of hi[0, n) (NaN left out), by whole vectors: the last
  // one overlaps the one before when n is not a multiple of the width (a lane seen twice does not
  // change a min or a max), so nothing past n is read; fewer than a vector, one at a time.
  static void bounds_union(const float* lo, const float* hi, std::uint32_t n, float& least, float& greatest) {
    const float inf = std::numeric_limits<float>::infinity();
    constexpr auto w = static_cast<std::uint32_t>(Lanes::width);
    if (n < w) {
      least = inf, greatest = -inf;
      for (std::uint32_t i = 0; i < n; ++i) least = std::min(least, lo[i]), greatest = std::max(greatest, hi[i]);
      return;
    }
    // min(x, acc) / max(x, acc) keep acc where x is NaN (the second operand wins, as minps does).
    Lanes a = Lanes::broadcast(inf), b = Lanes::broadcast(-inf);
    for (std::uint32_t i = 0;; i += w) {
      const std::uint32_t at = std::min(i, n - w);
      a = min(Lanes::load(lo + at), a);
      b = max(Lanes::load(hi + at), b);
      if (at == n - w) break;
    }
    least = hmin(a), greatest = hmax(b);
  }

  // Probe leaf p's face boxes (float, enclosing the transformed doubles) into pbox_ by slot, once
  // per query, after probe_leaf(p). float_below and float_above are non-decreasing (a product by
  // a power of two, a difference and a rounding to float, each monotone), so the least
  // float_below of a face's three vertices is float_below of their least coordinate: the face box
  // the face's own doubles give, taken from the bounds made once a vertex.
  void probe_faces(std::uint32_t p) {
    std::array<float, 8>& u = sc.lbox_[p];
    ST_ASSERT(sc.lstamp_[p] == gen, "probe_leaf() transformed the leaf this query");
    if (u[6] != 0) return;
    u[6] = 1;
    const SphereNode& hp = PT.nodes[p];
    const std::size_t nv = sc.nverts_;
    const float* lo = sc.vbnd_.data();
    const float* hi = lo + 3 * nv;
    float* pb = sc.pbox_.data();
    const std::size_t st = sc.pstride_;
    for (std::uint32_t slot = hp.first, e = hp.first + hp.count; slot < e; ++slot) {
      const auto& ix = sc.lidx_[slot];
      for (int k = 0; k < 3; ++k) {
        const float* l = lo + k * nv;
        const float* h = hi + k * nv;
        pb[k * st + slot] = std::min(l[ix[0]], std::min(l[ix[1]], l[ix[2]]));
        pb[(3 + k) * st + slot] = std::max(h[ix[0]], std::max(h[ix[1]], h[ix[2]]));
      }
    }
  }

  void emit(std::uint32_t pf, std::uint32_t of) {
    res.pairs.push_back({pf, of});
    if (res.pairs.size() > opt.max_pairs) [[unlikely]]
      res.stats.pair_limit_hit = true;
    if (sc.pmark_[pf] != gen) {
      sc.pmark_[pf] = gen;
      ++res.probe_faces;
    }
    if (sc.omark_[of] != gen) {
      sc.omark_[of] = gen;
      ++res.object_faces;
    }
  }

  // Bit i set when probe face box at slot first + i (i < n) meets box b (lo xyz, hi xyz).
  std::uint64_t probe_mask(std::uint32_t first, std::uint32_t n, const float* b) const {
    return soa_box_mask(sc.pbox_.data() + first, sc.pstride_, n, b);
  }

  // leaf_leaf(), its work charged to the object leaf (CollideConfig::node_work): 1 and its
  // candidate triangle pairs when it had any. Only those: charging every sphere test and every
  // leaf pair cost 3-6 % of the query (an extra random access per test), this under 1.5 %, and the
  // triangle tests are most of a contact's work.
  void counted_leaf_leaf(std::uint32_t p, std::uint32_t o) {
    if (!opt.node_work) [[likely]]
      return leaf_leaf(p, o);
    const std::uint64_t tris = res.stats.tri_pairs;
    leaf_leaf(p, o);
    opt.node_work->charge_leaf_pair(o, res.stats.tri_pairs - tris);
  }

  // Leaf pair: object faces against the probe leaf's box, probe faces against the survivors'
  // union box, then face box against face box, then the exact triangle test. Boxes are compared
  // without arithmetic, so every rejection is exact (see the top of this file).
  void leaf_leaf(std::uint32_t p, std::uint32_t o) {
    const SphereNode& hp = PT.nodes[p];
    const SphereNode& ho = OT.nodes[o];
    ++res.stats.leaf_pairs;
    const std::array<float, 8>& u = probe_leaf(p);
    // Probe leaf box against the object leaf sphere (float, radius widened by the slack) before
    // the object's face boxes are touched: most leaf pairs end here.
    {
      const float* os = sc.osph_.data();
      const std::size_t so = sc.nstride_o_;
      float d2 = 0;
      for (int k = 0; k < 3; ++k) {
        const float c = os[k * so + o];
        const float d = std::max(0.0f, std::max(u[k] - c, c - u[3 + k]));
        d2 += d * d;
      }
      const float r = os[3 * so + o] + slack;
      if (d2 > r * r) return;
    }
    // Probe leaf box against the object leaf box (union of its face boxes).
    {
      const std::array<float, 8>& v = sc.obox_[o];
      // Branch-free on purpose: int-valued | of all six comparisons, one branch at the end.
      if (int(v[0] > u[3]) | int(v[1] > u[4]) | int(v[2] > u[5]) | int(v[3] < u[0]) | int(v[4] < u[1]) | int(v[5] < u[2]))
        return;
    }
    const FaceBox* ob = OT.face_boxes.data() + ho.first;
    float ou[6];
    const std::uint64_t mo = face_box_mask(ob, ho.count, u.data(), ou);
    if (mo == 0) return;
    probe_faces(p);
    const std::uint64_t mp = probe_mask(hp.first, hp.count, ou);
    if (mp == 0) return;
    for (std::uint64_t m = mo; m != 0; m &= m - 1) {
      const unsigned j = static_cast<unsigned>(std::countr_zero(m));
      const FaceBox& fb = ob[j];
      const float b[6] = {fb.lo[0], fb.lo[1], fb.lo[2], fb.hi[0], fb.hi[1], fb.hi[2]};
      std::uint64_t mf = std::popcount(mp) == 1 ? mp : (probe_mask(hp.first, hp.count, b) & mp);
      if (mf == 0) continue;
      const std::uint32_t of = OT.face_order[ho.first + j];
      for (; mf != 0; mf &= mf - 1) {
        const std::uint32_t slot = hp.first + static_cast<unsigned>(std::countr_zero(mf));
        ++res.stats.tri_pairs;
        if (!opt.tri_filter) {
          if (exact_pair(slot, of)) emit(PT.face_order[slot], of);
          continue;
        }
        ST_ASSERT(tri_n < kTriBatch, "a full batch was flushed before the next candidate");
        tri_slot[tri_n] = slot;
        tri_face[tri_n] = of;
        if (++tri_n == kTriBatch) flush_tris();
      }
    }
  }

  // tri_tri_overlap on the very doubles the box filters bounded (counted in stats.tri_exact).
  bool exact_pair(std::uint32_t slot, std::uint32_t of) {
    ++res.stats.tri_exact;
    return overlaps(slot, of);
  }
  // The exact test itself, uncounted (exact_pair, and the checking mode below).
  bool overlaps(std::uint32_t slot, std::uint32_t of) const {
    const auto& ix = sc.lidx_[slot];
    const Tri& ot = O.faces[of];
    return tri_tri_overlap(sc.ptx(ix[0]), sc.ptx(ix[1]), sc.ptx(ix[2]), O.local[ot[0]], O.local[ot[1]], O.local[ot[2]]);
  }
  // Lanes n.. of a batch: read by whole steps, never decided.
  static void pad_lanes(float (*v)[kTriBatch], std::uint32_t n) {
    for (std::uint32_t i = n; i < kTriBatch; ++i)
      for (int r = 0; r < 15; ++r) v[r][i] = 0.0f;
  }

  // The waiting candidates (probe slot, object face) as tri_filter reads them: coordinates minus
  // the object triangle's vertex 0, in double, then rounded to float.
  void prep_tris(const std::uint32_t* slots, const std::uint32_t* faces, std::uint32_t n, float (*v)[kTriBatch]) const {
    for (std::uint32_t i = 0; i < n; ++i) {
      const auto& ix = sc.lidx_[slots[i]];
      const Tri& ot = O.faces[faces[i]];
      const Vec3& o0 = O.local[ot[0]];
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) v[3 * k + c][i] = static_cast<float>(sc.ptx_[c * sc.nverts_ + ix[k]] - o0[c]);
      // Candidates come grouped by object face (leaf_leaf's inner loop): its two edges once.
      if (i > 0 && faces[i] == faces[i - 1]) {
        for (int r = 9; r < 15; ++r) v[r][i] = v[r][i - 1];
        continue;
      }
      for (int k = 1; k < 3; ++k)
        for (int c = 0; c < 3; ++c) v[9 + 3 * (k - 1) + c][i] = static_cast<float>(O.local[ot[k]][c] - o0[c]);
    }
    pad_lanes(v, n);
  }

  // Checking mode (ST_CHECKS: debug, sanitizer and fuzzer builds): a decision of the filter
  // against the exact test (not counted in tri_exact).
  void check_decision(std::uint32_t slot, std::uint32_t of, bool hit) const {
    ST_ASSERT(hit == overlaps(slot, of), "the triangle filter's decision is the exact test's");
  }

  // The waiting candidates through the normals' pass; those it cannot prove apart wait for the
  // full filter (flush_full), so its nine edge axes run on full batches of the hard pairs only.
  void flush_tris() {
    if (tri_n == 0) return;
    alignas(64) float v[15][kTriBatch];
    prep_tris(tri_slot, tri_face, tri_n, v);
    const std::uint32_t apart = tri_apart_by_normals(v, tri_n);
    for (std::uint32_t i = 0; i < tri_n; ++i) {
      if ((apart >> i) & 1u) {
        check_decision(tri_slot[i], tri_face[i], false);
        continue;
      }
      ST_ASSERT(full_n < kTriBatch, "a full batch of hard pairs was filtered before the next");
      full_slot[full_n] = tri_slot[i];
      full_face[full_n] = tri_face[i];
      for (int r = 0; r < 15; ++r) full_v[r][full_n] = v[r][i];
      if (++full_n == kTriBatch) flush_full();
    }
    tri_n = 0;
  }

  // The full filter on the pairs the normals did not settle; the undecided through the exact test.
  void flush_full() {
    if (full_n == 0) return;
    pad_lanes(full_v, full_n);
    std::uint32_t decided = 0, overlap = 0;
    tri_filter(full_v, full_n, decided, overlap);
    for (std::uint32_t i = 0; i < full_n; ++i) {
      bool hit;
      if ((decided >> i) & 1u) {
        hit = (overlap >> i) & 1u;
        check_decision(full_slot[i], full_face[i], hit);
      } else {
        hit = exact_pair(full_slot[i], full_face[i]);
      }
      if (hit) emit(PT.face_order[full_slot[i]], full_face[i]);
    }
    full_n = 0;
  }

  void approx_pair(std::uint32_t p, std::uint32_t o) {
    ++res.stats.sphere_pairs;
    res.sphere_pairs.emplace_back(p, o);
    if (!opt.approx_face_pairs) return;
    for (const std::uint32_t* pf = PT.faces_begin(p); pf != PT.faces_end(p) && !res.stats.pair_limit_hit; ++pf)
      for (const std::uint32_t* of = OT.faces_begin(o); of != OT.faces_end(o); ++of) emit(*pf, *of);
  }

  void push_children(std::uint32_t mask, std::uint32_t first, std::uint32_t other, bool probe_side,
                     std::pair<std::uint32_t, std::uint32_t>* stack, std::uint32_t& n) const {
    // Highest child first, so the first child is popped first (depth-first in child order).
    for (; mask != 0; mask &= ~(1u << (31 - std::countl_zero(mask)))) {
      const std::uint32_t c = first + static_cast<std::uint32_t>(31 - std::countl_zero(mask));
      stack[n++] = probe_side ? std::pair{c, other} : std::pair{other, c};
    }
    ST_ASSERT(n <= sc.stack_cap_, "descend() leaves room for kMaxChildren before each push");
  }

  // One descent from (proot, oroot), then the candidates it left waiting.
  void descend(std::uint32_t proot, std::uint32_t oroot) {
    walk(proot, oroot);
    flush_tris();
    flush_full();
  }

  void walk(std::uint32_t proot, std::uint32_t oroot) {
    auto* stack = sc.stack_.data();
    const float* ps = sc.psph_.data();
    const float* os = sc.osph_.data();
    const std::size_t sp = sc.nstride_p_, so = sc.nstride_o_;
    std::uint32_t n = 0;
    put_probe_sphere(proot);
    res.stats.node_pairs += 1;
    if (sphere_mask(os + oroot, so, 1, ps[proot], ps[sp + proot], ps[2 * sp + proot], ps[3 * sp + proot]) == 0) return;
    stack[n++] = {proot, oroot};
    while (n > 0 && !res.stats.pair_limit_hit) {
      // The budget is checked once per popped pair: between two checks a leaf pair adds at most
      // kMaxLeafFaces² candidates, a split at most kMaxChildren sphere tests. Without a budget
      // (the default) nothing is read here: collide() fills exact_evals once at the end.
      if (opt.max_work != UINT64_MAX) [[unlikely]] {
        res.stats.exact_evals = detail::exact_evaluations - evals0;
        if (res.stats.work() > opt.max_work) {
          res.stats.work_limit_hit = true;
          return;
        }
      }
      const auto [p, o] = stack[--n];
      const SphereNode& hp = PT.nodes[p];
      const SphereNode& ho = OT.nodes[o];
      const bool tp = terminal_p(hp), to = terminal_o(ho);
      if (tp && to) {
        if (exact)
          counted_leaf_leaf(p, o);
        else
          approx_pair(p, o);
        continue;
      }
      // A tree deeper than its num_depths claims (never one built or read by tree_io, which
      // checks; a hand-made one could) would overflow the stack: stop, and say so.
      if (n + kMaxChildren > sc.stack_cap_) [[unlikely]] {
        ++res.stats.truncated;
        return;
      }
      // Descend the larger sphere; test all its children against the other sphere at once.
      if (!to && (tp || ho.radius >= s * hp.radius)) {
        res.stats.node_pairs += ho.count;
        const std::uint32_t m =
            sphere_mask(os + ho.first, so, ho.count, ps[p], ps[sp + p], ps[2 * sp + p], ps[3 * sp + p]);
        push_children(m, ho.first, p, false, stack, n);
      } else {
        probe_children(p);
        res.stats.node_pairs += hp.count;
        const std::uint32_t m =
            sphere_mask(ps + hp.first, sp, hp.count, os[o], os[so + o], os[2 * so + o], os[3 * so + o]);
        push_children(m, hp.first, o, true, stack, n);
      }
    }
  }
};
