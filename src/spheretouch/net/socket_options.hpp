// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The socket options every spheretouch ZeroMQ socket (worker and client) starts from.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <zmq.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// Sets LINGER 0, the given high-water marks and ZMQ_MAXMSGSIZE = max_message_bytes (libzmq
/// drops a peer that sends more).
inline void set_common_options(zmq::socket_t& s, int sndhwm, int rcvhwm, std::int64_t max_message_bytes) {
  s.set(zmq::sockopt::linger, 0);
  s.set(zmq::sockopt::sndhwm, sndhwm);
  s.set(zmq::sockopt::rcvhwm, rcvhwm);
  s.set(zmq::sockopt::maxmsgsize, max_message_bytes);
}

}  // namespace st::net
