// SPDX-License-Identifier: BSD-3-Clause
// A worker of the protocol version before this one (tests only): a ROUTER on a free loopback
// port that answers every message with a Hello whose header says version 1, so a client can be
// checked for what it says about a daemon it cannot read.
#pragma once
#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include <spheretouch/net/protocol.hpp>

namespace st::test {

class OldVersionWorker {
 public:
  explicit OldVersionWorker(zmq::context_t& ctx) : sock_(ctx, zmq::socket_type::router) {
    sock_.set(zmq::sockopt::linger, 0);
    sock_.bind("tcp://127.0.0.1:*");
    endpoint_ = sock_.get(zmq::sockopt::last_endpoint);
    thread_ = std::thread([this] { loop(); });
  }
  ~OldVersionWorker() {
    stop_ = true;
    thread_.join();
  }
  OldVersionWorker(const OldVersionWorker&) = delete;
  OldVersionWorker& operator=(const OldVersionWorker&) = delete;
  const std::string& endpoint() const { return endpoint_; }  ///< tcp://127.0.0.1:PORT

 private:
  void loop() {
    while (!stop_) {
      zmq::pollitem_t it{sock_.handle(), 0, ZMQ_POLLIN, 0};
      zmq::poll(&it, 1, std::chrono::milliseconds(10));
      if (!(it.revents & ZMQ_POLLIN)) continue;
      zmq::message_t id, frame;
      (void)sock_.recv(id);
      do (void)sock_.recv(frame);  // the whole multipart message
      while (frame.more());
      std::vector<std::uint8_t> hello = net::encode(net::HelloMsg{0, 5, 0, {}});
      hello[4] = 1;  // the header's version: the one before the Query's skip list
      sock_.send(id, zmq::send_flags::sndmore);
      sock_.send(zmq::buffer(hello), zmq::send_flags::none);
    }
  }
  zmq::socket_t sock_;
  std::string endpoint_;
  std::atomic<bool> stop_{false};
  std::thread thread_;  // last: starts once the members above exist
};

}  // namespace st::test
