// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The socket options every spheretouch ZeroMQ socket (worker and client) starts from.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <zmq.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// Neither side turns on ZMTP heartbeats (ZMQ_HEARTBEAT_IVL): in libzmq 4.3 a connection that
/// fails (reset, hung up) while its input is stopped — its queue to the application at rcvhwm, as
/// a worker's often is (rcvhwm 4) — is left in an I/O-error state until the application drains
/// the queue, and a heartbeat PING written in that state, or a PONG to a PING still in its input,
/// fails the assertion `!_io_error` (stream_engine_base.cpp) and aborts the process. Liveness is
/// the application's own Heartbeat message (the client's revive_silent) and TCP keepalive (the
/// worker).
///
/// Sets LINGER 0, the given high-water marks and ZMQ_MAXMSGSIZE = max_message_bytes (libzmq
/// drops a peer that sends more).
inline void set_common_options(zmq::socket_t& s, int sndhwm, int rcvhwm, std::int64_t max_message_bytes) {
  s.set(zmq::sockopt::linger, 0);
  s.set(zmq::sockopt::sndhwm, sndhwm);
  s.set(zmq::sockopt::rcvhwm, rcvhwm);
  s.set(zmq::sockopt::maxmsgsize, max_message_bytes);
}

}  // namespace st::net
