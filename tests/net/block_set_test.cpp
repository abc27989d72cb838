// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/block_set.*: building shares, canonical encoding and content hash, checked decode.
#include <doctest/doctest.h>

#include <algorithm>
#include <random>

#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/net/block_set.hpp>

using namespace st;
using namespace st::net;

namespace {

struct Scene {
  geom::Mesh probe = geom::make_capsule(2.0, 6.0, 8);
  geom::Mesh object = geom::make_icosphere(20.0, 5);  // 500 faces
  Blocks blocks = spatial_blocks(object, 16);
};

void put_u32(std::vector<std::uint8_t>& b, std::size_t at, std::uint32_t v) { std::memcpy(b.data() + at, &v, 4); }

}  // namespace

TEST_CASE("spatial_blocks partitions every face exactly once; block_cyclic deals blocks round the workers") {
  Scene s;
  std::vector<int> seen(s.object.faces.size(), 0);
  for (const auto& b : s.blocks) {
    CHECK(b.size() <= 16);
    for (auto f : b) ++seen[f];
  }
  CHECK(std::all_of(seen.begin(), seen.end(), [](int c) { return c == 1; }));
  const auto bc = block_cyclic(10, 4);
  REQUIRE(bc.size() == 4);
  CHECK(bc[0] == std::vector<std::uint32_t>{0, 4, 8});
  CHECK(bc[3] == std::vector<std::uint32_t>{3, 7});
}

TEST_CASE("a share holds its blocks' faces with global ids and only the vertices they use, exactly") {
  Scene s;
  const auto per = block_cyclic(static_cast<std::uint32_t>(s.blocks.size()), 3);
  std::vector<std::uint32_t> all;
  for (const auto& ids : per) {
    auto bs = make_block_set(s.probe, s.object, s.blocks, ids, 8);
    REQUIRE(bs.ok());
    const BlockSet& b = bs.value();
    REQUIRE(b.object.faces.size() == b.object_face_ids.size());
    // Faces block by block, each block's in ascending global order: exactly the block's faces.
    REQUIRE(b.block_faces.size() == ids.size());
    std::size_t at = 0;
    for (std::size_t k = 0; k < ids.size(); ++k) {
      const auto first = b.object_face_ids.begin() + static_cast<std::ptrdiff_t>(at);
      const std::vector<std::uint32_t> got(first, first + b.block_faces[k]);
      std::vector<std::uint32_t> want = s.blocks[b.blocks[k]];
      std::sort(want.begin(), want.end());
      CHECK(got == want);
      at += b.block_faces[k];
    }
    CHECK(at == b.object_face_ids.size());
    for (std::size_t i = 0; i < b.object.faces.size(); ++i)
      for (int k = 0; k < 3; ++k)  // same doubles as the original: results cannot differ
        CHECK(b.object.vertex(b.object.faces[i][k]) == s.object.vertex(s.object.faces[b.object_face_ids[i]][k]));
    CHECK(b.object.local.size() < s.object.local.size());
    all.insert(all.end(), b.object_face_ids.begin(), b.object_face_ids.end());
  }
  std::sort(all.begin(), all.end());
  CHECK(all.size() == s.object.faces.size());
  CHECK(std::adjacent_find(all.begin(), all.end()) == all.end());
}

TEST_CASE("encoding is canonical: round trip, equal sets hash equal, different sets differ") {
  Scene s;
  const std::vector<std::uint32_t> ids{0, 3, 5}, same{5, 0, 3}, other{0, 3, 6};
  const auto e1 = encode_block_set(make_block_set(s.probe, s.object, s.blocks, ids, 8).value());
  const auto e2 = encode_block_set(make_block_set(s.probe, s.object, s.blocks, same, 8).value());
  const auto e3 = encode_block_set(make_block_set(s.probe, s.object, s.blocks, other, 8).value());
  const auto e4 = encode_block_set(make_block_set(s.probe, s.object, s.blocks, ids, 4).value());
  CHECK(e1 == e2);
  CHECK(block_set_hash(e1) == block_set_hash(e2));
  CHECK(block_set_hash(e1) != block_set_hash(e3));
  CHECK(block_set_hash(e1) != block_set_hash(e4));
  auto d = decode_block_set(e1, DefaultLimits());
  REQUIRE_MESSAGE(d.ok(), d.error());
  CHECK(encode_block_set(d.value()) == e1);
  CHECK(d.value().blocks == std::vector<std::uint32_t>{0, 3, 5});
  // The scene object it is a share of is part of its content: the same share as object 3 is
  // another set, and decodes naming object 3; an id at or above max_objects is refused at byte 6.
  const auto e5 = encode_block_set(make_block_set(s.probe, s.object, s.blocks, ids, 8, 3).value());
  CHECK(block_set_hash(e5) != block_set_hash(e1));
  auto d5 = decode_block_set(e5, DefaultLimits());
  REQUIRE_MESSAGE(d5.ok(), d5.error());
  CHECK(d5.value().object_id == 3);
  CHECK(d.value().object_id == 0);
  Limits few = DefaultLimits();
  few.max_objects = 3;
  auto bad = decode_block_set(e5, few);
  REQUIRE_FALSE(bad.ok());
  CHECK(bad.error().find("byte 6") != std::string::npos);
  CHECK(bad.error().find("object: 3 is not below max_objects = 3") != std::string::npos);
  CHECK_FALSE(make_block_set(s.probe, s.object, s.blocks, ids, 8, 70000).ok());
}

TEST_CASE("make_block_set refuses bad block ids") {
  Scene s;
  const std::vector<std::uint32_t> dup{1, 1}, out{999};
  CHECK_FALSE(make_block_set(s.probe, s.object, s.blocks, dup, 8).ok());
  CHECK_FALSE(make_block_set(s.probe, s.object, s.blocks, out, 8).ok());
  const std::vector<std::uint32_t> one{0};
  CHECK_FALSE(make_block_set(s.probe, s.object, s.blocks, one, 0).ok());
}

TEST_CASE("hostile block sets: truncation at every offset, bad indices, order, counts, NaN") {
  geom::Mesh probe = geom::make_box({1, 1, 1});
  geom::Mesh object = geom::make_box({2, 2, 2});
  Blocks blocks = spatial_blocks(object, 3);
  const std::vector<std::uint32_t> ids{0, 2};
  const BlockSet bs = make_block_set(probe, object, blocks, ids, 2).value();
  const auto good = encode_block_set(bs);
  const Limits L = DefaultLimits();
  REQUIRE(decode_block_set(good, L).ok());
  for (std::size_t n = 0; n < good.size(); ++n) {
    CAPTURE(n);
    CHECK_FALSE(decode_block_set(std::span(good).first(n), L).ok());
  }
  // Layout: 20-byte header, block count, 2 block ids, probe {origin 24, nv, nf, verts, faces}, object {...}, ids.
  const std::size_t probe_at = 24 + 4 * ids.size();
  const std::size_t probe_nv_at = probe_at + 24, probe_nf_at = probe_nv_at + 4;
  const std::size_t probe_faces_at = probe_nf_at + 4 + probe.local.size() * 24;
  const std::size_t obj_at = probe_faces_at + probe.faces.size() * 12;
  const std::size_t obj_faces_at = obj_at + 32 + bs.object.local.size() * 24;
  const std::size_t counts_at = obj_faces_at + bs.object.faces.size() * 12;
  const std::size_t ids_at = counts_at + 4 * ids.size();
  auto expect_error = [&](std::vector<std::uint8_t> b, const char* word) {
    INFO("expecting: " << std::string(word));
    auto d = decode_block_set(b, L);
    REQUIRE_FALSE(d.ok());
    CHECK_MESSAGE(d.error().find(word) != std::string::npos, d.error());
  };
  {
    auto b = good;
    put_u32(b, probe_faces_at + 4, 1000);
    expect_error(b, "out of range");
  }
  {
    auto b = good;
    put_u32(b, obj_faces_at, 1000);
    expect_error(b, "out of range");
  }
  {
    auto b = good;
    put_u32(b, 28, 0);
    expect_error(b, "not above");
  }  // block ids 0, 0
  {
    auto b = good;
    put_u32(b, ids_at + 4, bs.object_face_ids[0]);
    expect_error(b, "not above");
  }
  {
    auto b = good;  // the first block's first face again as the second block's first (still ascending)
    const std::uint32_t n0 = bs.block_faces[0];
    REQUIRE((n0 >= 1 && bs.block_faces[1] >= 1));
    REQUIRE((bs.block_faces[1] == 1 || bs.object_face_ids[0] < bs.object_face_ids[n0 + 1]));
    put_u32(b, ids_at + 4 * n0, bs.object_face_ids[0]);
    expect_error(b, "listed twice");
  }
  {
    auto b = good;  // counts that do not add up to the share's faces
    put_u32(b, counts_at, bs.block_faces[0] + 1);
    expect_error(b, "block face count");
  }
  {
    auto b = good;
    put_u32(b, counts_at, 0xffffffffu);
    expect_error(b, "exceed the share");
  }
  {
    auto b = good;
    put_u32(b, ids_at, 12);
    expect_error(b, "out of range");
  }  // id >= total faces
  {
    auto b = good;
    put_u32(b, probe_nv_at, 0xfffffff0u);
    expect_error(b, "vertex count");
  }
  {
    auto b = good;
    put_u32(b, probe_nf_at, 0x7ffffff0u);
    expect_error(b, "face count");
  }
  {
    auto b = good;
    put_u32(b, 8, 0);
    expect_error(b, "leaf_faces");
  }
  {
    auto b = good;
    put_u32(b, 16, 1);
    expect_error(b, "block id");
  }  // blocks_total 1
  {
    auto b = good;
    const double nan = std::nan("");
    std::memcpy(b.data() + probe_at + 8, &nan, 8);
    expect_error(b, "finite");
  }
  {
    auto b = good;
    b.push_back(0);
    expect_error(b, "trailing");
  }
  {
    auto b = good;
    b[4] = 9;
    expect_error(b, "version");
  }
  std::mt19937_64 rng(7);
  for (int t = 0; t < 3000; ++t) {
    auto b = good;
    for (int f = 0; f < 3; ++f) b[rng() % b.size()] ^= static_cast<std::uint8_t>(1u << (rng() % 8));
    auto d = decode_block_set(b, L);
    if (d.ok()) {
      for (const auto& f : d.value().object.faces)
        for (auto v : f) CHECK(v < d.value().object.local.size());
    }
  }
}
