// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The client assist (ScatterConfig::assist_blocks; ScatterGather's, not installed): each round
/// the collision thread answers a few of the busiest workers' heaviest blocks itself while the
/// Queries are out, with the very backend a worker runs (tree_backend.hpp), loaded once with a
/// block set of every block: no second block extractor, the same subtrees, the same pairs.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <spheretouch/net/backend.hpp>
#include <spheretouch/net/block_deal.hpp>
#include <spheretouch/net/block_set_cache.hpp>
#include <spheretouch/net/peer.hpp>

namespace st::inline SPHERETOUCH_ABI::net::client {

class ClientAssist {
 public:
  /// For `scene`: at most `max_blocks` blocks a round, each refused past `max_pairs` (left to its
  /// worker's refusal). Builds the backend (cold: a tree over the whole object).
  static Result<std::unique_ptr<ClientAssist>> create(const SceneData& scene, std::uint32_t max_blocks,
                                                      std::uint32_t max_pairs);
  /// This round's blocks: choose_assist() over the work each block cost last round and the
  /// worker `deal` gives it to, each withdrawn from that worker's lists.
  void choose(std::vector<Peer>& peers, BlockDeal& deal, const WorkLedger& ledger);
  /// Answers the chosen blocks at `pose`: their pairs appended to out.pairs, covered[b] set for
  /// each one answered, their work noted in `ledger`, out.assist and out.stats counted.
  void answer(const geom::Pose& pose, RoundResult& out, std::vector<std::uint8_t>& covered, WorkLedger& ledger);

 private:
  ClientAssist() = default;
  std::uint32_t max_blocks_ = 0, max_pairs_ = 0;
  std::unique_ptr<CollisionBackend> backend_;  // a worker's backend over every block
  std::vector<std::uint32_t> taken_;           // blocks answered this round, ascending
  std::vector<BlockWork> candidates_;          // scratch for choose_assist
  std::vector<FacePair> pairs_;                // scratch: one block's pairs
};

}  // namespace st::net::client
