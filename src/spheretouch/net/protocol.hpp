// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Wire protocol between the scatter-gather client and the workers (paper §3.4). One ZeroMQ frame
/// per message: a 12-byte header {magic "STNP", version u16, type u8, flags u8 = 0, body length
/// u32} and a little-endian body. decode() checks every length, count, index and number against
/// explicit Limits before using or allocating from it, and its error names the message, the field
/// and the byte offset.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/result.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

inline constexpr std::uint32_t kMagic = 0x504E5453;  ///< "STNP" read as a little-endian u32
/// Bumped on any incompatible change (2: Query skip list; 3: Query and Result name the scene
/// object, block sets carry it; 4: Result reports the work of its blocks; 5: Query names a standby
/// set and the blocks of it to take).
inline constexpr std::uint16_t kVersion = 5;
inline constexpr std::size_t kHeaderBytes = 12;  ///< magic, version, type, flags, body length

/// Upper bounds applied while decoding; a message over any of them is rejected, not truncated.
struct Limits {
  std::uint32_t max_message_bytes = 64u << 20;    ///< whole frame (also ZMQ_MAXMSGSIZE), bytes
  std::uint32_t max_chunk_bytes = 1u << 20;       ///< LoadBlocks payload per message, bytes
  std::uint64_t max_blockset_bytes = 2ull << 30;  ///< a whole encoded block set, bytes (worker memory)
  /// Face pairs in one Result (2 MiB). Real contacts give a few pairs each; a worker needs about
  /// 0.25 µs per pair to reach the limit on a pile of overlapping faces (spheretouch-bench hostile),
  /// during which it answers no one else.
  std::uint32_t max_pairs = 1u << 18;
  std::uint32_t max_held = 8;               ///< block sets listed in a Hello
  std::uint32_t max_text = 1024;            ///< Error text, bytes
  std::uint32_t max_vertices = 64u << 20;   ///< per mesh in a block set
  std::uint32_t max_faces = 64u << 20;      ///< per mesh in a block set
  std::uint32_t max_blocks = 1u << 20;      ///< blocks in a partition
  std::uint32_t max_skip = 256;             ///< blocks a Query may ask the worker to leave out
  std::uint32_t max_leaf_faces = 1u << 16;  ///< sphere-tree leaf size parameter
  std::uint32_t max_objects = 1024;         ///< scene objects a block set, Query or Result may name
  std::uint32_t max_worked = 4096;          ///< blocks whose work one Result reports (WorkedBlock)
  std::uint32_t max_take = 4096;            ///< blocks of its standby set a Query may ask the worker to answer
};

/// Default limits (sized for multi-million-face meshes; workers may lower max_blockset_bytes).
inline Limits DefaultLimits() { return Limits{}; }

/// One colliding pair: probe face index and (global) object face index, file order.
/// The collision core's own pair type; on the wire as {u32 probe, u32 object} little-endian.
using FacePair = geom::FacePair;
static_assert(sizeof(FacePair) == 8 && std::is_trivially_copyable_v<FacePair> && offsetof(FacePair, probe) == 0 &&
              offsetof(FacePair, object) == 4);

/// Work counters a worker reports with each Result (summed over workers by the client).
struct QueryStats {
  std::uint64_t sphere_tests = 0;  ///< bounding-volume tests
  std::uint64_t tri_tests = 0;     ///< triangle-triangle tests
  std::uint64_t compute_ns = 0;    ///< worker time inside the backend query, ns
  /// Not on the wire: the backend stopped at its work budget (QueryBudget::max_work); the worker
  /// answers TooLarge.
  bool work_limit_hit = false;
};

/// Message type codes (the header's type byte).
enum class MsgType : std::uint8_t { Hello = 1, LoadBlocks = 2, Query = 3, Result = 4, Heartbeat = 5, Error = 6 };

/// A block set a worker holds in memory.
struct Held {
  std::uint64_t hash = 0;   ///< content hash of the block set (block_set.hpp)
  std::uint32_t faces = 0;  ///< object faces in it
  /// Field by field.
  friend bool operator==(const Held&, const Held&) = default;
};

/// Worker → client: who it is and what it holds. Sent in reply to Heartbeat, after a load
/// completes, and after a Query for a block set it does not hold.
struct HelloMsg {
  std::uint32_t worker_id = 0;  ///< configured worker id
  std::uint64_t epoch = 0;      ///< random per process start: a new epoch means memory was lost
  std::uint64_t echo = 0;       ///< nonce of the Heartbeat answered, 0 if unsolicited
  std::vector<Held> held;       ///< block sets in memory, most recently used first
  /// Field by field.
  friend bool operator==(const HelloMsg&, const HelloMsg&) = default;
};

/// Client → worker: one chunk of an encoded block set. Chunks of a set are sent in order; the
/// worker checks the assembled bytes against `hash` before decoding them.
struct LoadBlocksMsg {
  std::uint64_t hash = 0;          ///< content hash of the whole encoded block set
  std::uint64_t total_bytes = 0;   ///< size of the whole encoded block set
  std::uint64_t offset = 0;        ///< where this chunk starts
  std::vector<std::uint8_t> data;  ///< chunk bytes, offset + size <= total_bytes
  /// Field by field.
  friend bool operator==(const LoadBlocksMsg&, const LoadBlocksMsg&) = default;
};

/// Client → worker: collide the probe at `pose` against block set `hash`, leaving out the blocks
/// in `skip` (another worker or the client answers those this round: ScatterConfig::replicas,
/// ScatterConfig::assist_blocks), and against the blocks `take` of block set `standby` (the
/// worker's second copies of other workers' blocks, ScatterConfig::replicas).
struct QueryMsg {
  std::uint64_t seq = 0;                     ///< round sequence number, echoed in the Result
  std::uint64_t hash = 0;                    ///< block set to answer with (content-addressed)
  geom::Pose pose = geom::Pose::Identity();  ///< probe file coords → object file coords (rigid)
  /// Global block ids to leave out, strictly ascending, at most Limits::max_skip; ids the set
  /// does not hold are ignored.
  std::vector<std::uint32_t> skip;
  /// The scene object the set is a share of (checked by the worker; on the wire after `hash`).
  std::uint32_t object = 0;
  /// A second block set of the same client and object the worker holds (0: none; on the wire
  /// after `skip`): named, it counts as used this round even when `take` is empty.
  std::uint64_t standby = 0;
  /// Global block ids of `standby` to answer too, strictly ascending, at most Limits::max_take;
  /// ids the standby set does not hold are ignored. Empty when `standby` is 0.
  std::vector<std::uint32_t> take{};
  /// Field by field (the pose's matrices exactly).
  friend bool operator==(const QueryMsg& a, const QueryMsg& b) {
    return a.seq == b.seq && a.hash == b.hash && a.object == b.object && a.pose.matrix() == b.pose.matrix() &&
           a.skip == b.skip && a.standby == b.standby && a.take == b.take;
  }
};

/// The work one block of a worker's set cost it in a query (geom::NodeWork summed over the
/// block's leaves: its candidate triangle pairs and the leaf pairs that tested any): what the
/// client weighs to deal the next round's blocks (the client assist). On the wire as
/// {u32 block, u32 work}.
struct WorkedBlock {
  std::uint32_t block = 0;  ///< global block id
  std::uint32_t work = 0;   ///< > 0
  /// Field by field.
  friend bool operator==(const WorkedBlock&, const WorkedBlock&) = default;
};

/// Worker → client: the colliding pairs of one Query.
struct ResultMsg {
  std::uint64_t seq = 0;        ///< the Query's sequence number
  std::uint32_t worker_id = 0;  ///< who answered
  std::uint64_t hash = 0;       ///< the block set used
  QueryStats stats;             ///< work counters
  std::vector<FacePair> pairs;  ///< colliding (probe, global object) face pairs
  std::uint32_t object = 0;     ///< the scene object whose faces `pairs` name (on the wire after `hash`)
  /// The blocks that cost the query any work, by ascending id, at most Limits::max_worked (the
  /// heaviest when more did); on the wire after `pairs`.
  std::vector<WorkedBlock> worked{};
  /// Field by field; of the stats, the sphere and triangle tests and compute_ns.
  friend bool operator==(const ResultMsg& a, const ResultMsg& b) {
    return a.seq == b.seq && a.worker_id == b.worker_id && a.hash == b.hash && a.object == b.object &&
           a.pairs == b.pairs && a.stats.sphere_tests == b.stats.sphere_tests &&
           a.stats.tri_tests == b.stats.tri_tests && a.stats.compute_ns == b.stats.compute_ns && a.worked == b.worked;
  }
};

/// Client → worker: liveness probe; the worker answers with a Hello echoing `nonce`.
struct HeartbeatMsg {
  std::uint64_t nonce = 0;  ///< echoed in HelloMsg::echo
  /// Field by field.
  friend bool operator==(const HeartbeatMsg&, const HeartbeatMsg&) = default;
};

/// Why a message was refused.
enum class ErrorCode : std::uint16_t {
  BadMessage = 1,  ///< could not be decoded (text says what and where)
  NotLoaded = 2,   ///< Query named a block set the worker does not hold
  LoadFailed = 3,  ///< a block set failed its hash, decode or build
  TooLarge = 4,    ///< over a configured memory limit
  Unexpected = 5,  ///< a valid message of a type this side does not accept
};

/// Either side → the other: a refusal, with the sequence number or hash it concerns.
struct ErrorMsg {
  ErrorCode code = ErrorCode::BadMessage;  ///< category
  std::uint64_t ref = 0;                   ///< Query seq or block-set hash concerned, else 0
  std::string text;                        ///< human-readable, <= Limits::max_text bytes
  /// Field by field.
  friend bool operator==(const ErrorMsg&, const ErrorMsg&) = default;
};

/// Any protocol message.
using Message = std::variant<HelloMsg, LoadBlocksMsg, QueryMsg, ResultMsg, HeartbeatMsg, ErrorMsg>;

/// Encodes `m` into `out` (replacing its contents): header + body.
void encode(const Message& m, std::vector<std::uint8_t>& out);
/// Convenience: encode into a new vector.
std::vector<std::uint8_t> encode(const Message& m);
/// Decodes one frame, checking it completely against `limits`.
Result<Message> decode(std::span<const std::uint8_t> frame, const Limits& limits);
/// The same into `out`: a Result into the ResultMsg `out` already holds, if it holds one, its
/// vectors' room reused (a client that decodes every Result into one Message allocates nothing
/// for them once the room is there). On an error `out` holds whatever was read so far.
Status decode(std::span<const std::uint8_t> frame, const Limits& limits, Message& out);

/// Name of a message type for logs ("Query"), or "unknown".
const char* type_name(MsgType t);
/// Name of the variant alternative held by `m`.
const char* type_name(const Message& m);

}  // namespace st::net
