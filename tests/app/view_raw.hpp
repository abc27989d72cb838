// SPDX-License-Identifier: BSD-3-Clause
// Raw HTTP to the live view (no doctest: the hostile bench uses it too): a request sent as it
// is over TCP, and the WebSocket handshakes an attacker or a page would send.
#pragma once
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <string>

namespace st::test {

/// A raw TCP connection to the view sending `request` as it is; the reply's status code (0: none
/// within 5 s). With `keep`, the socket stays open (a page that then stops reading, after reading
/// for `drain_ms` more) and is returned there, its receive buffer shrunk to 4 KiB.
inline int view_raw(int port, const std::string& request, int* keep = nullptr, std::string* reply = nullptr,
                    int drain_ms = 0) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  const int small = 4096;
  ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(std::uint16_t(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  int code = 0;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
      ::send(fd, request.data(), request.size(), MSG_NOSIGNAL) == ssize_t(request.size())) {
    std::string got;
    char buf[512];
    pollfd pf{fd, POLLIN, 0};
    while (got.find("\r\n\r\n") == std::string::npos && ::poll(&pf, 1, 5000) > 0) {
      const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
      if (n <= 0) break;
      got.append(buf, std::size_t(n));
    }
    if (got.rfind("HTTP/1.1 ", 0) == 0) code = std::atoi(got.c_str() + 9);
    if (reply) *reply = got;
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(drain_ms);
    while (std::chrono::steady_clock::now() < until && ::poll(&pf, 1, 50) >= 0) {
      const ssize_t n = (pf.revents & POLLIN) ? ::recv(fd, buf, sizeof buf, 0) : 1;
      if (n <= 0) break;
      if (reply && (pf.revents & POLLIN)) reply->append(buf, std::size_t(n));
    }
  }
  if (keep)
    *keep = fd;
  else
    ::close(fd);
  return code;
}

/// A WebSocket handshake for /ws with these query, Host and Origin ("" = no such header).
inline std::string view_upgrade(const std::string& query, const std::string& host, const std::string& origin) {
  std::string r = "GET /ws" + query + " HTTP/1.1\r\n";
  if (!host.empty()) r += "Host: " + host + "\r\n";
  if (!origin.empty()) r += "Origin: " + origin + "\r\n";
  return r +
         "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
         "Sec-WebSocket-Version: 13\r\n\r\n";
}

}  // namespace st::test
