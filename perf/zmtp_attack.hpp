// SPDX-License-Identifier: BSD-3-Clause
// A raw ZMTP peer for what libzmq would not send on its own (spheretouch-bench hostile's
// ping_after_reset, and the daemon test that the worker survives it). Header-only, POSIX sockets.
#pragma once
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <iterator>
#include <random>
#include <string>
#include <vector>

namespace st::bench {

/// One connection of a raw ZMTP 3.1 peer (NULL mechanism) to 127.0.0.1:`port`: the greeting and
/// READY, then `frames` 20-byte message frames each followed by a PING command, then a reset
/// (SO_LINGER 0). What libzmq 4.3 fails on: the frames stop the worker's input at rcvhwm, the
/// reset sets its engine's I/O error, and a PING still to decode when the worker drains the queue
/// is answered with a write that asserts. False if the connection could not be made.
inline bool ping_after_reset(int port, int frames) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return false;
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  timeval tv{2, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) return false;
  auto put = [&](const std::vector<std::uint8_t>& b) {
    return ::send(fd, b.data(), b.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(b.size());
  };
  std::vector<std::uint8_t> greeting(64, 0);
  greeting[0] = 0xff, greeting[9] = 0x7f, greeting[10] = 3, greeting[11] = 1;
  std::memcpy(&greeting[12], "NULL", 4);
  if (!put(greeting)) return false;
  std::uint8_t theirs[64];
  for (std::size_t got = 0; got < sizeof theirs;) {
    const ssize_t n = ::recv(fd, theirs + got, sizeof theirs - got, 0);
    if (n <= 0) return false;
    got += std::size_t(n);
  }
  // READY with Socket-Type DEALER: a short command (flags 0x04), then its body.
  const std::string ready = std::string("\x05READY\x0bSocket-Type") + std::string("\0\0\0\x06", 4) + "DEALER";
  std::vector<std::uint8_t> burst{0x04, std::uint8_t(ready.size())};
  burst.insert(burst.end(), ready.begin(), ready.end());
  std::mt19937 rng(11);
  for (int i = 0; i < frames; ++i) {
    burst.push_back(0x00);  // a short, final message frame
    burst.push_back(20);
    for (int k = 0; k < 20; ++k) burst.push_back(std::uint8_t(rng()));
    const std::uint8_t ping[] = {0x04, 0x07, 0x04, 'P', 'I', 'N', 'G', 0x00, 0x00};  // PING, TTL 0
    burst.insert(burst.end(), std::begin(ping), std::end(ping));
  }
  (void)put(burst);  // the worker may already have cut it (bad messages): the reset follows anyway
  linger lg{1, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &lg, sizeof lg);
  return true;
}

}  // namespace st::bench
