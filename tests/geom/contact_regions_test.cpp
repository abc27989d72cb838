// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/contact_regions.*: the union-find (against connected components found by a
// search, roots the smallest members whatever the order of the unions), and the grouping of a
// body's colliding faces over rounds on a generated grid: group_faces (afresh, faces joined to
// the groups they carry, a bridge joining two groups, a split group staying one) and new_groups
// (covered faces, new faces attached to them, a new region).
#include <spheretouch/geom/contact_regions.hpp>

#include <doctest/doctest.h>

#include <algorithm>
#include <random>
#include <utility>
#include <vector>

#include <spheretouch/geom/contact_patch.hpp>
#include "test_models.hpp"

using namespace st::geom;

namespace {

/// Components of 0 .. n − 1 joined by `edges` (a depth-first search): per member, the smallest
/// member of its component.
std::vector<std::uint32_t> components(std::uint32_t n, const std::vector<std::pair<std::uint32_t, std::uint32_t>>& edges) {
  std::vector<std::vector<std::uint32_t>> adj(n);
  for (auto [a, b] : edges) adj[a].push_back(b), adj[b].push_back(a);
  std::vector<std::uint32_t> comp(n, UINT32_MAX);
  for (std::uint32_t s = 0; s < n; ++s) {  // s is the smallest member of a component first seen
    if (comp[s] != UINT32_MAX) continue;
    std::vector<std::uint32_t> stack = {s};
    comp[s] = s;
    while (!stack.empty()) {
      const std::uint32_t v = stack.back();
      stack.pop_back();
      for (std::uint32_t w : adj[v])
        if (comp[w] == UINT32_MAX) comp[w] = s, stack.push_back(w);
    }
  }
  return comp;
}

using st::test::grid;

constexpr int kGrid = 12;

/// The faces of the squares [i0, i1] × [j0, j1] of the grid, appended to `faces`.
void squares(std::vector<std::uint32_t>& faces, int i0, int i1, int j0, int j1) {
  for (int j = j0; j <= j1; ++j)
    for (int i = i0; i <= i1; ++i) faces.push_back(2 * (j * kGrid + i)), faces.push_back(2 * (j * kGrid + i) + 1);
}

/// Counts `faces` as T's colliding faces of round `epoch`, as a round of the patch model does
/// for each body (ContactBuilder::Patch::take_pairs, make_records).
void collide_round(PatchBody& T, const std::vector<std::uint32_t>& faces, std::uint32_t epoch) {
  T.begin_round();
  for (std::uint32_t f : faces) T.see(f, epoch);
  T.settle(epoch);
  T.fill_new();
  T.fixed_epoch = epoch;
}

/// Per slot, the smallest slot of its set of faces connected through shared vertices.
std::vector<std::uint32_t> face_components(const PatchBody& T) {
  const auto n = std::uint32_t(T.faces.size());
  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
  for (std::uint32_t a = 0; a < n; ++a)
    for (std::uint32_t b = a + 1; b < n; ++b) {
      const Tri& ta = T.mesh->faces[T.faces[a]];
      const Tri& tb = T.mesh->faces[T.faces[b]];
      bool share = false;
      for (std::uint32_t u : ta) share |= u == tb[0] || u == tb[1] || u == tb[2];
      if (share) edges.push_back({a, b});
    }
  return components(n, edges);
}

/// Whether labels partition the slots as `comp` does.
bool same_partition(const std::vector<std::uint32_t>& labels, const std::vector<std::uint32_t>& comp) {
  for (std::size_t a = 0; a < comp.size(); ++a)
    for (std::size_t b = 0; b < comp.size(); ++b)
      if ((labels[a] == labels[b]) != (comp[a] == comp[b])) return false;
  return true;
}

}  // namespace

TEST_CASE("contact regions: union-find sets are the connected components, roots their smallest members") {
  std::mt19937 rng(11);
  for (std::uint32_t n : {1u, 2u, 17u, 200u}) {
    for (int trial = 0; trial < 5; ++trial) {
      std::uniform_int_distribution<std::uint32_t> pick(0, n - 1);
      std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
      for (std::uint32_t k = 0; k < n * 3 / 4; ++k) edges.push_back({pick(rng), pick(rng)});
      const std::vector<std::uint32_t> comp = components(n, edges);
      UnionFind sets;
      sets.reset(n);
      for (std::uint32_t i = 0; i < n; ++i) CHECK(sets.root(i) == i);
      for (auto [a, b] : edges) sets.unite(a, b);
      std::shuffle(edges.begin(), edges.end(), rng);  // another order, the other way round
      UnionFind other;
      other.reset(n);
      for (auto [a, b] : edges) other.unite(b, a);
      REQUIRE(sets.size() == n);
      for (std::uint32_t i = 0; i < n; ++i) {
        CHECK(sets.root(i) == comp[i]);
        CHECK(other.root(i) == comp[i]);
      }
    }
  }
}

TEST_CASE("contact regions: union-find grows one set at a time") {
  UnionFind sets;
  CHECK(sets.size() == 0);
  for (std::uint32_t i = 0; i < 6; ++i) CHECK(sets.add() == i);
  sets.unite(4, 2);
  sets.unite(5, 4);
  CHECK(sets.root(5) == 2);
  CHECK(sets.root(3) == 3);
  CHECK(sets.add() == 6);
  CHECK(sets.root(6) == 6);
  sets.clear();
  CHECK(sets.size() == 0);
}

TEST_CASE("contact regions: group_faces over rounds: afresh, joined, bridged, split, afresh again") {
  const Mesh m = grid(kGrid);
  PatchBody T;
  T.reset(m);
  std::vector<std::uint32_t> a, b, bridge;
  squares(a, 1, 3, 1, 3);  // two regions 1 square apart: no vertex shared
  squares(b, 5, 7, 1, 3);
  squares(bridge, 4, 4, 2, 2);
  auto cat = [](std::initializer_list<const std::vector<std::uint32_t>*> parts) {
    std::vector<std::uint32_t> all;
    for (const auto* p : parts) all.insert(all.end(), p->begin(), p->end());
    return all;
  };
  auto labels_of = [&](const std::vector<std::uint32_t>& faces) {  // by face, this round
    std::vector<std::uint32_t> out;
    for (std::uint32_t f : faces) out.push_back(T.group_label[T.face_mark[f].slot]);
    return out;
  };
  std::uint32_t epoch = 0;

  // Round 1: every face new, grouped afresh: A then B, numbered in slot order.
  collide_round(T, cat({&a, &b}), ++epoch);
  CHECK(group_faces(T, epoch) == 2);
  CHECK(T.n_groups == 2);
  CHECK(same_partition(T.group_label, face_components(T)));
  for (std::uint32_t l : labels_of(a)) CHECK(l == 0);
  for (std::uint32_t l : labels_of(b)) CHECK(l == 1);

  // Round 2: A grows by one square (2 new faces of 38: joined, not regrouped); B's faces come
  // first now, yet each face keeps its group.
  std::vector<std::uint32_t> grown;
  squares(grown, 1, 1, 4, 4);
  collide_round(T, cat({&b, &a, &grown}), ++epoch);
  CHECK(group_faces(T, epoch) == 2);
  CHECK(same_partition(T.group_label, face_components(T)));
  const std::uint32_t la = labels_of(a)[0], lb = labels_of(b)[0];
  CHECK(la != lb);
  for (std::uint32_t l : labels_of(grown)) CHECK(l == la);

  // Round 3: the bridge square touches both: one group.
  collide_round(T, cat({&a, &grown, &b, &bridge}), ++epoch);
  CHECK(group_faces(T, epoch) == 1);
  CHECK(same_partition(T.group_label, face_components(T)));

  // Round 4: the bridge lifts off: the group split since, but stays one (the patrol's case).
  collide_round(T, cat({&a, &grown, &b}), ++epoch);
  CHECK(group_faces(T, epoch) == 1);

  // Round 5: C appears with many new faces (more than 1 in 6): every face grouped afresh.
  std::vector<std::uint32_t> c_big;
  squares(c_big, 8, 11, 6, 11);
  collide_round(T, cat({&a, &grown, &b, &c_big}), ++epoch);
  CHECK(group_faces(T, epoch) == 3);
  CHECK(same_partition(T.group_label, face_components(T)));
  for (std::uint32_t slot = 0; slot < T.faces.size(); ++slot) CHECK(T.fixed(slot).group == T.group_label[slot]);
}

TEST_CASE("contact regions: new_groups opens the sets of new faces that touch no covered face") {
  const Mesh m = grid(kGrid);
  PatchBody T;
  T.reset(m);
  std::vector<std::uint32_t> a, grown, c;
  squares(a, 1, 3, 1, 3);
  squares(grown, 4, 4, 2, 2);  // next to A
  squares(c, 8, 9, 8, 9);      // a region of its own
  std::uint32_t epoch = 0;
  collide_round(T, a, ++epoch);
  T.cover_all();  // a search for new regions has seen A

  std::vector<std::uint32_t> faces = a;
  faces.insert(faces.end(), grown.begin(), grown.end());
  faces.insert(faces.end(), c.begin(), c.end());
  collide_round(T, faces, ++epoch);
  const std::uint32_t n = new_groups(T);
  REQUIRE(n == 3);  // 0: the covered faces; the grown square; C
  auto label = [&](std::uint32_t f) { return T.group_label[T.face_mark[f].slot]; };
  for (std::uint32_t f : a) CHECK(label(f) == 0);
  const std::uint32_t lg = label(grown[0]), lc = label(c[0]);
  CHECK(lg != 0);
  CHECK(lc != 0);
  CHECK(lg != lc);
  for (std::uint32_t f : grown) CHECK(label(f) == lg);
  for (std::uint32_t f : c) CHECK(label(f) == lc);
  REQUIRE(T.group_open.size() == n);
  CHECK(T.group_open[lg] == 0);  // attached to A: followed
  CHECK(T.group_open[lc] == 1);  // new

  // Once covered, nothing is new; once A stops colliding its vertices count no covered face,
  // so A coming back is a new region again.
  T.cover_all();
  collide_round(T, faces, ++epoch);
  CHECK(new_groups(T) == 1);
  collide_round(T, c, ++epoch);
  for (std::uint32_t f : a)
    for (std::uint32_t v : m.faces[f]) CHECK(T.cover_count[v] == 0);
  faces = c;
  faces.insert(faces.end(), a.begin(), a.end());
  collide_round(T, faces, ++epoch);
  REQUIRE(new_groups(T) == 2);
  CHECK(T.group_open[label(a[0])] == 1);
}
