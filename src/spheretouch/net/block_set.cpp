// SPDX-License-Identifier: BSD-3-Clause
// Block sets: building a worker's share, canonical encoding, checked decoding (block_set.hpp).
#include <spheretouch/net/block_set.hpp>

#include <algorithm>
#include <numeric>

#include <spheretouch/net/wire.hpp>

#include <sodium.h>

namespace st::inline SPHERETOUCH_ABI::net {

namespace {

constexpr std::uint32_t kBlockSetMagic = 0x53425453;  // "STBS" read as a little-endian u32
constexpr std::uint16_t kBlockSetVersion = 3;  // 2: faces grouped by block, block_faces; 3: the object id (was reserved)

void put_mesh(Writer& w, const geom::Mesh& m) {
  for (int k = 0; k < 3; ++k) w.f64(m.origin[k]);
  w.u32(static_cast<std::uint32_t>(m.local.size()));
  w.u32(static_cast<std::uint32_t>(m.faces.size()));
  for (const auto& v : m.local)
    for (int k = 0; k < 3; ++k) w.f64(v[k]);
  for (const auto& f : m.faces)
    for (int k = 0; k < 3; ++k) w.u32(f[k]);
}

// Reads a mesh whose face count must not exceed `max_faces`; checks every vertex index.
void get_mesh(Reader& r, geom::Mesh& m, const char* which, std::uint32_t max_faces, const Limits& L) {
  for (int k = 0; k < 3; ++k) m.origin[k] = r.f64("origin");
  const std::uint32_t nv = r.u32("vertex count");
  const std::size_t nf_at = r.offset();
  const std::uint32_t nf = r.u32("face count");
  if (r.ok() && nf > max_faces) {
    r.fail_at(nf_at, "face count", ": ", which, " has ", nf, " faces, more than ", max_faces);
    return;
  }
  if (!r.count_ok(nv, L.max_vertices, 24, "vertex count")) return;
  // The faces follow the vertices: check both fit before allocating either.
  if (r.ok() && std::uint64_t{nf} * 12 > r.left() - std::size_t{nv} * 24) {
    r.fail_at(nf_at, "face count", ": ", nf, " faces do not fit in the bytes left");
    return;
  }
  m.local.resize(nv);
  for (auto& v : m.local)
    for (int k = 0; k < 3; ++k) v[k] = r.f64("vertex");
  m.faces.resize(nf);
  for (std::uint32_t f = 0; f < nf && r.ok(); ++f)
    for (int k = 0; k < 3; ++k) {
      const std::size_t at = r.offset();
      const std::uint32_t i = r.u32("face");
      if (r.ok() && i >= nv) {
        r.fail_at(at, "face", " ", f, " of the ", which, ": vertex index ", i, " out of range [0, ", nv, ")");
        return;
      }
      m.faces[f][k] = i;
    }
}

// Reads `n` u32 ids that must be strictly ascending and below `total`.
void get_ascending(Reader& r, std::vector<std::uint32_t>& ids, std::uint32_t n, std::uint32_t total, const char* field) {
  if (!r.count_ok(n, total, 4, field)) return;
  ids.resize(n);
  for (std::uint32_t i = 0; i < n && r.ok(); ++i) {
    const std::size_t at = r.offset();
    ids[i] = r.u32(field);
    if (r.ok() && ids[i] >= total) r.fail_at(at, field, " ", i, ": ", ids[i], " out of range [0, ", total, ")");
    if (r.ok() && i > 0 && ids[i] <= ids[i - 1])
      r.fail_at(at, field, " ", i, ": ", ids[i], " not above the previous ", ids[i - 1]);
  }
}

std::uint64_t spread3(std::uint64_t x) {  // 21 bits → every third bit (Morton code)
  x &= 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffull;
  x = (x | x << 16) & 0x1f0000ff0000ffull;
  x = (x | x << 8) & 0x100f00f00f00f00full;
  x = (x | x << 4) & 0x10c30c30c30c30c3ull;
  x = (x | x << 2) & 0x1249249249249249ull;
  return x;
}

}  // namespace

Result<BlockSet> make_block_set(const geom::Mesh& probe, const geom::Mesh& object, const Blocks& blocks,
                                std::span<const std::uint32_t> block_ids, std::uint32_t leaf_faces,
                                std::uint32_t object_id) {
  if (leaf_faces == 0) return fail("block set: leaf_faces must be at least 1");
  if (object_id > 0xffff) return fail("block set: object ", object_id, " above 65535");
  BlockSet s;
  s.object_id = object_id;
  s.leaf_faces = leaf_faces;
  s.object_faces_total = static_cast<std::uint32_t>(object.faces.size());
  s.blocks_total = static_cast<std::uint32_t>(blocks.size());
  s.blocks.assign(block_ids.begin(), block_ids.end());
  std::sort(s.blocks.begin(), s.blocks.end());
  for (std::size_t i = 0; i < s.blocks.size(); ++i) {
    if (s.blocks[i] >= blocks.size())
      return fail("block set: block ", s.blocks[i], " out of range [0, ", blocks.size(), ")");
    if (i > 0 && s.blocks[i] == s.blocks[i - 1]) return fail("block set: block ", s.blocks[i], " listed twice");
  }
  std::vector<bool> taken(object.faces.size(), false);
  for (std::uint32_t b : s.blocks) {
    const std::size_t start = s.object_face_ids.size();
    for (std::uint32_t f : blocks[b]) {
      if (f >= object.faces.size())
        return fail("block set: block ", b, ": face ", f, " out of range [0, ", object.faces.size(), ")");
      if (!taken[f]) s.object_face_ids.push_back(f);
      taken[f] = true;
    }
    std::sort(s.object_face_ids.begin() + static_cast<std::ptrdiff_t>(start), s.object_face_ids.end());
    s.block_faces.push_back(static_cast<std::uint32_t>(s.object_face_ids.size() - start));
  }

  // Vertices used by the share, in ascending original order, renumbered densely.
  constexpr std::uint32_t kUnused = 0xffffffffu;
  std::vector<std::uint32_t> remap(object.local.size(), kUnused);
  for (std::uint32_t f : s.object_face_ids)
    for (std::uint32_t v : object.faces[f]) remap[v] = 0;
  s.object.name = object.name + " (share)";
  s.object.origin = object.origin;
  for (std::size_t v = 0; v < remap.size(); ++v)
    if (remap[v] == 0) {
      remap[v] = static_cast<std::uint32_t>(s.object.local.size());
      s.object.local.push_back(object.local[v]);
    }
  s.object.faces.reserve(s.object_face_ids.size());
  for (std::uint32_t f : s.object_face_ids) {
    const auto& t = object.faces[f];
    s.object.faces.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
  }
  s.probe.name = probe.name;
  s.probe.origin = probe.origin;
  s.probe.local = probe.local;
  s.probe.faces = probe.faces;
  return s;
}

std::vector<std::uint8_t> encode_block_set(const BlockSet& s) {
  std::vector<std::uint8_t> out;
  out.reserve(64 + s.blocks.size() * 4 + (s.probe.local.size() + s.object.local.size()) * 24 +
              (s.probe.faces.size() + s.object.faces.size()) * 12 + s.object_face_ids.size() * 4);
  Writer w(out);
  w.u32(kBlockSetMagic);
  w.u16(kBlockSetVersion);
  w.u16(static_cast<std::uint16_t>(s.object_id));
  w.u32(s.leaf_faces);
  w.u32(s.object_faces_total);
  w.u32(s.blocks_total);
  w.u32(static_cast<std::uint32_t>(s.blocks.size()));
  for (std::uint32_t b : s.blocks) w.u32(b);
  put_mesh(w, s.probe);
  put_mesh(w, s.object);
  for (std::uint32_t n : s.block_faces) w.u32(n);
  for (std::uint32_t f : s.object_face_ids) w.u32(f);
  return out;
}

Digest block_set_digest(std::span<const std::uint8_t> encoded) {
  // sodium_init() picks the fastest BLAKE2b for this CPU; it is idempotent and thread-safe.
  static const int sodium_ready = sodium_init();
  (void)sodium_ready;  // < 0 only when /dev/urandom is missing, which the hash does not need
  Digest d;
  crypto_generichash(d.data(), d.size(), encoded.data(), encoded.size(), nullptr, 0);
  return d;
}

std::uint64_t digest_key(const Digest& d) {
  std::uint64_t k = 0;
  for (int i = 7; i >= 0; --i) k = (k << 8) | d[static_cast<std::size_t>(i)];
  return k;
}

std::uint64_t block_set_hash(std::span<const std::uint8_t> encoded) { return digest_key(block_set_digest(encoded)); }

Result<BlockSet> decode_block_set(std::span<const std::uint8_t> encoded, const Limits& L) {
  Reader r(encoded, "block set");
  BlockSet s;
  const std::uint32_t magic = r.u32("magic");
  if (r.ok() && magic != kBlockSetMagic) r.fail_at(0, "magic", ": not \"STBS\"");
  const std::uint16_t version = r.u16("version");
  if (r.ok() && version != kBlockSetVersion)
    r.fail_at(4, "version", ": ", version, " not supported (this build reads ", kBlockSetVersion, ")");
  s.object_id = r.u16("object");
  if (r.ok() && s.object_id >= L.max_objects)
    r.fail_at(6, "object", ": ", s.object_id, " is not below max_objects = ", L.max_objects);
  s.leaf_faces = r.u32("leaf_faces");
  if (r.ok() && (s.leaf_faces == 0 || s.leaf_faces > L.max_leaf_faces))
    r.fail_at(8, "leaf_faces", ": ", s.leaf_faces, " outside [1, ", L.max_leaf_faces, "]");
  s.object_faces_total = r.u32("object_faces_total");
  if (r.ok() && s.object_faces_total > L.max_faces)
    r.fail_at(12, "object_faces_total", ": ", s.object_faces_total, " exceeds the limit ", L.max_faces);
  s.blocks_total = r.u32("blocks_total");
  if (r.ok() && s.blocks_total > L.max_blocks)
    r.fail_at(16, "blocks_total", ": ", s.blocks_total, " exceeds the limit ", L.max_blocks);
  const std::uint32_t nb = r.u32("block count");
  get_ascending(r, s.blocks, nb, s.blocks_total, "block id");
  if (r.ok()) get_mesh(r, s.probe, "probe", L.max_faces, L);
  if (r.ok()) get_mesh(r, s.object, "object share", s.object_faces_total, L);
  // Faces per block (they sum to the share's faces), then the share's global face ids: ascending
  // within each block, none twice.
  const auto share = static_cast<std::uint32_t>(s.object.faces.size());
  if (r.ok() && r.count_ok(nb, s.blocks_total, 4, "block face count")) {
    std::uint64_t sum = 0;
    s.block_faces.resize(nb);
    for (std::uint32_t i = 0; i < nb && r.ok(); ++i) {
      const std::size_t at = r.offset();
      s.block_faces[i] = r.u32("block face count");
      sum += s.block_faces[i];
      if (r.ok() && sum > share)
        r.fail_at(at, "block face count", " ", i, ": the counts so far (", sum, ") exceed the share's ", share,
                  " faces");
    }
    if (r.ok() && sum != share)
      r.fail_at(r.offset(), "block face count", "s: sum ", sum, ", the share has ", share, " faces");
  }
  if (r.ok() && r.count_ok(share, s.object_faces_total, 4, "object face id")) {
    s.object_face_ids.resize(share);
    std::uint32_t i = 0;
    for (std::uint32_t blk = 0; blk < nb && r.ok(); ++blk)
      for (std::uint32_t k = 0; k < s.block_faces[blk] && r.ok(); ++k, ++i) {
        const std::size_t at = r.offset();
        const std::uint32_t id = s.object_face_ids[i] = r.u32("object face id");
        if (r.ok() && id >= s.object_faces_total)
          r.fail_at(at, "object face id", " ", i, ": ", id, " out of range [0, ", s.object_faces_total, ")");
        if (r.ok() && k > 0 && id <= s.object_face_ids[i - 1])
          r.fail_at(at, "object face id", " ", i, ": ", id, " not above the previous ", s.object_face_ids[i - 1],
                    " of its block");
      }
    if (r.ok()) {
      std::vector<std::uint32_t> sorted = s.object_face_ids;
      std::sort(sorted.begin(), sorted.end());
      if (const auto dup = std::adjacent_find(sorted.begin(), sorted.end()); dup != sorted.end())
        r.fail_at(r.offset(), "object face id", "s: ", *dup, " listed twice");
    }
  }
  if (!r.expect_end()) return Error{r.error()};
  s.probe.name = "probe";
  s.object.name = "object share";
  return s;
}

std::vector<std::vector<std::uint32_t>> deal_blocks(std::uint32_t num_blocks, std::uint32_t workers,
                                                    geom::Mapping mapping, std::uint64_t seed) {
  std::vector<std::vector<std::uint32_t>> out(workers);
  if (workers == 0) return out;
  const std::vector<std::uint32_t> owners = geom::block_owners(num_blocks, workers, mapping, seed);
  for (std::uint32_t b = 0; b < num_blocks; ++b) out[owners[b]].push_back(b);
  return out;
}

std::uint32_t second_holder(std::uint32_t block, std::uint32_t owner, std::uint32_t workers) {
  if (workers < 2) return owner;
  const std::uint64_t h = (std::uint64_t(block) + 1) * 0x9e3779b97f4a7c15ull;  // Fibonacci hashing
  return std::uint32_t((owner + 1 + (h >> 33) % (workers - 1)) % workers);
}

std::vector<std::vector<std::uint32_t>> standby_shares(const std::vector<std::vector<std::uint32_t>>& shares) {
  const auto workers = static_cast<std::uint32_t>(shares.size());
  std::vector<std::vector<std::uint32_t>> out(workers);
  if (workers < 2) return out;
  for (std::uint32_t w = 0; w < workers; ++w)
    for (std::uint32_t b : shares[w]) out[second_holder(b, w, workers)].push_back(b);
  for (auto& v : out) std::sort(v.begin(), v.end());
  return out;
}

std::vector<std::vector<std::uint32_t>> block_cyclic(std::uint32_t num_blocks, std::uint32_t workers) {
  return deal_blocks(num_blocks, workers, geom::Mapping::block_cyclic);
}

Blocks spatial_blocks(const geom::Mesh& object, std::uint32_t faces_per_block) {
  faces_per_block = std::max<std::uint32_t>(faces_per_block, 1);
  const std::size_t nf = object.faces.size();
  std::vector<geom::Vec3> c(nf);
  geom::Box box;
  for (std::size_t f = 0; f < nf; ++f) {
    const auto& t = object.faces[f];
    c[f] = (object.local[t[0]] + object.local[t[1]] + object.local[t[2]]) / 3.0;
    box.grow(c[f]);
  }
  std::vector<std::pair<std::uint64_t, std::uint32_t>> key(nf);
  const geom::Vec3 ext = (box.hi - box.lo).cwiseMax(geom::Vec3::Constant(1e-300));
  for (std::size_t f = 0; f < nf; ++f) {
    std::uint64_t code = 0;
    for (int k = 0; k < 3; ++k) {
      const double u = std::clamp((c[f][k] - box.lo[k]) / ext[k], 0.0, 1.0);
      code |= spread3(static_cast<std::uint64_t>(u * 2097151.0)) << k;
    }
    key[f] = {code, static_cast<std::uint32_t>(f)};
  }
  std::sort(key.begin(), key.end());
  Blocks blocks((nf + faces_per_block - 1) / faces_per_block);
  for (std::size_t i = 0; i < nf; ++i) blocks[i / faces_per_block].push_back(key[i].second);
  for (auto& b : blocks) std::sort(b.begin(), b.end());
  return blocks;
}

}  // namespace st::net
