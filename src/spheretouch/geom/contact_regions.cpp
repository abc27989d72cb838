// SPDX-License-Identifier: BSD-3-Clause
// Grouping one body's colliding faces into contact regions for the patch model's depth search
// (contact_regions.hpp): group_faces() carries the last grouping's groups and joins new faces to
// them, new_groups() joins only the faces new since the last search.
#include <spheretouch/geom/contact_regions.hpp>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/contact_patch.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

namespace {

/// Faces grouped afresh (not from the last grouping) when more than 1 in this many are new since
/// then: joining a new face looks at the ~18 faces around its corners, a fresh grouping at the
/// 3 corners of every face.
constexpr std::uint32_t kFreshGrouping = 6;
constexpr std::uint32_t kNoGroup = UINT32_MAX;

/// Every face grouped afresh: union-find over the slots (label[slot] = slot), each vertex
/// remembering the first slot it was seen in, in a small hash table (scratch, stays in cache; a
/// per-vertex array would be read at random over the whole mesh).
void group_afresh(PatchBody& T, UnionFind& sets, std::vector<std::uint32_t>& label) {
  const auto n_slots = static_cast<std::uint32_t>(T.faces.size());
  sets.reset(n_slots);
  for (std::uint32_t i = 0; i < n_slots; ++i) label[i] = i;
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
          sets.unite(std::uint32_t(table[h]), slot);
          break;
        }
      }
    }
  }
}

/// A face new since the last grouping joins the colliding faces around its vertices (found through
/// the mesh's vertex-face lists and this round's face marks); alone, it starts a group.
void join_new_faces(PatchBody& T, std::uint32_t epoch, UnionFind& sets, std::vector<std::uint32_t>& label) {
  const auto n_slots = static_cast<std::uint32_t>(T.faces.size());
  for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
    if (label[slot] != kNoGroup) continue;
    if (!T.fixed(slot).bad_index)
      for (std::uint32_t v : T.fixed(slot).vid)
        for (std::uint32_t k = T.vf.first[v]; k < T.vf.first[v + 1]; ++k) {
          const PatchBody::Mark& mk = T.face_mark[T.vf.faces[k]];
          if (mk.stamp != epoch || mk.slot == slot || label[mk.slot] == kNoGroup) continue;
          if (label[slot] == kNoGroup)
            label[slot] = label[mk.slot];
          else
            sets.unite(label[slot], label[mk.slot]);
        }
    if (label[slot] == kNoGroup) label[slot] = sets.add();
  }
}

}  // namespace

std::uint32_t group_faces(PatchBody& T, std::uint32_t epoch) {
  const auto n_slots = static_cast<std::uint32_t>(T.faces.size());
  std::vector<std::uint32_t>& label = T.group_label;
  UnionFind& sets = T.group_sets;  // over labels
  std::vector<std::uint32_t>& remap = T.group_remap;
  label.assign(n_slots, kNoGroup);
  sets.clear();
  // The faces that were grouped last time keep their groups (renumbered from 0).
  remap.assign(T.n_groups, kNoGroup);
  std::uint32_t n_new = 0;
  for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
    const std::uint32_t g = T.fixed(slot).group;
    if (g >= T.n_groups) {
      ++n_new;
      continue;
    }
    if (remap[g] == kNoGroup) remap[g] = sets.add();
    label[slot] = remap[g];
  }
  if (std::uint64_t(n_new) * kFreshGrouping > n_slots)
    group_afresh(T, sets, label);
  else
    join_new_faces(T, epoch, sets, label);
  // Dense labels, kept with the faces for the next grouping.
  remap.assign(sets.size(), kNoGroup);
  std::uint32_t n = 0;
  for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
    const std::uint32_t r = sets.root(label[slot]);
    ST_ASSERT(r <= label[slot], "a set's root is its smallest member");
    if (remap[r] == kNoGroup) remap[r] = n++;
    T.fixed(slot).group = label[slot] = remap[r];
  }
  T.n_groups = n;
  return n;
}

std::uint32_t new_groups(PatchBody& T) {
  const auto n_slots = static_cast<std::uint32_t>(T.faces.size());
  std::vector<std::uint32_t>& label = T.group_label;
  UnionFind& sets = T.group_sets;                          // over the new faces' slots
  std::vector<std::uint8_t>& attached = T.group_attached;  // per slot: its set shares a vertex with a covered face
  label.assign(n_slots, 0);
  sets.reset(n_slots);
  attached.assign(n_slots, 0);
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
    const PatchBody::Fixed& fx = T.fixed(slot);
    if (fx.covered || fx.bad_index) continue;
    for (std::uint32_t v : fx.vid) {
      if (T.cover_count[v] > 0) attached[slot] = 1;
      const std::uint64_t m = mark[v];
      if ((m >> 32) != T.vertex_stamp)
        mark[v] = stamp | slot;
      else
        sets.unite(slot, std::uint32_t(m));
    }
  }
  // Labels: 0 the covered faces (and those with bad indices), 1 + n for the n-th set of new faces.
  std::vector<std::uint32_t>& remap = T.group_remap;
  remap.assign(n_slots, kNoGroup);
  std::uint32_t n = 1;
  for (std::uint32_t slot = 0; slot < n_slots; ++slot) {
    const PatchBody::Fixed& fx = T.fixed(slot);
    if (fx.covered || fx.bad_index) continue;
    const std::uint32_t r = sets.root(slot);
    ST_ASSERT(r <= slot, "a set's root is its smallest member");
    if (remap[r] == kNoGroup) remap[r] = n++;
    label[slot] = remap[r];
    if (attached[slot]) attached[r] = 1;
  }
  std::vector<std::uint8_t>& open = T.group_open;
  open.assign(n, 0);
  for (std::uint32_t slot = 0; slot < n_slots; ++slot)
    if (label[slot] != 0) open[label[slot]] = attached[sets.root(slot)] ? 0 : 1;
  return n;
}

}  // namespace st::geom
