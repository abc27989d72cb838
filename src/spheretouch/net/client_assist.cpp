// SPDX-License-Identifier: BSD-3-Clause
// ClientAssist (client_assist.hpp) and choose_assist() (scatter_gather.hpp).
#include <spheretouch/net/client_assist.hpp>

#include <algorithm>
#include <numeric>

#include <spheretouch/net/tree_backend.hpp>

namespace st::inline SPHERETOUCH_ABI::net {
namespace client {

Result<std::unique_ptr<ClientAssist>> ClientAssist::create(const SceneData& scene, std::uint32_t max_blocks,
                                                           std::uint32_t max_pairs) {
  std::unique_ptr<ClientAssist> a(new ClientAssist());
  a->max_blocks_ = max_blocks;
  a->max_pairs_ = max_pairs;
  const auto nblocks = static_cast<std::uint32_t>(scene.blocks.size());
  std::vector<std::uint32_t> all(nblocks);
  std::iota(all.begin(), all.end(), 0u);
  auto set = make_block_set(scene.probe, scene.object, scene.blocks, all, scene.leaf_faces, scene.object_id);
  if (!set) return fail("scatter-gather: client assist: ", set.error());
  a->backend_ = tree_backend_factory()();
  if (Status s = a->backend_->load(set.value()); !s) return fail("scatter-gather: client assist: ", s.error());
  return a;
}

void ClientAssist::choose(std::vector<Peer>& peers, BlockDeal& deal, const WorkLedger& ledger) {
  taken_.clear();
  if (ledger.worked().empty()) return;
  candidates_.clear();
  for (std::uint32_t b : ledger.worked())
    if (const std::uint32_t a = deal.answerer(b); a != BlockDeal::kNone)
      candidates_.push_back({b, a, ledger.work()[b]});
  for (std::uint32_t b : choose_assist(candidates_, static_cast<std::uint32_t>(peers.size()), max_blocks_))
    if (deal.withdraw(peers, b)) taken_.push_back(b);
}

void ClientAssist::answer(const geom::Pose& pose, RoundResult& out, std::vector<std::uint8_t>& covered, WorkLedger& ledger) {
  if (taken_.empty()) return;
  const auto t0 = std::chrono::steady_clock::now();
  for (std::uint32_t b : taken_) {
    // The worker's query on the block's own subtree, so the pairs are the ones it would have found.
    pairs_.clear();
    const QueryStats st = backend_->query_only(pose, std::span(&b, 1), pairs_, {max_pairs_, UINT64_MAX});
    if (pairs_.size() > max_pairs_) continue;  // left to the worker's refusal: the round is incomplete
    out.pairs.insert(out.pairs.end(), pairs_.begin(), pairs_.end());
    ledger.note(backend_->worked());
    out.assist.sphere_tests += st.sphere_tests;
    out.assist.tri_tests += st.tri_tests;
    ++out.blocks_assisted;
    covered[b] = 1;
  }
  out.stats.sphere_tests += out.assist.sphere_tests;
  out.stats.tri_tests += out.assist.tri_tests;
  out.assist.compute_ns =
      std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count());
}

}  // namespace client

std::vector<std::uint32_t> choose_assist(std::span<const BlockWork> worked, std::uint32_t workers, std::uint32_t max_blocks) {
  std::vector<double> load(workers, 0.0);
  for (const BlockWork& w : worked)
    if (w.owner < workers && w.work > 0) load[w.owner] += w.work;
  std::vector<std::uint8_t> moved(worked.size(), 0);
  std::vector<std::uint32_t> out;
  double client = 0;
  while (out.size() < max_blocks && workers > 0) {
    const auto busiest = static_cast<std::uint32_t>(std::max_element(load.begin(), load.end()) - load.begin());
    const double gap = load[busiest] - client;  // a block lighter than this shortens the longer of the two
    std::size_t pick = worked.size();
    for (std::size_t i = 0; i < worked.size(); ++i)
      if (!moved[i] && worked[i].owner == busiest && worked[i].work > 0 && worked[i].work < gap &&
          (pick == worked.size() || worked[i].work > worked[pick].work))
        pick = i;
    if (pick == worked.size()) break;
    moved[pick] = 1;
    load[busiest] -= worked[pick].work;
    client += worked[pick].work;
    out.push_back(worked[pick].block);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace st::net
