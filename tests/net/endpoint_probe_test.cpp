// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/endpoint_probe.*: against a WorkerService with CURVE on tcp loopback (its own
// context and thread) the probe tells an admitted client, a refused key, a client without keys
// and a wrong server key apart; a plain worker and a closed port are told apart too.
#include <doctest/doctest.h>

#include <atomic>
#include <mutex>
#include <thread>

#include <spheretouch/net/curve_keys.hpp>
#include <spheretouch/net/endpoint_probe.hpp>
#include <spheretouch/net/tree_backend.hpp>
#include <spheretouch/net/worker_service.hpp>
#include "net_test_util.hpp"
#include "process_util.hpp"

using namespace st;
using namespace st::net;
using namespace std::chrono_literals;

namespace {

/// A worker on 127.0.0.1:<free port> in its own context, served by a thread until destroyed.
struct ServedWorker {
  zmq::context_t ctx;
  std::atomic<bool> stop{false};
  std::unique_ptr<WorkerService> svc;
  std::thread thread;
  std::string endpoint;

  std::mutex log_mutex;
  std::vector<std::string> log_lines;  // what the worker logged (read after halt())

  explicit ServedWorker(std::optional<CurveServer> curve) {
    WorkerConfig wc;
    wc.curve = std::move(curve);
    wc.log = [this](int, const std::string& line) {
      std::lock_guard lk(log_mutex);
      log_lines.push_back(line);
    };
    svc = test::make_worker(ctx, wc, tree_backend_factory());
    endpoint = "tcp://127.0.0.1:" + std::to_string(test::free_port());
    Status s = svc->bind(endpoint);
    REQUIRE_MESSAGE(s.ok(), s.error());
    thread = std::thread([this] { svc->run(stop, 10ms); });
  }
  /// Stops the thread (then the counters may be read).
  void halt() {
    stop = true;
    if (thread.joinable()) thread.join();
  }
  ~ServedWorker() { halt(); }
};

}  // namespace

TEST_CASE("probe_endpoint: admitted, refused, no keys, wrong server key, plain worker, nothing listening") {
  const CurveKeyPair server = generate_curve_key_pair().value(), client = generate_curve_key_pair().value(),
                     rogue = generate_curve_key_pair().value();
  zmq::context_t ctx;
  {
    ServedWorker w(CurveServer{server.secret_z85, {client.public_z85}});
    auto ok = probe_endpoint(ctx, w.endpoint, server.public_z85, client.public_z85, client.secret_z85, 5000ms);
    CHECK_MESSAGE(ok.outcome == ProbeOutcome::handshake_ok, ok.detail);
    CHECK_FALSE(ok.definitive());

    auto refused = probe_endpoint(ctx, w.endpoint, server.public_z85, rogue.public_z85, rogue.secret_z85, 5000ms);
    CHECK_MESSAGE(refused.outcome == ProbeOutcome::auth_refused, refused.detail);
    CHECK(refused.definitive());
    CHECK(refused.detail.find("ZAP status 400") != std::string::npos);

    // The worker's reset may overtake its greeting: a mismatch, or a hang-up that says why it may be.
    auto plain = probe_endpoint(ctx, w.endpoint, "", "", "", 5000ms);
    CHECK_MESSAGE((plain.outcome == ProbeOutcome::security_mismatch || plain.outcome == ProbeOutcome::handshake_failed),
                  plain.detail);
    CHECK(plain.definitive());
    CHECK(plain.detail.find("requires CURVE") != std::string::npos);

    auto wrong = probe_endpoint(ctx, w.endpoint, rogue.public_z85, client.public_z85, client.secret_z85, 5000ms);
    CHECK_MESSAGE(wrong.outcome == ProbeOutcome::handshake_failed, wrong.detail);
    CHECK(wrong.detail.find("server key") != std::string::npos);
    w.halt();
    CHECK(w.svc->counters().refused >= 1);
  }
  {
    ServedWorker w(std::nullopt);
    auto curve = probe_endpoint(ctx, w.endpoint, server.public_z85, client.public_z85, client.secret_z85, 5000ms);
    CHECK_MESSAGE((curve.outcome == ProbeOutcome::security_mismatch || curve.outcome == ProbeOutcome::handshake_failed),
                  curve.detail);
    CHECK(curve.definitive());
    CHECK(curve.detail.find("does not use CURVE") != std::string::npos);
    auto plain = probe_endpoint(ctx, w.endpoint, "", "", "", 5000ms);
    CHECK_MESSAGE(plain.outcome == ProbeOutcome::handshake_ok, plain.detail);
  }
  const std::string closed = "tcp://127.0.0.1:" + std::to_string(test::free_port());
  const auto t0 = std::chrono::steady_clock::now();
  auto none = probe_endpoint(ctx, closed, "", "", "", 5000ms);
  CHECK_MESSAGE(none.outcome == ProbeOutcome::connection_refused, none.detail);
  CHECK_FALSE(none.definitive());
  CHECK(std::chrono::steady_clock::now() - t0 < 3s);  // three refused connects say enough
}

TEST_CASE("a client rotating CURVE keys is refused every time and logged once, not once per key") {
  const CurveKeyPair server = generate_curve_key_pair().value(), client = generate_curve_key_pair().value();
  zmq::context_t ctx;
  ServedWorker w(CurveServer{server.secret_z85, {client.public_z85}});
  constexpr int kKeys = 40;
  for (int i = 0; i < kKeys; ++i) {
    const CurveKeyPair rogue = generate_curve_key_pair().value();
    auto r = probe_endpoint(ctx, w.endpoint, server.public_z85, rogue.public_z85, rogue.secret_z85, 5000ms);
    REQUIRE_MESSAGE(r.outcome == ProbeOutcome::auth_refused, r.detail);
  }
  w.halt();
  CHECK(w.svc->counters().refused >= kKeys);
  int refused_lines = 0;
  for (const std::string& l : w.log_lines) refused_lines += l.find("refused CURVE client") != std::string::npos;
  CHECK(refused_lines == 1);
}
