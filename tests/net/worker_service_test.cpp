// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/worker_service.* as clients see it over inproc://: clients kept apart (uploads,
// visible sets), loads built off the socket thread (heartbeats answered during a build), and the
// bounds on buffered upload bytes, concurrent uploads and abandoned uploads.
#include <doctest/doctest.h>

#include <atomic>
#include <condition_variable>
#include <filesystem>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <mutex>
#include <thread>

#include <spheretouch/net/curve_keys.hpp>
#include <spheretouch/net/local_workers.hpp>
#include <spheretouch/net/reference_backend.hpp>
#include "net_test_util.hpp"

using namespace st;
using namespace st::net;
using namespace std::chrono_literals;

namespace {

std::string ws_tag() {
  static int n = 0;
  return "ws" + std::to_string(++n);
}

/// A raw client: a DEALER with a chosen routing id.
struct RawClient {
  zmq::socket_t d;
  RawClient(zmq::context_t& ctx, const std::string& endpoint, const std::string& id)
      : d(ctx, zmq::socket_type::dealer) {
    d.set(zmq::sockopt::linger, 0);
    d.set(zmq::sockopt::rcvtimeo, 10000);
    d.set(zmq::sockopt::routing_id, zmq::buffer(id));
    d.connect(endpoint);
  }
  void send(const std::vector<std::uint8_t>& bytes) { d.send(zmq::buffer(bytes), zmq::send_flags::none); }
  Message recv() {
    zmq::message_t m;
    REQUIRE(d.recv(m));
    auto r = decode({static_cast<const std::uint8_t*>(m.data()), m.size()}, DefaultLimits());
    REQUIRE(r.ok());
    return r.value();
  }
  Message ask(const std::vector<std::uint8_t>& bytes) {
    send(bytes);
    return recv();
  }
  /// Waits until the worker has handled everything this client sent (a Heartbeat round trip:
  /// one connection's messages are handled in order, different connections' in any order).
  void sync() {
    const Message m = ask(encode(HeartbeatMsg{0x5e5e}));
    REQUIRE(std::holds_alternative<HelloMsg>(m));
  }
  /// Sends `bytes` as LoadBlocks chunks of `chunk` bytes, from `from` up to `to` (byte offsets).
  void upload(const std::vector<std::uint8_t>& bytes, std::uint64_t hash, std::size_t chunk, std::size_t from = 0,
              std::size_t to = SIZE_MAX) {
    for (std::size_t off = from; off < std::min(to, bytes.size()); off += chunk) {
      const std::size_t n = std::min(chunk, bytes.size() - off);
      send(encode(LoadBlocksMsg{hash, bytes.size(), off, {bytes.begin() + off, bytes.begin() + off + n}}));
    }
  }
};

ErrorMsg error_of(const Message& m) {
  const auto* e = std::get_if<ErrorMsg>(&m);
  REQUIRE_MESSAGE(e, "expected an Error, got ", type_name(m));
  return *e;
}

HelloMsg hello_of(const Message& m) {
  const auto* h = std::get_if<HelloMsg>(&m);
  REQUIRE_MESSAGE(h, "expected a Hello, got ", type_name(m));
  return *h;
}

bool holds(const HelloMsg& h, std::uint64_t hash) {
  return std::any_of(h.held.begin(), h.held.end(), [&](const Held& x) { return x.hash == hash; });
}

/// The encoded block set of a small scene (every block), and its hash.
struct Encoded {
  std::vector<std::uint8_t> bytes;
  std::uint64_t hash = 0;
};
Encoded encoded_scene(int freq) {
  const test::NetScene s = test::small_scene(freq);
  std::vector<std::uint32_t> all(s.blocks.size());
  for (std::uint32_t b = 0; b < all.size(); ++b) all[b] = b;
  auto set = make_block_set(s.probe, s.object, s.blocks, all, 24);
  REQUIRE(set.ok());
  Encoded e;
  e.bytes = encode_block_set(set.value());
  e.hash = block_set_hash(e.bytes);
  return e;
}

/// A backend whose load() waits until the test opens the gate: a build that takes as long as the
/// test wants, without timing anything.
struct Gate {
  std::mutex m;
  std::condition_variable cv;
  bool open = false;
  int loads_started = 0;
  void release() {
    std::lock_guard lk(m);
    open = true;
    cv.notify_all();
  }
};
class GatedBackend final : public CollisionBackend {
 public:
  explicit GatedBackend(std::shared_ptr<Gate> g) : gate_(std::move(g)), inner_(reference_backend_factory()()) {}
  Status load(const BlockSet& set) override {
    std::unique_lock lk(gate_->m);
    ++gate_->loads_started;
    gate_->cv.notify_all();
    gate_->cv.wait(lk, [&] { return gate_->open; });
    return inner_->load(set);
  }
  QueryStats query(const geom::Pose& pose, std::span<const std::uint32_t> skip, std::vector<FacePair>& out,
                   const QueryBudget& budget) override {
    return inner_->query(pose, skip, out, budget);
  }
  QueryStats query_only(const geom::Pose& pose, std::span<const std::uint32_t> only, std::vector<FacePair>& out,
                        const QueryBudget& budget) override {
    return inner_->query_only(pose, only, out, budget);
  }

 private:
  std::shared_ptr<Gate> gate_;
  std::unique_ptr<CollisionBackend> inner_;
};

}  // namespace

TEST_CASE("BLAKE2b-256 keys block sets: the published test vector for \"abc\"") {
  const std::string abc = "abc";
  const std::span<const std::uint8_t> b(reinterpret_cast<const std::uint8_t*>(abc.data()), abc.size());
  const Digest d = block_set_digest(b);
  const std::uint8_t want[8] = {0xbd, 0xdd, 0x81, 0x3c, 0x63, 0x42, 0x39, 0x72};  // bddd813c63423972…
  for (int i = 0; i < 8; ++i) CHECK(d[static_cast<std::size_t>(i)] == want[i]);
  CHECK(d[31] == 0x19);
  CHECK(block_set_hash(b) == 0x723942633c81ddbdull);
}

TEST_CASE("two clients: each sees and queries only the sets it sent; neither can abort the other's upload") {
  zmq::context_t ctx;
  const std::string t = ws_tag();
  auto w = LocalWorkers::start(ctx, 1, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE(w.ok());
  const std::string ep = w.value()->endpoints()[0];
  RawClient a(ctx, ep, "client-a"), b(ctx, ep, "client-b");
  const Encoded set = encoded_scene(6);
  const std::size_t chunk = set.bytes.size() / 3 + 1;
  REQUIRE(set.bytes.size() > chunk);

  // a sends the first part of its set.
  a.upload(set.bytes, set.hash, chunk, 0, chunk);
  // b sends a chunk of the same set out of order, and then starts (and drops) its own upload of it:
  // both concern b's upload only.
  CHECK(error_of(b.ask(encode(LoadBlocksMsg{set.hash, set.bytes.size(), chunk, {1, 2, 3}}))).code == ErrorCode::LoadFailed);
  b.upload(set.bytes, set.hash, chunk, 0, chunk);
  CHECK(error_of(b.ask(encode(LoadBlocksMsg{set.hash, set.bytes.size(), 7, {1}}))).code == ErrorCode::LoadFailed);
  // a's upload completes.
  a.upload(set.bytes, set.hash, chunk, chunk);
  const HelloMsg ha = hello_of(a.recv());
  CHECK(holds(ha, set.hash));

  // b is shown nothing and may not query a's set.
  const HelloMsg hb = hello_of(b.ask(encode(HeartbeatMsg{42})));
  CHECK(hb.echo == 42);
  CHECK(hb.held.empty());
  const ErrorMsg e = error_of(b.ask(encode(QueryMsg{9, set.hash, geom::Pose::Identity(), {}})));
  CHECK(e.code == ErrorCode::NotLoaded);
  CHECK(e.ref == 9);
  CHECK(hello_of(b.recv()).held.empty());  // the Hello after NotLoaded: still nothing of a's

  // a queries its set.
  const Message r = a.ask(encode(QueryMsg{10, set.hash, geom::Pose::Identity(), {}}));
  REQUIRE(std::holds_alternative<ResultMsg>(r));
  CHECK(std::get<ResultMsg>(r).seq == 10);

  CHECK(std::get<ResultMsg>(r).object == 0);  // the set's object, echoed
  // A Query naming another scene object than the set's is refused: its pairs would be read as
  // another object's faces.
  QueryMsg other{12, set.hash, geom::Pose::Identity(), {}};
  other.object = 1;
  const ErrorMsg eo = error_of(a.ask(encode(other)));
  CHECK(eo.code == ErrorCode::BadMessage);
  CHECK(eo.ref == 12);
  CHECK(eo.text.find("Query names object 1 but block set") != std::string::npos);

  // b sends the same bytes: now it may query them too (built again for b: see the quota case).
  b.upload(set.bytes, set.hash, chunk);
  CHECK(holds(hello_of(b.recv()), set.hash));
  const Message rb = b.ask(encode(QueryMsg{11, set.hash, geom::Pose::Identity(), {}}));
  REQUIRE(std::holds_alternative<ResultMsg>(rb));
  CHECK(std::get<ResultMsg>(rb).pairs == std::get<ResultMsg>(r).pairs);
}

TEST_CASE("a worker answers heartbeats and other clients' queries while it builds a block set") {
  zmq::context_t ctx;
  const std::string t = ws_tag();
  auto gate = std::make_shared<Gate>();
  int built = 0;
  // The first set builds at once; every later one waits at the gate.
  BackendFactory factory = [gate, &built]() -> std::unique_ptr<CollisionBackend> {
    if (built++ == 0) return reference_backend_factory()();
    return std::make_unique<GatedBackend>(gate);
  };
  auto w = LocalWorkers::start(ctx, 1, factory, [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE(w.ok());
  const std::string ep = w.value()->endpoints()[0];
  RawClient a(ctx, ep, "client-a"), b(ctx, ep, "client-b");
  const Encoded small = encoded_scene(4), big = encoded_scene(8);
  a.upload(small.bytes, small.hash, 1 << 20);
  REQUIRE(holds(hello_of(a.recv()), small.hash));

  b.upload(big.bytes, big.hash, 1 << 20);
  {  // wait until b's set is at the gate: the build has started
    std::unique_lock lk(gate->m);
    REQUIRE(gate->cv.wait_for(lk, 10s, [&] { return gate->loads_started == 1; }));
  }
  // During the build: b's heartbeat is answered (its set not yet listed), a's queries are answered.
  const HelloMsg during = hello_of(b.ask(encode(HeartbeatMsg{7})));
  CHECK(during.echo == 7);
  CHECK_FALSE(holds(during, big.hash));
  for (std::uint64_t seq = 1; seq <= 3; ++seq) {
    const Message r = a.ask(encode(QueryMsg{seq, small.hash, geom::Pose::Identity(), {}}));
    REQUIRE(std::holds_alternative<ResultMsg>(r));
  }
  gate->release();
  const HelloMsg after = hello_of(b.recv());  // the Hello that reports the finished load
  CHECK(after.echo == 0);
  CHECK(holds(after, big.hash));
}

TEST_CASE("upload bounds: total buffered bytes, concurrent uploads, and abandoned uploads freed") {
  zmq::context_t ctx;
  const Encoded set = encoded_scene(6);
  const std::size_t chunk = 1024;
  REQUIRE(set.bytes.size() > 4 * chunk);

  SUBCASE("bytes over max_upload_bytes are refused; the first client's upload completes") {
    WorkerConfig wc;
    // The first upload's buffer grows to min(total, 1 MiB); a second one cannot fit.
    wc.max_upload_bytes = set.bytes.size() + set.bytes.size() / 2;
    const std::string t = ws_tag();
    auto w = LocalWorkers::start(
        ctx, 1, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, wc);
    REQUIRE(w.ok());
    RawClient a(ctx, w.value()->endpoints()[0], "client-a"), b(ctx, w.value()->endpoints()[0], "client-b");
    a.upload(set.bytes, set.hash, chunk, 0, chunk);
    a.sync();  // a's upload is in before b's starts
    const ErrorMsg e = error_of(
        b.ask(encode(LoadBlocksMsg{set.hash, set.bytes.size(), 0, {set.bytes.begin(), set.bytes.begin() + chunk}})));
    CHECK(e.code == ErrorCode::TooLarge);
    CHECK(e.text.find("max_upload_bytes") != std::string::npos);
    a.upload(set.bytes, set.hash, chunk, chunk);
    CHECK(holds(hello_of(a.recv()), set.hash));
  }
  SUBCASE("more than max_uploads clients uploading at once: the next is told the worker is busy") {
    WorkerConfig wc;
    wc.max_uploads = 2;
    const std::string t = ws_tag();
    auto w = LocalWorkers::start(
        ctx, 1, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, wc);
    REQUIRE(w.ok());
    const std::string ep = w.value()->endpoints()[0];
    RawClient a(ctx, ep, "client-a"), b(ctx, ep, "client-b"), c(ctx, ep, "client-c");
    a.upload(set.bytes, set.hash, chunk, 0, chunk);
    b.upload(set.bytes, set.hash, chunk, 0, chunk);
    a.sync();  // both uploads are in before c's starts
    b.sync();
    const ErrorMsg e = error_of(
        c.ask(encode(LoadBlocksMsg{set.hash, set.bytes.size(), 0, {set.bytes.begin(), set.bytes.begin() + chunk}})));
    CHECK(e.code == ErrorCode::TooLarge);
    CHECK(e.text.find("max_uploads") != std::string::npos);
    b.upload(set.bytes, set.hash, chunk, chunk);  // b finishes: a slot is free again
    CHECK(holds(hello_of(b.recv()), set.hash));
    c.upload(set.bytes, set.hash, chunk);
    CHECK(holds(hello_of(c.recv()), set.hash));
  }
  SUBCASE("an upload with no chunk for upload_timeout is dropped: its next chunk is out of order") {
    WorkerConfig wc;
    wc.upload_timeout = 100ms;
    const std::string t = ws_tag();
    auto w = LocalWorkers::start(
        ctx, 1, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, wc);
    REQUIRE(w.ok());
    RawClient a(ctx, w.value()->endpoints()[0], "client-a");
    a.upload(set.bytes, set.hash, chunk, 0, chunk);
    // The worker looks for abandoned uploads once a second; wait well past timeout + check period.
    std::this_thread::sleep_for(2500ms);
    const ErrorMsg e = error_of(a.ask(encode(
        LoadBlocksMsg{set.hash, set.bytes.size(), chunk, {set.bytes.begin() + chunk, set.bytes.begin() + 2 * chunk}})));
    CHECK(e.code == ErrorCode::LoadFailed);
    CHECK(e.text.find("out of order") != std::string::npos);
  }
}

TEST_CASE("upload slots: an upload stalled for upload_stall gives its slot to a new one; its next chunk is refused") {
  // Four identities trickling a byte every few seconds used to hold every slot: a stalled upload
  // now loses its slot when another client needs one.
  zmq::context_t ctx;
  const Encoded set = encoded_scene(6);
  const std::size_t chunk = 1024;
  WorkerConfig wc;
  wc.max_uploads = 1;
  wc.upload_stall = 100ms;
  const std::string t = ws_tag();
  auto w = LocalWorkers::start(
      ctx, 1, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, wc);
  REQUIRE(w.ok());
  const std::string ep = w.value()->endpoints()[0];
  RawClient trickler(ctx, ep, "trickler"), honest(ctx, ep, "honest");
  trickler.upload(set.bytes, set.hash, chunk, 0, chunk);
  trickler.sync();
  std::this_thread::sleep_for(400ms);  // well past upload_stall
  honest.upload(set.bytes, set.hash, chunk);
  CHECK(holds(hello_of(honest.recv()), set.hash));
  const ErrorMsg e = error_of(trickler.ask(encode(
      LoadBlocksMsg{set.hash, set.bytes.size(), chunk, {set.bytes.begin() + chunk, set.bytes.begin() + 2 * chunk}})));
  CHECK(e.code == ErrorCode::LoadFailed);
  CHECK(e.text.find("out of order") != std::string::npos);
}

TEST_CASE("a block set over the worker's max_blockset_bytes is refused as TooLarge naming the limit") {
  zmq::context_t ctx;
  WorkerConfig wc;
  wc.limits.max_blockset_bytes = 4096;
  const std::string t = ws_tag();
  auto w = LocalWorkers::start(
      ctx, 1, reference_backend_factory(), [&](int i) { return inproc_endpoint(i, t); }, wc);
  REQUIRE(w.ok());
  RawClient a(ctx, w.value()->endpoints()[0], "client-a");
  const std::vector<std::uint8_t> chunk(1024, 7);
  const ErrorMsg e = error_of(a.ask(encode(LoadBlocksMsg{0xb16, 8192, 0, chunk})));
  CHECK(e.code == ErrorCode::TooLarge);
  CHECK(e.ref == 0xb16);
  CHECK(e.text.find("block set of 8192 bytes is over this worker's max_blockset_bytes = 4096") != std::string::npos);
}

TEST_CASE("set quotas: a client's load evicts its own sets first; a set another client queries is never evicted") {
  zmq::context_t ctx;
  WorkerConfig wc;
  wc.max_sets = 2;
  wc.max_sets_per_client = 1;
  wc.active_set = 60s;        // every set queried in this test counts as in use
  std::atomic<int> built{0};  // counted on the loader thread, read here
  BackendFactory counting = [&built]() {
    ++built;
    return reference_backend_factory()();
  };
  const std::string t = ws_tag();
  auto w = LocalWorkers::start(
      ctx, 1, counting, [&](int i) { return inproc_endpoint(i, t); }, wc);
  REQUIRE(w.ok());
  const std::string ep = w.value()->endpoints()[0];
  RawClient a(ctx, ep, "client-a"), b(ctx, ep, "client-b"), c(ctx, ep, "client-c");
  const Encoded s1 = encoded_scene(4), s2 = encoded_scene(5), s3 = encoded_scene(6), s4 = encoded_scene(7);
  auto load = [](RawClient& cl, const Encoded& e) {
    cl.upload(e.bytes, e.hash, 1 << 20);
    return cl.recv();
  };
  auto query = [](RawClient& cl, const Encoded& e, std::uint64_t seq) {
    return cl.ask(encode(QueryMsg{seq, e.hash, geom::Pose::Identity(), {}}));
  };
  REQUIRE(holds(hello_of(load(a, s1)), s1.hash));
  REQUIRE(holds(hello_of(load(b, s2)), s2.hash));
  REQUIRE(std::holds_alternative<ResultMsg>(query(a, s1, 1)));
  REQUIRE(std::holds_alternative<ResultMsg>(query(b, s2, 2)));
  // a's second set: over a's quota of one, so a's own first set goes, not b's.
  const HelloMsg ha = hello_of(load(a, s3));
  CHECK(holds(ha, s3.hash));
  CHECK_FALSE(holds(ha, s1.hash));
  CHECK(std::holds_alternative<ResultMsg>(query(b, s2, 3)));
  CHECK(error_of(query(a, s1, 4)).code == ErrorCode::NotLoaded);
  (void)a.recv();  // the Hello after NotLoaded
  REQUIRE(std::holds_alternative<ResultMsg>(query(a, s3, 5)));
  // c: both slots hold sets their clients use; c's load is refused, and nothing of theirs is lost.
  const ErrorMsg full = error_of(load(c, s4));
  CHECK(full.code == ErrorCode::TooLarge);
  CHECK(full.text.find("worker full") != std::string::npos);
  CHECK(std::holds_alternative<ResultMsg>(query(a, s3, 6)));
  CHECK(std::holds_alternative<ResultMsg>(query(b, s2, 7)));
  // Another client's copy of the same bytes is built again (what others hold is not revealed by
  // a load that is quicker); the same client sending its bytes again shares its backend.
  const int before = built.load();
  REQUIRE(holds(hello_of(load(a, s2)), s2.hash));  // evicts a's s3 (a's quota)
  CHECK(built == before + 1);
  REQUIRE(holds(hello_of(load(a, s2)), s2.hash));
  CHECK(built == before + 1);
}

TEST_CASE("a build that runs out of memory is refused with its reason; the worker keeps every other set") {
  zmq::context_t ctx;
  struct Starved final : CollisionBackend {
    Status load(const BlockSet&) override { throw std::bad_alloc(); }
    QueryStats query(const geom::Pose&, std::span<const std::uint32_t>, std::vector<FacePair>&, const QueryBudget&) override {
      return {};
    }
    QueryStats query_only(const geom::Pose&, std::span<const std::uint32_t>, std::vector<FacePair>&,
                          const QueryBudget&) override {
      return {};
    }
  };
  std::atomic<int> built{0};
  BackendFactory factory = [&built]() -> std::unique_ptr<CollisionBackend> {
    if (built++ == 0) return reference_backend_factory()();
    return std::make_unique<Starved>();
  };
  const std::string t = ws_tag();
  auto w = LocalWorkers::start(ctx, 1, factory, [&](int i) { return inproc_endpoint(i, t); });
  REQUIRE(w.ok());
  const std::string ep = w.value()->endpoints()[0];
  RawClient a(ctx, ep, "client-a"), b(ctx, ep, "client-b");
  const Encoded s1 = encoded_scene(4), s2 = encoded_scene(5);
  a.upload(s1.bytes, s1.hash, 1 << 20);
  REQUIRE(holds(hello_of(a.recv()), s1.hash));
  b.upload(s2.bytes, s2.hash, 1 << 20);
  const ErrorMsg e = error_of(b.recv());
  CHECK(e.code == ErrorCode::LoadFailed);
  CHECK(e.text.find("out of memory while building the block set") != std::string::npos);
  CHECK(std::holds_alternative<ResultMsg>(a.ask(encode(QueryMsg{1, s1.hash, geom::Pose::Identity(), {}}))));
}

TEST_CASE("of a burst of Queries from one client only the newest is answered") {
  // A haptic client wants the newest pose; a backlog would only let a client queue work for the
  // worker. Driven on this thread: the three Queries are queued before the worker reads them.
  zmq::context_t ctx;
  auto svc = test::make_worker(ctx, WorkerConfig{}, reference_backend_factory());
  const std::string ep = "inproc://" + ws_tag();
  REQUIRE(svc->bind(ep).ok());
  RawClient a(ctx, ep, "client-a");
  a.d.set(zmq::sockopt::rcvtimeo, 300);
  for (std::uint64_t seq = 1; seq <= 3; ++seq) a.send(encode(QueryMsg{seq, 0x1234, geom::Pose::Identity(), {}}));
  for (int i = 0; i < 20 && svc->counters().superseded + svc->counters().errors_sent < 3; ++i) svc->poll_once(50ms);
  const ErrorMsg e = error_of(a.recv());  // the set is not held: NotLoaded, for the newest Query only
  CHECK(e.code == ErrorCode::NotLoaded);
  CHECK(e.ref == 3);
  (void)hello_of(a.recv());
  zmq::message_t more;
  CHECK_FALSE(a.d.recv(more));  // nothing for Queries 1 and 2
  CHECK(svc->counters().superseded == 2);
}

namespace {
/// A Heartbeat from another process (fork, then exec of tests/net/zmq_ping), optionally as another
/// user: 0 when a Hello came back within 1.5 s, 1 when none did, 2 when switching user failed.
int heartbeat_from_child(const std::string& endpoint, int as_uid) {
  const std::string ping = test::build_root() + "/tests/net/zmq_ping";
  REQUIRE_MESSAGE(std::filesystem::exists(ping), "helper missing: " << ping);
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (as_uid >= 0 && (::setgid(gid_t(as_uid)) != 0 || ::setuid(uid_t(as_uid)) != 0)) ::_exit(2);
    ::execl(ping.c_str(), ping.c_str(), endpoint.c_str(), "1500", static_cast<char*>(nullptr));
    ::_exit(3);
  }
  int ws = 0;
  ::waitpid(pid, &ws, 0);
  return WIFEXITED(ws) ? WEXITSTATUS(ws) : 4;
}
}  // namespace

TEST_CASE("ipc://: missing directories are made 0700, the socket 0600; other users are refused by uid") {
  test::TempDir d;
  const std::string path = d.file("run/spheretouch/w.sock");
  {
    zmq::context_t ctx;
    auto svc_made = test::make_worker(ctx, WorkerConfig{}, reference_backend_factory());
    WorkerService& svc = *svc_made;
    Status s = svc.bind("ipc://" + path);
    REQUIRE_MESSAGE(s.ok(), s.error());
    struct stat st {};
    REQUIRE(::stat(d.file("run").c_str(), &st) == 0);
    CHECK((st.st_mode & 0777) == 0700);
    REQUIRE(::stat(d.file("run/spheretouch").c_str(), &st) == 0);
    CHECK((st.st_mode & 0777) == 0700);
    REQUIRE(::stat(path.c_str(), &st) == 0);
    CHECK((st.st_mode & 0777) == 0600);
  }
  // The uid filter, on an abstract socket (no file permissions in the way): this user is answered,
  // another is not. Switching user needs root (CI runs as root); otherwise only the first half runs.
  zmq::context_t ctx;
  std::atomic<bool> stop{false};
  auto svc_made = test::make_worker(ctx, WorkerConfig{}, reference_backend_factory());
  WorkerService& svc = *svc_made;
  const std::string ep = "ipc://@spheretouch-test-" + std::to_string(::getpid());
  REQUIRE(svc.bind(ep).ok());
  std::thread t([&] { svc.run(stop, 10ms); });
  CHECK(heartbeat_from_child(ep, -1) == 0);
  if (::geteuid() == 0)
    CHECK(heartbeat_from_child(ep, 65534) == 1);
  else
    MESSAGE("not root: the other-user half of this test needs root to switch user");
  stop = true;
  t.join();
}

TEST_CASE("connections past max_connections are shut down as they are accepted; a freed slot is reused") {
  zmq::context_t ctx;
  WorkerConfig wc;
  wc.max_connections = 2;
  auto svc_made = test::make_worker(ctx, wc, reference_backend_factory());
  WorkerService& svc = *svc_made;
  REQUIRE(svc.bind("tcp://127.0.0.1:*").ok());
  const std::string ep = svc.last_endpoint();
  std::atomic<bool> stop{false};
  std::thread t([&] { svc.run(stop, 10ms); });
  auto answered = [&](RawClient& c, std::uint64_t nonce, int timeout_ms) {
    c.d.set(zmq::sockopt::rcvtimeo, timeout_ms);
    c.send(encode(HeartbeatMsg{nonce}));
    zmq::message_t m;
    return c.d.recv(m).has_value();
  };
  auto a = std::make_unique<RawClient>(ctx, ep, "conn-a");
  RawClient b(ctx, ep, "conn-b");
  CHECK(answered(*a, 1, 10000));
  CHECK(answered(b, 2, 10000));
  RawClient c(ctx, ep, "conn-c");
  CHECK_FALSE(answered(c, 3, 1500));  // the third connection is shut down (and retried by libzmq)
  a.reset();                          // a slot frees
  bool later = false;
  for (int i = 0; i < 10 && !later; ++i) later = answered(c, 4 + std::uint64_t(i), 1000);
  CHECK(later);
  stop = true;
  t.join();
  CHECK(svc.counters().connections_refused >= 1);
}

TEST_CASE("CURVE over ipc://: an admitted key is answered, a client without keys is not") {
  const CurveKeyPair server = generate_curve_key_pair().value(), client = generate_curve_key_pair().value();
  zmq::context_t ctx;
  WorkerConfig wc;
  wc.curve = CurveServer{server.secret_z85, {client.public_z85}};
  auto svc_made = test::make_worker(ctx, wc, reference_backend_factory());
  WorkerService& svc = *svc_made;
  const std::string ep = "ipc://@spheretouch-curve-test-" + std::to_string(::getpid());
  REQUIRE(svc.bind(ep).ok());
  std::atomic<bool> stop{false};
  std::thread t([&] { svc.run(stop, 10ms); });
  auto heartbeat = [&](bool with_keys) {
    zmq::socket_t d(ctx, zmq::socket_type::dealer);
    d.set(zmq::sockopt::linger, 0);
    d.set(zmq::sockopt::rcvtimeo, with_keys ? 10000 : 1500);
    if (with_keys) {
      d.set(zmq::sockopt::curve_serverkey, server.public_z85);
      d.set(zmq::sockopt::curve_publickey, client.public_z85);
      d.set(zmq::sockopt::curve_secretkey, client.secret_z85);
    }
    d.connect(ep);
    d.send(zmq::buffer(encode(HeartbeatMsg{8})), zmq::send_flags::none);
    zmq::message_t m;
    return d.recv(m).has_value();
  };
  CHECK(heartbeat(true));
  CHECK_FALSE(heartbeat(false));
  stop = true;
  t.join();
}
