// SPDX-License-Identifier: BSD-3-Clause
// libFuzzer target: the wire decoder (net/protocol.hpp), i.e. every frame a worker or the client
// accepts from the network, and the block-set decoder (net/block_set.hpp) behind LoadBlocks.
// Properties, beyond "no crash, leak, UB or unbounded allocation":
//  * a frame that decodes re-encodes to the identical bytes (the encoding is canonical) and
//    decodes again to an equal message;
//  * a frame accepted under tight limits is accepted, equal, under the default ones;
//  * a LoadBlocks frame carrying a whole block set (offset 0, every byte) has that block set
//    decoded as the worker does once the chunks are assembled (the worker checks the content
//    hash first; the harness skips that, since no mutation would pass it). A block set that
//    decodes satisfies the decoder's contract and re-encodes to the identical bytes.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "fuzz_check.hpp"
#include <spheretouch/net/block_set.hpp>
#include <spheretouch/net/protocol.hpp>

namespace {

using namespace st::net;

/// Limits small enough that short inputs reach every limit check.
Limits tight_limits() {
  Limits L;
  L.max_message_bytes = 512;
  L.max_chunk_bytes = 64;
  L.max_blockset_bytes = 256;
  L.max_pairs = 8;
  L.max_held = 2;
  L.max_text = 16;
  L.max_vertices = 8;
  L.max_faces = 8;
  L.max_blocks = 8;
  L.max_leaf_faces = 4;
  return L;
}

void check_mesh(const st::geom::Mesh& m, const char* which) {
  ST_FUZZ_CHECK(m.origin.allFinite(), which);
  for (const st::geom::Vec3& v : m.local) {
    ST_FUZZ_CHECK(v.allFinite(), which);
    ST_FUZZ_CHECK((m.origin + v).allFinite(), which);
  }
  for (const st::geom::Tri& f : m.faces)
    for (std::uint32_t i : f) ST_FUZZ_CHECK(i < m.local.size(), which);
}

void check_ascending(std::span<const std::uint32_t> ids, std::uint32_t total, const char* which) {
  for (std::size_t i = 0; i < ids.size(); ++i) {
    ST_FUZZ_CHECK(ids[i] < total, which);
    ST_FUZZ_CHECK(i == 0 || ids[i] > ids[i - 1], which);
  }
}

void check_block_set(std::span<const std::uint8_t> bytes, const Limits& L) {
  st::Result<BlockSet> r = decode_block_set(bytes, L);
  if (!r) return;
  const BlockSet& s = r.value();
  ST_FUZZ_CHECK(s.leaf_faces >= 1 && s.leaf_faces <= L.max_leaf_faces, "block set leaf_faces");
  ST_FUZZ_CHECK(s.object_faces_total <= L.max_faces && s.blocks_total <= L.max_blocks, "block set totals");
  check_ascending(s.blocks, s.blocks_total, "block ids");
  ST_FUZZ_CHECK(s.object_face_ids.size() == s.object.faces.size(), "one global id per share face");
  ST_FUZZ_CHECK(s.block_faces.size() == s.blocks.size(), "a face count per block");
  std::size_t at = 0;
  for (std::uint32_t n : s.block_faces) {
    ST_FUZZ_CHECK(at + n <= s.object_face_ids.size(), "block face counts within the share");
    check_ascending(std::span(s.object_face_ids).subspan(at, n), s.object_faces_total, "a block's face ids");
    at += n;
  }
  ST_FUZZ_CHECK(at == s.object_face_ids.size(), "block face counts add up to the share");
  std::vector<std::uint32_t> sorted = s.object_face_ids;
  std::sort(sorted.begin(), sorted.end());
  ST_FUZZ_CHECK(std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end(), "no face id twice");
  ST_FUZZ_CHECK(s.probe.local.size() <= L.max_vertices && s.object.local.size() <= L.max_vertices, "vertex limit");
  check_mesh(s.probe, "block set probe");
  check_mesh(s.object, "block set object share");
  const std::vector<std::uint8_t> again = encode_block_set(s);
  ST_FUZZ_CHECK(again.size() == bytes.size() && std::memcmp(again.data(), bytes.data(), bytes.size()) == 0,
                "block set re-encodes to the identical bytes");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> frame(data, size);
  const Limits defaults = DefaultLimits();
  st::Result<Message> r = decode(frame, defaults);
  st::Result<Message> tight = decode(frame, tight_limits());
  if (tight) {
    ST_FUZZ_CHECK(r.ok(), "accepted under tight limits but refused under the defaults");
    ST_FUZZ_CHECK(tight.value() == r.value(), "tight and default limits decode differently");
  }
  if (!r) {
    ST_FUZZ_CHECK(!r.error().empty(), "a refusal says why");
    return 0;
  }
  const Message& m = r.value();
  const std::vector<std::uint8_t> again = encode(m);
  ST_FUZZ_CHECK(again.size() == size && std::memcmp(again.data(), data, size) == 0,
                "a decoded frame re-encodes to the identical bytes");
  st::Result<Message> r2 = decode(again, defaults);
  ST_FUZZ_CHECK(r2.ok(), "a re-encoded frame decodes");
  ST_FUZZ_CHECK(r2.value() == m, "decode(encode(m)) == m");

  if (const auto* q = std::get_if<QueryMsg>(&m)) {
    ST_FUZZ_CHECK(q->pose.matrix().allFinite(), "Query pose finite");
  } else if (const auto* lb = std::get_if<LoadBlocksMsg>(&m)) {
    ST_FUZZ_CHECK(lb->offset + lb->data.size() <= lb->total_bytes, "chunk inside its block set");
    ST_FUZZ_CHECK(lb->total_bytes <= defaults.max_blockset_bytes && lb->data.size() <= defaults.max_chunk_bytes,
                  "chunk limits");
    if (lb->offset == 0 && lb->data.size() == lb->total_bytes) {
      check_block_set(lb->data, defaults);
      check_block_set(lb->data, tight_limits());
    }
  } else if (const auto* e = std::get_if<ErrorMsg>(&m)) {
    ST_FUZZ_CHECK(e->text.size() <= defaults.max_text, "Error text limit");
  }
  return 0;
}
