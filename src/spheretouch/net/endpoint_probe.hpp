// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Why a worker does not answer: connects one throw-away DEALER, with the client's security
/// settings, to a worker endpoint and watches libzmq's socket monitor for the outcome of the
/// connect and of the ZMTP/CURVE handshake (a refused client key, a security mismatch, nothing
/// listening). Start-up diagnostics only: never used while rounds run.
#pragma once
#include <spheretouch/abi.hpp>
#include <chrono>
#include <string>
#include <zmq.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// What a probe saw, most telling first.
enum class ProbeOutcome {
  handshake_ok,        ///< connected and the handshake succeeded: the worker is reachable
  auth_refused,        ///< the worker's ZAP handler refused this client's CURVE key
  security_mismatch,   ///< one side uses CURVE and the other does not
  handshake_failed,    ///< the handshake failed otherwise (such as a wrong server key)
  connection_refused,  ///< nothing accepts connections at the endpoint
  no_connection,       ///< no connection within the timeout (host down, filtered, slow)
};

/// The outcome and a sentence for the user.
struct ProbeResult {
  ProbeOutcome outcome = ProbeOutcome::no_connection;  ///< what happened
  std::string detail;  ///< in words, such as "the worker refused this client's CURVE key"
  /// True when waiting longer cannot help (a refused key, a mismatch, a failed handshake).
  bool definitive() const {
    return outcome == ProbeOutcome::auth_refused || outcome == ProbeOutcome::security_mismatch ||
           outcome == ProbeOutcome::handshake_failed;
  }
};

/// Connects to `endpoint` with CURVE when `server_public` is set (client keys `public_z85`,
/// `secret_z85`, all Z85), plain otherwise, and waits up to `timeout` for a telling event.
ProbeResult probe_endpoint(zmq::context_t& ctx, const std::string& endpoint, const std::string& server_public,
                           const std::string& public_z85, const std::string& secret_z85, std::chrono::milliseconds timeout);

}  // namespace st::net
