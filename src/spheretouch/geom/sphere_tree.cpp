// SPDX-License-Identifier: BSD-3-Clause
// SphereTree build: balanced octree-style subdivision (paper §3.3) with exact-enclosing, tight
// (Welzl) spheres.
//
// Subdivision. With F faces and M = ceil(F / leaf_faces) leaves, leaf j gets the faces of slots
// [floor(j F / M), floor((j+1) F / M)), so all leaves hold floor(F/M) or ceil(F/M) faces. A node
// owning leaves [j0, j1) splits its faces in two by the median (nth_element) of face centroids
// along the longest extent of those centroids, at the slot where the leaf range splits in half;
// three such binary levels make the up-to-8 children of one octree node (a balanced octree whose
// split order follows the longest extent per part, as in a k-d tree). Children are appended
// contiguously and then each child's descendants, so every subtree is {node} + a node range.
//
// Spheres. Every node's sphere is the minimal enclosing sphere of the (distinct) vertices of its
// faces: Welzl's algorithm in Gärtner's move-to-front form, seeded with the support points of the
// children, which makes it close to one linear containment pass per node.
//
// Conservative float spheres. The hot copy stores c_f = float(c) and r_f >= max_i |p_i - c_f|
// exactly: r' = max_i fl(|p_i - c_f|) is computed in double from the double vertices and the
// double value of c_f (exact). fl(|v|) of a 3-vector has relative error below 4·2^-53 < 1e-15, so
// r'·(1 + 1e-12) >= the exact max distance; rounding that up to float (nextafter when the
// conversion rounded down) keeps it an upper bound. Hence every vertex lies in the float sphere
// exactly, and a culling test that is conservative for the stored spheres (collide.cpp adds its
// own arithmetic slack) never rejects a pair the exact double test would accept.
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/geom/check.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

namespace st::inline SPHERETOUCH_ABI::geom {
namespace {

// GCC 12.2 at -O3 -march=native (tree SLP vectorizer) was seen to drop the double->float->double
// round trip of the centre in the loop below, so the radius was measured from the unrounded
// centre (sphere_tree_test caught it). A non-inlined conversion keeps the rounding observable.
[[gnu::noinline]] float to_float(double x) { return static_cast<float>(x); }

float round_up(double x) {
  float f = to_float(x);
  if (static_cast<double>(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}
float round_down(double x) {
  float f = to_float(x);
  if (static_cast<double>(f) > x) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
  return f;
}

// Smallest sphere with the n <= 4 points on its boundary (circumsphere in their affine hull).
// Returns false for affinely dependent points (caller keeps the previous ball).
bool ball_through(const Vec3* s, int n, Vec3& c, double& r2) {
  if (n == 0) {
    c.setZero();
    r2 = -1;
    return true;
  }
  if (n == 1) {
    c = s[0];
    r2 = 0;
    return true;
  }
  // c = s0 + sum_k lambda_k (s_k - s0), with |c - s_k| = |c - s0|: G lambda = b,
  // G_ij = (s_i - s0).(s_j - s0), b_i = |s_i - s0|^2 / 2.
  const int m = n - 1;
  Vec3 d[3];
  for (int k = 0; k < m; ++k) d[k] = s[k + 1] - s[0];
  double G[3][3], b[3];
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < m; ++j) G[i][j] = d[i].dot(d[j]);
    b[i] = 0.5 * G[i][i];
  }
  double lam[3] = {0, 0, 0};
  if (m == 1) {
    if (!(G[0][0] > 0)) return false;
    lam[0] = 0.5;
  } else if (m == 2) {
    const double det = G[0][0] * G[1][1] - G[0][1] * G[1][0];
    if (!(std::abs(det) > 1e-14 * G[0][0] * G[1][1])) return false;
    lam[0] = (b[0] * G[1][1] - G[0][1] * b[1]) / det;
    lam[1] = (G[0][0] * b[1] - b[0] * G[1][0]) / det;
  } else {
    Eigen::Matrix3d A;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) A(i, j) = G[i][j];
    const double det = A.determinant();
    if (!(std::abs(det) > 1e-14 * G[0][0] * G[1][1] * G[2][2])) return false;
    const Vec3 l = A.inverse() * Vec3(b[0], b[1], b[2]);
    lam[0] = l[0];
    lam[1] = l[1];
    lam[2] = l[2];
  }
  c = s[0];
  for (int k = 0; k < m; ++k) c += lam[k] * d[k];
  r2 = 0;
  for (int k = 0; k < n; ++k) r2 = std::max(r2, (s[k] - c).squaredNorm());
  return true;
}

// Gärtner's move-to-front Welzl: ball of pts[0, end) with `sup` on the boundary.
void mtf(std::vector<Vec3>& pts, std::size_t end, Vec3* sup, int ns, Vec3& c, double& r2) {
  if (!ball_through(sup, ns, c, r2)) return;  // dependent support: keep caller's ball
  if (ns == 4) return;
  for (std::size_t i = 0; i < end; ++i) {
    if ((pts[i] - c).squaredNorm() > r2 * (1 + 1e-13)) {
      sup[ns] = pts[i];
      Vec3 c2 = c;
      double r22 = r2;
      mtf(pts, i, sup, ns + 1, c2, r22);
      if (r22 > r2) {
        c = c2;
        r2 = r22;
      }
      const Vec3 p = pts[i];
      std::copy_backward(pts.begin(), pts.begin() + static_cast<std::ptrdiff_t>(i),
                         pts.begin() + static_cast<std::ptrdiff_t>(i) + 1);
      pts[0] = p;
    }
  }
}

struct Cent {
  float c[3];
  std::uint32_t id;
};

// The axis along which the points point(i), i in [lo, hi), extend furthest.
template <class Point>
int longest_axis(std::uint32_t lo, std::uint32_t hi, Point&& point) {
  float bl[3] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max(), std::numeric_limits<float>::max()};
  float bh[3] = {-bl[0], -bl[1], -bl[2]};
  for (std::uint32_t i = lo; i < hi; ++i) {
    const float* c = point(i);
    for (int k = 0; k < 3; ++k) {
      bl[k] = std::min(bl[k], c[k]);
      bh[k] = std::max(bh[k], c[k]);
    }
  }
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (bh[k] - bl[k] > bh[axis] - bl[axis]) axis = k;
  return axis;
}

struct Builder {
  const Mesh& mesh;
  std::uint32_t F, M;
  std::vector<Cent> cents;
  SphereTree& t;
  std::vector<std::uint32_t> leaf_slot;  // grouped build: first slot of each leaf (M + 1 entries)

  std::uint32_t slot_of_leaf(std::uint64_t j) const {
    return leaf_slot.empty() ? static_cast<std::uint32_t>(j * F / M) : leaf_slot[j];
  }

  struct Group {
    std::uint32_t j0, j1;
  };

  // Binary median splits of leaves [j0, j1) down `levels` levels or to single leaves.
  void split(std::uint32_t j0, std::uint32_t j1, int levels, Group* out, int& n) {
    if (levels == 0 || j1 - j0 == 1) {
      out[n++] = {j0, j1};
      return;
    }
    const std::uint32_t lo = slot_of_leaf(j0), hi = slot_of_leaf(j1);
    const std::uint32_t jm = j0 + (j1 - j0 + 1) / 2;
    const std::uint32_t mid = slot_of_leaf(jm);
    const int axis = longest_axis(lo, hi, [this](std::uint32_t s) { return cents[s].c; });
    std::nth_element(cents.begin() + lo, cents.begin() + mid, cents.begin() + hi,
                     [axis](const Cent& a, const Cent& b) { return a.c[axis] < b.c[axis]; });
    split(j0, jm, levels - 1, out, n);
    split(jm, j1, levels - 1, out, n);
  }

  void build(std::uint32_t node, std::uint32_t j0, std::uint32_t j1, std::uint32_t depth) {
    SphereNodeCold& cn = t.cold[node];
    cn.face_begin = slot_of_leaf(j0);
    cn.face_end = slot_of_leaf(j1);
    t.nodes[node].depth = static_cast<std::uint8_t>(depth);
    t.num_depths = std::max(t.num_depths, depth + 1);
    if (j1 - j0 == 1) {
      t.nodes[node].leaf = 1;
      t.nodes[node].first = cn.face_begin;
      t.nodes[node].count = static_cast<std::uint16_t>(cn.face_end - cn.face_begin);
      ST_ASSERT(t.nodes[node].count >= 1 && t.nodes[node].count <= kMaxLeafFaces,
                "a leaf holds 1..kMaxLeafFaces faces (collide() keeps them in 64-bit masks)");
      cn.desc_end = cn.face_begin;  // unused for leaves
      return;
    }
    Group g[8];
    int n = 0;
    split(j0, j1, 3, g, n);
    add_children(node, g, n, [&](std::uint32_t child, const Group& c) { build(child, c.j0, c.j1, depth + 1); });
  }

  // Appends node's n children contiguously, then builds each (`build_child(index, its group)`),
  // so that every subtree is {node} + one node range.
  template <class BuildChild>
  void add_children(std::uint32_t node, const Group* g, int n, BuildChild&& build_child) {
    const auto first = static_cast<std::uint32_t>(t.nodes.size());
    t.nodes.resize(first + n);
    t.cold.resize(first + n);
    // t.nodes may have reallocated: no references across the resize.
    t.nodes[node].leaf = 0;
    t.nodes[node].first = first;
    t.nodes[node].count = static_cast<std::uint16_t>(n);
    ST_ASSERT(n >= 1 && n <= kMaxChildren, "an inner node has 1..kMaxChildren children (the traversal's SoA padding)");
    for (int k = 0; k < n; ++k) {
      t.cold[first + k].parent = node;
      build_child(first + static_cast<std::uint32_t>(k), g[k]);
    }
    t.cold[node].desc_end = static_cast<std::uint32_t>(t.nodes.size());
  }

  // Grouped build: the groups in the order of `order` occupy consecutive slots and leaves
  // (group_slot[p], group_leaf[p]: first slot and leaf of the group at position p, G + 1 entries).
  struct Run {
    float c[3];           // centroid of its face centroids
    std::uint32_t first;  // first face, mesh order
    std::uint32_t size;   // faces
  };
  std::vector<Run> runs;
  std::vector<std::uint32_t> order, group_slot, group_leaf;

  // Binary median splits of the groups at positions [a, b) down `levels` levels, as split() does
  // for leaves; with `reorder` false only the boundaries (the same ones: they depend on a, b only).
  void split_groups(std::uint32_t a, std::uint32_t b, int levels, bool reorder, Group* out, int& n) {
    if (levels == 0 || b - a == 1) {
      out[n++] = {a, b};
      return;
    }
    const std::uint32_t m = a + (b - a + 1) / 2;
    if (reorder) {
      const int axis = longest_axis(a, b, [this](std::uint32_t p) { return runs[order[p]].c; });
      std::nth_element(order.begin() + a, order.begin() + m, order.begin() + b,
                       [this, axis](std::uint32_t x, std::uint32_t y) { return runs[x].c[axis] < runs[y].c[axis]; });
    }
    split_groups(a, m, levels - 1, reorder, out, n);
    split_groups(m, b, levels - 1, reorder, out, n);
  }
  void order_groups(std::uint32_t a, std::uint32_t b) {
    if (b - a <= 1) return;
    Group g[8];
    int n = 0;
    split_groups(a, b, 3, true, g, n);
    for (int k = 0; k < n; ++k) order_groups(g[k].j0, g[k].j1);
  }
  void build_top(std::uint32_t node, std::uint32_t a, std::uint32_t b, std::uint32_t depth) {
    if (b - a == 1) {
      build(node, group_leaf[a], group_leaf[b], depth);
      return;
    }
    SphereNodeCold& cn = t.cold[node];
    cn.face_begin = group_slot[a];
    cn.face_end = group_slot[b];
    t.nodes[node].depth = static_cast<std::uint8_t>(depth);
    t.num_depths = std::max(t.num_depths, depth + 1);
    Group g[8];
    int n = 0;
    split_groups(a, b, 3, false, g, n);
    add_children(node, g, n, [&](std::uint32_t child, const Group& c) { build_top(child, c.j0, c.j1, depth + 1); });
  }

  // Lays the groups out: orders them (top levels), permutes the centroids into slot order and
  // gives each group its own leaves. Returns the total leaf count.
  std::uint32_t layout_groups(std::uint32_t leaf_faces) {
    const auto G = static_cast<std::uint32_t>(runs.size());
    order.resize(G);
    for (std::uint32_t g = 0; g < G; ++g) order[g] = g;
    order_groups(0, G);
    std::vector<Cent> by_slot;
    by_slot.reserve(F);
    group_slot.assign(G + 1, 0);
    group_leaf.assign(G + 1, 0);
    leaf_slot.clear();
    for (std::uint32_t p = 0; p < G; ++p) {
      const Run& r = runs[order[p]];
      group_slot[p] = static_cast<std::uint32_t>(by_slot.size());
      group_leaf[p] = static_cast<std::uint32_t>(leaf_slot.size());
      by_slot.insert(by_slot.end(), cents.begin() + r.first, cents.begin() + r.first + r.size);
      const std::uint32_t m = (r.size + leaf_faces - 1) / leaf_faces;
      for (std::uint64_t j = 0; j < m; ++j)
        leaf_slot.push_back(group_slot[p] + static_cast<std::uint32_t>(j * r.size / m));
    }
    group_slot[G] = F;
    group_leaf[G] = static_cast<std::uint32_t>(leaf_slot.size());
    leaf_slot.push_back(F);
    cents.swap(by_slot);
    return group_leaf[G];
  }
};

}  // namespace

void min_sphere(std::vector<Vec3>& pts, Vec3& centre, double& radius) {
  if (pts.empty()) {
    centre.setZero();
    radius = 0;
    return;
  }
  Vec3 sup[4];
  Vec3 c = pts[0];
  double r2 = 0;
  mtf(pts, pts.size(), sup, 0, c, r2);
  double m2 = 0;
  for (const Vec3& p : pts) m2 = std::max(m2, (p - c).squaredNorm());
  centre = c;
  radius = std::sqrt(m2);
}

std::uint64_t tree_hash(const Mesh& mesh, const TreeConfig& params, std::span<const std::uint32_t> groups) {
  WordHash h = mesh_words(mesh);  // not cryptographic: detects a stale cache file
  h.word(params.leaf_faces);
  if (!groups.empty()) {
    h.word(0x47524f555053ull ^ groups.size());  // "GROUPS"
    h.bytes(groups.data(), groups.size() * sizeof(std::uint32_t));
  }
  h.word(0x5354524545ull);  // "STREE" + layout generation of the build algorithm
  return h.finish();
}

Result<SphereTree> SphereTree::build(const Mesh& mesh, const TreeConfig& params, std::span<const std::uint32_t> groups) {
  if (params.leaf_faces < 1 || params.leaf_faces > kMaxLeafFaces)
    return fail(mesh.name, ": leaf_faces = ", params.leaf_faces, " out of range [1, ", kMaxLeafFaces, "]");
  if (mesh.faces.empty()) return fail(mesh.name, ": no faces to build a sphere tree over");
  if (mesh.faces.size() >= (1ull << 31)) return fail(mesh.name, ": too many faces (", mesh.faces.size(), ")");
  if (Status s = mesh.validate(); !s) return Error{s.error()};

  const auto F = static_cast<std::uint32_t>(mesh.faces.size());
  std::uint64_t grouped_faces = 0, nonempty = 0;
  for (std::uint32_t g : groups) grouped_faces += g, nonempty += g > 0;
  if (!groups.empty() && grouped_faces != F)
    return fail(mesh.name, ": face groups cover ", grouped_faces, " faces, the mesh has ", F);

  SphereTree t;
  t.params = params;
  t.mesh_hash = tree_hash(mesh, params, groups);
  t.num_vertices = static_cast<std::uint32_t>(mesh.local.size());
  std::uint32_t M = (F + params.leaf_faces - 1) / params.leaf_faces;

  Builder b{mesh, F, M, {}, t, {}, {}, {}, {}, {}};
  b.cents.resize(F);
  std::vector<FaceBox> boxes(F);  // file order; permuted into slot order below
  for (std::uint32_t f = 0; f < F; ++f) {
    const Tri& tr = mesh.faces[f];
    const Vec3& a = mesh.local[tr[0]];
    const Vec3& a1 = mesh.local[tr[1]];
    const Vec3& a2 = mesh.local[tr[2]];
    const Vec3 c = (a + a1 + a2) / 3.0;
    for (int k = 0; k < 3; ++k) {
      boxes[f].lo[k] = round_down(std::min(a[k], std::min(a1[k], a2[k])));
      boxes[f].hi[k] = round_up(std::max(a[k], std::max(a1[k], a2[k])));
    }
    b.cents[f] = {{static_cast<float>(c.x()), static_cast<float>(c.y()), static_cast<float>(c.z())}, f};
  }
  t.nodes.reserve(2 * static_cast<std::size_t>(M) + 1);
  t.cold.reserve(2 * static_cast<std::size_t>(M) + 1);
  t.nodes.resize(1);
  t.cold.resize(1);
  t.cold[0].parent = kNoNode;
  if (nonempty > 1) {
    for (std::uint32_t first = 0; std::uint32_t size : groups) {
      if (size > 0) {
        float c[3] = {0, 0, 0};
        for (std::uint32_t f = first; f < first + size; ++f)
          for (int k = 0; k < 3; ++k) c[k] += b.cents[f].c[k] / static_cast<float>(size);
        b.runs.push_back({{c[0], c[1], c[2]}, first, size});
      }
      first += size;
    }
    M = b.M = b.layout_groups(params.leaf_faces);
    b.build_top(0, 0, static_cast<std::uint32_t>(b.runs.size()), 0);
  } else {
    b.build(0, 0, M, 0);
  }
  t.nodes.shrink_to_fit();
  t.cold.shrink_to_fit();

  // Face boxes and the leaf point array: the distinct vertices of each leaf, leaves in slot
  // order, so the points below ANY node are the contiguous range [pt_at[face_begin], pt_at[face_end]).
  t.face_order.resize(F);
  t.face_boxes.resize(F);
  const std::uint32_t N = t.num_nodes();
  std::vector<Vec3> pts;
  pts.reserve(F + F / 2 + 64);
  std::vector<std::uint32_t> pt_at(F + 1, 0);
  std::vector<std::uint32_t> vstamp(mesh.local.size(), kNoNode);
  for (std::uint32_t s = 0; s < F; ++s) {
    t.face_order[s] = b.cents[s].id;
    t.face_boxes[s] = boxes[b.cents[s].id];
  }
  std::vector<FaceBox>().swap(boxes);
  std::vector<Cent>().swap(b.cents);
  std::vector<std::uint32_t> leaves;  // in slot order (node order differs: children blocks first)
  leaves.reserve(M);
  for (std::uint32_t i = 0; i < N; ++i)
    if (t.nodes[i].leaf) leaves.push_back(i);
  std::sort(leaves.begin(), leaves.end(),
            [&t](std::uint32_t a, std::uint32_t c) { return t.nodes[a].first < t.nodes[c].first; });
  for (const std::uint32_t i : leaves) {
    const SphereNode& h = t.nodes[i];
    pt_at[h.first] = static_cast<std::uint32_t>(pts.size());
    for (std::uint32_t s = h.first; s < h.first + h.count; ++s) {
      const Tri& tr = mesh.faces[t.face_order[s]];
      for (std::uint32_t v : tr)
        if (vstamp[v] != i) {
          vstamp[v] = i;
          pts.push_back(mesh.local[v]);
        }
    }
  }
  pt_at[F] = static_cast<std::uint32_t>(pts.size());
  std::vector<std::uint32_t>().swap(vstamp);

  // Spheres bottom-up (every descendant has a larger index than its ancestors). Leaves: Welzl on
  // their points. Inner nodes: Welzl on a small candidate set seeded with the children's support
  // points, grown by the farthest outside point until a linear scan finds none outside; the MES of
  // a subset that encloses every point IS the MES of all points (it cannot be larger, and the
  // full set's MES cannot be smaller), so this is exact Welzl at the cost of a few scans.
  std::vector<std::array<Vec3, 4>> hints(N);
  std::vector<std::uint8_t> nhints(N, 0);
  std::vector<Vec3> cand;
  for (std::uint32_t i = N; i-- > 0;) {
    SphereNode& h = t.nodes[i];
    SphereNodeCold& c = t.cold[i];
    const Vec3* p0 = pts.data() + pt_at[c.face_begin];
    const Vec3* p1 = pts.data() + pt_at[c.face_end];
    cand.clear();
    Vec3 ctr;
    double r;
    if (h.leaf) {
      cand.assign(p0, p1);
      min_sphere(cand, ctr, r);
    } else {
      for (std::uint32_t k = 0; k < h.count; ++k)
        for (std::uint32_t q = 0; q < nhints[h.first + k]; ++q) cand.push_back(hints[h.first + k][q]);
      for (;;) {
        min_sphere(cand, ctr, r);
        const double lim = r * r * (1 + 1e-12);
        double far2 = lim;
        const Vec3* far = nullptr;
        for (const Vec3* p = p0; p != p1; ++p) {
          const double d2 = (*p - ctr).squaredNorm();
          if (d2 > far2) {
            far2 = d2;
            far = p;
          }
        }
        if (!far) break;
        cand.push_back(*far);
      }
    }
    // Move-to-front leaves the support points at the front: hints for the parent.
    nhints[i] = static_cast<std::uint8_t>(std::min<std::size_t>(4, cand.size()));
    for (std::uint32_t q = 0; q < nhints[i]; ++q) hints[i][q] = cand[q];
    for (int k = 0; k < 3; ++k) c.centre[k] = ctr[k];
    c.radius = r;
    // Conservative float copy (see the comment at the top of this file).
    // Store the floats first and read them back: the distances must be taken from the stored centre.
    for (int k = 0; k < 3; ++k) h.centre[k] = to_float(ctr[k]);
    const Vec3 cf(double{h.centre[0]}, double{h.centre[1]}, double{h.centre[2]});
    double m2 = 0;
    for (const Vec3* p = p0; p != p1; ++p) m2 = std::max(m2, (*p - cf).squaredNorm());
    h.radius = round_up(std::sqrt(m2) * (1 + 1e-12));
  }
  return t;
}

std::vector<std::vector<std::uint32_t>> group_roots(const SphereTree& tree, std::size_t num_faces,
                                                    std::span<const std::uint32_t> groups) {
  std::vector<std::uint32_t> group_of(num_faces, UINT32_MAX);
  std::size_t f = 0;
  for (std::size_t g = 0; g < groups.size(); ++g)
    for (std::uint32_t k = 0; k < groups[g] && f < num_faces; ++k) group_of[f++] = static_cast<std::uint32_t>(g);
  if (f != num_faces || tree.nodes.empty() || tree.num_faces() != num_faces) return {};
  std::vector<std::vector<std::uint32_t>> roots(groups.size());
  std::vector<std::uint32_t> stack{0};
  while (!stack.empty()) {
    const std::uint32_t i = stack.back();
    stack.pop_back();
    const std::uint32_t* b = tree.faces_begin(i);
    const std::uint32_t* e = tree.faces_end(i);
    if (b == e) continue;
    const std::uint32_t g = b[0] < num_faces ? group_of[b[0]] : UINT32_MAX;
    const bool one =
        g != UINT32_MAX && std::all_of(b, e, [&](std::uint32_t x) { return x < num_faces && group_of[x] == g; });
    if (one) {
      roots[g].push_back(i);
    } else if (tree.nodes[i].leaf) {
      return {};  // a leaf mixes groups: they cannot be collided apart
    } else {
      for (std::uint32_t c = tree.nodes[i].first + tree.nodes[i].count; c-- > tree.nodes[i].first;) stack.push_back(c);
    }
  }
  return roots;
}

std::uint32_t SphereTree::num_leaves() const {
  std::uint32_t n = 0;
  for (const SphereNode& h : nodes) n += h.leaf;
  return n;
}

Crowding crowding(const SphereTree& tree, std::uint32_t stop) {
  Crowding c;
  std::vector<std::uint32_t> stack;
  for (std::uint32_t l = 0; l < tree.num_nodes() && c.leaves < stop; ++l) {
    const SphereNode& a = tree.nodes[l];
    if (!a.leaf) continue;
    const float half = 0.5f * a.radius;
    std::uint32_t n = 0;
    stack.assign(1, 0);
    while (!stack.empty() && n < stop) {
      const SphereNode& b = tree.nodes[stack.back()];
      stack.pop_back();
      const float dx = b.centre[0] - a.centre[0], dy = b.centre[1] - a.centre[1], dz = b.centre[2] - a.centre[2];
      const float r = a.radius + b.radius;
      if (!(dx * dx + dy * dy + dz * dz <= r * r)) continue;  // apart (a NaN sphere counts as apart)
      if (b.leaf) {
        n += b.radius >= half;
      } else {
        for (std::uint32_t k = 0; k < b.count; ++k) stack.push_back(b.first + k);
      }
    }
    if (n > c.leaves) c = {n, l};
  }
  return c;
}

std::vector<std::uint32_t> SphereTree::layer(std::uint32_t n) const {
  std::vector<std::uint32_t> out;
  if (nodes.empty()) return out;
  std::vector<std::uint32_t> stack{0};
  while (!stack.empty()) {
    const std::uint32_t i = stack.back();
    stack.pop_back();
    const SphereNode& h = nodes[i];
    if (h.leaf || h.depth == n) {
      out.push_back(i);
      continue;
    }
    for (std::uint32_t k = h.count; k-- > 0;) stack.push_back(h.first + k);  // keep child order
  }
  return out;
}

std::size_t SphereTree::bytes() const {
  return nodes.capacity() * sizeof(SphereNode) + cold.capacity() * sizeof(SphereNodeCold) +
         face_order.capacity() * sizeof(std::uint32_t) + face_boxes.capacity() * sizeof(FaceBox);
}

}  // namespace st::geom
