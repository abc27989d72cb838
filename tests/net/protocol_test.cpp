// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/protocol.*: round trips of every message, and hostile decoding (truncation at
// every byte offset, oversized counts, wrong version, bit flips, random garbage).
#include <doctest/doctest.h>

#include <random>

#include <spheretouch/net/protocol.hpp>
#include <spheretouch/net/wire.hpp>

using namespace st;
using namespace st::net;

namespace {

geom::Pose some_pose() {
  geom::Pose p = geom::Pose::Identity();
  p.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  p.translation() = Eigen::Vector3d(1e6, -2.5, 0.125);
  return p;
}

std::vector<Message> samples() {
  std::vector<Message> v;
  v.push_back(HelloMsg{7, 0x1234567890abcdefull, 42, {{0xdeadbeefull, 1000}, {0x1ull, 0}}});
  v.push_back(HelloMsg{0, 1, 0, {}});
  LoadBlocksMsg lb{0xfeedull, 10, 4, {1, 2, 3, 4, 5, 6}};
  v.push_back(lb);
  v.push_back(QueryMsg{99, 0xabcull, some_pose(), {}});
  v.push_back(QueryMsg{100, 0xabcull, some_pose(), {0, 7, 0xfffffu}});
  v.push_back(QueryMsg{101, 0xabcull, some_pose(), {3}, 2, 0xdefull, {1, 4, 0xfffffu}});
  v.push_back(QueryMsg{102, 0xabcull, some_pose(), {}, 0, 0xdefull, {}});
  ResultMsg r{99, 3, 0xabcull, {10, 20, 30}, {{1, 2}, {3, 4}, {0xffffffffu, 0}}};
  v.push_back(r);
  r.worked = {{0, 1}, {7, 0xffffffffu}, {0xfffffu, 12}};
  v.push_back(r);
  v.push_back(ResultMsg{1, 0, 0, {}, {}});
  v.push_back(HeartbeatMsg{0x55aa});
  v.push_back(ErrorMsg{ErrorCode::NotLoaded, 17, "block set 0x11 not held"});
  return v;
}

}  // namespace

TEST_CASE("fnv1a64 matches the published test vectors") {
  const std::string a = "a", foobar = "foobar";
  CHECK(fnv1a64({}) == 0xcbf29ce484222325ull);
  CHECK(fnv1a64({reinterpret_cast<const std::uint8_t*>(a.data()), a.size()}) == 0xaf63dc4c8601ec8cull);
  CHECK(fnv1a64({reinterpret_cast<const std::uint8_t*>(foobar.data()), foobar.size()}) == 0x85944171f73967e8ull);
}

TEST_CASE("every message survives encode/decode unchanged") {
  for (const Message& m : samples()) {
    CAPTURE(type_name(m));
    const auto bytes = encode(m);
    auto d = decode(bytes, DefaultLimits());
    REQUIRE_MESSAGE(d.ok(), d.error());
    CHECK(d.value().index() == m.index());
    CHECK(d.value() == m);
  }
}

TEST_CASE("decoding into a reused Message gives what a fresh decode gives, whatever it held") {
  // The client decodes every Result into one Message (its vectors' room kept): nothing of an
  // earlier message may show through, after a larger Result, another type, or a refused frame.
  std::mt19937_64 rng(777);
  const Limits L = DefaultLimits();
  ResultMsg big{
      5, 1, 0xbeefull, {1, 2, 3}, std::vector<FacePair>(500, FacePair{9, 9}), 3, std::vector<WorkedBlock>(40, WorkedBlock{1, 1})};
  for (std::uint32_t i = 0; i < big.worked.size(); ++i) big.worked[i] = {i, i + 1};
  big.stats.work_limit_hit = true;  // not on the wire: a decode must not keep it either
  Message reused = big;
  int compared = 0, refused = 0;
  for (int pass = 0; pass < 3; ++pass)
    for (const Message& m : samples()) {
      auto bytes = encode(m);
      if (pass == 2) bytes[rng() % bytes.size()] ^= static_cast<std::uint8_t>(1u << (rng() % 8));
      const auto fresh = decode(bytes, L);
      const Status st = decode(bytes, L, reused);
      REQUIRE(st.ok() == fresh.ok());
      if (!st.ok()) {
        CHECK(st.error() == fresh.error());
        ++refused;
        reused = big;  // whatever the refused frame left, the next decode starts from a large Result
        continue;
      }
      CHECK(reused == fresh.value());
      if (const auto* r = std::get_if<ResultMsg>(&reused)) CHECK_FALSE(r->stats.work_limit_hit);
      ++compared;
      if (pass == 1) reused = big;  // a Result decoded into a larger one
    }
  CHECK(compared > 2 * int(samples().size()));
  MESSAGE(compared << " compared, " << refused << " refused alike");
  // A small Result into a larger one's room: no allocation (the room is kept), the small one's values.
  Message x = big;
  const ResultMsg small{8, 2, 0xcafeull, {4, 5, 6}, {{1, 2}}, 0, {{3, 4}}};
  REQUIRE(decode(encode(small), L, x).ok());
  CHECK(std::get<ResultMsg>(x) == small);
  CHECK(std::get<ResultMsg>(x).pairs.capacity() >= 500);
}

TEST_CASE("header layout is pinned: magic, version, type, flags, body length, little-endian") {
  const auto b = encode(HeartbeatMsg{0x0102030405060708ull});
  REQUIRE(b.size() == kHeaderBytes + 8);
  const std::vector<std::uint8_t> want{'S', 'T', 'N', 'P', 5, 0, 5, 0, 8, 0, 0, 0, 8, 7, 6, 5, 4, 3, 2, 1};
  CHECK(b == want);
}

TEST_CASE("every body is its fields in order, little-endian, the header's length its size") {
  // The encoder sizes a message first and writes it in place; this writes the same fields one by
  // one with Writer, as the protocol lays them out, and compares the bytes.
  auto header = [](Writer& w, MsgType t) {
    w.u32(0x504e5453);  // "STNP"
    w.u16(5);
    w.u8(static_cast<std::uint8_t>(t));
    w.u8(0);
    w.u32(0);
  };
  auto pose = [](Writer& w, const geom::Pose& p) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) w.f64(p.matrix()(r, c));
  };
  for (const Message& m : samples()) {
    CAPTURE(m.index());
    std::vector<std::uint8_t> want;
    Writer w(want);
    header(w, static_cast<MsgType>(m.index() + 1));
    if (const auto* h = std::get_if<HelloMsg>(&m)) {
      w.u32(h->worker_id), w.u64(h->epoch), w.u64(h->echo), w.u32(std::uint32_t(h->held.size()));
      for (const Held& x : h->held) w.u64(x.hash), w.u32(x.faces);
    } else if (const auto* l = std::get_if<LoadBlocksMsg>(&m)) {
      w.u64(l->hash), w.u64(l->total_bytes), w.u64(l->offset), w.u32(std::uint32_t(l->data.size())), w.bytes(l->data);
    } else if (const auto* q = std::get_if<QueryMsg>(&m)) {
      w.u64(q->seq), w.u64(q->hash), w.u32(q->object), pose(w, q->pose), w.u32(std::uint32_t(q->skip.size()));
      for (std::uint32_t b : q->skip) w.u32(b);
      w.u64(q->standby), w.u32(std::uint32_t(q->take.size()));
      for (std::uint32_t b : q->take) w.u32(b);
    } else if (const auto* r = std::get_if<ResultMsg>(&m)) {
      w.u64(r->seq), w.u32(r->worker_id), w.u64(r->hash), w.u32(r->object);
      w.u64(r->stats.sphere_tests), w.u64(r->stats.tri_tests), w.u64(r->stats.compute_ns);
      w.u32(std::uint32_t(r->pairs.size()));
      for (const FacePair& p : r->pairs) w.u32(p.probe), w.u32(p.object);
      w.u32(std::uint32_t(r->worked.size()));
      for (const WorkedBlock& b : r->worked) w.u32(b.block), w.u32(b.work);
    } else if (const auto* hb = std::get_if<HeartbeatMsg>(&m)) {
      w.u64(hb->nonce);
    } else if (const auto* e = std::get_if<ErrorMsg>(&m)) {
      w.u16(static_cast<std::uint16_t>(e->code)), w.u64(e->ref), w.u32(std::uint32_t(e->text.size()));
      w.raw(e->text.data(), e->text.size());
    }
    w.patch_u32(8, static_cast<std::uint32_t>(want.size() - kHeaderBytes));
    CHECK(encode(m) == want);
    // Into a buffer that held a longer message: the same bytes, nothing of the old one left.
    std::vector<std::uint8_t> reused(want.size() + 100, 0xee);
    encode(m, reused);
    CHECK(reused == want);
  }
}

TEST_CASE("a message truncated at every byte offset is rejected with a message") {
  for (const Message& m : samples()) {
    const auto full = encode(m);
    for (std::size_t n = 0; n < full.size(); ++n) {
      CAPTURE(type_name(m));
      CAPTURE(n);
      auto d = decode(std::span(full).first(n), DefaultLimits());
      REQUIRE_FALSE(d.ok());
      CHECK_FALSE(d.error().empty());
    }
  }
}

TEST_CASE("truncating the body but fixing the length field still fails inside the body, naming the field") {
  auto b = encode(ResultMsg{5, 1, 2, {}, {{1, 2}, {3, 4}}});
  b.resize(b.size() - 4 - 3);  // the worked count and 3 bytes of the last pair
  const std::uint32_t body = static_cast<std::uint32_t>(b.size() - kHeaderBytes);
  std::memcpy(b.data() + 8, &body, 4);
  auto d = decode(b, DefaultLimits());
  REQUIRE_FALSE(d.ok());
  CHECK(d.error().find("Result at byte") != std::string::npos);
  CHECK(d.error().find("pair count") != std::string::npos);
}

TEST_CASE("trailing bytes are rejected") {
  auto b = encode(HeartbeatMsg{1});
  b.push_back(0);
  b[8] += 1;
  auto d = decode(b, DefaultLimits());
  REQUIRE_FALSE(d.ok());
  CHECK(d.error().find("trailing") != std::string::npos);
}

TEST_CASE("wrong magic, version, type and flags are rejected, naming the field") {
  const auto good = encode(HeartbeatMsg{1});
  struct Case {
    std::size_t at;
    std::uint8_t v;
    const char* word;
  };
  for (Case c : {Case{0, 'X', "magic"}, Case{4, 4, "version"}, Case{4, 6, "version"}, Case{5, 1, "version"},
                 Case{6, 0, "type"}, Case{6, 7, "type"}, Case{7, 1, "flags"}}) {
    auto b = good;
    b[c.at] = c.v;
    auto d = decode(b, DefaultLimits());
    REQUIRE_FALSE(d.ok());
    CHECK_MESSAGE(d.error().find(c.word) != std::string::npos, d.error());
  }
}

TEST_CASE("oversized counts are refused before allocating") {
  Limits L = DefaultLimits();
  SUBCASE("pair count over the limit") {
    auto b = encode(ResultMsg{1, 1, 1, {}, {}});
    const std::uint32_t huge = 0xffffffffu;
    std::memcpy(b.data() + b.size() - 8, &huge, 4);  // pair count, then the worked count
    auto d = decode(b, L);
    REQUIRE_FALSE(d.ok());
    CHECK(d.error().find("exceeds the limit") != std::string::npos);
  }
  SUBCASE("pair count under the limit but more than the bytes present") {
    auto b = encode(ResultMsg{1, 1, 1, {}, {}});
    const std::uint32_t n = L.max_pairs;
    std::memcpy(b.data() + b.size() - 8, &n, 4);
    auto d = decode(b, L);
    REQUIRE_FALSE(d.ok());
    CHECK(d.error().find("does not fit") != std::string::npos);
  }
  SUBCASE("held count") {
    auto b = encode(HelloMsg{1, 1, 0, {}});
    const std::uint32_t n = 1000;
    std::memcpy(b.data() + b.size() - 4, &n, 4);
    CHECK_FALSE(decode(b, L).ok());
  }
  SUBCASE("error text") {
    ErrorMsg e{ErrorCode::BadMessage, 0, std::string(L.max_text + 1, 'x')};
    auto d = decode(encode(e), L);
    REQUIRE_FALSE(d.ok());
    CHECK(d.error().find("text length") != std::string::npos);
  }
  SUBCASE("chunk over max_chunk_bytes") {
    L.max_chunk_bytes = 4;
    auto d = decode(encode(LoadBlocksMsg{1, 100, 0, std::vector<std::uint8_t>(5, 0)}), L);
    REQUIRE_FALSE(d.ok());
    CHECK(d.error().find("chunk length") != std::string::npos);
  }
  SUBCASE("block set larger than max_blockset_bytes") {
    L.max_blockset_bytes = 64;
    auto d = decode(encode(LoadBlocksMsg{1, 65, 0, {1}}), L);
    REQUIRE_FALSE(d.ok());
    CHECK(d.error().find("total_bytes") != std::string::npos);
  }
  SUBCASE("chunk outside the block set") {
    auto d = decode(encode(LoadBlocksMsg{1, 10, 8, {1, 2, 3}}), L);
    REQUIRE_FALSE(d.ok());
    CHECK(d.error().find("outside") != std::string::npos);
  }
  SUBCASE("frame over max_message_bytes") {
    L.max_message_bytes = 16;
    CHECK_FALSE(decode(encode(QueryMsg{}), L).ok());
  }
}

TEST_CASE("Query and Result name the scene object (protocol 3); one at or above max_objects is refused at its byte") {
  QueryMsg q{7, 0xabcull, some_pose(), {1, 4}};
  q.object = 5;
  auto dq = decode(encode(q), DefaultLimits());
  REQUIRE(dq.ok());
  CHECK(std::get<QueryMsg>(dq.value()) == q);
  ResultMsg r{7, 2, 0xabcull, {}, {{1, 2}}};
  r.object = 5;
  auto dr = decode(encode(r), DefaultLimits());
  REQUIRE(dr.ok());
  CHECK(std::get<ResultMsg>(dr.value()).object == 5);
  Limits small = DefaultLimits();
  small.max_objects = 5;
  const auto bq = decode(encode(q), small);
  REQUIRE_FALSE(bq.ok());
  CHECK(bq.error().find("byte 28") != std::string::npos);  // header 12, seq 8, hash 8
  CHECK(bq.error().find("object: 5 is not below max_objects = 5") != std::string::npos);
  const auto br = decode(encode(r), small);
  REQUIRE_FALSE(br.ok());
  CHECK(br.error().find("byte 32") != std::string::npos);  // header 12, seq 8, worker_id 4, hash 8
}

TEST_CASE("a Result's worked blocks (protocol 4): ascending, below max_blocks, non-zero, at most max_worked") {
  ResultMsg r{7, 2, 0xabcull, {}, {{1, 2}}};
  r.worked = {{3, 10}, {9, 1}};
  auto d = decode(encode(r), DefaultLimits());
  REQUIRE(d.ok());
  CHECK(std::get<ResultMsg>(d.value()).worked == r.worked);
  // header 12, seq 8, worker_id 4, hash 8, object 4, stats 24, pair count 4, one pair 8,
  // worked count 4: the first worked block at byte 76, its work at 80, the second block at 84.
  const auto refused = [](const ResultMsg& m, const Limits& L, const std::string& at, const std::string& what) {
    const auto e = decode(encode(m), L);
    REQUIRE_FALSE(e.ok());
    CHECK_MESSAGE(e.error().find(at) != std::string::npos, e.error());
    CHECK_MESSAGE(e.error().find(what) != std::string::npos, e.error());
  };
  ResultMsg bad = r;
  bad.worked = {{9, 1}, {3, 10}};
  refused(bad, DefaultLimits(), "byte 84", "worked block: block 3 after 9 (must be strictly ascending)");
  bad.worked = {{3, 10}, {3, 1}};
  refused(bad, DefaultLimits(), "byte 84", "must be strictly ascending");
  bad.worked = {{3, 0}};
  refused(bad, DefaultLimits(), "byte 80", "worked work: 0");
  Limits small = DefaultLimits();
  small.max_blocks = 9;
  refused(r, small, "byte 84", "worked block: block 9 is not below max_blocks = 9");
  small = DefaultLimits();
  small.max_worked = 1;
  refused(r, small, "worked count", "exceeds the limit");
}

TEST_CASE("non-finite and non-rigid poses are refused") {
  auto b = encode(QueryMsg{1, 2, some_pose(), {}});
  const std::size_t pose_at = kHeaderBytes + 20;  // after seq, hash and object
  SUBCASE("NaN") {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::memcpy(b.data() + pose_at + 8 * 3, &nan, 8);
    auto d = decode(b, DefaultLimits());
    REQUIRE_FALSE(d.ok());
    CHECK(d.error().find("finite") != std::string::npos);
  }
  SUBCASE("scaled rotation") {
    const double two = 2.0;
    std::memcpy(b.data() + pose_at, &two, 8);
    auto d = decode(b, DefaultLimits());
    REQUIRE_FALSE(d.ok());
    CHECK(d.error().find("rigid") != std::string::npos);
  }
  SUBCASE("reflection") {
    geom::Pose p = geom::Pose::Identity();
    p.matrix()(0, 0) = -1;
    CHECK_FALSE(decode(encode(QueryMsg{1, 2, p, {}}), DefaultLimits()).ok());
  }
}

TEST_CASE("a Query's skip list must be ascending, below max_blocks and within max_skip; the error says where") {
  const Limits L = DefaultLimits();
  const std::size_t list_at = kHeaderBytes + 20 + 96 + 4;  // seq, hash, object, pose, count
  auto refused = [&](std::vector<std::uint32_t> skip, const char* what, const Limits& lim) {
    const auto d = decode(encode(QueryMsg{1, 2, some_pose(), std::move(skip)}), lim);
    REQUIRE_FALSE(d.ok());
    CHECK(d.error().find(what) != std::string::npos);
    return d.error();
  };
  const std::string e = refused({3, 3}, "ascending", L);
  CHECK(e.find("byte " + std::to_string(list_at + 4)) != std::string::npos);
  refused({5, 2}, "ascending", L);
  refused({L.max_blocks}, "max_blocks", L);
  Limits small = L;
  small.max_skip = 2;
  refused({1, 2, 3}, "skip count", small);
  CHECK(decode(encode(QueryMsg{1, 2, some_pose(), {1, 2}}), small).ok());
  // A count larger than the bytes that follow is refused before anything is allocated.
  auto b = encode(QueryMsg{1, 2, some_pose(), {4}});
  const std::uint32_t huge = 200;
  std::memcpy(b.data() + list_at - 4, &huge, 4);
  CHECK_FALSE(decode(b, L).ok());
}

TEST_CASE("a Query's standby set and take list (protocol 5): ascending, within max_take, a second set, named") {
  const Limits L = DefaultLimits();
  const std::size_t take_at = kHeaderBytes + 20 + 96 + 4 + 8 + 4;  // seq, hash, object, pose, skip count, standby, count
  auto refused = [&](QueryMsg q, const char* what, const Limits& lim) {
    const auto d = decode(encode(q), lim);
    REQUIRE_FALSE(d.ok());
    CHECK_MESSAGE(d.error().find(what) != std::string::npos, d.error());
    return d.error();
  };
  const std::string e = refused(QueryMsg{1, 2, some_pose(), {}, 0, 9, {4, 4}}, "ascending", L);
  CHECK(e.find("byte " + std::to_string(take_at + 4)) != std::string::npos);
  CHECK(e.find("take") != std::string::npos);
  refused(QueryMsg{1, 2, some_pose(), {}, 0, 9, {L.max_blocks}}, "max_blocks", L);
  refused(QueryMsg{1, 2, some_pose(), {}, 0, 0, {1}}, "no standby set named", L);
  refused(QueryMsg{1, 2, some_pose(), {}, 0, 2, {1}}, "the same block set as hash", L);
  Limits small = L;
  small.max_take = 2;
  refused(QueryMsg{1, 2, some_pose(), {}, 0, 9, {1, 2, 3}}, "take count", small);
  CHECK(decode(encode(QueryMsg{1, 2, some_pose(), {}, 0, 9, {1, 2}}), small).ok());
}

TEST_CASE("unknown error codes are refused") {
  auto b = encode(ErrorMsg{ErrorCode::BadMessage, 0, ""});
  b[kHeaderBytes] = 99;
  CHECK_FALSE(decode(b, DefaultLimits()).ok());
}

TEST_CASE("bit flips and random garbage never crash and never decode into out-of-limit values") {
  std::mt19937_64 rng(12345);
  const Limits L = DefaultLimits();
  int decoded = 0, refused = 0;
  for (const Message& m : samples()) {
    const auto good = encode(m);
    for (int trial = 0; trial < 2000; ++trial) {
      auto b = good;
      const int flips = 1 + static_cast<int>(rng() % 4);
      for (int f = 0; f < flips; ++f) b[rng() % b.size()] ^= static_cast<std::uint8_t>(1u << (rng() % 8));
      auto d = decode(b, L);
      if (!d.ok()) {
        ++refused;
        continue;
      }
      ++decoded;
      if (auto* r = std::get_if<ResultMsg>(&d.value())) CHECK(r->pairs.size() <= L.max_pairs);
      if (auto* h = std::get_if<HelloMsg>(&d.value())) CHECK(h->held.size() <= L.max_held);
    }
  }
  for (int trial = 0; trial < 20000; ++trial) {
    std::vector<std::uint8_t> b(rng() % 200);
    for (auto& c : b) c = static_cast<std::uint8_t>(rng());
    if (trial % 2 && b.size() >= kHeaderBytes) {  // valid header, garbage body: reaches the body decoders
      const std::uint32_t magic = kMagic, body = static_cast<std::uint32_t>(b.size() - kHeaderBytes);
      std::memcpy(b.data(), &magic, 4);
      b[4] = kVersion;
      b[5] = 0;
      b[6] = static_cast<std::uint8_t>(1 + rng() % 6);
      b[7] = 0;
      std::memcpy(b.data() + 8, &body, 4);
    }
    auto d = decode(b, L);
    if (d.ok())
      ++decoded;
    else
      ++refused;
  }
  CHECK(refused > 0);
  MESSAGE("garbage: " << decoded << " decoded (harmless), " << refused << " refused");
}
