// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/scatter_gather.* and src/spheretouch/net/worker_service.* in one process over inproc://:
// exact merged results for 1..8 workers, content-addressed loading, a worker stopped while
// rounds stream (rounds return, are marked incomplete, blocks are reassigned, results are exact
// again) and restarted (reloaded), hostile messages to a worker, and a block set built to make a
// worker compute N² pairs (refused at max_pairs, collide() stops its traversal there).
#include <doctest/doctest.h>

#include <algorithm>
#include <array>
#include <numeric>
#include <random>
#include <thread>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/net/local_workers.hpp>
#include <spheretouch/net/reference_backend.hpp>
#include <spheretouch/net/tree_backend.hpp>
#include <spheretouch/net/scatter_gather.hpp>
#include "net_test_util.hpp"

using namespace st;
using namespace st::net;
using namespace std::chrono_literals;

namespace {

std::string tag() {
  static int n = 0;
  return "sg" + std::to_string(++n);
}

std::unique_ptr<ScatterGather> client(zmq::context_t& ctx, const LocalWorkers& w, const test::NetScene& s,
                                      std::uint32_t miss_limit = 3, std::string routing_id = {}) {
  ScatterConfig cfg;
  cfg.routing_id = std::move(routing_id);
  cfg.endpoints = w.endpoints();
  cfg.miss_limit = miss_limit;
  cfg.heartbeat_period = 20ms;
  auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, s.blocks);
  REQUIRE_MESSAGE(c.ok(), c.error());
  return std::move(c.value());
}

// Every worker up, none with a missed deadline.
void check_none_missed(const ScatterGather& c) {
  for (const WorkerStatus& ws : c.workers()) {
    CHECK(ws.up);
    CHECK(ws.misses == 0);
  }
}

// A fresh client gets these workers ready and one complete round equal to the reference.
void check_one_exact_round(zmq::context_t& ctx, const LocalWorkers& w, const test::NetScene& s) {
  auto c = client(ctx, w, s);
  REQUIRE(c->wait_ready(Clock::now() + 10s));
  const auto pose = test::contact_poses(s, 1)[0];
  RoundResult r = c->round(1, pose, Clock::now() + 5s);
  CHECK(r.complete);
  CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
}

}  // namespace

TEST_CASE("merged pairs equal the single-process reference for 1, 2, 4 and 8 inproc workers") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(10, 24);
  const auto poses = test::contact_poses(s, 10);
  for (int n : {1, 2, 4, 8}) {
    CAPTURE(n);
    const std::string t = tag();
    auto w = LocalWorkers::start(ctx, n, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
    REQUIRE_MESSAGE(w.ok(), w.error());
    auto c = client(ctx, *w.value(), s);
    REQUIRE(c->wait_ready(Clock::now() + 10s));
    std::uint64_t seq = 0;
    std::vector<std::uint32_t> ids;
    for (const geom::Pose& pose : poses) {
      RoundResult r = c->round(++seq, pose, Clock::now() + 5s);
      CHECK(r.complete);
      CHECK(r.workers_asked == static_cast<std::uint32_t>(n));
      CHECK(r.workers_replied == static_cast<std::uint32_t>(n));
      CHECK(r.blocks_covered == s.blocks.size());
      CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
      CHECK(std::is_sorted(r.pairs.begin(), r.pairs.end()));
      CHECK(r.contacts() == geom::count_faces(r.pairs, ids).contacts());
      CHECK(std::adjacent_find(r.probe_faces.begin(), r.probe_faces.end()) == r.probe_faces.end());
    }
  }
}

TEST_CASE("more workers than blocks: the idle ones are not awaited between heartbeats, never missed or marked down") {
  // Two blocks over four workers (a small object of a scene, or a pinned split): two workers have
  // nothing to answer. A round awaits a Hello from an idle worker only when it sends it a
  // Heartbeat; it once awaited one every round, so each round between Heartbeats waited out its
  // deadline, counted a miss and, three rounds on, marked the idle worker down.
  zmq::context_t ctx;
  test::NetScene s = test::small_scene(4, 24);
  s.blocks = spatial_blocks(s.object, 200);
  REQUIRE(s.blocks.size() == 2);
  const std::string t = tag();
  auto w = LocalWorkers::start(ctx, 4, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE_MESSAGE(w.ok(), w.error());
  for (const bool replicas : {false, true}) {
    CAPTURE(replicas);
    ScatterConfig cfg;
    cfg.endpoints = w.value()->endpoints();
    cfg.routing_id = replicas ? "idle-r" : "idle";
    cfg.replicas = replicas;
    cfg.heartbeat_period = 1h;  // no Heartbeat after the first: every round is one between them
    auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, s.blocks);
    REQUIRE_MESSAGE(c.ok(), c.error());
    REQUIRE(c.value()->wait_ready(Clock::now() + 10s));
    std::uint64_t seq = 0;
    for (const geom::Pose& pose : test::contact_poses(s, 6)) {
      RoundResult r = c.value()->round(++seq, pose, Clock::now() + 200ms);
      CHECK(r.complete);
      CHECK(r.workers_asked == 2);
      CHECK(r.workers_replied == 2);
      CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
      check_none_missed(*c.value());
    }
  }
}

TEST_CASE("a worker that refuses a round's Query (over max_pairs) is not awaited, missed or marked down; it says why") {
  // Workers that take at most 10 pairs a query: a pose in deep contact gives each more. The
  // refusal (TooLarge, naming the Query's seq) ends that worker's turn: the round is incomplete
  // without its blocks, the worker stays up with no miss (it once waited out every round's
  // deadline for a Result that never came and, three rounds on, was marked down), and
  // WorkerStatus::refused carries the worker's reason. A pose apart is answered again.
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(10, 24);
  WorkerConfig base;
  base.limits.max_pairs = 10;
  base.penalty_factor = 0;  // (the penalty's own refusals end the turn the same way)
  const std::string t = tag();
  auto w = LocalWorkers::start(
      ctx, 2, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, base);
  REQUIRE_MESSAGE(w.ok(), w.error());
  auto c = client(ctx, *w.value(), s);
  REQUIRE(c->wait_ready(Clock::now() + 10s));
  geom::Pose deep = geom::Pose::Identity();
  deep.translation() = geom::Vec3(0, 0, 28);  // the fingertip well into the sphere's top
  REQUIRE(reference_collide(s.probe, s.object, deep).size() > 40);
  std::uint64_t seq = 0;
  for (int k = 0; k < 5; ++k) {
    RoundResult r = c->round(++seq, deep, Clock::now() + 5s);
    CHECK_FALSE(r.complete);
    CHECK(r.workers_asked == 2);
    check_none_missed(*c);
    const auto ws = c->workers();
    CHECK(std::any_of(ws.begin(), ws.end(),
                      [](const WorkerStatus& x) { return x.refused.find("max_pairs") != std::string::npos; }));
  }
  geom::Pose apart = geom::Pose::Identity();
  apart.translation() = geom::Vec3(0, 0, 100);
  RoundResult r = c->round(++seq, apart, Clock::now() + 5s);
  CHECK(r.complete);
  CHECK(r.pairs.empty());
}

TEST_CASE("randomised fleets: any deal, fewer blocks than workers, assist, replicas: exact rounds, no miss") {
  // Seeded cases of what a caller may configure: 1-6 workers, an icosphere or capsule object cut
  // into tree blocks or spatial blocks (sometimes fewer than the workers), each mapping, assist
  // and replicas on or off; the probe slid along and into the object. Every round is complete and
  // equals collide(); no worker misses a deadline or is marked down (a long heartbeat period: a
  // round that awaited a reply it never asked for would count misses here).
  zmq::context_t ctx;
  std::mt19937_64 rng(20261129);
  auto uni = [&](int a, int b) { return std::uniform_int_distribution<int>(a, b)(rng); };
  for (int c = 0; c < 8; ++c) {
    CAPTURE(c);
    const geom::Mesh object = uni(0, 1) ? geom::make_icosphere(30.0, uni(3, 5)) : geom::make_capsule(12.0, 30.0, 16);
    const geom::Mesh probe = geom::make_icosphere(8.0, 2);
    const geom::SphereTree object_tree = geom::SphereTree::build(object).value();
    const geom::SphereTree probe_tree = geom::SphereTree::build(probe).value();
    const int workers = uni(1, 6);
    Blocks blocks = uni(0, 2) ? tree_blocks(object_tree, std::uint32_t(uni(1, 3)), std::uint32_t(uni(1, 2))).value()
                              : spatial_blocks(object, std::uint32_t(uni(60, 400)));
    const std::string t = tag();
    auto w = LocalWorkers::start(ctx, workers, tree_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
    REQUIRE_MESSAGE(w.ok(), w.error());
    ScatterConfig cfg;
    cfg.endpoints = w.value()->endpoints();
    cfg.mapping = std::array{geom::Mapping::block_cyclic, geom::Mapping::contiguous, geom::Mapping::random}[uni(0, 2)];
    cfg.assist_blocks = uni(0, 1) ? std::uint32_t(uni(1, 3)) : 0;
    cfg.replicas = workers > 1 && uni(0, 1);
    cfg.heartbeat_period = 1h;
    CAPTURE(workers);
    CAPTURE(blocks.size());
    CAPTURE(cfg.replicas);
    CAPTURE(cfg.assist_blocks);
    auto sg = ScatterGather::create(ctx, cfg, probe, object, blocks);
    REQUIRE_MESSAGE(sg.ok(), sg.error());
    REQUIRE(sg.value()->wait_ready(Clock::now() + 10s));
    const geom::Vec3 dir = geom::Vec3(uni(-9, 9), uni(-9, 9), 10).normalized();
    geom::Pose pose = geom::Pose::Identity();
    geom::CollideScratch scratch;
    geom::CollideResult plain;
    geom::CollideConfig opt;
    opt.sort_pairs = true;
    RoundResult r;
    for (int k = 0; k < 30; ++k) {
      pose.translation() = dir * (36.0 - 0.3 * k) + geom::Vec3(0.2 * k, 0, 0);
      sg.value()->round(std::uint64_t(k + 1), pose, Clock::now() + 5s, r);
      geom::collide(probe, probe_tree, object, object_tree, pose, opt, scratch, plain);
      CHECK(r.complete);
      CHECK(r.pairs == plain.pairs);
    }
    check_none_missed(*sg.value());
  }
}

TEST_CASE("without distinct_faces a round gives the same pairs and leaves the face lists empty") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(10, 24);
  const std::string t = tag();
  auto w = LocalWorkers::start(ctx, 3, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE_MESSAGE(w.ok(), w.error());
  ScatterConfig cfg;
  cfg.endpoints = w.value()->endpoints();
  cfg.distinct_faces = false;
  auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, s.blocks);
  REQUIRE_MESSAGE(c.ok(), c.error());
  REQUIRE(c.value()->wait_ready(Clock::now() + 10s));
  std::uint64_t seq = 0;
  RoundResult r;
  r.probe_faces = {1, 2};  // a caller's vector reused from a round that had them
  int touching = 0;
  for (const geom::Pose& pose : test::contact_poses(s, 4)) {
    c.value()->round(++seq, pose, Clock::now() + 5s, r);
    CHECK(r.complete);
    CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
    CHECK(r.probe_faces.empty());
    CHECK(r.object_faces.empty());
    touching += !r.pairs.empty();
  }
  CHECK(touching > 0);  // rounds that had faces to leave out
}

TEST_CASE("every mapping (block-cyclic, contiguous, random) of sphere-layer blocks gives the exact merged result") {
  zmq::context_t ctx;
  test::NetScene s = test::small_scene(16, 24);
  const geom::SphereTree tree = geom::SphereTree::build(s.object).value();
  const auto poses = test::contact_poses(s, 6);
  for (geom::Mapping m : {geom::Mapping::block_cyclic, geom::Mapping::contiguous, geom::Mapping::random}) {
    for (int n : {3, 5}) {
      CAPTURE(geom::to_string(m));
      CAPTURE(n);
      auto blocks = tree_blocks(tree, 3, 2);
      REQUIRE(blocks.ok());
      const std::string t = tag();
      auto w = LocalWorkers::start(ctx, n, tree_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
      REQUIRE_MESSAGE(w.ok(), w.error());
      ScatterConfig cfg;
      cfg.endpoints = w.value()->endpoints();
      cfg.mapping = m;
      cfg.mapping_seed = 11;
      const auto share = deal_blocks(std::uint32_t(blocks.value().size()), std::uint32_t(n), m, 11);
      auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, blocks.value());
      REQUIRE_MESSAGE(c.ok(), c.error());
      REQUIRE(c.value()->wait_ready(Clock::now() + 10s));
      // Each worker was given exactly the blocks the mapping deals it.
      const auto ws = c.value()->workers();
      for (int i = 0; i < n; ++i) CHECK(ws[std::size_t(i)].target_blocks == share[std::size_t(i)]);
      std::uint64_t seq = 0;
      for (const geom::Pose& pose : poses) {
        RoundResult r = c.value()->round(++seq, pose, Clock::now() + 5s);
        CHECK(r.complete);
        CHECK(r.blocks_covered == blocks.value().size());
        CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
      }
    }
  }
}

TEST_CASE("a worker that already holds a client's block set is not sent it again; another client must send it") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(6);
  const std::string t = tag();
  auto w = LocalWorkers::start(ctx, 3, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE(w.ok());
  {
    auto c = client(ctx, *w.value(), s, 3, "client-one");
    REQUIRE(c->wait_ready(Clock::now() + 10s));
    for (const auto& ws : c->workers()) CHECK(ws.loads_sent == 1);
  }
  auto c2 = client(ctx, *w.value(), s, 3, "client-one");  // the same client again (restarted): same hashes
  REQUIRE(c2->wait_ready(Clock::now() + 10s));
  for (const auto& ws : c2->workers()) {
    CHECK(ws.loads_sent == 0);
    CHECK(ws.bytes_sent == 0);
    CHECK(ws.holds_target);
  }
  CHECK(c2->round(1, test::contact_poses(s, 1)[0], Clock::now() + 5s).complete);
  // A different client is not shown client-one's sets: it sends its own bytes (the workers keep
  // one backend for both) and gets exact rounds.
  auto c3 = client(ctx, *w.value(), s);
  REQUIRE(c3->wait_ready(Clock::now() + 10s));
  for (const auto& ws : c3->workers()) CHECK(ws.loads_sent == 1);
  CHECK(c3->round(1, test::contact_poses(s, 1)[0], Clock::now() + 5s).complete);
}

TEST_CASE(
    "a stopped worker: rounds return by their deadline, incomplete until reassigned, then exact; restart reloads") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(10, 24);
  const auto poses = test::contact_poses(s, 6);
  const std::string t = tag();
  auto wr = LocalWorkers::start(ctx, 4, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE(wr.ok());
  LocalWorkers& w = *wr.value();
  const std::uint32_t K = 3;
  auto c = client(ctx, w, s, K);
  REQUIRE(c->wait_ready(Clock::now() + 10s));
  std::uint64_t seq = 0;
  // Short deadlines while a worker is stopped (misses are counted); rounds that must be complete
  // (every live worker holds its blocks) get a long one, so a slow machine cannot fail them.
  const auto deadline_for = [] { return Clock::now() + 50ms; };
  const auto healthy = [] { return Clock::now() + 5s; };
  for (const auto& pose : poses) REQUIRE(c->round(++seq, pose, healthy()).complete);

  w.stop(2);
  // Rounds keep returning; the first K miss worker 2 and are incomplete.
  int incomplete = 0, rounds = 0;
  bool exact_again = false;
  const auto give_up = Clock::now() + 20s;
  while (Clock::now() < give_up) {
    const auto& pose = poses[rounds % poses.size()];
    const auto d = deadline_for();
    RoundResult r = c->round(++seq, pose, d);
    CHECK(Clock::now() < d + 500ms);  // liveness: returned, not 10x after its deadline
    ++rounds;
    if (!r.complete) {
      ++incomplete;
      CHECK(r.blocks_covered < r.blocks_total);
      continue;
    }
    CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
    exact_again = true;
    break;
  }
  CHECK(exact_again);
  CHECK(incomplete >= static_cast<int>(K));
  auto ws = c->workers();
  CHECK_FALSE(ws[2].up);
  CHECK(ws[2].target_blocks.empty());
  std::size_t reassigned = 0;
  for (int i : {0, 1, 3}) {
    CHECK(ws[i].up);
    reassigned += ws[i].target_blocks.size();
  }
  CHECK(reassigned == s.blocks.size());
  for (int k = 0; k < 5; ++k) {
    const auto& pose = poses[k % poses.size()];
    RoundResult r = c->round(++seq, pose, healthy());
    CHECK(r.complete);
    CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
  }

  // Restart: a new epoch with empty memory; it is given back its blocks and reloaded.
  REQUIRE(w.restart(2).ok());
  std::vector<std::uint32_t> loads_before;
  for (const auto& x : c->workers()) loads_before.push_back(x.loads_sent);
  for (int i : {0, 1, 3}) CHECK(loads_before[i] == 2);  // own share, then the enlarged one
  bool back = false;
  for (int k = 0; k < 400 && !back; ++k) {
    const auto& pose = poses[k % poses.size()];
    RoundResult r = c->round(++seq, pose, deadline_for());
    if (r.complete) CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
    ws = c->workers();
    back = ws[2].up && ws[2].holds_target && r.workers_replied == 4 && r.complete;
  }
  REQUIRE(back);
  CHECK(ws[2].loads_sent == loads_before[2] + 1);
  for (int i = 0; i < 4; ++i)
    CHECK(ws[i].target_blocks == block_cyclic(static_cast<std::uint32_t>(s.blocks.size()), 4)[i]);
  // Survivors kept their own share in memory: only the returning worker was sent anything.
  for (int i : {0, 1, 3}) CHECK(ws[i].loads_sent == loads_before[i]);
}

TEST_CASE("a worker answers hostile messages with an Error or drops them, and keeps serving") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(6);
  const std::string t = tag();
  auto w = LocalWorkers::start(ctx, 1, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE(w.ok());
  zmq::socket_t d(ctx, zmq::socket_type::dealer);
  d.set(zmq::sockopt::linger, 0);
  d.set(zmq::sockopt::rcvtimeo, 2000);
  d.connect(w.value()->endpoints()[0]);
  auto expect_error = [&](const std::vector<std::uint8_t>& bytes, ErrorCode code) {
    d.send(zmq::buffer(bytes), zmq::send_flags::none);
    zmq::message_t m;
    REQUIRE(d.recv(m));
    auto r = decode({static_cast<const std::uint8_t*>(m.data()), m.size()}, DefaultLimits());
    REQUIRE(r.ok());
    auto* e = std::get_if<ErrorMsg>(&r.value());
    REQUIRE(e);
    CHECK(e->code == code);
    return e->text;
  };
  CHECK(expect_error({1, 2, 3}, ErrorCode::BadMessage).find("header") != std::string::npos);
  auto q = encode(QueryMsg{1, 2, geom::Pose::Identity(), {}});
  auto bad_version = q;
  bad_version[4] = 9;
  CHECK(expect_error(bad_version, ErrorCode::BadMessage).find("version") != std::string::npos);
  auto truncated = q;
  truncated.resize(q.size() - 1);
  expect_error(truncated, ErrorCode::BadMessage);
  expect_error(encode(ResultMsg{}), ErrorCode::Unexpected);
  expect_error(q, ErrorCode::NotLoaded);
  {
    zmq::message_t hello;
    REQUIRE(d.recv(hello));
  }  // the Hello that follows NotLoaded
  // A chunk out of order, and a block set whose bytes do not match the hash.
  expect_error(encode(LoadBlocksMsg{7, 10, 4, {1, 2}}), ErrorCode::LoadFailed);
  expect_error(encode(LoadBlocksMsg{7, 3, 0, {1, 2, 3}}), ErrorCode::LoadFailed);
  // A set with the right hash but garbage content fails to decode.
  std::vector<std::uint8_t> junk(40, 0xab);
  expect_error(encode(LoadBlocksMsg{block_set_hash(junk), junk.size(), 0, junk}), ErrorCode::LoadFailed);
  // Two frames in one message.
  d.send(zmq::buffer(q), zmq::send_flags::sndmore);
  d.send(zmq::buffer(q), zmq::send_flags::none);
  {
    zmq::message_t m;
    REQUIRE(d.recv(m));
    auto r = decode({static_cast<const std::uint8_t*>(m.data()), m.size()}, DefaultLimits());
    REQUIRE(r.ok());
    CHECK(std::get<ErrorMsg>(r.value()).code == ErrorCode::BadMessage);
  }
  // Random garbage: every message is answered (an Error) or dropped; the worker stays alive.
  std::mt19937_64 rng(3);
  for (int i = 0; i < 500; ++i) {
    std::vector<std::uint8_t> g(1 + rng() % 64);
    for (auto& c : g) c = static_cast<std::uint8_t>(rng());
    d.send(zmq::buffer(g), zmq::send_flags::dontwait);
  }
  // Still serving: a real client works afterwards.
  check_one_exact_round(ctx, *w.value(), s);
}

TEST_CASE("an oversized frame is cut off by ZMQ_MAXMSGSIZE before it is buffered") {
  zmq::context_t ctx;
  const std::string t = tag();
  WorkerConfig wc;
  wc.limits.max_chunk_bytes = 1024;
  auto w = LocalWorkers::start(
      ctx, 1, reference_backend_factory(), [&](int) { return std::string("tcp://127.0.0.1:*"); }, wc);
  REQUIRE(w.ok());
  zmq::socket_t d(ctx, zmq::socket_type::dealer);
  d.set(zmq::sockopt::linger, 0);
  d.set(zmq::sockopt::rcvtimeo, 300);
  d.connect(w.value()->endpoints()[0]);
  std::vector<std::uint8_t> big(1 << 20, 0);
  d.send(zmq::buffer(big), zmq::send_flags::none);
  zmq::message_t m;
  CHECK_FALSE(d.recv(m));  // dropped with the connection: no reply, no crash
  // The worker still answers a fresh connection.
  zmq::socket_t d2(ctx, zmq::socket_type::dealer);
  d2.set(zmq::sockopt::linger, 0);
  d2.set(zmq::sockopt::rcvtimeo, 2000);
  d2.connect(w.value()->endpoints()[0]);
  d2.send(zmq::buffer(encode(HeartbeatMsg{5})), zmq::send_flags::none);
  REQUIRE(d2.recv(m));
  auto r = decode({static_cast<const std::uint8_t*>(m.data()), m.size()}, DefaultLimits());
  REQUIRE(r.ok());
  CHECK(std::get<HelloMsg>(r.value()).echo == 5);
}

TEST_CASE(
    "wait_ready over tcp with a long heartbeat period: the first Heartbeat, dropped before the connection is up, is "
    "sent again") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(6, 24);
  auto wr = LocalWorkers::start(ctx, 2, reference_backend_factory(), [](int) { return std::string("tcp://127.0.0.1:*"); });
  REQUIRE(wr.ok());
  ScatterConfig cfg;
  cfg.endpoints = wr.value()->endpoints();
  cfg.heartbeat_period = 1h;
  auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, s.blocks);
  REQUIRE(c.ok());
  CHECK(c.value()->wait_ready(Clock::now() + 5s));  // before: not until the second Heartbeat, an hour on
  for (const WorkerStatus& w : c.value()->workers()) CHECK(w.up);
}

TEST_CASE("a worker restarted before it is marked down (new epoch) is reloaded; the others are left alone") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(8, 24);
  const auto poses = test::contact_poses(s, 4);
  auto wr = LocalWorkers::start(ctx, 3, reference_backend_factory(), [](int) { return std::string("tcp://127.0.0.1:*"); });
  REQUIRE(wr.ok());
  LocalWorkers& w = *wr.value();
  auto c = client(ctx, w, s, 1u << 30);  // never marked down: only the epoch tells
  REQUIRE(c->wait_ready(Clock::now() + 10s));
  const std::uint64_t epoch0 = c->workers()[1].epoch;
  std::uint64_t seq = 0;
  REQUIRE(c->round(++seq, poses[0], Clock::now() + 1s).complete);
  REQUIRE(w.restart(1).ok());
  bool reloaded = false;
  const auto give_up = Clock::now() + 20s;  // rounds that skip the reconnecting worker are fast: bound by time
  for (int k = 0; Clock::now() < give_up && !reloaded; ++k) {
    const auto& pose = poses[k % poses.size()];
    RoundResult r = c->round(++seq, pose, Clock::now() + 50ms);
    if (r.complete) CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
    const auto ws = c->workers();
    reloaded = r.complete && ws[1].epoch != epoch0 && ws[1].holds_target;
  }
  REQUIRE(reloaded);
  const auto ws = c->workers();
  CHECK(ws[1].loads_sent == 2);
  CHECK(ws[0].loads_sent == 1);
  CHECK(ws[2].loads_sent == 1);
  for (const auto& x : ws) CHECK(x.up);
}

TEST_CASE("after a fault, idle reassigned sets are dropped by workers and client; a second fault reloads them") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(10, 24);
  const auto poses = test::contact_poses(s, 6);
  const std::string t = tag();
  WorkerConfig base;
  base.idle_set_ttl = 300ms;
  auto wr = LocalWorkers::start(
      ctx, 4, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, base);
  REQUIRE(wr.ok());
  LocalWorkers& w = *wr.value();
  ScatterConfig cfg;
  cfg.endpoints = w.endpoints();
  cfg.heartbeat_period = 20ms;
  cfg.held_refresh_period = 50ms;
  auto cr = ScatterGather::create(ctx, cfg, s.probe, s.object, s.blocks);
  REQUIRE_MESSAGE(cr.ok(), cr.error());
  ScatterGather& c = *cr.value();
  REQUIRE(c.wait_ready(Clock::now() + 10s));
  std::uint64_t seq = 0;
  // Rounds until `done` holds (or 20 s): every complete round is exact.
  auto rounds_until = [&](auto done) {
    const auto give_up = Clock::now() + 20s;
    for (int k = 0; Clock::now() < give_up; ++k) {
      const auto& pose = poses[std::size_t(k) % poses.size()];
      RoundResult r = c.round(++seq, pose, Clock::now() + 50ms);
      if (r.complete) CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
      if (done(r)) return true;
      std::this_thread::sleep_for(1ms);
    }
    return false;
  };
  const std::size_t originals = c.encoded_sets();
  CHECK(originals == 4);

  // Fault: worker 2 stops; the survivors load enlarged sets (2 held each), the client encodes them.
  w.stop(2);
  REQUIRE(rounds_until([&](const RoundResult& r) { return r.complete && !c.workers()[2].up; }));
  REQUIRE(rounds_until([&](const RoundResult&) {
    const auto ws = c.workers();
    return ws[0].sets_held == 2 && ws[1].sets_held == 2 && ws[3].sets_held == 2;
  }));
  CHECK(c.encoded_sets() == originals + 3);
  std::vector<std::uint32_t> loads;
  for (const WorkerStatus& x : c.workers()) loads.push_back(x.loads_sent);

  // Back: worker 2 restarts and is reloaded; 300 ms later the survivors drop their idle enlarged
  // sets, say so in their next Hello, and the client drops its copies.
  REQUIRE(w.restart(2).ok());
  REQUIRE(rounds_until([&](const RoundResult& r) {
    const auto ws = c.workers();
    return r.complete && r.workers_replied == 4 && ws[0].sets_held == 1 && ws[1].sets_held == 1 &&
           ws[3].sets_held == 1 && c.encoded_sets() == originals;
  }));

  // The same fault again: the enlarged sets are encoded and sent again, results exact again.
  w.stop(2);
  REQUIRE(rounds_until([&](const RoundResult& r) {
    const auto ws = c.workers();
    return r.complete && !ws[2].up && ws[0].holds_target && ws[1].holds_target && ws[3].holds_target;
  }));
  for (int i : {0, 1, 3}) CHECK(c.workers()[std::size_t(i)].loads_sent == loads[std::size_t(i)] + 1);
}

namespace {
/// One in-process worker (tree or reference backend) holding the set of `probe` against
/// `object` (every face one block), loaded by `d`, a DEALER that then asks it.
struct OneSetWorker {
  Result<std::unique_ptr<LocalWorkers>> w;
  zmq::socket_t d;
  std::uint64_t hash = 0;
  OneSetWorker(zmq::context_t& ctx, bool tree, const WorkerConfig& base, const geom::Mesh& probe, const geom::Mesh& object)
      : w(LocalWorkers::start(
            ctx, 1, tree ? tree_backend_factory() : reference_backend_factory(),
            [t = tag()](int i) { return inproc_endpoint(i, t); }, base)),
        d(ctx, zmq::socket_type::dealer) {
    REQUIRE(w.ok());
    Blocks one(1);
    for (std::uint32_t f = 0; f < object.faces.size(); ++f) one[0].push_back(f);
    auto set = make_block_set(probe, object, one, std::vector<std::uint32_t>{0}, 24);
    REQUIRE(set.ok());
    const std::vector<std::uint8_t> bytes = encode_block_set(set.value());
    hash = block_set_hash(bytes);
    d.set(zmq::sockopt::linger, 0);
    d.set(zmq::sockopt::rcvtimeo, 10000);
    d.connect(w.value()->endpoints()[0]);
    REQUIRE(std::holds_alternative<HelloMsg>(reply(encode(LoadBlocksMsg{hash, bytes.size(), 0, bytes}))));
  }
  Message reply(const std::vector<std::uint8_t>& msg) {
    d.send(zmq::buffer(msg), zmq::send_flags::none);
    zmq::message_t m;
    REQUIRE(d.recv(m));
    auto r = decode({static_cast<const std::uint8_t*>(m.data()), m.size()}, DefaultLimits());
    REQUIRE(r.ok());
    return r.value();
  }
};
}  // namespace

TEST_CASE("a worker that refuses the client's block set says why (WorkerStatus::refused)") {
  zmq::context_t ctx;
  WorkerConfig base;
  base.limits.max_blockset_bytes = 4096;  // the scene's set is larger
  const std::string t = tag();
  auto w = LocalWorkers::start(
      ctx, 1, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, base);
  REQUIRE(w.ok());
  const test::NetScene s = test::small_scene(8);
  ScatterConfig cfg;
  cfg.endpoints = w.value()->endpoints();
  cfg.heartbeat_period = 50ms;
  auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, s.blocks);
  REQUIRE(c.ok());
  CHECK_FALSE(c.value()->wait_ready(Clock::now() + 2s));  // refused: it never holds its target
  const std::vector<WorkerStatus> ws = c.value()->workers();
  REQUIRE(ws.size() == 1);
  CHECK_FALSE(ws[0].holds_target);
  CHECK(ws[0].refused.find("over this worker's max_blockset_bytes = 4096") != std::string::npos);
}

TEST_CASE("a block set of faces piled on each other: the worker refuses the query at max_pairs, then serves") {
  // The N² attack: every probe face overlaps every object face (1,000 identical triangles
  // on each side: 10^6 pairs). With max_pairs = 50,000 the traversal must stop near the cap and
  // the worker answer TooLarge at once, not compute and hold the million pairs first.
  zmq::context_t ctx;
  for (const bool tree : {true, false}) {
    CAPTURE(tree);
    WorkerConfig base;
    base.limits.max_pairs = 50'000;
    base.query_work_base = base.max_query_work = 1ull << 40;  // the pair cap alone (the budget: next case)
    base.penalty_factor = 0;                                  // (the penalty: next case)
    geom::Mesh pile;
    pile.name = "pile";
    pile.local = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}};
    pile.faces.assign(1000, geom::Tri{0, 1, 2});
    OneSetWorker one(ctx, tree, base, pile, pile);
    const std::uint64_t hash = one.hash;
    auto reply = [&](const std::vector<std::uint8_t>& msg) { return one.reply(msg); };
    geom::Pose shifted = geom::Pose::Identity();
    shifted.translation() = geom::Vec3(1, 1, 0);  // coplanar and overlapping: every pair collides
    Message refused = reply(encode(QueryMsg{5, hash, shifted, {}}));
    auto* e = std::get_if<ErrorMsg>(&refused);
    REQUIRE(e);
    CHECK(e->code == ErrorCode::TooLarge);
    CHECK(e->ref == 5);
    CHECK(e->text.find("max_pairs") != std::string::npos);
    // It keeps answering (how far the traversal got is checked on collide() itself, below).
    geom::Pose apart = geom::Pose::Identity();
    apart.translation() = geom::Vec3(0, 0, 50);
    Message answered = reply(encode(QueryMsg{6, hash, apart, {}}));
    auto* res = std::get_if<ResultMsg>(&answered);
    REQUIRE(res);
    CHECK(res->pairs.empty());
  }
}

namespace {
/// n copies of a triangle in the plane z = 0 (probe) and n of an upright one (object) whose boxes
/// overlap that one's but which never touch it: n² candidate pairs, no pair.
std::pair<geom::Mesh, geom::Mesh> crossing_piles(std::uint32_t n) {
  geom::Mesh flat, upright;
  flat.name = "flat pile";
  flat.local = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}};
  flat.faces.assign(n, geom::Tri{0, 1, 2});
  upright.name = "upright pile";
  // Crosses z = 0 on the segment (9, 9) → (12, 6), where x + y = 18 > 10: outside the flat one.
  upright.local = {{9, 9, -1}, {9, 9, 1}, {12, 6, 0}};
  upright.faces.assign(n, geom::Tri{0, 1, 2});
  return {flat, upright};
}
}  // namespace

TEST_CASE("faces piled so their boxes overlap but they never touch: the worker refuses the query at its work budget") {
  // The N² attack with no pair: 700 × 700 candidate tests, none colliding, so the pair cap never
  // acts. The budget (sized from the set: base + per face) stops the query and the worker says so.
  zmq::context_t ctx;
  const auto [flat, upright] = crossing_piles(700);
  for (const bool tree : {true, false}) {
    CAPTURE(tree);
    WorkerConfig base;
    base.query_work_base = 100'000;
    base.query_work_per_face = 16;  // 122,400 units for the 1,400 faces: under the 490,000 tests
    OneSetWorker one(ctx, tree, base, flat, upright);
    const std::uint64_t hash = one.hash;
    auto reply = [&](const std::vector<std::uint8_t>& msg) { return one.reply(msg); };
    Message refused = reply(encode(QueryMsg{5, hash, geom::Pose::Identity(), {}}));
    auto* e = std::get_if<ErrorMsg>(&refused);
    REQUIRE(e);
    CHECK(e->code == ErrorCode::TooLarge);
    CHECK(e->ref == 5);
    CHECK(e->text.find("work budget") != std::string::npos);
    // Its next query, sent at once, is refused unanswered (penalty_factor × the refused query's
    // compute time); once that has passed, the client is served again.
    geom::Pose apart = geom::Pose::Identity();
    apart.translation() = geom::Vec3(0, 0, 50);
    Message penalised = reply(encode(QueryMsg{6, hash, apart, {}}));
    REQUIRE(std::holds_alternative<ErrorMsg>(penalised));
    CHECK(std::get<ErrorMsg>(penalised).text.find("refused unanswered") != std::string::npos);
    Message answered = penalised;
    for (std::uint64_t seq = 7; seq < 400 && !std::holds_alternative<ResultMsg>(answered); ++seq) {
      std::this_thread::sleep_for(50ms);
      answered = reply(encode(QueryMsg{seq, hash, apart, {}}));
    }
    REQUIRE(std::holds_alternative<ResultMsg>(answered));
    CHECK(std::get<ResultMsg>(answered).pairs.empty());
  }
}

TEST_CASE("collide() stops its traversal at max_work; without a budget the same query finds the same pairs") {
  const auto [flat, upright] = crossing_piles(1500);
  const geom::SphereTree tf = geom::SphereTree::build(flat).value(), tu = geom::SphereTree::build(upright).value();
  geom::CollideScratch sc;
  geom::CollideResult r;
  geom::CollideConfig opt;
  geom::collide(flat, tf, upright, tu, geom::Pose::Identity(), opt, sc, r);
  CHECK_FALSE(r.stats.work_limit_hit);
  CHECK(r.pairs.empty());
  CHECK(r.stats.tri_pairs == 1500u * 1500u);  // every candidate tested: the cost the budget bounds
  opt.max_work = 200'000;
  geom::collide(flat, tf, upright, tu, geom::Pose::Identity(), opt, sc, r);
  CHECK(r.stats.work_limit_hit);
  // Checked once per popped sphere pair: past the budget by at most one leaf pair's tests.
  CHECK(r.stats.work() <= opt.max_work +
                              std::uint64_t{geom::kMaxLeafFaces} * geom::kMaxLeafFaces * (1 + geom::kExactTestWork) +
                              geom::kMaxChildren);
  // An honest contact under a generous budget: the same pairs as without one.
  const test::NetScene s = test::small_scene(12);
  const geom::SphereTree tp = geom::SphereTree::build(s.probe).value(), to = geom::SphereTree::build(s.object).value();
  geom::Pose touch = geom::Pose::Identity();
  touch.translation() = geom::Vec3(30, 0, 0);
  geom::CollideConfig plain;
  plain.sort_pairs = true;
  geom::collide(s.probe, tp, s.object, to, touch, plain, sc, r);
  const std::vector<FacePair> want = r.pairs;
  REQUIRE_FALSE(want.empty());
  plain.max_work = r.stats.work() + 1;
  geom::collide(s.probe, tp, s.object, to, touch, plain, sc, r);
  CHECK_FALSE(r.stats.work_limit_hit);
  CHECK(r.pairs == want);
  plain.max_work = r.stats.work() / 2;  // half of it: stopped, and said so
  geom::collide(s.probe, tp, s.object, to, touch, plain, sc, r);
  CHECK(r.stats.work_limit_hit);
}

TEST_CASE("a block set of faces piled on one spot is refused at load (tree backend), naming where") {
  geom::Mesh pile;
  pile.name = "pile";
  pile.local = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}};
  pile.faces.assign(24 * 300, geom::Tri{0, 1, 2});  // 300 leaves of 24 faces, all at one spot
  const test::NetScene s = test::small_scene(6);
  Blocks one(1);
  for (std::uint32_t f = 0; f < pile.faces.size(); ++f) one[0].push_back(f);
  std::unique_ptr<CollisionBackend> be = tree_backend_factory()();
  Status st = be->load(make_block_set(s.probe, pile, one, std::vector<std::uint32_t>{0}, 24).value());
  REQUIRE_FALSE(st.ok());
  CHECK(st.error().find("object share: more than 256 leaves of 24 faces piled around (") != std::string::npos);
  // The probe is checked the same way; a surface (the model set: 22-34 at most) passes.
  Blocks sphere_blocks(1);
  for (std::uint32_t f = 0; f < s.object.faces.size(); ++f) sphere_blocks[0].push_back(f);
  st = be->load(make_block_set(pile, s.object, sphere_blocks, std::vector<std::uint32_t>{0}, 24).value());
  REQUIRE_FALSE(st.ok());
  CHECK(st.error().find("probe: more than 256 leaves") != std::string::npos);
  CHECK(be->load(make_block_set(s.probe, s.object, sphere_blocks, std::vector<std::uint32_t>{0}, 24).value()).ok());
  CHECK(geom::crowding(geom::SphereTree::build(s.object).value(), 1000).leaves < 64);
}

TEST_CASE("collide() stops its traversal at max_pairs") {
  geom::Mesh pile;
  pile.local = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}};
  pile.faces.assign(2000, geom::Tri{0, 1, 2});
  const geom::SphereTree tree = geom::SphereTree::build(pile).value();
  geom::CollideScratch sc;
  geom::CollideResult r;
  geom::CollideConfig opt;
  opt.max_pairs = 10'000;
  geom::collide(pile, tree, pile, tree, geom::Pose::Identity(), opt, sc, r);
  CHECK(r.stats.pair_limit_hit);
  CHECK(r.pairs.size() > opt.max_pairs);
  CHECK(r.pairs.size() <= opt.max_pairs + std::size_t{geom::kMaxLeafFaces} * geom::kMaxLeafFaces);
  CHECK(r.stats.tri_pairs < 100'000);  // nowhere near the 4 million pairs of the whole pile
  opt.max_pairs = SIZE_MAX;
  geom::collide(pile, tree, pile, tree, geom::Pose::Identity(), opt, sc, r);
  CHECK_FALSE(r.stats.pair_limit_hit);
  CHECK(r.pairs.size() == 2000u * 2000u);
}

TEST_CASE("workers bound to tcp://localhost and tcp://[::1] serve a client (docs/user-guide/fleet.md documents both)") {
  zmq::context_t ctx;
  const test::NetScene s = test::small_scene(6);
  for (const std::string host : {"localhost", "[::1]"}) {
    CAPTURE(host);
    auto w = LocalWorkers::start(ctx, 2, reference_backend_factory(), [&](int) { return "tcp://" + host + ":*"; });
    if (!w.ok()) FAIL(w.error());
    check_one_exact_round(ctx, *w.value(), s);
  }
}

namespace {
// The small scene's layer-3 blocks and one block set holding them all (what the client assist
// loads), for testing a backend on its own.
struct WholeSet {
  test::NetScene s = test::small_scene(16, 24);
  Blocks blocks;
  BlockSet set;
  WholeSet() {
    const geom::SphereTree tree = geom::SphereTree::build(s.object).value();
    auto b = tree_blocks(tree, 3, 1);
    REQUIRE(b.ok());
    blocks = std::move(b).value();
    std::vector<std::uint32_t> all(blocks.size());
    std::iota(all.begin(), all.end(), 0u);
    auto made = make_block_set(s.probe, s.object, blocks, all, 24);
    REQUIRE(made.ok());
    set = std::move(made).value();
  }
};
}  // namespace

TEST_CASE("a backend leaves out the blocks a Query skips, and only those (tree and reference backends)") {
  WholeSet whole;
  const test::NetScene& s = whole.s;
  const Blocks& blocks = whole.blocks;
  std::vector<std::uint32_t> block_of(s.object.faces.size());
  for (std::uint32_t b = 0; b < blocks.size(); ++b)
    for (std::uint32_t f : blocks[b]) block_of[f] = b;
  for (bool use_tree : {true, false}) {
    CAPTURE(use_tree);
    auto be = use_tree ? tree_backend_factory()() : reference_backend_factory()();
    REQUIRE(be->load(whole.set).ok());
    int checked = 0;
    for (const geom::Pose& pose : test::contact_poses(s, 6)) {
      std::vector<FacePair> full;
      be->query(pose, {}, full, {});
      std::sort(full.begin(), full.end());
      REQUIRE(full == reference_collide(s.probe, s.object, pose));
      // The tree backend reports the work of each block it worked in (ascending ids, each > 0,
      // every block that gave a pair among them); the reference backend does not count.
      const std::vector<WorkedBlock> worked = be->worked();
      const auto worked_in = [&worked](std::uint32_t b) {
        return std::any_of(worked.begin(), worked.end(), [b](const WorkedBlock& w) { return w.block == b; });
      };
      if (use_tree) {
        if (!full.empty()) CHECK_FALSE(worked.empty());
        for (std::size_t i = 1; i < worked.size(); ++i) CHECK(worked[i - 1].block < worked[i].block);
        for (const WorkedBlock& w : worked) CHECK(w.work > 0);
        for (const FacePair& p : full) CHECK(worked_in(block_of[p.object]));
      } else {
        CHECK(worked.empty());
      }
      // Skip every block that has pairs but one, plus a block id no set holds.
      std::vector<std::uint32_t> skip;
      for (const FacePair& p : full) skip.push_back(block_of[p.object]);
      std::sort(skip.begin(), skip.end());
      skip.erase(std::unique(skip.begin(), skip.end()), skip.end());
      if (skip.size() < 2) continue;
      skip.erase(skip.begin());
      skip.push_back(std::uint32_t(blocks.size()) + 5);
      std::vector<FacePair> part;
      const QueryStats st = be->query(pose, skip, part, {});
      std::sort(part.begin(), part.end());
      std::vector<FacePair> expect;
      for (const FacePair& p : full)
        if (!std::binary_search(skip.begin(), skip.end(), block_of[p.object])) expect.push_back(p);
      CHECK(part == expect);
      CHECK_FALSE(expect.empty());
      CHECK(st.tri_tests > 0);
      const std::vector<WorkedBlock> part_worked = be->worked();
      for (const WorkedBlock& w : part_worked)  // a skipped block costs nothing
        CHECK_FALSE(std::binary_search(skip.begin(), skip.end(), w.block));
      if (use_tree)
        for (const FacePair& p : part)
          CHECK(std::any_of(part_worked.begin(), part_worked.end(),
                            [&](const WorkedBlock& w) { return w.block == block_of[p.object]; }));
      ++checked;
    }
    CHECK(checked >= 2);  // the poses touch several blocks
  }
}

TEST_CASE("the tree backend's coherent switch: the same pairs; certificates reused only when on") {
  WholeSet whole;
  const test::NetScene& s = whole.s;
  auto coherent = tree_backend_factory(true, kDefaultMaxCrowding, true)();
  auto plain = tree_backend_factory(true, kDefaultMaxCrowding, false)();
  REQUIRE(coherent->load(whole.set).ok());
  REQUIRE(plain->load(whole.set).ok());
  int reused = 0, poses = 0;
  for (const geom::Pose& pose : test::contact_poses(s, 4)) {
    std::vector<std::uint64_t> tc, tp;
    for (int k = 0; k < 8; ++k) {  // the same pose again: nothing moved, every certificate holds
      std::vector<FacePair> a, b;
      tc.push_back(coherent->query(pose, {}, a, {}).tri_tests);
      tp.push_back(plain->query(pose, {}, b, {}).tri_tests);
      std::sort(a.begin(), a.end());
      std::sort(b.begin(), b.end());
      CHECK(a == b);
      CHECK(b == reference_collide(s.probe, s.object, pose));
    }
    if (tp[0] == 0) continue;
    ++poses;
    CHECK(tp[7] == tp[0]);  // the plain path tests the same pairs every time
    reused += tc[7] < tp[7];
  }
  REQUIRE(poses > 0);
  CHECK(reused == poses);
}

TEST_CASE("choose_assist takes the busiest worker's heaviest blocks while each move shortens the round") {
  // Worker 0 carries 8 (blocks 10: 5, 11: 3), worker 1 carries 1: the client takes block 10;
  // then worker 0 (3) is lighter than the client (5) and nothing more helps.
  const std::vector<BlockWork> w = {{10, 0, 5}, {11, 0, 3}, {20, 1, 1}};
  CHECK(choose_assist(w, 2, 8) == std::vector<std::uint32_t>{10});
  CHECK(choose_assist(w, 2, 0).empty());
  // One block alone on the busiest worker: moving it only moves the critical path.
  const std::vector<BlockWork> one = {{3, 1, 7}, {4, 0, 2}};
  CHECK(choose_assist(one, 2, 8).empty());
  // Many equal blocks on one worker: the client takes half of its load, never more.
  std::vector<BlockWork> many;
  for (std::uint32_t b = 0; b < 10; ++b) many.push_back({b, 2, 1.0});
  const auto taken = choose_assist(many, 3, 16);
  CHECK(taken.size() == 5);  // 10 -> 5 on the worker, 5 on the client; a sixth would make it 4 / 6: no shorter
  CHECK(std::is_sorted(taken.begin(), taken.end()));
  CHECK(choose_assist(many, 3, 2).size() == 2);  // capped
}

TEST_CASE("client assist: the client answers some blocks itself, every round stays exact and complete") {
  zmq::context_t ctx;
  test::NetScene s = test::small_scene(16, 24);
  const geom::SphereTree tree = geom::SphereTree::build(s.object).value();
  auto blocks = tree_blocks(tree, 3, 1);
  REQUIRE(blocks.ok());
  const std::string t = tag();
  auto w = LocalWorkers::start(ctx, 4, tree_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE_MESSAGE(w.ok(), w.error());
  ScatterConfig cfg;
  cfg.endpoints = w.value()->endpoints();
  cfg.assist_blocks = 4;
  auto c = ScatterGather::create(ctx, cfg, s.probe, s.object, blocks.value());
  REQUIRE_MESSAGE(c.ok(), c.error());
  REQUIRE(c.value()->wait_ready(Clock::now() + 10s));
  std::uint64_t seq = 0;
  std::uint32_t assisted_rounds = 0;
  for (const geom::Pose& pose : test::contact_poses(s, 8)) {
    bool was_assisted = false;
    for (int k = 0; k < 3; ++k) {  // the same pose again: the round before's pairs say where the work is
      RoundResult r = c.value()->round(++seq, pose, Clock::now() + 5s);
      CHECK(r.complete);
      CHECK(r.blocks_covered == r.blocks_total);
      CHECK(r.workers_replied == 4);
      CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
      CHECK(r.blocks_assisted <= cfg.assist_blocks);
      if (seq == 1) CHECK(r.blocks_assisted == 0);  // nothing known yet
      if (r.blocks_assisted > 0) {
        ++assisted_rounds;
        // At the pose they were picked at (a new pose may miss them), the first round the client
        // answers them tests triangles; later rounds at the same pose may answer them from the
        // coherent collider's certificates without a test.
        if (k > 0 && !was_assisted) CHECK(r.assist.tri_tests > 0);
        CHECK(r.stats.tri_tests >= r.assist.tri_tests);
      }
      was_assisted = r.blocks_assisted > 0;
    }
  }
  CHECK(assisted_rounds > 0);
  // Workers whose backend reports no work per block (the reference backend): the assist weighs
  // the pairs each block gave instead, and still takes blocks.
  {
    const std::string t2 = tag();
    auto wr = LocalWorkers::start(ctx, 4, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t2); });
    REQUIRE_MESSAGE(wr.ok(), wr.error());
    ScatterConfig rcfg = cfg;
    rcfg.endpoints = wr.value()->endpoints();
    auto rc = ScatterGather::create(ctx, rcfg, s.probe, s.object, blocks.value());
    REQUIRE_MESSAGE(rc.ok(), rc.error());
    REQUIRE(rc.value()->wait_ready(Clock::now() + 10s));
    std::uint32_t by_pairs = 0;
    for (const geom::Pose& pose : test::contact_poses(s, 4))
      for (int k = 0; k < 2; ++k) {
        RoundResult r = rc.value()->round(++seq, pose, Clock::now() + 5s);
        CHECK(r.complete);
        CHECK(r.pairs == reference_collide(s.probe, s.object, pose));
        by_pairs += r.blocks_assisted > 0;
      }
    CHECK(by_pairs > 0);
  }
  // More than the skip list may carry is refused up front.
  cfg.assist_blocks = cfg.limits.max_skip + 1;
  CHECK_FALSE(ScatterGather::create(ctx, cfg, s.probe, s.object, blocks.value()).ok());
}
