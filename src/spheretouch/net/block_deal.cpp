// SPDX-License-Identifier: BSD-3-Clause
// WorkLedger and BlockDeal (block_deal.hpp).
#include <spheretouch/net/block_deal.hpp>

#include <algorithm>

namespace st::inline SPHERETOUCH_ABI::net::client {

WorkLedger::WorkLedger(const Blocks& blocks, std::size_t object_faces) {
  face_block_.assign(object_faces, UINT32_MAX);
  for (std::uint32_t b = 0; b < blocks.size(); ++b)
    for (std::uint32_t f : blocks[b])
      if (f < face_block_.size() && face_block_[f] == UINT32_MAX) face_block_[f] = b;
  block_work_.assign(blocks.size(), 0);
}

void WorkLedger::note(std::span<const WorkedBlock> worked) {
  for (const WorkedBlock& w : worked)
    if (w.block < block_work_.size() && w.work > 0) reported_.push_back(w);
}

void WorkLedger::end_round(const std::vector<FacePair>& pairs) {
  for (std::uint32_t b : worked_) block_work_[b] = 0;
  worked_.clear();
  const auto add = [this](std::uint32_t b, double w) {
    if (block_work_[b] == 0) worked_.push_back(b);
    block_work_[b] += w;
  };
  if (!reported_.empty()) {
    for (const WorkedBlock& w : reported_) add(w.block, double(w.work));
    reported_.clear();
    return;
  }
  for (const FacePair& fp : pairs) {
    const std::uint32_t b = fp.object < face_block_.size() ? face_block_[fp.object] : UINT32_MAX;
    if (b != UINT32_MAX) add(b, 1.0);
  }
}

BlockDeal::BlockDeal(std::uint32_t blocks, const Limits& limits, bool balance, double stickiness)
    : blocks_(blocks),
      max_skip_(limits.max_skip),
      max_take_(limits.max_take),
      balance_(balance),
      stickiness_(stickiness),
      home_(blocks, kNone),
      alt_(blocks, kNone),
      home_takes_(blocks, 0),
      answer_(blocks, kNone),
      last_(blocks, kNone) {}

void BlockDeal::map_holders(const std::vector<Peer>& peers) {
  std::fill(home_.begin(), home_.end(), kNone);
  std::fill(alt_.begin(), alt_.end(), kNone);
  std::fill(home_takes_.begin(), home_takes_.end(), 0);
  forced_.clear();
  for (std::uint32_t i = 0; i < peers.size(); ++i)
    if (const SetPtr& s = peers[i].asked)
      for (std::uint32_t b : s->blocks)
        if (b < blocks_ && home_[b] == kNone) home_[b] = i;
  for (std::uint32_t i = 0; i < peers.size(); ++i)
    if (const SetPtr& s = peers[i].standby_asked)
      for (std::uint32_t b : s->blocks) {
        if (b >= blocks_) continue;
        if (home_[b] == kNone) {  // no queried set holds it: its copy answers, every round
          home_[b] = i;
          home_takes_[b] = 1;
          forced_.push_back(b);
        } else if (home_[b] != i && !home_takes_[b] && alt_[b] == kNone) {
          alt_[b] = i;
        }
      }
  std::sort(forced_.begin(), forced_.end());
  answer_ = home_;
  seen_asked_.clear();
  seen_standby_.clear();
  for (const Peer& p : peers) {
    seen_asked_.push_back(p.asked);
    seen_standby_.push_back(p.standby_asked);
  }
}

void BlockDeal::deal(std::vector<Peer>& peers, const WorkLedger& ledger) {
  bool same = seen_asked_.size() == peers.size();
  for (std::size_t i = 0; same && i < peers.size(); ++i)
    same = seen_asked_[i] == peers[i].asked && seen_standby_[i] == peers[i].standby_asked;
  if (!same) map_holders(peers);
  for (std::uint32_t b : order_) answer_[b] = home_[b];  // last round's moves (and withdrawals) undone
  for (std::uint32_t b : forced_) answer_[b] = home_[b];
  order_.clear();
  moved_ = 0;
  for (Peer& p : peers) {
    p.skip.clear();
    p.take.clear();
  }
  for (std::uint32_t b : forced_) {
    std::vector<std::uint32_t>& take = peers[home_[b]].take;
    if (take.size() < max_take_)
      take.push_back(b);
    else
      answer_[b] = kNone;  // over the limit: uncovered this round (the reassigned sets will hold it)
  }
  if (!balance_) return;  // every block at home; the forced takes are ascending (forced_ is)
  const std::span<const double> work = ledger.work();
  load_.assign(peers.size(), 0.0);
  double total = 0;
  std::uint32_t asked = 0;
  for (const Peer& p : peers) asked += p.asked || p.standby_asked;
  for (std::uint32_t b : ledger.worked()) {
    const std::uint32_t h = answer_[b];
    if (h == kNone) continue;
    total += work[b];
    if (balance_ && alt_[b] != kNone)
      order_.push_back(b);
    else
      load_[h] += work[b];
  }
  std::sort(order_.begin(), order_.end(),
            [&](std::uint32_t x, std::uint32_t y) { return work[x] != work[y] ? work[x] > work[y] : x < y; });
  const double tolerance = asked ? stickiness_ * total / asked : 0.0;
  for (std::uint32_t b : order_) {
    const std::uint32_t h = home_[b], a = alt_[b];
    std::uint32_t pick = load_[a] < load_[h] ? a : h;
    const std::uint32_t other = pick == a ? h : a;
    if (last_[b] == other && load_[other] - load_[pick] < tolerance) pick = other;  // stay put
    if (pick == a && (peers[h].skip.size() >= max_skip_ || peers[a].take.size() >= max_take_)) pick = h;
    if (pick == a) {
      peers[h].skip.push_back(b);
      peers[a].take.push_back(b);
      ++moved_;
    }
    answer_[b] = last_[b] = pick;
    load_[pick] += work[b];
  }
  for (Peer& p : peers) {
    std::sort(p.skip.begin(), p.skip.end());
    std::sort(p.take.begin(), p.take.end());
  }
}

bool BlockDeal::withdraw(std::vector<Peer>& peers, std::uint32_t b) {
  const std::uint32_t a = b < blocks_ ? answer_[b] : kNone;
  if (a == kNone) return false;
  Peer& p = peers[a];
  if (const auto it = std::lower_bound(p.take.begin(), p.take.end(), b); it != p.take.end() && *it == b) {
    p.take.erase(it);
  } else {
    if (p.skip.size() >= max_skip_) return false;
    p.skip.insert(std::lower_bound(p.skip.begin(), p.skip.end(), b), b);
  }
  answer_[b] = kNone;
  order_.push_back(b);  // restored next round
  return true;
}

}  // namespace st::net::client
