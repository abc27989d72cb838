// SPDX-License-Identifier: BSD-3-Clause
// libFuzzer target: the worker's message handler as a whole (net/worker_service.hpp), fed
// sequences of messages from four clients: uploads interleaved, restarted and abandoned,
// queries for held and foreign sets, heartbeats, garbage. Input: records of
//   u8 client (low 2 bits) | u16 length (little-endian) | length bytes (one frame)
// until the input ends. Loads finish before the next record (the loader thread is waited for).
// Properties, beyond "no crash, leak, UB, hang or unbounded allocation":
//  * buffered upload bytes never exceed max_upload_bytes;
//  * distinct block sets held never exceed max_sets, and each client sees at most those;
//  * every counter only grows.
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "fuzz_check.hpp"
#include <spheretouch/net/reference_backend.hpp>
#include <spheretouch/net/worker_service.hpp>

namespace {

using namespace st::net;
using namespace std::chrono_literals;

WorkerConfig fuzz_config() {
  WorkerConfig c;
  c.max_sets = 2;
  c.max_uploads = 2;
  c.max_upload_bytes = 16u << 10;
  c.idle_set_ttl = 0ms;
  c.limits.max_chunk_bytes = 4096;
  c.limits.max_blockset_bytes = 12u << 10;
  c.limits.max_vertices = 512;
  c.limits.max_faces = 512;
  c.limits.max_blocks = 64;
  c.limits.max_pairs = 4096;
  return c;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static zmq::context_t ctx;
  const WorkerConfig cfg = fuzz_config();
  auto made = WorkerService::create(ctx, cfg, reference_backend_factory());
  if (!made) __builtin_trap();  // a valid configuration: creation cannot fail
  WorkerService& svc = *made.value();
  WorkerCounters before{};
  std::size_t pos = 0;
  for (int records = 0; pos + 3 <= size && records < 256; ++records) {
    const std::string peer = "client-" + std::to_string(data[pos] & 3);
    std::size_t len = std::size_t(data[pos + 1]) | std::size_t(data[pos + 2]) << 8;
    pos += 3;
    len = std::min(len, size - pos);
    if (len > 0) svc.handle_message(peer, std::span<const std::uint8_t>(data + pos, len));
    pos += len;
    for (int spins = 0; svc.loading() && spins < 20000; ++spins) svc.poll_once(1ms);
    ST_FUZZ_CHECK(!svc.loading(), "a load finishes");
    ST_FUZZ_CHECK(svc.upload_bytes() <= cfg.max_upload_bytes, "buffered upload bytes within max_upload_bytes");
    std::vector<std::uint64_t> distinct;
    for (const Held& h : svc.held())
      if (std::find(distinct.begin(), distinct.end(), h.hash) == distinct.end()) distinct.push_back(h.hash);
    ST_FUZZ_CHECK(distinct.size() <= cfg.max_sets, "distinct sets held within max_sets");
    const WorkerCounters& c = svc.counters();
    ST_FUZZ_CHECK(c.queries >= before.queries && c.loads >= before.loads && c.bad_messages >= before.bad_messages &&
                      c.errors_sent >= before.errors_sent && c.uploads_refused >= before.uploads_refused,
                  "counters only grow");
    before = c;
  }
  return 0;
}
