// SPDX-License-Identifier: BSD-3-Clause
// The segment kernel's four-lane code (contact_segments.cpp), compiled once per instruction set:
// contact_segments.cpp includes it inside a namespace per ISA (and that ISA's target region,
// simd.hpp) with ST_SEG_SIMD naming the ISA's namespace in simd.hpp, whose Quad (four doubles)
// and QuadMask it is written in; SegmentAreaSum and FirstSegment run the one simd::active_isa()
// names, so simd.hpp's switch (ST_SIMD, set_isa, -Dsimd=false) turns this kernel's SIMD off too.
// No #include here.

using D4 = simd::ST_SEG_SIMD::Quad;
using M4 = simd::ST_SEG_SIMD::QuadMask;
using simd::ST_SEG_SIMD::select;
using simd::ST_SEG_SIMD::sqrt;

inline D4 splat(double x) { return D4::broadcast(x); }
/// b < a ? b : a and a < b ? b : a per lane (NaN as in those scalar selects).
[[gnu::always_inline]] inline D4 min4(const D4& a, const D4& b) { return select(b < a, b, a); }
[[gnu::always_inline]] inline D4 max4(const D4& a, const D4& b) { return select(a < b, b, a); }

/// Four records as columns: vertices, unit normal and plane offset, lane l = row l.
struct Rec4 {
  D4 x[3], y[3], z[3], nx, ny, nz, c;
};

/// Fields [f, f + 4) of four records r[0..3] as four columns (a 4 × 4 transpose).
[[gnu::always_inline]] inline void columns4(const double* const r[4], int f, D4& c0, D4& c1, D4& c2, D4& c3) {
  const double* const at[4] = {r[0] + f, r[1] + f, r[2] + f, r[3] + f};
  simd::ST_SEG_SIMD::transpose(at, c0, c1, c2, c3);
}

/// The records p[0..3] as columns (FaceRec: v0, v1, v2, n, c = 13 doubles).
[[gnu::always_inline]] inline Rec4 load4(const FaceRec* const p[4]) {
  const double* const r[4] = {p[0]->v[0].data(), p[1]->v[0].data(), p[2]->v[0].data(), p[3]->v[0].data()};
  Rec4 q;
  columns4(r, 0, q.x[0], q.y[0], q.z[0], q.x[1]);
  columns4(r, 4, q.y[1], q.z[1], q.x[2], q.y[2]);
  columns4(r, 8, q.z[2], q.nx, q.ny, q.nz);
  q.c = D4::set(r[0][12], r[1][12], r[2][12], r[3][12]);
  return q;
}

/// Where a triangle with signed distances d0..d2 to the other triangle's plane and heights
/// t0..t2 = x·L along the line direction L crosses that plane: the interval [lo, hi] of x·L, ok
/// when it crosses (not all distances of one strict sign). Branch-free: an edge crossing the
/// plane at d_i / (d_i − d_j) along it counts when its ends' signs differ, the quotient of the
/// others is discarded (0/0 on an edge that does not cross is never selected).
///
/// A vertex exactly on the plane (d = 0) counts as on its positive side (a symbolic perturbation,
/// as in Edelsbrunner & Mücke's simulation of simplicity): the decision depends on the vertex and
/// the plane only, so two faces sharing an edge that lies in the plane agree, and the curve is
/// counted once instead of twice or not at all.
[[gnu::always_inline]] inline void crossing(const D4& d0, const D4& d1, const D4& d2, const D4& t0, const D4& t1,
                                            const D4& t2, D4& lo, D4& hi, M4& ok) {
  const D4 inf = splat(std::numeric_limits<double>::infinity()), ninf = splat(-std::numeric_limits<double>::infinity());
  const D4 zero = splat(0);
  const M4 n0 = d0 < zero, n1 = d1 < zero, n2 = d2 < zero;
  const M4 c01 = n0 ^ n1, c12 = n1 ^ n2, c20 = n2 ^ n0;
  const D4 s01 = d0 / (d0 - d1), s12 = d1 / (d1 - d2), s20 = d2 / (d2 - d0);  // d_j = 0 gives vertex j
  const D4 e01 = t0 + s01 * (t1 - t0), e12 = t1 + s12 * (t2 - t1), e20 = t2 + s20 * (t0 - t2);
  lo = min4(min4(select(c01, e01, inf), select(c12, e12, inf)), select(c20, e20, inf));
  hi = max4(max4(select(c01, e01, ninf), select(c12, e12, ninf)), select(c20, e20, ninf));
  ok = c01 | c12 | c20;
}

/// The intersection segments of four rows: per row, the segment of object face a and probe
/// face b (unit normals) along L = n_a × n_b, the direction the boundary of the object surface
/// inside the probe runs (the inside on its left seen from outside): its vector area
/// ½ (s0 − o) × (s1 − o) and that area's length (both 0 where there is no segment: parallel
/// planes, no crossing, or the intervals meet in a point), and its end points s0, s1 relative to
/// o. With t = x·L on the line, s1 − s0 = (hi − lo) L / |L|², and (s0 − o) × L = c_b n_a − c_a n_b
/// for any point of the line (c = n·(v0 − o): the records' offsets c = n·v0 less n·o; the
/// component along L drops out). The line's point nearest o is x0 = (c_a (n_b × L) + c_b (L × n_a))
/// / |L|² relative to o, so s − o = x0 + (t − o·L) L / |L|². (Each row's area is measured from a
/// point o near the patch: the sum does not depend on o, but the sum of the rows' lengths does,
/// and FD's cancellation test compares the two.) Inlined, a caller's unused outputs cost nothing.
struct Seg4 {
  M4 ok;                            ///< a segment
  D4 px, py, pz, pabs;              ///< vector area and its length (0 where none)
  D4 s0x, s0y, s0z, s1x, s1y, s1z;  ///< end points − o (where ok)
};
[[gnu::always_inline]] inline Seg4 segments4(const Rec4& a, const Rec4& b, const D4& ox, const D4& oy, const D4& oz) {
  const D4 lx = a.ny * b.nz - a.nz * b.ny, ly = a.nz * b.nx - a.nx * b.nz, lz = a.nx * b.ny - a.ny * b.nx;
  const D4 l2 = lx * lx + ly * ly + lz * lz;  // unit normals: |L| = sin of the angle between the planes
  D4 da[3], db[3], ta[3], tb[3];
  for (int k = 0; k < 3; ++k) {
    da[k] = b.nx * (a.x[k] - b.x[0]) + b.ny * (a.y[k] - b.y[0]) + b.nz * (a.z[k] - b.z[0]);  // a's vertices vs b's plane
    db[k] = a.nx * (b.x[k] - a.x[0]) + a.ny * (b.y[k] - a.y[0]) + a.nz * (b.z[k] - a.z[0]);  // b's vertices vs a's plane
    ta[k] = a.x[k] * lx + a.y[k] * ly + a.z[k] * lz;
    tb[k] = b.x[k] * lx + b.y[k] * ly + b.z[k] * lz;
  }
  D4 alo, ahi, blo, bhi;
  M4 aok, bok;
  crossing(da[0], da[1], da[2], ta[0], ta[1], ta[2], alo, ahi, aok);
  crossing(db[0], db[1], db[2], tb[0], tb[1], tb[2], blo, bhi, bok);
  const D4 lo = max4(alo, blo), hi = min4(ahi, bhi);
  Seg4 s;
  s.ok = (l2 > splat(1e-24)) & aok & bok & (hi > lo);  // parallel planes: touching or coplanar, no curve
  const D4 inv = splat(1) / l2, zero = splat(0);
  // Selects, not a zero scale: a row without a segment adds exactly nothing to the sums, even
  // where its products overflow.
  const D4 scale = splat(0.5) * (hi - lo) * inv;
  const D4 ca = a.c - (a.nx * ox + a.ny * oy + a.nz * oz), cb = b.c - (b.nx * ox + b.ny * oy + b.nz * oz);
  const D4 vx = cb * a.nx - ca * b.nx, vy = cb * a.ny - ca * b.ny, vz = cb * a.nz - ca * b.nz;
  s.px = select(s.ok, scale * vx, zero);
  s.py = select(s.ok, scale * vy, zero);
  s.pz = select(s.ok, scale * vz, zero);
  s.pabs = select(s.ok, sqrt(scale * scale * (vx * vx + vy * vy + vz * vz)), zero);
  const D4 x0 = (ca * (b.ny * lz - b.nz * ly) + cb * (ly * a.nz - lz * a.ny)) * inv;
  const D4 y0 = (ca * (b.nz * lx - b.nx * lz) + cb * (lz * a.nx - lx * a.nz)) * inv;
  const D4 z0 = (ca * (b.nx * ly - b.ny * lx) + cb * (lx * a.ny - ly * a.nx)) * inv;
  const D4 ol = ox * lx + oy * ly + oz * lz, s0 = (lo - ol) * inv, s1 = (hi - ol) * inv;
  s.s0x = x0 + s0 * lx;
  s.s0y = y0 + s0 * ly;
  s.s0z = z0 + s0 * lz;
  s.s1x = x0 + s1 * lx;
  s.s1y = y0 + s1 * ly;
  s.s1z = z0 + s1 * lz;
  return s;
}

/// SegmentAreaSum::run's rows: n (a multiple of 4) rows of object[k], probe[k] into sum (rows
/// 0-3: Σa and Σ|a|; rows 4-7: Σ length and Σ length · midpoint; rows 8-16: Σ a_j (s0 + s1)_k,
/// j-major; points relative to o).
inline void sum_rows(const FaceRec* const* object, const FaceRec* const* probe, int n, const double* origin,
                     double (*sum)[4]) {
  const D4 ox = splat(origin[0]), oy = splat(origin[1]), oz = splat(origin[2]), zero = splat(0), half = splat(0.5);
  D4 s[17];  // the sums while the batch runs (same order as row by row)
  for (int i = 0; i < 17; ++i) s[i] = D4::load(sum[i]);
  for (int k = 0; k < n; k += 4) {
    const Seg4 g = segments4(load4(object + k), load4(probe + k), ox, oy, oz);
    s[0] = s[0] + g.px, s[1] = s[1] + g.py, s[2] = s[2] + g.pz, s[3] = s[3] + g.pabs;
    // Selects again: a row without a segment has undefined end points and adds exactly nothing.
    const D4 dx = g.s1x - g.s0x, dy = g.s1y - g.s0y, dz = g.s1z - g.s0z;
    const D4 len = select(g.ok, sqrt(dx * dx + dy * dy + dz * dz), zero);
    const D4 m[3] = {select(g.ok, g.s0x + g.s1x, zero), select(g.ok, g.s0y + g.s1y, zero),
                     select(g.ok, g.s0z + g.s1z, zero)};
    s[4] = s[4] + len;
    s[5] = s[5] + len * (half * m[0]);
    s[6] = s[6] + len * (half * m[1]);
    s[7] = s[7] + len * (half * m[2]);
    const D4 a[3] = {g.px, g.py, g.pz};  // zero where there is no segment
    for (int j = 0; j < 3; ++j)
      for (int c = 0; c < 3; ++c) s[8 + 3 * j + c] = s[8 + 3 * j + c] + a[j] * m[c];
  }
  for (int i = 0; i < 17; ++i) s[i].store(sum[i]);
}

/// FirstSegment::run's four rows: the first row (in order) with a segment, its midpoint; false if none.
inline bool first_midpoint(const FaceRec* const* object, const FaceRec* const* probe, Vec3& midpoint) {
  // Measured from the common frame's origin (a body's centre): the rounding of one segment's end
  // points is ~1e-16 of the body's size.
  const D4 zero = splat(0);
  const Seg4 g = segments4(load4(object), load4(probe), zero, zero, zero);
  const std::uint32_t ok = g.ok.bits();
  if (ok == 0) return false;
  const int l = std::countr_zero(ok);
  midpoint = 0.5 * Vec3(g.s0x.lane(l) + g.s1x.lane(l), g.s0y.lane(l) + g.s1y.lane(l), g.s0z.lane(l) + g.s1z.lane(l));
  return true;
}
