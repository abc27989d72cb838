// SPDX-License-Identifier: BSD-3-Clause
// SphereTree file format (version 1), little-endian, native struct layout (sizes pinned by
// static_assert in sphere_tree.hpp):
//   [0,64) header: char magic[8] "STSPHTR1"; u32 version; u32 leaf_faces; u64 mesh_hash;
//                  u32 num_vertices; u32 num_faces; u32 num_nodes; u32 num_depths;
//                  u64 payload_bytes; u64 payload_checksum; u64 reserved
//   payload:       SphereNode[num_nodes], SphereNodeCold[num_nodes], u32 face_order[num_faces],
//                  FaceBox[num_faces]
#include <spheretouch/geom/tree_io.hpp>

#include <unistd.h>

#include <bit>
#include <cerrno>
#include <cstdio>
#include <cmath>
#include <cstring>
#include <limits>
#include <fstream>

namespace st::inline SPHERETOUCH_ABI::geom {
namespace {

static_assert(std::endian::native == std::endian::little, "tree files are little-endian");

constexpr char kMagic[8] = {'S', 'T', 'S', 'P', 'H', 'T', 'R', '1'};

struct Header {
  char magic[8];
  std::uint32_t version;
  std::uint32_t leaf_faces;
  std::uint64_t mesh_hash;
  std::uint32_t num_vertices;
  std::uint32_t num_faces;
  std::uint32_t num_nodes;
  std::uint32_t num_depths;
  std::uint64_t payload_bytes;
  std::uint64_t checksum;
  std::uint64_t reserved;
};
static_assert(sizeof(Header) == 64);

// FNV-1a over 64-bit words plus a final avalanche (integrity, not security).
std::uint64_t checksum(const void* p, std::size_t n, std::uint64_t h) {
  const auto* c = static_cast<const unsigned char*>(p);
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    std::uint64_t w;
    std::memcpy(&w, c + i, 8);
    h = (h ^ w) * 0x100000001b3ull;
    h ^= h >> 29;
  }
  for (; i < n; ++i) h = (h ^ c[i]) * 0x100000001b3ull;
  return h;
}

std::uint64_t payload_checksum(const SphereTree& t) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  h = checksum(t.nodes.data(), t.nodes.size() * sizeof(SphereNode), h);
  h = checksum(t.cold.data(), t.cold.size() * sizeof(SphereNodeCold), h);
  h = checksum(t.face_order.data(), t.face_order.size() * sizeof(std::uint32_t), h);
  h = checksum(t.face_boxes.data(), t.face_boxes.size() * sizeof(FaceBox), h);
  return h;
}

std::uint64_t payload_size(std::uint64_t nodes, std::uint64_t faces) {
  return nodes * (sizeof(SphereNode) + sizeof(SphereNodeCold)) + faces * (sizeof(std::uint32_t) + sizeof(FaceBox));
}

// Structural checks, so that a file whose checksum and hash were forged (they are not
// cryptographic) still cannot make collide() read or write out of bounds or run forever: the nodes
// must form exactly the tree SphereTree::build() makes. From the root, every node is reached once
// (a tree: no shared children, no cycles, nothing unreachable); a child's depth is its parent's
// plus one and the file's num_depths is the deepest depth plus one, at most kMaxTreeDepth (collide()
// sizes its stack from it); children are contiguous, after their parent, and their face ranges
// split the parent's range in order; a leaf holds 1..kMaxLeafFaces faces; face_order is a
// permutation.
Status check_structure(const SphereTree& t, const std::string& path) {
  const std::uint32_t N = t.num_nodes(), F = t.num_faces();
  if (t.num_depths == 0 || t.num_depths > kMaxTreeDepth)
    return fail(path, ": corrupt: num_depths ", t.num_depths, ", expected 1..", kMaxTreeDepth);
  const SphereNodeCold& root = t.cold[0];
  if (root.parent != kNoNode || t.nodes[0].depth != 0 || root.face_begin != 0 || root.face_end != F)
    return fail(path, ": corrupt: root node (parent, depth 0, faces [0, ", F, ")) expected");
  std::vector<std::uint8_t> reached(N, 0);
  reached[0] = 1;
  std::uint32_t max_depth = 0, count = 1;
  // Children always follow their parent, so one pass in index order visits parents first.
  for (std::uint32_t i = 0; i < N; ++i) {
    if (!reached[i]) return fail(path, ": corrupt: node ", i, " is not reachable from the root");
    const SphereNode& h = t.nodes[i];
    const SphereNodeCold& c = t.cold[i];
    if (!(std::isfinite(h.radius) && h.radius >= 0 && std::isfinite(h.centre[0]) && std::isfinite(h.centre[1]) &&
          std::isfinite(h.centre[2])))
      return fail(path, ": corrupt: node ", i, " sphere is not finite");
    if (c.face_begin >= c.face_end || c.face_end > F) return fail(path, ": corrupt: node ", i, " face range");
    max_depth = std::max<std::uint32_t>(max_depth, h.depth);
    if (h.leaf) {
      if (h.leaf != 1 || h.first != c.face_begin || h.count != c.face_end - c.face_begin || h.count > kMaxLeafFaces)
        return fail(path, ": corrupt: leaf ", i, " face range");
      continue;
    }
    if (h.count < 1 || h.count > kMaxChildren || h.first <= i || std::uint64_t{h.first} + h.count > N)
      return fail(path, ": corrupt: node ", i, " child range");
    std::uint32_t next_face = c.face_begin;
    for (std::uint32_t k = h.first; k < h.first + h.count; ++k) {
      if (reached[k]) return fail(path, ": corrupt: node ", k, " has two parents");
      reached[k] = 1;
      ++count;
      const SphereNodeCold& ck = t.cold[k];
      if (ck.parent != i) return fail(path, ": corrupt: node ", k, " names parent ", ck.parent, ", not ", i);
      if (t.nodes[k].depth != h.depth + 1)
        return fail(path, ": corrupt: node ", k, " depth ", unsigned(t.nodes[k].depth), ", expected ", h.depth + 1);
      if (ck.face_begin != next_face)
        return fail(path, ": corrupt: node ", k, " face range does not follow its sibling's");
      next_face = ck.face_end;
    }
    if (next_face != c.face_end) return fail(path, ": corrupt: node ", i, " children do not cover its faces");
  }
  if (count != N) return fail(path, ": corrupt: ", N - count, " nodes are not in the tree");
  if (t.num_depths != max_depth + 1)
    return fail(path, ": corrupt: num_depths ", t.num_depths, " but the deepest node is at depth ", max_depth);
  // Descendants of an inner node are the contiguous range [first, desc_end) (partition.cpp ships
  // subtrees by it): children come after their parent, so a backward pass gives each subtree's end.
  std::vector<std::uint32_t> sub_end(N);
  for (std::uint32_t i = N; i-- > 0;) {
    const SphereNode& h = t.nodes[i];
    sub_end[i] = i + 1;
    if (h.leaf) continue;
    for (std::uint32_t k = h.first; k < h.first + h.count; ++k) sub_end[i] = std::max(sub_end[i], sub_end[k]);
    if (t.cold[i].desc_end != sub_end[i]) return fail(path, ": corrupt: node ", i, " descendant range");
  }
  std::vector<bool> seen(F, false);
  for (std::uint32_t f : t.face_order) {
    if (f >= F || seen[f]) return fail(path, ": corrupt: face_order is not a permutation");
    seen[f] = true;
  }
  return Ok{};
}

// Every vertex below a node lies in its (padded) sphere, and every face box contains its face:
// what collide() relies on to skip a node. A forged file could otherwise hide collisions. And
// they are tight: a sphere no larger than the diagonal of its vertices' box (the builder's are
// within half of it, the smallest enclosing sphere's radius), a face box no larger than its
// face's box widened by the float rounding; a file of huge spheres or infinite boxes would
// otherwise pass and turn every query into brute force.
Status check_bounds(const SphereTree& t, const Mesh& mesh, const std::string& path) {
  const std::uint32_t N = t.num_nodes();
  for (std::uint32_t i = 0; i < N; ++i) {
    const SphereNode& h = t.nodes[i];
    const SphereNodeCold& c = t.cold[i];
    const Vec3 centre(h.centre[0], h.centre[1], h.centre[2]);
    const double r = double(h.radius) * (1 + 1e-6) + 1e-9;
    Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (std::uint32_t s = c.face_begin; s < c.face_end; ++s) {
      const std::uint32_t f = t.face_order[s];
      for (std::uint32_t v : mesh.faces[f]) {
        if (!(v < mesh.local.size()) || (mesh.local[v] - centre).norm() > r)
          return fail(path, ": corrupt: node ", i, " sphere does not hold face ", f);
        lo = lo.cwiseMin(mesh.local[v]);
        hi = hi.cwiseMax(mesh.local[v]);
      }
    }
    const double diagonal = (hi - lo).norm(), scale = std::max(lo.cwiseAbs().maxCoeff(), hi.cwiseAbs().maxCoeff());
    if (double(h.radius) > diagonal * (1 + 1e-6) + 1e-6 * scale + 1e-9)
      return fail(path, ": corrupt: node ", i, " sphere (radius ", h.radius, ") is not tight: its faces span ", diagonal);
  }
  for (std::uint32_t s = 0; s < t.num_faces(); ++s) {
    const FaceBox& b = t.face_boxes[s];
    for (int k = 0; k < 3; ++k) {
      double lo = std::numeric_limits<double>::infinity(), hi = -lo;
      for (std::uint32_t v : mesh.faces[t.face_order[s]]) {
        const double x = mesh.local[v][k];
        if (!(double(b.lo[k]) <= x && x <= double(b.hi[k])))
          return fail(path, ": corrupt: face box of face ", t.face_order[s], " does not hold it");
        lo = std::min(lo, x);
        hi = std::max(hi, x);
      }
      // Single precision rounded outward: a few ulps of the coordinate's size.
      const double slack = 1e-6 * std::max({std::abs(lo), std::abs(hi), 1.0});
      if (double(b.lo[k]) < lo - slack || double(b.hi[k]) > hi + slack)
        return fail(path, ": corrupt: face box of face ", t.face_order[s], " is not tight");
    }
  }
  return Ok{};
}

}  // namespace

Status write_tree(const SphereTree& t, const std::string& path) {
  Header h{};
  std::memcpy(h.magic, kMagic, 8);
  h.version = kTreeFormatVersion;
  h.leaf_faces = t.params.leaf_faces;
  h.mesh_hash = t.mesh_hash;
  h.num_vertices = t.num_vertices;
  h.num_faces = t.num_faces();
  h.num_nodes = t.num_nodes();
  h.num_depths = t.num_depths;
  h.payload_bytes = payload_size(h.num_nodes, h.num_faces);
  h.checksum = payload_checksum(t);
  // Written to a temporary file, flushed to the disk, then renamed over the old one: a crash or a
  // full disk leaves either the old file or the new one, never half of one, and no temporary.
  const std::string tmp = path + ".tmp";
  std::FILE* out = std::fopen(tmp.c_str(), "wb");
  if (!out) return fail(path, ": cannot open ", tmp, " for writing: ", std::strerror(errno));
  bool ok = std::fwrite(&h, sizeof h, 1, out) == 1;
  auto put = [&](const void* p, std::size_t n) { ok = ok && (n == 0 || std::fwrite(p, n, 1, out) == 1); };
  put(t.nodes.data(), t.nodes.size() * sizeof(SphereNode));
  put(t.cold.data(), t.cold.size() * sizeof(SphereNodeCold));
  put(t.face_order.data(), t.face_order.size() * 4);
  put(t.face_boxes.data(), t.face_boxes.size() * sizeof(FaceBox));
  ok = ok && std::fflush(out) == 0 && ::fsync(::fileno(out)) == 0;
  const int err = errno;
  ok = (std::fclose(out) == 0) && ok;
  if (!ok) {
    std::remove(tmp.c_str());
    return fail(path, ": write failed: ", std::strerror(err ? err : errno));
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    std::remove(tmp.c_str());
    return fail(path, ": cannot rename ", tmp, " into place: ", std::strerror(e));
  }
  return Ok{};
}

namespace {

/// The header's own checks against the file's size (before anything is allocated).
Status check_header(const Header& h, std::uint64_t file_size, const std::string& path) {
  if (std::memcmp(h.magic, kMagic, 8) != 0) return fail(path, ": corrupt: bad magic (not a spheretouch tree file)");
  if (h.version != kTreeFormatVersion)
    return fail(path, ": corrupt: format version ", h.version, ", expected ", kTreeFormatVersion);
  if (h.num_nodes == 0 || h.num_faces == 0 || h.payload_bytes != payload_size(h.num_nodes, h.num_faces) ||
      file_size != sizeof h + h.payload_bytes)
    return fail(path, ": corrupt: sizes (", h.num_nodes, " nodes, ", h.num_faces, " faces, payload ", h.payload_bytes,
                " bytes) do not match the file size ", file_size);
  return Ok{};
}

/// A tree with the arrays a file's header announces, filled from the payload that follows it
/// (check_header has matched the sizes to the bytes).
SphereTree payload_of(const Header& h, std::span<const std::uint8_t> bytes) {
  SphereTree t;
  t.nodes.resize(h.num_nodes);
  t.cold.resize(h.num_nodes);
  t.face_order.resize(h.num_faces);
  t.face_boxes.resize(h.num_faces);
  const std::uint8_t* p = bytes.data() + sizeof h;
  auto take = [&](void* dst, std::size_t n) {
    if (n) std::memcpy(dst, p, n);
    p += n;
  };
  take(t.nodes.data(), t.nodes.size() * sizeof(SphereNode));
  take(t.cold.data(), t.cold.size() * sizeof(SphereNodeCold));
  take(t.face_order.data(), t.face_order.size() * 4);
  take(t.face_boxes.data(), t.face_boxes.size() * sizeof(FaceBox));
  return t;
}

}  // namespace

Result<SphereTree> parse_tree(std::span<const std::uint8_t> bytes, const std::string& path, const Mesh& mesh,
                              const TreeConfig& params) {
  Header h{};
  if (bytes.size() < sizeof h)
    return fail(path, ": corrupt: file of ", bytes.size(), " bytes is shorter than the 64-byte header");
  std::memcpy(&h, bytes.data(), sizeof h);
  if (Status s = check_header(h, bytes.size(), path); !s) return Error{s.error()};
  SphereTree t = payload_of(h, bytes);
  t.params.leaf_faces = h.leaf_faces;
  t.mesh_hash = h.mesh_hash;
  t.num_vertices = h.num_vertices;
  t.num_depths = h.num_depths;
  if (payload_checksum(t) != h.checksum) return fail(path, ": corrupt: payload checksum mismatch");
  if (h.leaf_faces != params.leaf_faces || h.mesh_hash != tree_hash(mesh, params) || h.num_faces != mesh.num_faces() ||
      h.num_vertices != mesh.num_vertices())
    return fail(path, ": stale: built for another mesh or parameters (hash/leaf_faces/sizes differ from ", mesh.name,
                " with leaf_faces ", params.leaf_faces, ")");
  if (Status s = check_structure(t, path); !s) return Error{s.error()};
  if (Status s = check_bounds(t, mesh, path); !s) return Error{s.error()};
  return t;
}

Result<SphereTree> read_tree(const std::string& path, const Mesh& mesh, const TreeConfig& params) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return fail(path, ": cannot open");
  const auto file_size = static_cast<std::uint64_t>(in.tellg());
  in.seekg(0);
  Header h{};
  if (file_size < sizeof h || !in.read(reinterpret_cast<char*>(&h), sizeof h))
    return fail(path, ": corrupt: file of ", file_size, " bytes is shorter than the 64-byte header");
  // The sizes are checked before the payload is read, so a header cannot make us allocate.
  if (Status s = check_header(h, file_size, path); !s) return Error{s.error()};
  std::vector<std::uint8_t> all(file_size);
  in.seekg(0);
  if (!in.read(reinterpret_cast<char*>(all.data()), static_cast<std::streamsize>(file_size)))
    return fail(path, ": corrupt: short read");
  return parse_tree(all, path, mesh, params);
}

void seal_tree_bytes(std::vector<std::uint8_t>& bytes, const Mesh& mesh, const TreeConfig& params) {
  Header h{};
  if (bytes.size() < sizeof h) return;
  std::memcpy(&h, bytes.data(), sizeof h);
  h.mesh_hash = tree_hash(mesh, params);
  h.leaf_faces = params.leaf_faces;
  h.num_faces = static_cast<std::uint32_t>(mesh.num_faces());
  h.num_vertices = static_cast<std::uint32_t>(mesh.num_vertices());
  std::memcpy(bytes.data(), &h, sizeof h);
  if (!check_header(h, bytes.size(), "")) return;
  h.checksum = payload_checksum(payload_of(h, bytes));  // over the payload as parse_tree reads it
  std::memcpy(bytes.data(), &h, sizeof h);
}

}  // namespace st::geom
