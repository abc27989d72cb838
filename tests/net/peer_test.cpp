// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/peer.*: the order a round's Queries go out in, and how a round counts the
// blocks its Results cover (Coverage, choose_sets).
#include <doctest/doctest.h>

#include <vector>

#include <spheretouch/net/block_set_cache.hpp>
#include <spheretouch/net/peer.hpp>

using st::net::client::Peer;

TEST_CASE("send_order: the slowest worker of the round before first, ties in endpoint order") {
  std::vector<Peer> peers(5);
  const std::uint64_t compute_ns[] = {300, 0, 9000, 300, 4500};  // 1 answered nothing (or is new)
  for (std::size_t i = 0; i < peers.size(); ++i) peers[i].compute_ns = compute_ns[i];
  std::vector<std::uint32_t> order{7, 7};  // stale contents are replaced
  st::net::client::send_order(peers, order);
  CHECK(order == std::vector<std::uint32_t>{2, 4, 0, 3, 1});
  peers.clear();
  st::net::client::send_order(peers, order);
  CHECK(order.empty());
}

TEST_CASE("Coverage: counted while the asked sets are a partition of the blocks, marked otherwise, exact either way") {
  using namespace st::net::client;
  auto scene = std::make_shared<const SceneData>(SceneData{{}, {}, st::net::Blocks(6), 24});
  BlockSetCache sets(scene);
  const auto set_of = [&](std::vector<std::uint32_t> blocks, std::uint64_t hash) {
    SetPtr s = std::make_shared<const EncodedSet>(EncodedSet{std::move(blocks), hash, {}});
    sets.remember(s);
    return s;
  };
  const SetPtr even = set_of({0, 2, 4}, 11), odd = set_of({1, 3, 5}, 12), all = set_of({0, 1, 2, 3, 4, 5}, 13);
  std::vector<Peer> peers(2);
  for (auto [p, h] : {std::pair{&peers[0], 11}, std::pair{&peers[1], 12}}) {
    p->link = Link::Live;
    p->held = {std::uint64_t(h)};
    p->target_hash = std::uint64_t(h);
  }
  Coverage cover;
  cover.marks.assign(6, 0);
  choose_sets(peers, sets, cover);
  CHECK(cover.counting);
  CHECK(peers[0].asked == even);
  CHECK(peers[1].asked == odd);
  // Block 2 answered by worker 1 from its standby copy: worker 0 skips it, worker 1 takes it.
  peers[0].skip = {2};
  peers[1].take = {2};
  cover.begin_round();
  cover.note(peers[0]);
  CHECK(cover.covered(0) == 2);
  CHECK(cover.covered(1) == 3);  // and a block the client assist answered
  cover.note(peers[1]);
  CHECK(cover.covered(0) == 6);
  // The same sets again: the same partition, found without a pass over the blocks.
  cover.marks.assign(6, 7);  // (a pass would have rewritten them)
  choose_sets(peers, sets, cover);
  CHECK(cover.counting);
  CHECK(cover.marks == std::vector<std::uint8_t>(6, 7));
  cover.marks.assign(6, 0);
  // Worker 1 down: worker 0's set alone covers half, marked block by block.
  peers[1].link = Link::Down;
  peers[0].skip.clear();
  peers[1].take.clear();
  choose_sets(peers, sets, cover);
  CHECK_FALSE(cover.counting);
  CHECK(peers[1].asked == nullptr);
  cover.begin_round();
  cover.note(peers[0]);
  CHECK(cover.covered(0) == 3);
  // Worker 0 asked a superset of worker 1's set (a survivor still answering for a returning
  // worker): the sets overlap, the blocks are marked, and each is counted once.
  peers[1].link = Link::Live;
  peers[0].held = {13, 11};
  peers[0].target_hash = 13;
  choose_sets(peers, sets, cover);
  CHECK_FALSE(cover.counting);
  CHECK(peers[0].asked == all);
  cover.begin_round();
  cover.note(peers[0]);
  cover.note(peers[1]);
  CHECK(cover.covered(0) == 6);
  // Back to a partition: counted again.
  peers[0].target_hash = 11;
  choose_sets(peers, sets, cover);
  CHECK(cover.counting);
}
