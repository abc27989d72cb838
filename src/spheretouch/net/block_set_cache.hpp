// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The client's block sets (ScatterGather's, not installed): each worker's share of the object,
/// encoded once and kept by its blocks and by its content hash; a set a reassignment needs is
/// encoded on one background thread, never inside a round.
#pragma once
#include <spheretouch/abi.hpp>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <vector>

#include <spheretouch/net/block_set.hpp>

namespace st::inline SPHERETOUCH_ABI::net::client {

/// An encoded block set the client may send: its blocks, content hash and bytes.
struct EncodedSet {
  std::vector<std::uint32_t> blocks;  // sorted
  std::uint64_t hash = 0;
  std::vector<std::uint8_t> bytes;
};
using SetPtr = std::shared_ptr<const EncodedSet>;

/// What the client distributes: the probe, the object and its partition into blocks.
struct SceneData {
  geom::Mesh probe, object;
  Blocks blocks;
  std::uint32_t leaf_faces;
  std::uint32_t object_id = 0;  // ScatterConfig::object
};

/// The block set of `blocks` (sorted) of the scene, encoded.
Result<SetPtr> encode_set(const SceneData& s, std::vector<std::uint32_t> blocks);

/// The encoded sets, by blocks and by hash.
class BlockSetCache {
 public:
  explicit BlockSetCache(std::shared_ptr<const SceneData> scene);
  ~BlockSetCache();
  BlockSetCache(const BlockSetCache&) = delete;
  BlockSetCache& operator=(const BlockSetCache&) = delete;
  /// Keeps `s` (an own share encoded up front, or a finished background encoding).
  void remember(const SetPtr& s);
  /// The set of `blocks` (sorted), or null while it is being encoded in the background (the
  /// first call starts that).
  SetPtr get(const std::vector<std::uint32_t>& blocks);
  /// The set with this hash, or null.
  SetPtr find(std::uint64_t hash) const;
  /// Collects finished encodings, then drops every set `keep` says no (memory stays bounded
  /// however often workers come and go); the number dropped.
  std::size_t prune(const std::function<bool(const EncodedSet&)>& keep);
  std::size_t size() const { return by_blocks_.size(); }  ///< sets held

 private:
  /// One long-lived thread that encodes, jobs in order. A thread per job (std::async) maps a
  /// fresh stack for every fault, and a process that asked for mlockall(MCL_FUTURE)
  /// (`lock_memory`) keeps each one resident: +8 MB per encoding.
  class Encoder;
  std::shared_ptr<const SceneData> scene_;
  std::map<std::vector<std::uint32_t>, SetPtr> by_blocks_;
  std::unordered_map<std::uint64_t, SetPtr> by_hash_;
  std::map<std::vector<std::uint32_t>, std::future<Result<SetPtr>>> encoding_;
  std::unique_ptr<Encoder> encoder_;
};

}  // namespace st::net::client
