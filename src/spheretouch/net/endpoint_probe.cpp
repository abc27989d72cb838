// SPDX-License-Identifier: BSD-3-Clause
// Endpoint probe (endpoint_probe.hpp).
#include <spheretouch/net/endpoint_probe.hpp>

#include <spheretouch/net/worker_config.hpp>

#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <cstring>

namespace st::inline SPHERETOUCH_ABI::net {

namespace {

std::string hex(std::uint32_t v) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%08x", v);
  return b;
}

}  // namespace

ProbeResult probe_endpoint(zmq::context_t& ctx, const std::string& endpoint, const std::string& server_public,
                           const std::string& public_z85, const std::string& secret_z85, std::chrono::milliseconds timeout) {
  const bool curve = !server_public.empty();
  static std::atomic<int> probes{0};
  const std::string monitor_ep =
      "inproc://spheretouch-probe-" + std::to_string(::getpid()) + "-" + std::to_string(probes++);
  ProbeResult res;
  res.detail = "no connection within " + std::to_string(timeout.count()) + " ms (host down, port filtered, or slow)";
  try {
    zmq::socket_t s(ctx, zmq::socket_type::dealer);
    s.set(zmq::sockopt::linger, 0);
    s.set(zmq::sockopt::reconnect_ivl, 100);
    s.set(zmq::sockopt::reconnect_ivl_max, 100);
    if (curve) {
      s.set(zmq::sockopt::curve_serverkey, server_public);
      s.set(zmq::sockopt::curve_publickey, public_z85);
      s.set(zmq::sockopt::curve_secretkey, secret_z85);
    }
    // The monitor's PAIR is bound by libzmq now and connected before the connect, so no event is missed.
    if (zmq_socket_monitor(s.handle(), monitor_ep.c_str(), ZMQ_EVENT_ALL) != 0)
      return {ProbeOutcome::no_connection, std::string("cannot monitor the probe socket: ") + zmq_strerror(zmq_errno())};
    zmq::socket_t mon(ctx, zmq::socket_type::pair);
    mon.set(zmq::sockopt::linger, 0);
    mon.connect(monitor_ep);
    if (needs_ipv6(endpoint)) s.set(zmq::sockopt::ipv6, 1);
    s.connect(zmq_endpoint(endpoint));

    int retried = 0, no_detail = 0, dropped = 0;
    bool connected = false;
    const auto until = std::chrono::steady_clock::now() + timeout;
    bool done = false;
    while (!done) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      zmq::pollitem_t item{mon.handle(), 0, ZMQ_POLLIN, 0};
      if (zmq::poll(&item, 1, left) <= 0) continue;
      // Monitor message: frame 1 = uint16 event + uint32 value (host order), frame 2 = endpoint.
      zmq::message_t head, addr;
      if (!mon.recv(head, zmq::recv_flags::none)) continue;
      if (head.more()) (void)mon.recv(addr, zmq::recv_flags::none);
      if (head.size() < 6) continue;
      std::uint16_t event = 0;
      std::uint32_t value = 0;
      std::memcpy(&event, head.data(), 2);
      std::memcpy(&value, static_cast<const char*>(head.data()) + 2, 4);
      switch (event) {
        case ZMQ_EVENT_CONNECTED:
          connected = true;
          break;
        case ZMQ_EVENT_CONNECT_RETRIED:
          // Refused connects come back as retries every reconnect interval (0.1 s): three say enough.
          if (!connected && ++retried >= 3) {
            res = {ProbeOutcome::connection_refused,
                   "connection refused: nothing is listening there (is the worker running, on this port?)"};
            done = true;
          }
          break;
        case ZMQ_EVENT_HANDSHAKE_SUCCEEDED:
          res = {ProbeOutcome::handshake_ok, curve ? "the CURVE handshake succeeded: the worker accepts this client"
                                                   : "connected: the worker accepts plain connections"};
          done = true;
          break;
        case ZMQ_EVENT_HANDSHAKE_FAILED_AUTH:
          // The worker's ZAP handler said no (RFC 27 status 400; 500 = its handler failed).
          res = {ProbeOutcome::auth_refused,
                 "the worker refused this client's CURVE key (ZAP status " + std::to_string(value) + ")"};
          done = true;
          break;
        case ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL:
          if (value == ZMQ_PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH)
            res = {ProbeOutcome::security_mismatch,
                   curve ? "security mismatch: this client uses CURVE but the worker does not use CURVE (no [curve] in "
                           "its config)"
                         : "security mismatch: the worker requires CURVE but this client has no keys"};
          else if (value == ZMQ_PROTOCOL_ERROR_ZMTP_CRYPTOGRAPHIC)
            res = {ProbeOutcome::handshake_failed,
                   "the CURVE handshake failed with a cryptographic error "
                   "(is the server key the workers' public key?)"};
          else
            res = {ProbeOutcome::handshake_failed, "the handshake failed: ZMTP protocol error " + hex(value)};
          done = true;
          break;
        case ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL:
        case ZMQ_EVENT_DISCONNECTED:
          // The worker hung up mid-handshake without a reason: a CURVE server that cannot decrypt
          // our HELLO (wrong server key) does so, and so does a worker that saw the other security
          // mechanism first (its reset can overtake its greeting, hiding the mismatch from us).
          // Several in a row are not a hiccup; a mismatch seen meanwhile wins (above).
          if (event == ZMQ_EVENT_DISCONNECTED)
            ++dropped;
          else
            ++no_detail;
          if (no_detail >= 4 || dropped >= 4) {
            res = {ProbeOutcome::handshake_failed,
                   curve ? "the worker closed the connection during the CURVE handshake: the server key is not the "
                           "workers' public key, or the worker does not use CURVE"
                         : "the worker closed the connection during the handshake: it requires CURVE (this client "
                           "has no keys), or it is not a spheretouch worker"};
            done = true;
          }
          break;
        default:
          break;
      }
    }
    if (!done && connected)
      res = {ProbeOutcome::no_connection, "connected, but the handshake did not finish within " +
                                              std::to_string(timeout.count()) + " ms (worker busy or wedged?)"};
    zmq_socket_monitor(s.handle(), nullptr, 0);
  } catch (const zmq::error_t& e) {
    return {ProbeOutcome::no_connection, std::string("cannot probe ") + endpoint + ": " + e.what()};
  }
  return res;
}

}  // namespace st::net
