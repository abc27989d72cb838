// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Who answers each block this round (ScatterGather's, not installed). A WorkLedger keeps what
/// each block cost the round before (the workers' reports, ResultMsg::worked); a BlockDeal names,
/// from the block sets each worker is asked with, the worker that answers each block, and writes
/// each worker's skip and take lists (QueryMsg::skip, QueryMsg::take).
//
// Every block has a home: the first asked worker whose queried set holds it (its own share, or
// a set enlarged after a failure), else an asked worker whose standby set holds it
// (ScatterConfig::replicas: a worker is down and its blocks are answered from their copies at
// once), which then takes it every round. A block whose home holds it in its queried set may
// also have a standby holder; with replicas, each round the blocks that worked the round before
// are dealt, the heaviest first, to the less loaded of the two (a two-choice longest processing
// time first), a block staying where it was answered the round before unless the other holder is
// lighter by more than `stickiness` of the mean load, so that a worker's blocks change little
// from one round to the next (each change costs its coherent collider a plain round).
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <span>
#include <vector>

#include <spheretouch/net/block_set.hpp>
#include <spheretouch/net/peer.hpp>
#include <spheretouch/net/protocol.hpp>

namespace st::inline SPHERETOUCH_ABI::net::client {

/// What each block cost the round before.
class WorkLedger {
 public:
  /// For a partition of `blocks` (its object's faces per block: the pairs stand in for the work
  /// where no worker reports any).
  explicit WorkLedger(const Blocks& blocks, std::size_t object_faces);
  /// Blocks' work a Result (or the client's own answer) reported this round.
  void note(std::span<const WorkedBlock> worked);
  /// The round is over: what was reported is next round's work. Without any report (backends
  /// that do not count), each block's pairs in the round's merged result stand in for its work.
  void end_round(const std::vector<FacePair>& pairs);
  /// Per block: its work the round before (0: none).
  std::span<const double> work() const { return block_work_; }
  /// The blocks with work the round before, each once.
  std::span<const std::uint32_t> worked() const { return worked_; }

 private:
  std::vector<std::uint32_t> face_block_;  // object face -> its block
  std::vector<double> block_work_;         // per block: its work last round (0 where none)
  std::vector<std::uint32_t> worked_;      // blocks with block_work_ > 0
  std::vector<WorkedBlock> reported_;      // this round's reports
};

/// The answerer of each block and each asked worker's skip and take lists.
class BlockDeal {
 public:
  static constexpr std::uint32_t kNone = UINT32_MAX;  ///< no asked worker holds the block
  /// For `blocks` blocks; lists kept within `limits` (max_skip, max_take); `balance`: deal the
  /// blocks with work between their two holders (ScatterConfig::replicas), else each stays home.
  BlockDeal(std::uint32_t blocks, const Limits& limits, bool balance, double stickiness);
  /// Sets every peer's `skip` and `take` for this round from the sets it is asked with
  /// (Peer::asked, Peer::standby_asked) and the work of the round before.
  void deal(std::vector<Peer>& peers, const WorkLedger& ledger);
  /// The worker that answers block `b` this round (after deal()), or kNone. Valid for every
  /// block with work and every block some asked worker holds.
  std::uint32_t answerer(std::uint32_t b) const { return answer_[b]; }
  /// Gives block `b` to nobody this round (the client answers it): off its answerer's lists.
  /// False (nothing changed) when no worker answers it or its answerer's skip list is full.
  bool withdraw(std::vector<Peer>& peers, std::uint32_t b);
  /// Blocks moved from their home this round (a figure for tests and benches).
  std::uint32_t moved() const { return moved_; }

 private:
  void map_holders(const std::vector<Peer>& peers);
  std::uint32_t blocks_;
  std::uint32_t max_skip_, max_take_;
  bool balance_;
  double stickiness_;
  std::vector<SetPtr> seen_asked_, seen_standby_;  // the sets map_holders() saw (kept alive: no ABA)
  std::vector<std::uint32_t> home_;                // per block: its home worker, or kNone
  std::vector<std::uint32_t> alt_;                 // per block: a standby holder other than home, or kNone
  std::vector<std::uint8_t> home_takes_;           // per block: home holds it as standby only
  std::vector<std::uint32_t> forced_;              // blocks whose home takes them
  std::vector<std::uint32_t> answer_;              // per block: this round's answerer (home unless moved)
  std::vector<std::uint32_t> last_;                // per block: the round before's answerer, or kNone
  std::vector<std::uint32_t> order_;               // the blocks dealt (heaviest first) and withdrawn this round
  std::vector<double> load_;                       // scratch: per worker
  std::uint32_t moved_ = 0;
};

}  // namespace st::net::client
