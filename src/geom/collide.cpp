// Simultaneous descent of two SphereTrees (paper §3.3; traversal after Coal/FCL: relative
// transform, larger node first, explicit stack).
//
// Why no pair is ever missed. Let x be a point common to probe triangle P' (the fl-transformed
// vertices apply(rt, v)) and object triangle O. Every filter tests a convex set that contains x:
//  * object node sphere (c_o, r_o): contains O's vertices exactly (sphere_tree.cpp), hence O, hence x;
//  * probe node sphere: each apply(rt, v) lies within s·r_p of R c_p + t, where s >= ||R||_2
//    (Gershgorin bound on R^T R, so slightly non-orthonormal poses are covered) — hence within
//    s·r_p + (rounding of apply and of the centre) of the computed centre;
//  * probe face box: min/max of the very doubles tri_tri_overlap sees (exact);
//  * object face box: float rounded outward from the doubles (exact containment).
// Sphere-sphere and sphere-box distances are computed in double; every rounding error above is
// below 1e-14·M where M bounds the magnitudes (|t|, centres, radii), and each test is widened by
// eps = 1e-9·M. So a filter rejects only when the true sets are disjoint, and the final set equals
// {(p, o) : tri_tri_overlap(same doubles)}. Each face is in exactly one leaf and each leaf pair is
// reached at most once, so no pair is reported twice.
#include "geom/collide.hpp"

#include <algorithm>
#include <cassert>
#include <limits>

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

inline double box_dist2(const Vec3& c, const double* lo, const double* hi) {
  double d2 = 0;
  for (int k = 0; k < 3; ++k) {
    const double a = lo[k] - c[k], b = c[k] - hi[k];
    const double d = std::max(0.0, std::max(a, b));
    d2 += d * d;
  }
  return d2;
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
    std::fill(vstamp_.begin(), vstamp_.end(), 0u);
    std::fill(fstamp_.begin(), fstamp_.end(), 0u);
    std::fill(pmark_.begin(), pmark_.end(), 0u);
    std::fill(omark_.begin(), omark_.end(), 0u);
    gen_ = 1;
  }
  return gen_;
}

void CollideScratch::prepare(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object,
                             const SphereTree& object_tree) {
  auto fit = [](auto& v, std::size_t n) {
    if (v.size() != n) v.assign(n, {});
  };
  fit(vstamp_, probe.local.size());
  vx_.resize(probe.local.size());
  fit(fstamp_, probe.faces.size());
  fbox_.resize(probe.faces.size());
  fit(pmark_, probe.faces.size());
  fit(omark_, object.faces.size());
  // DFS with "replace one entry by at most 8": depth of the stack <= 1 + 7 (Dp + Do).
  const std::uint32_t cap = 8 * (probe_tree.num_depths + object_tree.num_depths) + 8;
  if (stack_.size() < cap) stack_.resize(cap);
  stack_cap_ = static_cast<std::uint32_t>(stack_.size());
}

struct CollideQuery {
  const Mesh& P;
  const SphereTree& PT;
  const Mesh& O;
  const SphereTree& OT;
  const CollideOptions& opt;
  CollideScratch& sc;
  CollideResult& res;
  RelTransform rt;
  double s = 1;    // >= ||R||_2
  double eps = 0;  // absolute slack of every distance test, mm
  std::uint32_t gen = 0;
  bool exact = true;
  std::uint32_t stop = 0;  // approximate mode: layer at which nodes become terminal

  Vec3 pcentre(const SphereNode& n) const { return apply(rt, centre_of(n)); }

  bool terminal_p(const SphereNode& n) const { return n.leaf || (!exact && n.depth >= stop); }
  bool terminal_o(const SphereNode& n) const { return n.leaf || (!exact && n.depth >= stop); }

  bool overlap(const Vec3& cp, const SphereNode& hp, const SphereNode& ho) {
    ++res.stats.node_pairs;
    const double rr = s * hp.radius + ho.radius + eps;
    return (cp - centre_of(ho)).squaredNorm() <= rr * rr;
  }

  const Vec3& vertex(std::uint32_t v) {
    if (sc.vstamp_[v] != gen) {
      sc.vstamp_[v] = gen;
      sc.vx_[v] = apply(rt, P.local[v]);
    }
    return sc.vx_[v];
  }

  const std::array<double, 6>& probe_box(std::uint32_t f) {
    if (sc.fstamp_[f] != gen) {
      sc.fstamp_[f] = gen;
      const Tri& t = P.faces[f];
      const Vec3& a = vertex(t[0]);
      const Vec3& b = vertex(t[1]);
      const Vec3& c = vertex(t[2]);
      auto& bx = sc.fbox_[f];
      for (int k = 0; k < 3; ++k) {
        bx[k] = std::min(a[k], std::min(b[k], c[k]));
        bx[3 + k] = std::max(a[k], std::max(b[k], c[k]));
      }
    }
    return sc.fbox_[f];
  }

  void emit(std::uint32_t pf, std::uint32_t of) {
    res.pairs.push_back({pf, of});
    if (sc.pmark_[pf] != gen) { sc.pmark_[pf] = gen; ++res.probe_faces; }
    if (sc.omark_[of] != gen) { sc.omark_[of] = gen; ++res.object_faces; }
  }

  void leaf_leaf(std::uint32_t p, std::uint32_t o, const Vec3& cp) {
    const SphereNode& hp = PT.nodes[p];
    const SphereNode& ho = OT.nodes[o];
    ++res.stats.leaf_pairs;
    const Vec3 co = centre_of(ho);
    const double ro = ho.radius + eps;
    const double rp = s * hp.radius + eps;
    std::uint32_t keep[kMaxLeafFaces];
    const std::array<double, 6>* kbox[kMaxLeafFaces];
    int nk = 0;
    // Probe faces whose (exact) box meets the object leaf sphere; their union box.
    double ulo[3] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
                     std::numeric_limits<double>::infinity()};
    double uhi[3] = {-ulo[0], -ulo[1], -ulo[2]};
    for (std::uint32_t slot = hp.first, e = hp.first + hp.count; slot < e; ++slot) {
      const std::uint32_t f = PT.face_order[slot];
      const auto& bx = probe_box(f);
      if (box_dist2(co, bx.data(), bx.data() + 3) <= ro * ro) {
        keep[nk] = f;
        kbox[nk] = &bx;
        ++nk;
        for (int k = 0; k < 3; ++k) { ulo[k] = std::min(ulo[k], bx[k]); uhi[k] = std::max(uhi[k], bx[3 + k]); }
      }
    }
    if (nk == 0) return;
    (void)cp;
    (void)rp;
    // Object faces whose (outward-rounded) box meets that union box, then face box vs face box.
    for (std::uint32_t slot = ho.first, e = ho.first + ho.count; slot < e; ++slot) {
      const FaceBox& fb = OT.face_boxes[slot];
      const double lo[3] = {fb.lo[0], fb.lo[1], fb.lo[2]};
      const double hi[3] = {fb.hi[0], fb.hi[1], fb.hi[2]};
      if ((ulo[0] > hi[0]) | (ulo[1] > hi[1]) | (ulo[2] > hi[2]) | (uhi[0] < lo[0]) | (uhi[1] < lo[1]) | (uhi[2] < lo[2]))
        continue;
      const std::uint32_t of = OT.face_order[slot];
      const Tri& ot = O.faces[of];
      for (int k = 0; k < nk; ++k) {
        const auto& pb = *kbox[k];
        if ((pb[0] > hi[0]) | (pb[1] > hi[1]) | (pb[2] > hi[2]) | (pb[3] < lo[0]) | (pb[4] < lo[1]) | (pb[5] < lo[2])) continue;
        ++res.stats.tri_pairs;
        const Tri& pt = P.faces[keep[k]];
        if (tri_tri_overlap(sc.vx_[pt[0]], sc.vx_[pt[1]], sc.vx_[pt[2]], O.local[ot[0]], O.local[ot[1]],
                            O.local[ot[2]]))
          emit(keep[k], of);
      }
    }
  }

  void approx_pair(std::uint32_t p, std::uint32_t o) {
    ++res.stats.sphere_pairs;
    res.sphere_pairs.emplace_back(p, o);
    if (!opt.approx_face_pairs) return;
    for (const std::uint32_t* pf = PT.faces_begin(p); pf != PT.faces_end(p); ++pf)
      for (const std::uint32_t* of = OT.faces_begin(o); of != OT.faces_end(o); ++of) emit(*pf, *of);
  }

  void descend(std::uint32_t proot, std::uint32_t oroot) {
    auto* stack = sc.stack_.data();
    std::uint32_t n = 0;
    if (!overlap(pcentre(PT.nodes[proot]), PT.nodes[proot], OT.nodes[oroot])) return;
    stack[n++] = {proot, oroot};
    while (n > 0) {
      const auto [p, o] = stack[--n];
      const SphereNode& hp = PT.nodes[p];
      const SphereNode& ho = OT.nodes[o];
      const bool tp = terminal_p(hp), to = terminal_o(ho);
      if (tp && to) {
        if (exact) leaf_leaf(p, o, pcentre(hp));
        else approx_pair(p, o);
        continue;
      }
      assert(n + kMaxChildren <= sc.stack_cap_);
      if (!to && (tp || ho.radius >= s * hp.radius)) {
        // Descend the object node (the larger sphere).
        const Vec3 cp = pcentre(hp);
        for (std::uint32_t k = ho.count; k-- > 0;) {
          const std::uint32_t c = ho.first + k;
          if (overlap(cp, hp, OT.nodes[c])) stack[n++] = {p, c};
        }
      } else {
        for (std::uint32_t k = hp.count; k-- > 0;) {
          const std::uint32_t c = hp.first + k;
          const SphereNode& hc = PT.nodes[c];
          if (overlap(pcentre(hc), hc, ho)) stack[n++] = {c, o};
        }
      }
    }
  }
};

void collide(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree,
             const Pose& pose, const CollideOptions& options, CollideScratch& scratch, CollideResult& result) {
  result.clear();
  if (probe_tree.nodes.empty() || object_tree.nodes.empty()) return;
  if (!pose.matrix().allFinite()) return;  // boundaries validate poses; never crash here
  if (scratch.vstamp_.size() != probe.local.size() || scratch.omark_.size() != object.faces.size() ||
      scratch.fstamp_.size() != probe.faces.size() ||
      scratch.stack_cap_ < 8 * (probe_tree.num_depths + object_tree.num_depths) + 8)
    scratch.prepare(probe, probe_tree, object, object_tree);

  CollideQuery q{probe, probe_tree, object, object_tree, options, scratch, result, transform_to_object(pose, probe, object)};
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
  q.eps = 1e-9 * mag + 1e-300;

  if (!options.restrict_object) {
    q.descend(0, 0);
  } else {
    for (const std::uint32_t r : options.object_roots)
      if (r < object_tree.num_nodes()) q.descend(0, r);
  }
  if (options.sort_pairs) std::sort(result.pairs.begin(), result.pairs.end());
}

}  // namespace st::geom
