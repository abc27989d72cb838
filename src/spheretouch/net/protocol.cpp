// SPDX-License-Identifier: BSD-3-Clause
// Encoding and checked decoding of the wire protocol (protocol.hpp).
#include <spheretouch/net/protocol.hpp>

#include <bit>
#include <cmath>
#include <cstring>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/pose_io.hpp>
#include <spheretouch/net/wire.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

// The wire's type byte of a message is its variant index + 1: the alternatives' order is the
// protocol's, asserted so a reordering cannot silently renumber the messages.
static_assert(std::variant_size_v<Message> == 6, "a new message needs its MsgType and a line below");
static_assert(std::is_same_v<std::variant_alternative_t<std::size_t(MsgType::Hello) - 1, Message>, HelloMsg>);
static_assert(std::is_same_v<std::variant_alternative_t<std::size_t(MsgType::LoadBlocks) - 1, Message>, LoadBlocksMsg>);
static_assert(std::is_same_v<std::variant_alternative_t<std::size_t(MsgType::Query) - 1, Message>, QueryMsg>);
static_assert(std::is_same_v<std::variant_alternative_t<std::size_t(MsgType::Result) - 1, Message>, ResultMsg>);
static_assert(std::is_same_v<std::variant_alternative_t<std::size_t(MsgType::Heartbeat) - 1, Message>, HeartbeatMsg>);
static_assert(std::is_same_v<std::variant_alternative_t<std::size_t(MsgType::Error) - 1, Message>, ErrorMsg>);

namespace {

/// Writes a message into bytes sized for it beforehand (BodySize): one resize a message instead of
/// one a field, the hot path's Queries and Results. The same calls as Writer; a write past the end
/// is not made and marks the writer overflowed (encode() then falls back to Writer).
class PlacedWriter {
 public:
  PlacedWriter(std::uint8_t* begin, std::uint8_t* end) : at_(begin), end_(end) {}
  void u8(std::uint8_t v) { raw(&v, 1); }
  void u16(std::uint16_t v) { raw(&v, 2); }
  void u32(std::uint32_t v) { raw(&v, 4); }
  void u64(std::uint64_t v) { raw(&v, 8); }
  void f64(double v) { raw(&v, 8); }
  void bytes(std::span<const std::uint8_t> b) { raw(b.data(), b.size()); }
  void raw(const void* p, std::size_t n) {
    if (n > std::size_t(end_ - at_)) {
      overflow_ = true;
      return;
    }
    if (n) std::memcpy(at_, p, n);
    at_ += n;
  }
  /// Every byte written, none past the end.
  bool filled() const { return !overflow_ && at_ == end_; }

 private:
  std::uint8_t* at_;
  std::uint8_t* end_;
  bool overflow_ = false;
};

static_assert(std::endian::native == std::endian::little, "the wire is little-endian; Writer copies host bytes");

template <class W>
void put_pose(W& w, const geom::Pose& p) {
  const auto& m = p.matrix();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) w.f64(m(r, c));  // rows of [R | t], row-major
}

/// A list of global block ids (a Query's skip or take): a u32 count ≤ `limit`, then the ids,
/// strictly ascending and below max_blocks. Errors name "<field> count" or "<field>".
// `field` and its count's name, e.g. "skip" and "skip count" (literals: nothing built a message).
void read_blocks(Reader& r, const Limits& L, std::uint32_t limit, const char* field, const char* count_field,
                 std::vector<std::uint32_t>& out) {
  const std::uint32_t n = r.u32(count_field);
  if (!r.count_ok(n, limit, 4, count_field)) return;
  out.resize(n);
  for (std::uint32_t i = 0; i < n && r.ok(); ++i) {
    const std::size_t at = r.offset();
    out[i] = r.u32(field);
    if (r.ok() && out[i] >= L.max_blocks)
      r.fail_at(at, field, ": block ", out[i], " is not below max_blocks = ", L.max_blocks);
    if (r.ok() && i > 0 && out[i] <= out[i - 1])
      r.fail_at(at, field, ": block ", out[i], " after ", out[i - 1], " (must be strictly ascending)");
  }
}

geom::Pose get_pose(Reader& r) {
  const std::size_t at = r.offset();
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  for (int i = 0; i < 3; ++i)
    for (int c = 0; c < 4; ++c) m(i, c) = r.f64("pose");
  if (r.ok()) {
    if (const std::string why = geom::check_rigid(m); !why.empty())
      r.fail_at(at, "pose", ": not a rigid transform (", why, ")");
  }
  geom::Pose p = geom::Pose::Identity();
  p.matrix() = m;
  return p;
}

template <class W>
struct BodyEncoder {
  W& w;
  void operator()(const HelloMsg& m) {
    w.u32(m.worker_id);
    w.u64(m.epoch);
    w.u64(m.echo);
    w.u32(static_cast<std::uint32_t>(m.held.size()));
    for (const Held& h : m.held) {
      w.u64(h.hash);
      w.u32(h.faces);
    }
  }
  void operator()(const LoadBlocksMsg& m) {
    w.u64(m.hash);
    w.u64(m.total_bytes);
    w.u64(m.offset);
    w.u32(static_cast<std::uint32_t>(m.data.size()));
    w.bytes(m.data);
  }
  void operator()(const QueryMsg& m) {
    w.u64(m.seq);
    w.u64(m.hash);
    w.u32(m.object);
    put_pose(w, m.pose);
    w.u32(static_cast<std::uint32_t>(m.skip.size()));
    for (std::uint32_t b : m.skip) w.u32(b);
    w.u64(m.standby);
    w.u32(static_cast<std::uint32_t>(m.take.size()));
    for (std::uint32_t b : m.take) w.u32(b);
  }
  void operator()(const ResultMsg& m) {
    w.u64(m.seq);
    w.u32(m.worker_id);
    w.u64(m.hash);
    w.u32(m.object);
    w.u64(m.stats.sphere_tests);
    w.u64(m.stats.tri_tests);
    w.u64(m.stats.compute_ns);
    w.u32(static_cast<std::uint32_t>(m.pairs.size()));
    w.raw(m.pairs.data(), m.pairs.size() * sizeof(FacePair));  // {u32 probe, u32 object} LE, no padding
    w.u32(static_cast<std::uint32_t>(m.worked.size()));
    for (const WorkedBlock& b : m.worked) {
      w.u32(b.block);
      w.u32(b.work);
    }
  }
  void operator()(const HeartbeatMsg& m) { w.u64(m.nonce); }
  void operator()(const ErrorMsg& m) {
    w.u16(static_cast<std::uint16_t>(m.code));
    w.u64(m.ref);
    w.u32(static_cast<std::uint32_t>(m.text.size()));
    w.raw(m.text.data(), m.text.size());
  }
};

/// The bytes BodyEncoder writes for a message's body.
struct BodySize {
  std::size_t operator()(const HelloMsg& m) const { return 24 + 12 * m.held.size(); }
  std::size_t operator()(const LoadBlocksMsg& m) const { return 28 + m.data.size(); }
  std::size_t operator()(const QueryMsg& m) const { return 20 + 96 + 4 + 4 * m.skip.size() + 12 + 4 * m.take.size(); }
  std::size_t operator()(const ResultMsg& m) const {
    return 24 + 24 + 4 + sizeof(FacePair) * m.pairs.size() + 4 + 8 * m.worked.size();
  }
  std::size_t operator()(const HeartbeatMsg&) const { return 8; }
  std::size_t operator()(const ErrorMsg& m) const { return 14 + m.text.size(); }
};

MsgType type_of(const Message& m) {
  return static_cast<MsgType>(m.index() + 1);  // variant order = MsgType order (asserted below)
}

// Decodes the body into `out`: a Result into the ResultMsg `out` holds, if it holds one, its
// vectors' room reused (every field is written); any other message anew.
Status decode_body(MsgType type, Reader& r, const Limits& L, Message& out) {
  switch (type) {
    case MsgType::Hello: {
      HelloMsg m;
      m.worker_id = r.u32("worker_id");
      m.epoch = r.u64("epoch");
      m.echo = r.u64("echo");
      const std::uint32_t n = r.u32("held count");
      if (r.count_ok(n, L.max_held, 12, "held count")) {
        m.held.resize(n);
        for (Held& h : m.held) {
          h.hash = r.u64("held hash");
          h.faces = r.u32("held faces");
        }
      }
      out = std::move(m);
      break;
    }
    case MsgType::LoadBlocks: {
      LoadBlocksMsg m;
      m.hash = r.u64("hash");
      m.total_bytes = r.u64("total_bytes");
      const std::size_t off_at = r.offset();
      m.offset = r.u64("offset");
      const std::uint32_t n = r.u32("chunk length");
      if (r.ok() && m.total_bytes > L.max_blockset_bytes)
        r.fail_at(off_at - 8, "total_bytes", ": ", m.total_bytes, " exceeds the limit ", L.max_blockset_bytes);
      if (r.ok() && (m.offset > m.total_bytes || n > m.total_bytes - m.offset))
        r.fail_at(off_at, "offset", ": chunk [", m.offset, ", +", n, ") outside the block set of ", m.total_bytes,
                  " bytes");
      if (r.ok() && n == 0) r.fail_at(off_at + 8, "chunk length", ": empty chunk");
      if (r.count_ok(n, L.max_chunk_bytes, 1, "chunk length")) {
        auto b = r.bytes(n, "chunk data");
        m.data.assign(b.begin(), b.end());
      }
      out = std::move(m);
      break;
    }
    case MsgType::Query: {
      QueryMsg m;
      m.seq = r.u64("seq");
      m.hash = r.u64("hash");
      {
        const std::size_t at = r.offset();
        m.object = r.u32("object");
        if (r.ok() && m.object >= L.max_objects)
          r.fail_at(at, "object", ": ", m.object, " is not below max_objects = ", L.max_objects);
      }
      m.pose = get_pose(r);
      read_blocks(r, L, L.max_skip, "skip", "skip count", m.skip);
      {
        const std::size_t at = r.offset();
        m.standby = r.u64("standby");
        if (r.ok() && m.standby != 0 && m.standby == m.hash)
          r.fail_at(at, "standby", ": the same block set as hash (a standby set is a second one)");
      }
      read_blocks(r, L, L.max_take, "take", "take count", m.take);
      if (r.ok() && m.standby == 0 && !m.take.empty())
        r.fail_at(r.offset(), "take", ": ", m.take.size(), " blocks to take but no standby set named");
      out = std::move(m);
      break;
    }
    case MsgType::Result: {
      ResultMsg& m = std::holds_alternative<ResultMsg>(out) ? std::get<ResultMsg>(out) : out.emplace<ResultMsg>();
      m.stats = {};
      m.pairs.clear();
      m.worked.clear();
      m.seq = r.u64("seq");
      m.worker_id = r.u32("worker_id");
      m.hash = r.u64("hash");
      {
        const std::size_t at = r.offset();
        m.object = r.u32("object");
        if (r.ok() && m.object >= L.max_objects)
          r.fail_at(at, "object", ": ", m.object, " is not below max_objects = ", L.max_objects);
      }
      m.stats.sphere_tests = r.u64("sphere_tests");
      m.stats.tri_tests = r.u64("tri_tests");
      m.stats.compute_ns = r.u64("compute_ns");
      const std::uint32_t n = r.u32("pair count");
      if (r.count_ok(n, L.max_pairs, sizeof(FacePair), "pair count")) {
        m.pairs.resize(n);
        auto b = r.bytes(std::size_t{n} * sizeof(FacePair), "pairs");
        if (r.ok() && n > 0) std::memcpy(m.pairs.data(), b.data(), b.size());
      }
      const std::uint32_t nw = r.u32("worked count");
      if (r.count_ok(nw, L.max_worked, 8, "worked count")) {
        m.worked.resize(nw);
        for (std::uint32_t i = 0; i < nw && r.ok(); ++i) {
          const std::size_t at = r.offset();
          m.worked[i].block = r.u32("worked block");
          m.worked[i].work = r.u32("worked work");
          if (r.ok() && m.worked[i].block >= L.max_blocks)
            r.fail_at(at, "worked block", ": block ", m.worked[i].block, " is not below max_blocks = ", L.max_blocks);
          if (r.ok() && i > 0 && m.worked[i].block <= m.worked[i - 1].block)
            r.fail_at(at, "worked block", ": block ", m.worked[i].block, " after ", m.worked[i - 1].block,
                      " (must be strictly ascending)");
          if (r.ok() && m.worked[i].work == 0) r.fail_at(at + 4, "worked work", ": 0 (a listed block did work)");
        }
      }
      break;
    }
    case MsgType::Heartbeat: {
      HeartbeatMsg m;
      m.nonce = r.u64("nonce");
      out = m;
      break;
    }
    case MsgType::Error: {
      ErrorMsg m;
      const std::size_t at = r.offset();
      const std::uint16_t code = r.u16("code");
      if (r.ok() && (code < 1 || code > static_cast<std::uint16_t>(ErrorCode::Unexpected)))
        r.fail_at(at, "code", ": unknown error code ", code);
      m.code = static_cast<ErrorCode>(code);
      m.ref = r.u64("ref");
      const std::uint32_t n = r.u32("text length");
      if (r.count_ok(n, L.max_text, 1, "text length")) {
        auto b = r.bytes(n, "text");
        m.text.assign(b.begin(), b.end());
      }
      out = std::move(m);
      break;
    }
  }
  if (!r.expect_end()) return Error{r.error()};
  return Ok{};
}

}  // namespace

const char* type_name(MsgType t) {
  switch (t) {
    case MsgType::Hello:
      return "Hello";
    case MsgType::LoadBlocks:
      return "LoadBlocks";
    case MsgType::Query:
      return "Query";
    case MsgType::Result:
      return "Result";
    case MsgType::Heartbeat:
      return "Heartbeat";
    case MsgType::Error:
      return "Error";
  }
  return "unknown";
}

const char* type_name(const Message& m) { return type_name(type_of(m)); }

void encode(const Message& m, std::vector<std::uint8_t>& out) {
  const std::size_t body = std::visit(BodySize{}, m);
  auto header = [&](auto& w) {
    w.u32(kMagic);
    w.u16(kVersion);
    w.u8(static_cast<std::uint8_t>(type_of(m)));
    w.u8(0);
    w.u32(static_cast<std::uint32_t>(body));  // body length
  };
  out.resize(kHeaderBytes + body);  // (within the capacity a reused buffer kept: no allocation)
  PlacedWriter w(out.data(), out.data() + out.size());
  header(w);
  std::visit(BodyEncoder<PlacedWriter>{w}, m);
  if (w.filled()) return;
  // BodySize and BodyEncoder disagree (a bug): encode field by field instead, and say so in
  // checked builds.
  ST_ASSERT(false, "BodySize gives the bytes BodyEncoder writes");
  out.clear();
  Writer v(out);
  header(v);
  std::visit(BodyEncoder<Writer>{v}, m);
  v.patch_u32(8, static_cast<std::uint32_t>(out.size() - kHeaderBytes));
}

std::vector<std::uint8_t> encode(const Message& m) {
  std::vector<std::uint8_t> out;
  encode(m, out);
  return out;
}

Result<Message> decode(std::span<const std::uint8_t> frame, const Limits& limits) {
  Message out;
  if (Status s = decode(frame, limits, out); !s) return Error{s.error()};
  return out;
}

Status decode(std::span<const std::uint8_t> frame, const Limits& limits, Message& out) {
  if (frame.size() > limits.max_message_bytes)
    return fail("message of ", frame.size(), " bytes exceeds the limit ", limits.max_message_bytes);
  Reader h(frame.first(std::min(frame.size(), kHeaderBytes)), "header");
  const std::uint32_t magic = h.u32("magic");
  if (h.ok() && magic != kMagic)
    return fail("header at byte 0: magic: 0x", std::hex, magic, " is not \"STNP\" (0x", kMagic, ")");
  const std::uint16_t version = h.u16("version");
  if (h.ok() && version != kVersion)
    return fail("header at byte 4: version: ", version, " not supported (this build speaks ", kVersion, ")");
  const std::uint8_t type = h.u8("type");
  if (h.ok() && (type < 1 || type > static_cast<std::uint8_t>(MsgType::Error)))
    return fail("header at byte 6: type: unknown message type ", unsigned{type});
  const std::uint8_t flags = h.u8("flags");
  if (h.ok() && flags != 0) return fail("header at byte 7: flags: 0x", std::hex, unsigned{flags}, " (must be 0)");
  const std::uint32_t body = h.u32("body length");
  if (!h.ok()) return Error{h.error()};
  if (body != frame.size() - kHeaderBytes)
    return fail("header at byte 8: body length: ", body, " but the frame carries ", frame.size() - kHeaderBytes,
                " bytes");
  const auto t = static_cast<MsgType>(type);
  Reader r(frame.subspan(kHeaderBytes), type_name(t), kHeaderBytes);
  return decode_body(t, r, limits, out);
}

}  // namespace st::net
