// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/block_deal.* and the replicated deal it serves (ScatterConfig::replicas): the
// standby copies each worker keeps, the deal of the blocks that worked between their two holders
// (skip and take lists, stickiness, limits, withdrawal by the assist), and rounds over in-process
// workers: exact and complete, balanced, and complete again as soon as a stopped worker is marked
// down, from the copies.
#include <doctest/doctest.h>

#include <algorithm>
#include <numeric>
#include <set>

#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/net/block_deal.hpp>
#include <spheretouch/net/local_workers.hpp>
#include <spheretouch/net/reference_backend.hpp>
#include <spheretouch/net/scatter_gather.hpp>
#include <spheretouch/net/tree_backend.hpp>
#include "net_test_util.hpp"

using namespace st;
using namespace st::net;
using namespace std::chrono_literals;

namespace {

std::string replicas_tag() {
  static int n = 0;
  return "rep" + std::to_string(++n);
}

client::SetPtr set_of(std::vector<std::uint32_t> blocks, std::uint64_t hash) {
  return std::make_shared<const client::EncodedSet>(client::EncodedSet{std::move(blocks), hash, {}});
}

// A ledger whose round before reported `work` ({block, work}).
client::WorkLedger ledger_with(const Blocks& blocks, std::vector<WorkedBlock> work) {
  client::WorkLedger l(blocks, 0);
  l.note(work);
  l.end_round({});
  return l;
}

}  // namespace

TEST_CASE("standby copies: every block once more, never on its owner, spread by a hash of the block") {
  for (std::uint32_t W : {2u, 3u, 4u, 8u, 32u}) {
    const auto share = block_cyclic(1000, W);
    const auto standby = standby_shares(share);
    REQUIRE(standby.size() == W);
    std::vector<std::uint32_t> copies(1000, 0);
    for (std::uint32_t w = 0; w < W; ++w) {
      CHECK(std::is_sorted(standby[w].begin(), standby[w].end()));
      for (std::uint32_t b : standby[w]) {
        ++copies[b];
        CHECK(b % W != w);  // not the block's owner
      }
      // Spread: each worker keeps about 1000 / W copies (a hash, not a count: within 40 %).
      CHECK(double(standby[w].size()) > 0.6 * 1000.0 / W);
      CHECK(double(standby[w].size()) < 1.4 * 1000.0 / W);
    }
    CHECK(std::all_of(copies.begin(), copies.end(), [](std::uint32_t c) { return c == 1; }));
  }
  CHECK(standby_shares(block_cyclic(10, 1)) == std::vector<std::vector<std::uint32_t>>(1));
}

TEST_CASE("the deal: the heaviest blocks first, each to the lighter of its two holders; skip and take lists") {
  const Blocks blocks(8);
  std::vector<client::Peer> peers(2);
  peers[0].asked = set_of({0, 1, 2, 3}, 10);
  peers[0].standby_asked = set_of({4, 5}, 11);
  peers[1].asked = set_of({4, 5, 6, 7}, 12);
  peers[1].standby_asked = set_of({0, 1, 2, 3}, 13);
  client::BlockDeal deal(8, DefaultLimits(), true, 0.0);
  // Four equal blocks on worker 0: two go to worker 1's copies.
  auto l = ledger_with(blocks, {{0, 10}, {1, 10}, {2, 10}, {3, 10}});
  deal.deal(peers, l);
  CHECK(deal.moved() == 2);
  CHECK(peers[0].skip == std::vector<std::uint32_t>{1, 3});
  CHECK(peers[1].take == std::vector<std::uint32_t>{1, 3});
  CHECK(peers[0].take.empty());
  CHECK(peers[1].skip.empty());
  for (std::uint32_t b : {0u, 2u}) CHECK(deal.answerer(b) == 0);
  for (std::uint32_t b : {1u, 3u}) CHECK(deal.answerer(b) == 1);
  CHECK(deal.answerer(6) == 1);  // a block without work stays home
  // Heaviest first: 30 stays home, then 20 and 10 go to the other worker's copies (30 vs 30).
  l = ledger_with(blocks, {{0, 20}, {1, 30}, {4, 10}});
  deal.deal(peers, l);
  CHECK(deal.answerer(1) == 0);
  CHECK(deal.answerer(0) == 1);
  CHECK(deal.answerer(4) == 1);
  CHECK(peers[0].skip == std::vector<std::uint32_t>{0});
  CHECK(peers[1].take == std::vector<std::uint32_t>{0});
  CHECK(peers[1].skip.empty());  // block 4 is home on worker 1
  // The assist withdraws a block from whoever answers it: a taken copy leaves the take list, a
  // block at home joins the skip list; nobody answers it this round.
  CHECK(deal.withdraw(peers, 0));
  CHECK(peers[1].take.empty());
  CHECK(deal.withdraw(peers, 1));
  CHECK(peers[0].skip == std::vector<std::uint32_t>{0, 1});
  CHECK(deal.answerer(0) == client::BlockDeal::kNone);
  CHECK_FALSE(deal.withdraw(peers, 0));
  // The next round starts from the homes again.
  l = ledger_with(blocks, {});
  deal.deal(peers, l);
  CHECK(deal.moved() == 0);
  for (const auto& p : peers) CHECK((p.skip.empty() && p.take.empty()));
  CHECK(deal.answerer(0) == 0);
  CHECK(deal.answerer(1) == 0);
}

TEST_CASE("the deal: a block stays with its last holder within the stickiness; a down worker's blocks are taken") {
  const Blocks blocks(8);
  std::vector<client::Peer> peers(2);
  peers[0].asked = set_of({0, 1, 2, 3}, 10);
  peers[0].standby_asked = set_of({4, 5, 6, 7}, 11);
  peers[1].asked = set_of({4, 5, 6, 7}, 12);
  peers[1].standby_asked = set_of({0, 1, 2, 3}, 13);
  client::BlockDeal sticky(8, DefaultLimits(), true, 0.5), fresh(8, DefaultLimits(), true, 0.0);
  auto l = ledger_with(blocks, {{0, 10}, {1, 10}, {2, 10}, {3, 10}});
  sticky.deal(peers, l);
  std::vector<std::uint32_t> before;
  for (std::uint32_t b = 0; b < 4; ++b) before.push_back(sticky.answerer(b));
  // Block 0 grows: a fresh deal would reshuffle; within half the mean load nothing moves.
  l = ledger_with(blocks, {{0, 14}, {1, 10}, {2, 10}, {3, 10}});
  sticky.deal(peers, l);
  fresh.deal(peers, l);
  for (std::uint32_t b = 0; b < 4; ++b) CHECK(sticky.answerer(b) == before[b]);
  CHECK(before == std::vector<std::uint32_t>{0, 1, 0, 1});
  CHECK(fresh.answerer(2) == 1);  // 14 on worker 0 against 10: the fresh deal sends block 2 over
  CHECK(fresh.answerer(3) == 0);
  // Worker 1 is not asked (down): its blocks are answered from worker 0's copies, every round.
  peers[1].asked = nullptr;
  peers[1].standby_asked = nullptr;
  l = ledger_with(blocks, {{5, 3}});
  sticky.deal(peers, l);
  CHECK(peers[0].take == std::vector<std::uint32_t>{4, 5, 6, 7});
  CHECK(peers[0].skip.empty());
  for (std::uint32_t b = 0; b < 8; ++b) CHECK(sticky.answerer(b) == 0);
  // Lists stay within their limits: blocks beyond max_take are left uncovered.
  Limits small = DefaultLimits();
  small.max_take = 2;
  client::BlockDeal capped(8, small, true, 0.0);
  capped.deal(peers, l);
  CHECK(peers[0].take == std::vector<std::uint32_t>{4, 5});
  CHECK(capped.answerer(6) == client::BlockDeal::kNone);
  // Without balancing (replicas off) nothing moves.
  peers[1].asked = set_of({4, 5, 6, 7}, 12);
  peers[1].standby_asked = set_of({0, 1, 2, 3}, 13);
  client::BlockDeal home(8, DefaultLimits(), false, 0.0);
  l = ledger_with(blocks, {{0, 10}, {1, 10}, {2, 10}, {3, 10}});
  home.deal(peers, l);
  CHECK(home.moved() == 0);
  for (const auto& p : peers) CHECK((p.skip.empty() && p.take.empty()));
}

TEST_CASE(
    "replicated deal over in-process workers: exact, complete and balanced; a stopped worker's blocks from "
    "their copies") {
  zmq::context_t ctx;
  test::NetScene s = test::small_scene(16, 24);
  const geom::SphereTree tree = geom::SphereTree::build(s.object).value();
  auto blocks = tree_blocks(tree, 3, 1);
  REQUIRE(blocks.ok());
  const auto nblocks = static_cast<std::uint32_t>(blocks.value().size());
  const auto poses = test::contact_poses(s, 8);
  for (const bool tree_backend : {true, false}) {
    CAPTURE(tree_backend);
    const std::string t = replicas_tag();
    // Three clients below, two sets each (a share and its standby copies), and the enlarged share
    // the last one sends after the fault: no set is evicted for another.
    WorkerConfig room;
    room.max_sets = 8;
    auto wr = LocalWorkers::start(
        ctx, 4, tree_backend ? tree_backend_factory() : reference_backend_factory(),
        [&](int i) { return inproc_endpoint(i, t); }, room);
    REQUIRE_MESSAGE(wr.ok(), wr.error());
    LocalWorkers& w = *wr.value();
    for (const std::uint32_t assist : {0u, 4u}) {
      CAPTURE(assist);
      ScatterConfig cfg;
      cfg.endpoints = w.endpoints();
      cfg.replicas = true;
      cfg.assist_blocks = assist;
      cfg.heartbeat_period = 20ms;
      auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, blocks.value());
      REQUIRE_MESSAGE(c.ok(), c.error());
      REQUIRE(c.value()->wait_ready(Clock::now() + 10s));
      std::vector<std::uint32_t> copies(nblocks, 0);
      for (const WorkerStatus& ws : c.value()->workers()) {
        CHECK(ws.holds_target);
        CHECK(ws.holds_standby);
        CHECK_FALSE(ws.standby_blocks.empty());
        for (std::uint32_t b : ws.standby_blocks) {
          ++copies[b];
          CHECK_FALSE(std::binary_search(ws.target_blocks.begin(), ws.target_blocks.end(), b));
        }
      }
      CHECK(std::all_of(copies.begin(), copies.end(), [](std::uint32_t n) { return n == 1; }));
      std::uint64_t seq = 0;
      std::uint32_t moved_rounds = 0;
      for (const geom::Pose& pose : poses)
        for (int k = 0; k < 3; ++k) {  // the same pose again: the round before says where the work is
          RoundResult r = c.value()->round(++seq, pose, Clock::now() + 5s);
          CHECK(r.complete);
          CHECK(r.workers_replied == 4);
          CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
          if (seq == 1) CHECK(r.blocks_moved == 0);  // nothing known yet
          moved_rounds += r.blocks_moved > 0;
        }
      CHECK(moved_rounds > 0);
    }

    // Worker 2 stops: the rounds miss it until it is marked down (miss_limit = 3), and the very
    // next round is complete and exact: its blocks are answered from their copies.
    ScatterConfig cfg;
    cfg.endpoints = w.endpoints();
    cfg.replicas = true;
    cfg.heartbeat_period = 20ms;
    auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, blocks.value());
    REQUIRE_MESSAGE(c.ok(), c.error());
    REQUIRE(c.value()->wait_ready(Clock::now() + 10s));
    std::uint64_t seq = 100;
    for (const geom::Pose& pose : poses) REQUIRE(c.value()->round(++seq, pose, Clock::now() + 5s).complete);
    w.stop(2);
    int incomplete = 0;
    for (int k = 0; k < 3; ++k) incomplete += !c.value()->round(++seq, poses[0], Clock::now() + 50ms).complete;
    CHECK(incomplete == 3);
    CHECK_FALSE(c.value()->workers()[2].up);
    for (const geom::Pose& pose : poses) {
      RoundResult r = c.value()->round(++seq, pose, Clock::now() + 5s);
      CHECK(r.complete);
      CHECK(r.workers_replied == 3);
      CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
    }
  }
}

TEST_CASE("a worker answers a Query's standby part only with a standby set it holds for that client") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(8, 24);
  const std::string t = replicas_tag();
  auto w = LocalWorkers::start(ctx, 2, tree_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE_MESSAGE(w.ok(), w.error());
  const std::string id = "replicas-test-client";
  {
    ScatterConfig cfg;
    cfg.endpoints = w.value()->endpoints();
    cfg.replicas = true;
    cfg.routing_id = id;
    auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, s.blocks);
    REQUIRE_MESSAGE(c.ok(), c.error());
    REQUIRE(c.value()->wait_ready(Clock::now() + 10s));
  }  // the client is gone; its sets stay on the workers
  zmq::socket_t d(ctx, zmq::socket_type::dealer);
  d.set(zmq::sockopt::routing_id, id);
  d.set(zmq::sockopt::linger, 0);
  d.set(zmq::sockopt::rcvtimeo, 5000);
  d.connect(w.value()->endpoints()[0]);
  const auto ask = [&](const Message& m) {
    d.send(zmq::buffer(encode(m)), zmq::send_flags::none);
    zmq::message_t reply;
    REQUIRE(d.recv(reply));
    auto r = decode({static_cast<const std::uint8_t*>(reply.data()), reply.size()}, DefaultLimits());
    REQUIRE_MESSAGE(r.ok(), r.error());
    return std::move(r).value();
  };
  const Message hello = ask(HeartbeatMsg{1});
  REQUIRE(std::holds_alternative<HelloMsg>(hello));
  const auto& held = std::get<HelloMsg>(hello).held;
  REQUIRE(held.size() == 2);  // its share and its standby copies
  const geom::Pose pose = test::contact_poses(s, 1)[0];
  // Named and taken in full, the two sets answer for every block of both.
  std::vector<std::uint32_t> all(s.blocks.size());
  std::iota(all.begin(), all.end(), 0u);
  const Message both = ask(QueryMsg{5, held[0].hash, pose, {}, 0, held[1].hash, all});
  REQUIRE(std::holds_alternative<ResultMsg>(both));
  // Named without taking: the share alone (a subset of the pairs).
  const Message one = ask(QueryMsg{6, held[0].hash, pose, {}, 0, held[1].hash, {}});
  REQUIRE(std::holds_alternative<ResultMsg>(one));
  const auto& p1 = std::get<ResultMsg>(one).pairs;
  const auto& p2 = std::get<ResultMsg>(both).pairs;
  CHECK(std::includes(p2.begin(), p2.end(), p1.begin(), p1.end()));
  CHECK(p2.size() >= p1.size());
  // A standby set it does not hold: NotLoaded for the round (then a Hello), nothing answered.
  const Message no = ask(QueryMsg{7, held[0].hash, pose, {}, 0, 0x5eedull, {1}});
  REQUIRE(std::holds_alternative<ErrorMsg>(no));
  CHECK(std::get<ErrorMsg>(no).code == ErrorCode::NotLoaded);
  CHECK(std::get<ErrorMsg>(no).ref == 7);
  CHECK(std::get<ErrorMsg>(no).text.find("standby") != std::string::npos);
  {
    zmq::message_t follow;
    REQUIRE(d.recv(follow));
  }
  // Another client (another routing id) cannot name this client's sets.
  zmq::socket_t other(ctx, zmq::socket_type::dealer);
  other.set(zmq::sockopt::linger, 0);
  other.set(zmq::sockopt::rcvtimeo, 5000);
  other.connect(w.value()->endpoints()[0]);
  other.send(zmq::buffer(encode(QueryMsg{8, held[0].hash, pose, {}, 0, held[1].hash, {1}})), zmq::send_flags::none);
  zmq::message_t reply;
  REQUIRE(other.recv(reply));
  auto r = decode({static_cast<const std::uint8_t*>(reply.data()), reply.size()}, DefaultLimits());
  REQUIRE(r.ok());
  REQUIRE(std::holds_alternative<ErrorMsg>(r.value()));
  CHECK(std::get<ErrorMsg>(r.value()).code == ErrorCode::NotLoaded);
}

TEST_CASE("a worker that dropped a client's standby copies: that client sends them again, not its share") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(8, 24);
  const auto poses = test::contact_poses(s, 3);
  const std::string t = replicas_tag();
  WorkerConfig tight;  // two sets per worker; a set queried within 2 s is in use
  tight.max_sets = 2;
  auto w = LocalWorkers::start(
      ctx, 2, tree_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, tight);
  REQUIRE_MESSAGE(w.ok(), w.error());
  ScatterConfig cfg;
  cfg.endpoints = w.value()->endpoints();
  cfg.replicas = true;
  const auto b_cfg = [&] {
    ScatterConfig other = cfg;
    other.replicas = false;
    return other;
  };
  {  // Another client's share first; it stops querying, so its set is idle.
    auto b = ScatterGather::create(ctx, b_cfg(), s.probe, s.object, s.blocks);
    REQUIRE_MESSAGE(b.ok(), b.error());
    REQUIRE(b.value()->wait_ready(Clock::now() + 10s));
  }
  auto a = ScatterGather::create(ctx, cfg, s.probe, s.object, s.blocks);
  REQUIRE_MESSAGE(a.ok(), a.error());
  REQUIRE(a.value()->wait_ready(Clock::now() + 10s));
  std::uint64_t seq = 0;
  bool exact = false;
  for (int k = 0; k < 200 && !exact; ++k) {
    const geom::Pose& pose = poses[k % poses.size()];
    RoundResult r = a.value()->round(++seq, pose, Clock::now() + 2s);
    auto ws = a.value()->workers();
    exact = r.complete && r.workers_replied == 2 && ws[0].holds_standby && ws[1].holds_standby &&
            r.pairs == reference_collide(s.probe, s.object, pose);
  }
  CHECK(exact);
  // Each worker made room by dropping the idle set, never one of this client's two in use: each
  // was sent once.
  for (const WorkerStatus& ws : a.value()->workers()) {
    CHECK(ws.holds_target);
    CHECK(ws.loads_sent == 2);
    CHECK(ws.refused.empty());
  }
}

TEST_CASE("a worker with room for one set: the client keeps its share, answers without copies there, and says why") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(8, 24);
  const auto poses = test::contact_poses(s, 3);
  const std::string t = replicas_tag();
  WorkerConfig one;
  one.max_sets = 1;
  auto w = LocalWorkers::start(
      ctx, 2, tree_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, one);
  REQUIRE_MESSAGE(w.ok(), w.error());
  ScatterConfig cfg;
  cfg.endpoints = w.value()->endpoints();
  cfg.replicas = true;
  auto a = ScatterGather::create(ctx, cfg, s.probe, s.object, s.blocks);
  REQUIRE_MESSAGE(a.ok(), a.error());
  // Ready without the copies: each worker's share displaced by its copies, sent again, and the
  // copies held back for load_timeout instead of trading places with the share on every load.
  REQUIRE(a.value()->wait_ready(Clock::now() + 10s));
  std::uint64_t seq = 0;
  for (int k = 0; k < 30; ++k) {
    const geom::Pose& pose = poses[k % poses.size()];
    RoundResult r = a.value()->round(++seq, pose, Clock::now() + 2s);
    CHECK(r.complete);
    CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
  }
  for (const WorkerStatus& ws : a.value()->workers()) {
    CHECK(ws.holds_target);
    CHECK_FALSE(ws.holds_standby);
    CHECK(ws.loads_sent <= 3);  // share, copies, share again
    CHECK(ws.refused.find("standby") != std::string::npos);
  }
}
