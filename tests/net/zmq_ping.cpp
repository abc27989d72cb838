// SPDX-License-Identifier: BSD-3-Clause
// Test helper for worker_service_test (ipc uid filter): sends one Heartbeat to ENDPOINT and exits
// 0 if a reply arrives within TIMEOUT_MS, 1 if none does, 2 on bad arguments. A program of its
// own so that a test can fork, switch user and exec it (threads must not start in a forked child
// of a multi-threaded test under TSan).
#include <cstdlib>
#include <string>
#include <zmq.hpp>

#include <spheretouch/net/protocol.hpp>

int main(int argc, char** argv) {
  if (argc != 3) return 2;
  zmq::context_t ctx;
  zmq::socket_t d(ctx, zmq::socket_type::dealer);
  d.set(zmq::sockopt::linger, 0);
  d.set(zmq::sockopt::rcvtimeo, std::atoi(argv[2]));
  d.connect(argv[1]);
  d.send(zmq::buffer(st::net::encode(st::net::HeartbeatMsg{3})), zmq::send_flags::none);
  zmq::message_t m;
  return d.recv(m) ? 0 : 1;
}
