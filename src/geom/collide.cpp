// Simultaneous descent of two SphereTrees (paper §3.3; traversal after Coal/FCL: relative
// transform, larger node first, explicit stack), then a leaf-pair stage of box masks.
//
// Why no pair is ever missed. Let x be a point common to probe triangle P' (the fl-transformed
// vertices apply(rt, v)) and object triangle O. Every filter tests a convex set that contains x:
//  * object node sphere (c_o, r_o): contains O's vertices exactly (sphere_tree.cpp), hence O, hence x;
//  * probe node sphere: each apply(rt, v) lies within s·r_p of R c_p + t, where s >= ||R||_2
//    (Gershgorin bound on R^T R, so slightly non-orthonormal poses are covered) — hence within
//    s·r_p + (rounding of apply and of the centre) of the computed centre;
//  * probe face box: min/max of the very doubles tri_tri_overlap sees, widened to float (exact
//    containment, float_below/float_above); a probe leaf box is the union of its face boxes;
//  * object face box: float rounded outward from the doubles (exact containment); an object leaf
//    box is the union of its face boxes.
// Box against box is pure comparison (no arithmetic), so it rejects only disjoint boxes.
// Sphere-sphere (sphere_mask) and leaf box-sphere tests run in float. Let M bound every centre,
// radius and coordinate involved (M = |t| + s(|c_p root| + r_p root) + |c_o root| + r_o root:
// every node's centre lies in the hull of its vertices, hence in the root sphere). The float
// probe centre is within 2^-24·M·√3 + 1e-14·M of the exact R c_p + t; radii are rounded once;
// the differences, squares and sums lose at most a few 2^-24 relative. Together that is below
// 4e-7·M in distance, and the probe radius (or, box-sphere, the object radius) is widened by
// slack = 1e-5·M, 25x that. So a filter rejects only when the true sets are disjoint, and the final
// set equals {(p, o) : tri_tri_overlap(same doubles)}. Each face is in exactly one leaf and each
// leaf pair is reached at most once, so no pair is reported twice.
#include "geom/collide.hpp"

#include <algorithm>
#include <bit>
#include <limits>

#include "geom/check.hpp"
#include "geom/simd.hpp"
#include "geom/tri_tri.hpp"

namespace st::geom {
namespace {

// Error-free transformations (Dekker/Knuth; Ogita, Rump, Oishi 2005 "Accurate sum and dot product").
inline void two_sum(double a, double b, double& s, double& e) {
  s = a + b;
  const double z = s - a;
  e = (a - (s - z)) + (b - z);
}

// sum of terms, accurate to ~1 ulp of the result (Sum2 of Ogita-Rump-Oishi, products split exactly).
double accurate_sum(const double* prod_a, const double* prod_b, int np, const double* add, int na) {
  double s = 0, comp = 0;
  for (int i = 0; i < np; ++i) {
    const double p = prod_a[i] * prod_b[i];
    const double pe = std::fma(prod_a[i], prod_b[i], -p);
    double e;
    two_sum(s, p, s, e);
    comp += e + pe;
  }
  for (int i = 0; i < na; ++i) {
    double e;
    two_sum(s, add[i], s, e);
    comp += e;
  }
  return s + comp;
}

inline Vec3 centre_of(const SphereNode& n) { return Vec3(n.centre[0], n.centre[1], n.centre[2]); }

// The three filters below are written once over simd::Lanes (AVX2, SSE2 or scalar, chosen at
// compile time), a step of Lanes::width lanes at a time; all three give the same masks.

// Bit k (k < n <= 8) set when sphere k of a float SoA block (x at c[0], y at c[st], z at c[2 st],
// radius at c[3 st]) meets the sphere (qx, qy, qz; qr): |c_k - q|^2 <= (r_k + qr)^2 in float.
// Conservative by the slack in the probe radii (see the top of this file). Reads whole steps past
// n: the SoA arrays are padded by kMaxChildren.
inline std::uint32_t sphere_mask(const float* c, std::size_t st, std::uint32_t n, float qx, float qy, float qz, float qr) {
  using simd::Lanes;
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
inline std::uint64_t soa_box_mask(const float* c, std::size_t st, std::uint32_t n, const float* b) {
  using simd::Lanes;
  const Lanes blx = Lanes::broadcast(b[0]), bly = Lanes::broadcast(b[1]), blz = Lanes::broadcast(b[2]);
  const Lanes bhx = Lanes::broadcast(b[3]), bhy = Lanes::broadcast(b[4]), bhz = Lanes::broadcast(b[5]);
  std::uint64_t m = 0;
  for (std::uint32_t i = 0; i < n; i += Lanes::width) {
    const simd::Mask h = (Lanes::load(c + i) <= bhx) & (Lanes::load(c + st + i) <= bhy) &
                         (Lanes::load(c + 2 * st + i) <= bhz) & (Lanes::load(c + 3 * st + i) >= blx) &
                         (Lanes::load(c + 4 * st + i) >= bly) & (Lanes::load(c + 5 * st + i) >= blz);
    m |= std::uint64_t{h.bits()} << i;
  }
  return n >= 64 ? m : m & ((std::uint64_t{1} << n) - 1);
}

// Bit j (j < n <= 64) set when face box fb[j] meets box b (lo xyz, hi xyz). Exact. A step's boxes
// are gathered from the 24-byte AoS, reading nothing past fb[n - 1] (face_boxes is not padded).
inline std::uint64_t face_box_mask(const FaceBox* fb, std::uint32_t n, const float* b) {
  static_assert(sizeof(FaceBox) == 6 * sizeof(float), "face boxes are read as 6 packed floats");
  using simd::Lanes;
  const Lanes blx = Lanes::broadcast(b[0]), bly = Lanes::broadcast(b[1]), blz = Lanes::broadcast(b[2]);
  const Lanes bhx = Lanes::broadcast(b[3]), bhy = Lanes::broadcast(b[4]), bhz = Lanes::broadcast(b[5]);
  const float* f = reinterpret_cast<const float*>(fb);
  std::uint64_t m = 0;
  for (std::uint32_t j = 0; j < n; j += Lanes::width) {
    const std::uint32_t live = n - j;
    const float* p = f + 6 * j;
    // Lanes past the last box are gathered as 0 and may compare true: the live mask clears them.
    const simd::Mask h = simd::Mask::first(live) & (Lanes::gather<6>(p, live) <= bhx) &
                         (Lanes::gather<6>(p + 1, live) <= bhy) & (Lanes::gather<6>(p + 2, live) <= bhz) &
                         (Lanes::gather<6>(p + 3, live) >= blx) & (Lanes::gather<6>(p + 4, live) >= bly) &
                         (Lanes::gather<6>(p + 5, live) >= blz);
    m |= std::uint64_t{h.bits()} << j;
  }
  return m;
}
}  // namespace

RelTransform transform_to_object(const Pose& pose, const Mesh& probe, const Mesh& object) {
  RelTransform rt;
  rt.R = pose.linear();
  for (int i = 0; i < 3; ++i) {
    const double a[3] = {rt.R(i, 0), rt.R(i, 1), rt.R(i, 2)};
    const double b[3] = {probe.origin.x(), probe.origin.y(), probe.origin.z()};
    const double add[2] = {pose.translation()[i], -object.origin[i]};
    rt.t[i] = accurate_sum(a, b, 3, add, 2);
  }
  return rt;
}

std::uint32_t CollideScratch::next_generation() {
  if (++gen_ == 0) {
    std::fill(cstamp_.begin(), cstamp_.end(), 0u);
    std::fill(lstamp_.begin(), lstamp_.end(), 0u);
    std::fill(pmark_.begin(), pmark_.end(), 0u);
    std::fill(omark_.begin(), omark_.end(), 0u);
    gen_ = 1;
  }
  return gen_;
}

void CollideScratch::prepare(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object,
                             const SphereTree& object_tree) {
  // The probe's part is derived again only for another probe: a client answering several object
  // blocks (net::ScatterConfig::assist_blocks) switches object trees every query, and the probe's
  // leaves take far longer to derive than a block's spheres.
  const bool same_probe = pkey_ == probe_tree.nodes.data() && phash_ == probe_tree.mesh_hash &&
                          lidx_.size() == probe_tree.face_order.size() && cstamp_.size() == probe_tree.nodes.size() &&
                          pmark_.size() == probe.faces.size();
  if (!same_probe) prepare_probe(probe, probe_tree);
  // Object spheres as float SoA, so the children of a node (contiguous) load as whole vectors.
  nstride_o_ = object_tree.nodes.size() + kMaxChildren;
  osph_.assign(4 * nstride_o_, 0.0f);
  for (std::size_t i = 0; i < object_tree.nodes.size(); ++i) {
    const SphereNode& h = object_tree.nodes[i];
    for (int k = 0; k < 3; ++k) osph_[k * nstride_o_ + i] = h.centre[k];
    osph_[3 * nstride_o_ + i] = h.radius;
  }
  obox_.assign(object_tree.nodes.size(), {});
  for (std::size_t i = 0; i < object_tree.nodes.size(); ++i) {
    const SphereNode& h = object_tree.nodes[i];
    if (!h.leaf) continue;
    const float inf = std::numeric_limits<float>::infinity();
    std::array<float, 8> b = {inf, inf, inf, -inf, -inf, -inf, 0, 0};
    for (std::uint32_t slot = h.first; slot < h.first + h.count; ++slot)
      for (int k = 0; k < 3; ++k) {
        b[k] = std::min(b[k], object_tree.face_boxes[slot].lo[k]);
        b[3 + k] = std::max(b[3 + k], object_tree.face_boxes[slot].hi[k]);
      }
    obox_[i] = b;
  }
  osph_key_ = object_tree.nodes.data();
  osph_hash_ = object_tree.mesh_hash;
  if (omark_.size() != object.faces.size()) omark_.assign(object.faces.size(), 0);
  // DFS with "replace one entry by at most 8": depth of the stack <= 1 + 7 (Dp + Do).
  const std::uint32_t cap = 8 * (probe_tree.num_depths + object_tree.num_depths) + 8;
  if (stack_.size() < cap) stack_.resize(cap);
  stack_cap_ = static_cast<std::uint32_t>(stack_.size());
}

void CollideScratch::prepare_probe(const Mesh& probe, const SphereTree& probe_tree) {
  auto fit = [](auto& v, std::size_t n) {
    if (v.size() != n) v.assign(n, {});
  };
  // Probe leaves as little meshes (distinct vertices per leaf, faces as indices into them).
  lvrange_.assign(probe_tree.nodes.size(), {0, 0});
  lverts_.clear();
  lidx_.assign(probe_tree.face_order.size(), {0, 0, 0});
  {
    std::vector<std::uint32_t> at(probe.local.size(), kNoNode), stamp(probe.local.size(), kNoNode);
    for (std::uint32_t i = 0; i < probe_tree.num_nodes(); ++i) {
      const SphereNode& h = probe_tree.nodes[i];
      if (!h.leaf) continue;
      const auto begin = static_cast<std::uint32_t>(lverts_.size());
      for (std::uint32_t slot = h.first; slot < h.first + h.count; ++slot) {
        const Tri& t = probe.faces[probe_tree.face_order[slot]];
        for (int k = 0; k < 3; ++k) {
          const std::uint32_t v = t[k];
          if (stamp[v] != i) {
            stamp[v] = i;
            at[v] = static_cast<std::uint32_t>(lverts_.size());
            lverts_.push_back(probe.local[v]);
          }
          lidx_[slot][k] = at[v];
        }
      }
      lvrange_[i] = {begin, static_cast<std::uint32_t>(lverts_.size())};
    }
  }
  lverts_.shrink_to_fit();
  ptx_.resize(lverts_.size());
  pkey_ = probe_tree.nodes.data();
  phash_ = probe_tree.mesh_hash;
  fit(cstamp_, probe_tree.nodes.size());
  nstride_p_ = probe_tree.nodes.size() + kMaxChildren;
  psph_.assign(4 * nstride_p_, 0.0f);
  fit(lstamp_, probe_tree.nodes.size());
  lbox_.resize(probe_tree.nodes.size());
  pstride_ = probe_tree.face_order.size() + kMaxLeafFaces;  // whole-vector loads past a leaf's end stay inside
  pbox_.assign(6 * pstride_, 0.0f);
  fit(pmark_, probe.faces.size());
}

std::size_t CollideScratch::bytes() const {
  auto b = [](const auto& v) { return v.capacity() * sizeof(v[0]); };
  return b(lvrange_) + b(lverts_) + b(lidx_) + b(ptx_) + b(cstamp_) + b(psph_) + b(osph_) + b(obox_) + b(lstamp_) +
         b(lbox_) + b(pbox_) + b(pmark_) + b(omark_) + b(stack_) + b(sort_keys_);
}

struct CollideQuery {
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
  bool exact = true;
  std::uint32_t stop = 0;  // approximate mode: layer at which nodes become terminal

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

  // Probe leaf p's face boxes (float, enclosing the transformed doubles) in SoA by slot, and their
  // union, computed once per query.
  const std::array<float, 8>& probe_leaf(std::uint32_t p) {
    std::array<float, 8>& u = sc.lbox_[p];
    if (sc.lstamp_[p] == gen) return u;
    sc.lstamp_[p] = gen;
    const SphereNode& hp = PT.nodes[p];
    const float inf = std::numeric_limits<float>::infinity();
    u = {inf, inf, inf, -inf, -inf, -inf, 0, 0};
    float* pb = sc.pbox_.data();
    const std::size_t st = sc.pstride_;
    // The very doubles tri_tri_overlap will see: apply(rt, v) of the same local vertices.
    const auto [v0, v1] = sc.lvrange_[p];
    for (std::uint32_t v = v0; v < v1; ++v) sc.ptx_[v] = apply(rt, sc.lverts_[v]);
    for (std::uint32_t slot = hp.first, e = hp.first + hp.count; slot < e; ++slot) {
      const auto& ix = sc.lidx_[slot];
      const Vec3& a = sc.ptx_[ix[0]];
      const Vec3& b = sc.ptx_[ix[1]];
      const Vec3& c = sc.ptx_[ix[2]];
      for (int k = 0; k < 3; ++k) {
        const float lo = float_below(std::min(a[k], std::min(b[k], c[k])));
        const float hi = float_above(std::max(a[k], std::max(b[k], c[k])));
        pb[k * st + slot] = lo;
        pb[(3 + k) * st + slot] = hi;
        u[k] = std::min(u[k], lo);
        u[3 + k] = std::max(u[3 + k], hi);
      }
    }
    return u;
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
    const std::uint64_t mo = face_box_mask(ob, ho.count, u.data());
    if (mo == 0) return;
    const float inf = std::numeric_limits<float>::infinity();
    float ou[6] = {inf, inf, inf, -inf, -inf, -inf};
    for (std::uint64_t m = mo; m != 0; m &= m - 1) {
      const FaceBox& fb = ob[std::countr_zero(m)];
      for (int k = 0; k < 3; ++k) {
        ou[k] = std::min(ou[k], fb.lo[k]);
        ou[3 + k] = std::max(ou[3 + k], fb.hi[k]);
      }
    }
    const std::uint64_t mp = probe_mask(hp.first, hp.count, ou);
    if (mp == 0) return;
    for (std::uint64_t m = mo; m != 0; m &= m - 1) {
      const unsigned j = static_cast<unsigned>(std::countr_zero(m));
      const FaceBox& fb = ob[j];
      const float b[6] = {fb.lo[0], fb.lo[1], fb.lo[2], fb.hi[0], fb.hi[1], fb.hi[2]};
      std::uint64_t mf = std::popcount(mp) == 1 ? mp : (probe_mask(hp.first, hp.count, b) & mp);
      if (mf == 0) continue;
      const std::uint32_t of = OT.face_order[ho.first + j];
      const Tri& ot = O.faces[of];
      const Vec3& o0 = O.local[ot[0]];
      const Vec3& o1 = O.local[ot[1]];
      const Vec3& o2 = O.local[ot[2]];
      for (; mf != 0; mf &= mf - 1) {
        const std::uint32_t slot = hp.first + static_cast<unsigned>(std::countr_zero(mf));
        ++res.stats.tri_pairs;
        const auto& ix = sc.lidx_[slot];
        if (tri_tri_overlap(sc.ptx_[ix[0]], sc.ptx_[ix[1]], sc.ptx_[ix[2]], o0, o1, o2)) emit(PT.face_order[slot], of);
      }
    }
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

  void descend(std::uint32_t proot, std::uint32_t oroot) {
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
      const auto [p, o] = stack[--n];
      const SphereNode& hp = PT.nodes[p];
      const SphereNode& ho = OT.nodes[o];
      const bool tp = terminal_p(hp), to = terminal_o(ho);
      if (tp && to) {
        if (exact)
          leaf_leaf(p, o);
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

void sort_face_pairs(std::span<FacePair> pairs, std::vector<std::uint64_t>& scratch) {
  const std::size_t n = pairs.size();
  if (n < 64) {  // a handful: the comparison sort is quicker than clearing the counts
    std::sort(pairs.begin(), pairs.end());
    return;
  }
  std::uint32_t max_probe = 0, max_object = 0;
  for (const FacePair& p : pairs) max_probe = std::max(max_probe, p.probe), max_object = std::max(max_object, p.object);
  const int object_bits = std::bit_width(max_object), bits = std::bit_width(max_probe) + object_bits;
  constexpr int kDigit = 11;
  constexpr std::size_t kBuckets = std::size_t(1) << kDigit;
  scratch.resize(2 * n);
  std::uint64_t* a = scratch.data();
  std::uint64_t* b = a + n;
  for (std::size_t i = 0; i < n; ++i) a[i] = (std::uint64_t(pairs[i].probe) << object_bits) | pairs[i].object;
  // One stable counting pass per digit, lowest first: the order of the keys is (probe, object).
  std::uint32_t count[kBuckets];
  for (int shift = 0; shift < bits; shift += kDigit) {
    std::fill(count, count + kBuckets, 0u);
    for (std::size_t i = 0; i < n; ++i) ++count[(a[i] >> shift) & (kBuckets - 1)];
    if (count[(a[0] >> shift) & (kBuckets - 1)] == n) continue;  // one digit value: nothing moves
    std::uint32_t sum = 0;
    for (std::uint32_t& c : count) sum += std::exchange(c, sum);
    for (std::size_t i = 0; i < n; ++i) b[count[(a[i] >> shift) & (kBuckets - 1)]++] = a[i];
    std::swap(a, b);
  }
  const std::uint64_t object_mask = (std::uint64_t(1) << object_bits) - 1;
  for (std::size_t i = 0; i < n; ++i)
    pairs[i] = {std::uint32_t(a[i] >> object_bits), std::uint32_t(a[i] & object_mask)};
}

FaceCounts count_faces(std::span<const FacePair> pairs, std::vector<std::uint32_t>& scratch) {
  const auto distinct = [&](auto field) {
    scratch.clear();
    for (const FacePair& p : pairs) scratch.push_back(p.*field);
    std::sort(scratch.begin(), scratch.end());
    return static_cast<std::uint32_t>(std::unique(scratch.begin(), scratch.end()) - scratch.begin());
  };
  return {distinct(&FacePair::probe), distinct(&FacePair::object)};
}

void collide(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree,
             const Pose& pose, const CollideConfig& options, CollideScratch& scratch, CollideResult& result) {
  result.clear();
  if (probe_tree.nodes.empty() || object_tree.nodes.empty()) return;
  if (!pose.matrix().allFinite()) return;  // boundaries validate poses; never crash here
  if (probe_tree.num_depths > kMaxTreeDepth || object_tree.num_depths > kMaxTreeDepth) {
    result.stats.truncated = 1;  // the stack is sized from num_depths: never from an unchecked value
    return;
  }
  if (scratch.pkey_ != probe_tree.nodes.data() || scratch.phash_ != probe_tree.mesh_hash ||
      scratch.lidx_.size() != probe_tree.face_order.size() || scratch.omark_.size() != object.faces.size() ||
      scratch.cstamp_.size() != probe_tree.nodes.size() || scratch.osph_key_ != object_tree.nodes.data() ||
      scratch.osph_hash_ != object_tree.mesh_hash || scratch.nstride_o_ != object_tree.nodes.size() + kMaxChildren ||
      scratch.stack_cap_ < 8 * (probe_tree.num_depths + object_tree.num_depths) + 8)
    scratch.prepare(probe, probe_tree, object, object_tree);

  CollideQuery q{probe,   probe_tree, object, object_tree,
                 options, scratch,    result, transform_to_object(pose, probe, object)};
  q.gen = scratch.next_generation();
  q.exact = options.stop_layer == kExact;
  q.stop = options.stop_layer >= 0 ? static_cast<std::uint32_t>(options.stop_layer) : 0xffffffffu;
  // s >= ||R||_2: sqrt of the largest row sum of |R^T R| (Gershgorin), widened for its rounding.
  const Eigen::Matrix3d G = q.rt.R.transpose() * q.rt.R;
  const double g = G.cwiseAbs().rowwise().sum().maxCoeff();
  q.s = std::sqrt(g) * (1 + 1e-12);
  const SphereNode& rp = probe_tree.nodes[0];
  const SphereNode& ro = object_tree.nodes[0];
  const double mag = q.rt.t.norm() + q.s * (centre_of(rp).norm() + rp.radius) + centre_of(ro).norm() + ro.radius;
  q.slack = static_cast<float>(1e-5 * mag) + 1e-30f;

  if (!options.restrict_object) {
    q.descend(0, 0);
  } else {
    for (const std::uint32_t r : options.object_roots)
      if (r < object_tree.num_nodes() && !result.stats.pair_limit_hit) q.descend(0, r);
  }
  if (options.sort_pairs) sort_face_pairs(result.pairs, scratch.sort_keys_);
}

}  // namespace st::geom
