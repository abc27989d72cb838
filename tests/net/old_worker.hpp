// SPDX-License-Identifier: BSD-3-Clause
// A worker of the protocol version before this one (tests only): a ROUTER on a free loopback
// port that answers every message with a Hello whose header says version 1, so a client can be
// checked for what it says about a daemon it cannot read.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include <spheretouch/net/protocol.hpp>
#include "scripted_worker.hpp"

namespace st::test {

class OldVersionWorker {
 public:
  explicit OldVersionWorker(zmq::context_t& ctx)
      : worker_(ctx, [this](const std::string& id, std::span<const std::uint8_t>) {
          std::vector<std::uint8_t> hello = net::encode(net::HelloMsg{0, 5, 0, {}});
          hello[4] = 1;  // the header's version: the one before the Query's skip list
          worker_.reply(id, hello);
        }) {}
  const std::string& endpoint() const { return worker_.endpoint(); }  ///< tcp://127.0.0.1:PORT

 private:
  ScriptedWorker worker_;
};

}  // namespace st::test
