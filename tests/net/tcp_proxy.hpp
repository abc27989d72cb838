// SPDX-License-Identifier: BSD-3-Clause
// TcpProxy: a loopback TCP relay placed between a client and one worker, for fault injection.
// set_forwarding(false) stops moving bytes in both directions and stops accepting: the
// connections stay open but nothing crosses them, as when the link to a host goes down
// (TCP holds what was sent; nothing is lost or reordered). set_forwarding(true) brings the link
// back and delivers what was held. Connections either end closes are closed on the other side.
#pragma once
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <thread>
#include <vector>

#include "test_util.hpp"

namespace st::test {

class TcpProxy {
 public:
  /// Listens on 127.0.0.1 (a free port) and relays every connection to 127.0.0.1:upstream_port.
  explicit TcpProxy(int upstream_port) : upstream_port_(upstream_port) {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    REQUIRE(listen_fd_ >= 0);
    sockaddr_in a = loopback(0);
    REQUIRE(::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
    REQUIRE(::listen(listen_fd_, 16) == 0);
    socklen_t len = sizeof a;
    REQUIRE(::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len) == 0);
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] { run(); });
  }
  ~TcpProxy() {
    stop_.store(true);
    thread_.join();
    for (const Link& l : links_) {
      ::close(l.client);
      ::close(l.upstream);
    }
    ::close(listen_fd_);
  }
  TcpProxy(const TcpProxy&) = delete;
  TcpProxy& operator=(const TcpProxy&) = delete;

  int port() const { return port_; }  ///< where clients connect
  /// true: relay; false: hold every byte and every new connection (the link is down). Returns
  /// once the relay thread has seen it: no byte moves after set_forwarding(false) returns.
  void set_forwarding(bool on) {
    forwarding_.store(on);
    while (!on && !paused_.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  std::uint64_t bytes_relayed() const { return bytes_.load(); }  ///< both directions, so far

 private:
  struct Link {
    int client, upstream;
  };

  static sockaddr_in loopback(int port) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    return a;
  }

  void run() {
    std::vector<pollfd> fds;
    char buf[64 * 1024];
    while (!stop_.load()) {
      if (!forwarding_.load()) {  // the link is down: touch nothing
        paused_.store(true);
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        continue;
      }
      paused_.store(false);
      fds.assign(1, pollfd{listen_fd_, POLLIN, 0});
      for (const Link& l : links_) {
        fds.push_back({l.client, POLLIN, 0});
        fds.push_back({l.upstream, POLLIN, 0});
      }
      if (::poll(fds.data(), fds.size(), 10) <= 0) continue;
      std::vector<std::size_t> dead;
      for (std::size_t i = 0; i < (fds.size() - 1) / 2; ++i) {  // the links that were polled
        for (int side = 0; side < 2; ++side) {
          const pollfd& p = fds[1 + 2 * i + std::size_t(side)];
          if (!(p.revents & (POLLIN | POLLHUP | POLLERR))) continue;
          const int to = side == 0 ? links_[i].upstream : links_[i].client;
          const ssize_t n = ::recv(p.fd, buf, sizeof buf, 0);
          if (n <= 0 || !send_all(to, buf, std::size_t(n))) {
            dead.push_back(i);
            break;
          }
          bytes_.fetch_add(std::uint64_t(n));
        }
      }
      for (auto it = dead.rbegin(); it != dead.rend(); ++it) {
        ::close(links_[*it].client);
        ::close(links_[*it].upstream);
        links_.erase(links_.begin() + std::ptrdiff_t(*it));
      }
      if (fds[0].revents & POLLIN) accept_one();  // after the loop: fds and links_ stay in step
    }
  }

  void accept_one() {
    const int c = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (c < 0) return;
    const int u = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a = loopback(upstream_port_);
    if (u < 0 || ::connect(u, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {  // upstream down: refuse
      if (u >= 0) ::close(u);
      ::close(c);
      return;
    }
    const int one = 1;
    ::setsockopt(c, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    ::setsockopt(u, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    links_.push_back({c, u});
  }

  static bool send_all(int fd, const char* p, std::size_t n) {
    while (n > 0) {
      const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) return false;
      p += w;
      n -= std::size_t(w);
    }
    return true;
  }

  int upstream_port_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::atomic<bool> forwarding_{true}, paused_{false}, stop_{false};
  std::atomic<std::uint64_t> bytes_{0};
  std::vector<Link> links_;  ///< owned by the relay thread (read by the destructor after join)
  std::thread thread_;
};

}  // namespace st::test
