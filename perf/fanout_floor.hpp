// SPDX-License-Identifier: BSD-3-Clause
// The raw ZeroMQ fan-out and gather, with nothing of ours in it: N ROUTER echo threads and N
// DEALERs in the caller. What a scatter-gather round over N workers costs on this machine before
// any of our code (spheretouch-bench scatter's floor; spheretouch-bench scale's gather term).
#pragma once
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <unistd.h>
#include <vector>
#include <zmq.hpp>

#include <spheretouch/net/local_workers.hpp>

namespace st::bench {

inline std::string endpoint_for(const std::string& transport, int i, const std::string& tag = "bench") {
  if (transport == "inproc") return net::inproc_endpoint(i, tag);
  if (transport == "ipc")
    return "ipc:///tmp/spheretouch-" + tag + "-" + std::to_string(::getpid()) + "-" + std::to_string(i) + ".sock";
  return "tcp://127.0.0.1:*";
}

/// Answers every request waiting on ROUTER `s` with `reply` (its first 8 bytes: the request's).
inline void echo_pending(zmq::socket_t& s, std::vector<std::uint8_t>& reply) {
  zmq::message_t id, body;
  while (s.recv(id, zmq::recv_flags::dontwait)) {
    if (!id.more() || !s.recv(body, zmq::recv_flags::dontwait)) break;
    std::memcpy(reply.data(), body.data(), std::min<std::size_t>({body.size(), reply.size(), 8}));
    s.send(id, zmq::send_flags::sndmore | zmq::send_flags::dontwait);
    s.send(zmq::buffer(reply), zmq::send_flags::dontwait);
  }
}

/// The gather of a raw fan-out: waits until every socket has answered round `word` (the 8 bytes
/// at `word_at` of a reply), polling only those not heard from yet, as ScatterGather does
/// (zmq_poll checks every socket's command mailbox before and after a wait: two system calls a
/// socket). An answer to an earlier round that timed out is not this round's. False at `end`.
class AwaitReplies {
 public:
  bool all(std::vector<zmq::socket_t>& socks, std::uint64_t word, std::size_t word_at,
           std::chrono::steady_clock::time_point end) {
    heard_.assign(socks.size(), 0);
    for (std::size_t got = 0; got < socks.size();) {
      items_.clear();
      which_.clear();
      for (std::size_t i = 0; i < socks.size(); ++i)
        if (!heard_[i]) items_.push_back({socks[i].handle(), 0, ZMQ_POLLIN, 0}), which_.push_back(i);
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now());
      if (left.count() <= 0 || zmq::poll(items_.data(), items_.size(), left) <= 0) return false;
      for (std::size_t k = 0; k < items_.size(); ++k) {
        const std::size_t i = which_[k];
        zmq::message_t m;
        while ((items_[k].revents & ZMQ_POLLIN) && socks[i].recv(m, zmq::recv_flags::dontwait)) {
          std::uint64_t back = 0;
          if (m.size() >= word_at + sizeof back)
            std::memcpy(&back, static_cast<const char*>(m.data()) + word_at, sizeof back);
          if (back == word && !heard_[i]) heard_[i] = 1, ++got;
        }
      }
    }
    return true;
  }

 private:
  std::vector<zmq::pollitem_t> items_;
  std::vector<std::size_t> which_;  // the socket of each item
  std::vector<std::uint8_t> heard_;
};

/// N DEALERs, one per echo endpoint: one frame to every echo, then wait for all of them.
class FanOutGather {
 public:
  FanOutGather(zmq::context_t& ctx, const std::vector<std::string>& endpoints) {
    for (const std::string& ep : endpoints) {
      zmq::socket_t dl(ctx, zmq::socket_type::dealer);
      dl.set(zmq::sockopt::linger, 0);
      dl.connect(ep);
      dealers_.push_back(std::move(dl));
    }
  }

  /// Sends `query_bytes` (at least the 8-byte round number) to every echo and waits for all the
  /// echoes of this round; false if the deadline passed first.
  bool round(std::chrono::milliseconds deadline, std::size_t query_bytes = 8) {
    const std::uint64_t word = ++seq_;
    query_.assign(std::max<std::size_t>(query_bytes, sizeof word), 0);
    std::memcpy(query_.data(), &word, sizeof word);
    for (zmq::socket_t& dl : dealers_) dl.send(zmq::buffer(query_), zmq::send_flags::dontwait);
    return wait_.all(dealers_, word, 0, std::chrono::steady_clock::now() + deadline);
  }

 private:
  std::vector<zmq::socket_t> dealers_;
  AwaitReplies wait_;
  std::vector<std::uint8_t> query_;
  std::uint64_t seq_ = 0;
};

/// N ROUTER echo threads and a FanOutGather to them. Each echo answers with `reply_bytes` bytes
/// (at least the 8-byte round number), so the gather can carry what a worker's Result would.
class FanOutFloor {
 public:
  FanOutFloor(zmq::context_t& ctx, const std::string& transport, int n, std::size_t reply_bytes = 8)
      : reply_bytes_(std::max<std::size_t>(reply_bytes, 8)) {
    static std::atomic<int> instances{0};  // inproc names are per context: each floor its own
    const std::string tag = "bench-floor-" + std::to_string(instances++);
    std::vector<std::string> bound;
    for (int i = 0; i < n; ++i) {
      zmq::socket_t s(ctx, zmq::socket_type::router);
      s.set(zmq::sockopt::linger, 0);
      s.bind(endpoint_for(transport, i, tag));
      bound.push_back(s.get(zmq::sockopt::last_endpoint));
      echoes_.emplace_back([this, s = std::move(s)]() mutable { echo(s); });
    }
    gather_ = std::make_unique<FanOutGather>(ctx, bound);
  }
  ~FanOutFloor() {
    stop_ = true;
    for (std::thread& t : echoes_) t.join();
  }
  FanOutFloor(const FanOutFloor&) = delete;
  FanOutFloor& operator=(const FanOutFloor&) = delete;

  /// One frame of `query_bytes` (at least 8) to every echo, then wait for all of them; false if
  /// the deadline passed first.
  bool round(std::chrono::milliseconds deadline, std::size_t query_bytes = 8) {
    return gather_->round(deadline, query_bytes);
  }

 private:
  void echo(zmq::socket_t& s) {
    std::vector<std::uint8_t> reply(reply_bytes_, 0);
    while (!stop_) {
      zmq::pollitem_t it{s.handle(), 0, ZMQ_POLLIN, 0};
      if (zmq::poll(&it, 1, std::chrono::milliseconds(20)) > 0) echo_pending(s, reply);
    }
  }

  std::size_t reply_bytes_;
  std::vector<std::thread> echoes_;
  std::unique_ptr<FanOutGather> gather_;
  std::atomic<bool> stop_{false};
};

}  // namespace st::bench
