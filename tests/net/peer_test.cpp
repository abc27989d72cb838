// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/net/peer.*: the order a round's Queries go out in.
#include <doctest/doctest.h>

#include <vector>

#include <spheretouch/net/peer.hpp>

using st::net::client::Peer;

TEST_CASE("send_order: the slowest worker of the round before first, ties in endpoint order") {
  std::vector<Peer> peers(5);
  const std::uint64_t compute_ns[] = {300, 0, 9000, 300, 4500};  // 1 answered nothing (or is new)
  for (std::size_t i = 0; i < peers.size(); ++i) peers[i].compute_ns = compute_ns[i];
  std::vector<std::uint32_t> order{7, 7};  // stale contents are replaced
  st::net::client::send_order(peers, order);
  CHECK(order == std::vector<std::uint32_t>{2, 4, 0, 3, 1});
  peers.clear();
  st::net::client::send_order(peers, order);
  CHECK(order.empty());
}
