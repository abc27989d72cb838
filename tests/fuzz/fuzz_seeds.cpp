// SPDX-License-Identifier: BSD-3-Clause
// Writes the generated part of the fuzz seed corpus: wire frames made by our own encoder (every
// message type, empty and non-empty lists, a LoadBlocks carrying a whole small block set) for
// fuzz_wire, tiny meshes in every format fuzz_mesh reads (its first byte selects the format),
// message sequences for fuzz_worker, a tree file for fuzz_tree and a live segment for fuzz_shm.
// Scene and pose seeds are copies of real files (configs/*.toml, perf/poses/). Usage:
//   build-fuzz/tests/fuzz/fuzz_seeds tests/fuzz/corpus
// (overwrites the seed_* files it writes; run from any build, it needs no libFuzzer).
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/tree_io.hpp>
#include <spheretouch/net/block_set.hpp>
#include <spheretouch/net/protocol.hpp>
#include <spheretouch/rt/shm_segment.hpp>

namespace {

using namespace st;
using namespace st::net;
namespace fs = std::filesystem;

void write(const fs::path& path, const void* data, std::size_t size) {
  fs::create_directories(path.parent_path());
  std::ofstream o(path, std::ios::binary | std::ios::trunc);
  o.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  if (!o) {
    std::fprintf(stderr, "cannot write %s\n", path.c_str());
    std::exit(1);
  }
}

void write_frame(const fs::path& dir, const std::string& name, const Message& m) {
  const std::vector<std::uint8_t> b = encode(m);
  write(dir / ("seed_" + name + ".bin"), b.data(), b.size());
}

geom::Pose some_pose() {
  geom::Pose p = geom::Pose::Identity();
  p.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  p.translation() = Eigen::Vector3d(1e6, -2.5, 0.125);
  return p;
}

void wire_seeds(const fs::path& dir) {
  write_frame(dir, "hello", HelloMsg{7, 0x1234567890abcdefull, 42, {{0xdeadbeefull, 1000}, {0x1ull, 0}}});
  write_frame(dir, "hello_empty", HelloMsg{0, 1, 0, {}});
  write_frame(dir, "loadblocks_chunk", LoadBlocksMsg{0xfeedull, 10, 4, {1, 2, 3, 4, 5, 6}});
  write_frame(dir, "query", QueryMsg{99, 0xabcull, some_pose(), {}});
  write_frame(dir, "query_identity", QueryMsg{1, 2, geom::Pose::Identity(), {}});
  write_frame(dir, "query_skip", QueryMsg{3, 0xabcull, some_pose(), {0, 2, 9}});
  write_frame(dir, "query_take", QueryMsg{4, 0xabcull, some_pose(), {1}, 0, 0xdefull, {0, 2, 9}});
  write_frame(dir, "result", ResultMsg{99, 3, 0xabcull, {10, 20, 30}, {{1, 2}, {3, 4}, {0xffffffffu, 0}}});
  write_frame(dir, "result_empty", ResultMsg{1, 0, 0, {}, {}});
  ResultMsg worked{99, 3, 0xabcull, {10, 20, 30}, {{1, 2}}};
  worked.worked = {{0, 5}, {17, 1}, {4096, 0xffffffffu}};
  write_frame(dir, "result_worked", worked);
  write_frame(dir, "heartbeat", HeartbeatMsg{0x55aa});
  write_frame(dir, "error", ErrorMsg{ErrorCode::NotLoaded, 17, "block set 0x11 not held"});
  // A whole block set in one chunk, as a client sends a small one: a box probe against an
  // icosphere cut into blocks, this worker holding every other block.
  const geom::Mesh probe = geom::make_box(geom::Vec3(4, 4, 4));
  const geom::Mesh object = geom::make_icosphere(10.0, 1);
  const Blocks blocks = spatial_blocks(object, 4);
  std::vector<std::uint32_t> mine;
  for (std::uint32_t b = 0; b < blocks.size(); b += 2) mine.push_back(b);
  Result<BlockSet> set = make_block_set(probe, object, blocks, mine, 4);
  if (!set) {
    std::fprintf(stderr, "%s\n", set.error().c_str());
    std::exit(1);
  }
  const std::vector<std::uint8_t> enc = encode_block_set(set.value());
  write_frame(dir, "loadblocks_whole_set", LoadBlocksMsg{block_set_hash(enc), enc.size(), 0, enc});
}

// A square pyramid (the mesh_io tests' shape) in each format; the first byte picks the reader.
const std::vector<geom::Vec3> kPos = {{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {0, 2, 0}, {1, 1, 1.5}};
const std::vector<geom::Tri> kTris = {{0, 2, 1}, {0, 3, 2}, {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}};

void write_mesh(const fs::path& dir, const std::string& name, char format, const std::string& body) {
  const std::string bytes = std::string(1, format) + body;
  write(dir / ("seed_" + name), bytes.data(), bytes.size());
}

void mesh_seeds(const fs::path& dir) {
  write_mesh(
      dir, "off", 0,
      "OFF\n# a pyramid\n5 5 0\n0 0 0\n2 0 0\n2 2 0\n0 2 0\n1 1 1.5\n4 0 3 2 1\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n");
  write_mesh(dir, "obj", 1,
             "# pyramid\nv 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nv 1 1 1.5\nvn 0 0 1\nvt 0 0\ng base\nusemtl a\n"
             "f 1/1/1 3/1/1 2/1/1\nf -5//1 -2//1 -3//1\ng sides\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\nl 1 2\n");
  write_mesh(
      dir, "ply_ascii", 2,
      "ply\nformat ascii 1.0\ncomment pyramid\nelement vertex 5\nproperty float x\nproperty float y\n"
      "property float z\nproperty uchar red\nelement face 5\nproperty list uchar int vertex_indices\n"
      "end_header\n0 0 0 1\n2 0 0 2\n2 2 0 3\n0 2 0 4\n1 1 1.5 5\n4 0 3 2 1\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n");
  {
    std::string ply =
        "ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
        "property float z\nelement face 6\nproperty list uchar int vertex_indices\nend_header\n";
    for (const geom::Vec3& p : kPos)
      for (int c = 0; c < 3; ++c) {
        const float f = float(p[c]);
        ply.append(reinterpret_cast<const char*>(&f), 4);
      }
    for (const geom::Tri& t : kTris) {
      ply += char(3);
      for (std::uint32_t i : t) {
        const std::int32_t v = std::int32_t(i);
        ply.append(reinterpret_cast<const char*>(&v), 4);
      }
    }
    write_mesh(dir, "ply_binary", 2, ply);
  }
  std::string ascii = "solid pyramid\n", binary(80, ' ');
  const auto n = static_cast<std::uint32_t>(kTris.size());
  binary.append(reinterpret_cast<const char*>(&n), 4);
  for (const geom::Tri& t : kTris) {
    const geom::Vec3 nrm = (kPos[t[1]] - kPos[t[0]]).cross(kPos[t[2]] - kPos[t[0]]).normalized();
    ascii += " facet normal " + std::to_string(nrm.x()) + " " + std::to_string(nrm.y()) + " " +
             std::to_string(nrm.z()) + "\n  outer loop\n";
    float f[12] = {float(nrm.x()), float(nrm.y()), float(nrm.z())};
    for (int k = 0; k < 3; ++k) {
      ascii += "   vertex";
      for (int c = 0; c < 3; ++c) {
        f[3 + 3 * k + c] = float(kPos[t[k]][c]);
        ascii += " " + std::to_string(kPos[t[k]][c]);
      }
      ascii += "\n";
    }
    ascii += "  endloop\n endfacet\n";
    binary.append(reinterpret_cast<const char*>(f), sizeof f);
    binary.append(2, '\0');
  }
  ascii += "endsolid pyramid\n";
  write_mesh(dir, "stl_ascii", 3, ascii);
  write_mesh(dir, "stl_binary", 3, binary);
}

// fuzz_worker: message sequences (records: u8 client, u16 length, frame) over a block set small
// enough for the harness's limits.
void add_record(std::vector<std::uint8_t>& seq, int client, const std::vector<std::uint8_t>& frame) {
  seq.push_back(std::uint8_t(client));
  seq.push_back(std::uint8_t(frame.size() & 0xFF));
  seq.push_back(std::uint8_t(frame.size() >> 8));
  seq.insert(seq.end(), frame.begin(), frame.end());
}

void worker_seeds(const fs::path& dir) {
  const geom::Mesh probe = geom::make_box(geom::Vec3(4, 4, 4));
  const geom::Mesh object = geom::make_icosphere(10.0, 1);
  const Blocks blocks = spatial_blocks(object, 8);
  std::vector<std::uint32_t> all;
  for (std::uint32_t b = 0; b < blocks.size(); ++b) all.push_back(b);
  const std::vector<std::uint8_t> enc = encode_block_set(make_block_set(probe, object, blocks, all, 4).value());
  const std::uint64_t h = block_set_hash(enc);
  const std::size_t half = enc.size() / 2;
  const LoadBlocksMsg first{h, enc.size(), 0, {enc.begin(), enc.begin() + half}};
  const LoadBlocksMsg second{h, enc.size(), half, {enc.begin() + half, enc.end()}};
  geom::Pose touching = geom::Pose::Identity();
  touching.translation() = geom::Vec3(9, 0, 0);
  std::vector<std::uint8_t> seq;
  // One client loads in two chunks and queries; another queries the same set and is refused.
  add_record(seq, 0, encode(first));
  add_record(seq, 0, encode(second));
  add_record(seq, 0, encode(QueryMsg{1, h, touching, {}}));
  add_record(seq, 1, encode(QueryMsg{2, h, touching, {}}));
  add_record(seq, 1, encode(HeartbeatMsg{3}));
  write(dir / "seed_load_query.bin", seq.data(), seq.size());
  // A second set (standby copies of the first blocks), then a Query naming it and taking two.
  seq.clear();
  const std::vector<std::uint32_t> few = {0, 1, 2};
  const std::vector<std::uint8_t> enc2 = encode_block_set(make_block_set(probe, object, blocks, few, 4).value());
  const std::uint64_t h2 = block_set_hash(enc2);
  add_record(seq, 0, encode(first));
  add_record(seq, 0, encode(second));
  add_record(seq, 0, encode(LoadBlocksMsg{h2, enc2.size(), 0, enc2}));
  add_record(seq, 0, encode(QueryMsg{5, h, touching, {1}, 0, h2, {0, 1}}));
  add_record(seq, 0, encode(QueryMsg{6, h, touching, {}, 0, h2 ^ 1, {2}}));
  write(dir / "seed_standby.bin", seq.data(), seq.size());
  // Interleaved uploads, one restarted, a third client refused, then the same bytes shared.
  seq.clear();
  add_record(seq, 0, encode(first));
  add_record(seq, 1, encode(first));
  add_record(seq, 2, encode(first));
  add_record(seq, 1, encode(first));
  add_record(seq, 0, encode(second));
  add_record(seq, 1, encode(second));
  add_record(seq, 1, encode(QueryMsg{4, h, touching, {}}));
  add_record(seq, 3, encode(second));
  write(dir / "seed_interleaved.bin", seq.data(), seq.size());
}

// fuzz_tree: the tree file of the harness's fixture (icosphere 10 mm, 2 subdivisions, 4 faces a leaf).
void tree_seeds(const fs::path& dir) {
  const geom::Mesh object = geom::make_icosphere(10.0, 2);
  geom::TreeConfig params = geom::DefaultTreeConfig();
  params.leaf_faces = 4;
  fs::create_directories(dir);
  if (Status s = geom::write_tree(geom::SphereTree::build(object, params).value(), (dir / "seed_icosphere.tree").string());
      !s) {
    std::fprintf(stderr, "%s\n", s.error().c_str());
    std::exit(1);
  }
}

// fuzz_shm: a live segment's bytes after a pose and a contact model went through it.
void shm_seeds(const fs::path& dir) {
  const std::string name = "/spheretouch-seed-" + std::to_string(::getpid());
  auto seg = rt::ShmSegment::create(name);
  if (!seg) {
    std::fprintf(stderr, "%s\n", seg.error().c_str());
    std::exit(1);
  }
  rt::PoseSample p{};
  p.seq = 7;
  p.pose = geom::to_pod(geom::Pose::Identity());
  seg.value()->poses().write(p);
  geom::ContactModel m{};
  m.seq = 3;
  m.flags = geom::kInContact;
  m.force_dir = geom::to_pod(geom::Vec3(0, 0, 1));
  m.penetration_mm = 0.8;
  seg.value()->models().write(geom::ContactSet::of(m));
  // A view frame with a few faces (what a run publishes for a live view).
  auto f = std::make_unique<rt::ViewFrame>();
  f->round = 3;
  f->flags = rt::ViewFrame::kInContact;
  f->n_probe = 2;
  f->n_object = 3;
  const std::uint32_t faces[5] = {1, 4, 10, 11, 12};
  std::copy(faces, faces + 5, f->faces);
  f->contacts = 5;
  seg.value()->status().view.store(*f, f->used_bytes());
  const int fd = ::shm_open(name.c_str(), O_RDONLY, 0);
  std::vector<std::uint8_t> bytes(sizeof(rt::ShmLayout));
  if (fd < 0 || ::pread(fd, bytes.data(), bytes.size(), 0) != static_cast<ssize_t>(bytes.size())) {
    std::fprintf(stderr, "cannot read back %s\n", name.c_str());
    std::exit(1);
  }
  ::close(fd);
  write(dir / "seed_segment.bin", bytes.data(), bytes.size());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_DIR (tests/fuzz/corpus)\n", argv[0]);
    return 2;
  }
  const fs::path root(argv[1]);
  wire_seeds(root / "fuzz_wire");
  mesh_seeds(root / "fuzz_mesh");
  worker_seeds(root / "fuzz_worker");
  tree_seeds(root / "fuzz_tree");
  shm_seeds(root / "fuzz_shm");
  std::printf("wrote wire, mesh, worker, tree and shm seeds under %s\n", root.c_str());
  return 0;
}
