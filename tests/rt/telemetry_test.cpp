// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/spsc_queue.hpp and src/spheretouch/rt/telemetry.*: FIFO order across two threads, drops
// counted when full, the writer draining everything to a file that states the drop count.
#include <spheretouch/rt/telemetry.hpp>

#include <doctest/doctest.h>

#include <fstream>
#include <sstream>
#include <thread>
#include <unistd.h>

#include <spheretouch/rt/spsc_queue.hpp>
#include "rt_test_util.hpp"

using namespace st::rt;

TEST_CASE("SpscQueue: full and empty, then FIFO across two threads") {
  SpscQueue<std::uint64_t> q(4);
  CHECK(q.capacity() == 4);
  std::uint64_t v = 0;
  CHECK_FALSE(q.try_pop(v));
  for (std::uint64_t i = 0; i < 4; ++i) CHECK(q.try_push(i));
  CHECK_FALSE(q.try_push(99));
  CHECK(q.try_pop(v));
  CHECK(v == 0);

  SpscQueue<std::uint64_t> big(1024);
  constexpr std::uint64_t n = 2'000'000;
  std::thread producer([&] {
    for (std::uint64_t i = 1; i <= n;)
      if (big.try_push(i)) ++i;
  });
  std::uint64_t expect = 1, bad = 0;
  while (expect <= n) {
    if (big.try_pop(v)) {
      if (v != expect) ++bad;
      ++expect;
    }
  }
  producer.join();
  CHECK(bad == 0);
}

TEST_CASE("Telemetry: a full queue drops and counts; nothing is lost silently") {
  Telemetry t(8);
  TelemetrySample s;
  for (int i = 0; i < 20; ++i) {
    s.tick = static_cast<std::uint64_t>(i);
    t.push(s);
  }
  CHECK(t.stats().pushed == 8);
  CHECK(t.stats().dropped == 12);
  TelemetrySample out[32];
  CHECK(t.drain_to(out, 32) == 8);
  CHECK(out[7].tick == 7);
}

TEST_CASE("Telemetry: writer thread drains to CSV and reports the drop count") {
  const std::string path = "/tmp/spheretouch-telemetry-test-" + std::to_string(getpid()) + ".csv";
  auto t = Telemetry::open(path, 4096);
  REQUIRE_MESSAGE(t.ok(), err_of(t));
  TelemetrySample s;
  for (int i = 0; i < 3000; ++i) {
    s.tick = static_cast<std::uint64_t>(i);
    s.force_N[2] = 0.5;
    t.value()->push(s);
  }
  t.value()->close();
  const TelemetryStats st = t.value()->stats();
  CHECK(st.pushed + st.dropped == 3000);
  CHECK(st.written == st.pushed);
  std::ifstream f(path);
  std::string line, last;
  int lines = 0;
  while (std::getline(f, line)) {
    ++lines;
    last = line;
  }
  CHECK(lines == static_cast<int>(st.written) + 2);  // header + rows + summary
  CHECK(last.find("dropped " + std::to_string(st.dropped)) != std::string::npos);
  std::remove(path.c_str());
  CHECK_FALSE(Telemetry::open("/nonexistent-dir/x.csv").ok());
}
