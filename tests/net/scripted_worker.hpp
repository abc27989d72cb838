// SPDX-License-Identifier: BSD-3-Clause
// A stand-in worker for tests: a ROUTER on a free loopback port whose thread hands every message
// (the client's routing id and the first frame; further frames are read and dropped) to a
// script, which answers through reply(). Between polls (every few ms) the script's `between`
// runs too (to send what no request asked for). The fakes of the client tests are such scripts.
#pragma once
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <thread>
#include <utility>
#include <zmq.hpp>

namespace st::test {

class ScriptedWorker {
 public:
  using OnMessage = std::function<void(const std::string& id, std::span<const std::uint8_t> frame)>;
  /// `on_message` and `between` run on the worker's thread; they may call reply(). What they use
  /// must outlive this object (declare it after them).
  ScriptedWorker(zmq::context_t& ctx, OnMessage on_message, std::function<void()> between = {})
      : sock_(ctx, zmq::socket_type::router), on_message_(std::move(on_message)), between_(std::move(between)) {
    sock_.set(zmq::sockopt::linger, 0);
    sock_.set(zmq::sockopt::router_handover, 1);  // as WorkerService: a reconnecting client keeps its routing id
    sock_.bind("tcp://127.0.0.1:*");
    endpoint_ = sock_.get(zmq::sockopt::last_endpoint);
    thread_ = std::thread([this] { loop(); });
  }
  ~ScriptedWorker() {
    stop_ = true;
    thread_.join();
  }
  ScriptedWorker(const ScriptedWorker&) = delete;
  ScriptedWorker& operator=(const ScriptedWorker&) = delete;
  const std::string& endpoint() const { return endpoint_; }  ///< tcp://127.0.0.1:PORT

  /// Sends `bytes` to the client `id`, as one frame (more_after: the next reply's frames follow it
  /// in the same message). From the scripts only (the worker's thread).
  void reply(const std::string& id, std::span<const std::uint8_t> bytes, bool more_after = false) {
    sock_.send(zmq::buffer(id), zmq::send_flags::sndmore);
    sock_.send(zmq::buffer(bytes.data(), bytes.size()), more_after ? zmq::send_flags::sndmore : zmq::send_flags::none);
  }

 private:
  void loop() {
    while (!stop_) {
      if (between_) between_();
      zmq::pollitem_t it{sock_.handle(), 0, ZMQ_POLLIN, 0};
      zmq::poll(&it, 1, std::chrono::milliseconds(5));
      if (!(it.revents & ZMQ_POLLIN)) continue;
      zmq::message_t id, frame, rest;
      (void)sock_.recv(id);
      (void)sock_.recv(frame);
      for (bool more = frame.more(); more; more = rest.more()) (void)sock_.recv(rest);
      on_message_(std::string(static_cast<const char*>(id.data()), id.size()),
                  {static_cast<const std::uint8_t*>(frame.data()), frame.size()});
    }
  }
  zmq::socket_t sock_;
  std::string endpoint_;
  OnMessage on_message_;
  std::function<void()> between_;
  std::atomic<bool> stop_{false};
  std::thread thread_;  // last: starts once the members above exist
};

}  // namespace st::test
