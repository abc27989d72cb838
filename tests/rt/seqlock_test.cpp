// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/seqlock.hpp: nothing before the first store, the newest value after, and a
// two-thread hammer (one writer, two readers): no torn copy, versions never go back; the same
// for a payload large enough to be read in place (no stack copy), written in prefixes.
#include <spheretouch/rt/seqlock.hpp>

#include <doctest/doctest.h>

#include <atomic>
#include <memory>
#include <thread>

using st::rt::SeqLock;

namespace {
struct Payload {
  std::uint64_t seq = 0;
  std::uint64_t words[7] = {};  // each = seq * (i + 1): a torn copy mixes sequences
};
bool consistent(const Payload& p) {
  for (std::uint64_t i = 0; i < 7; ++i)
    if (p.words[i] != p.seq * (i + 1)) return false;
  return true;
}
}  // namespace

TEST_CASE("SeqLock: empty until the first store, then the newest value") {
  SeqLock<Payload> s;
  Payload p;
  CHECK_FALSE(s.load(p));
  CHECK(s.version() == 0);
  Payload v;
  v.seq = 7;
  s.store(v);
  v.seq = 8;
  s.store(v);
  REQUIRE(s.load(p));
  CHECK(p.seq == 8);
  CHECK(s.version() == 2);
}

namespace {
/// What two readers saw while one writer stored.
struct Hammered {
  std::uint64_t torn = 0, backwards = 0, reads = 0;
};
/// One writer calls write(i) for i = 1 .. writes while two readers each call a reader made by
/// make_reader(): reader(seq, whole) is false when there was nothing to read, else gives the
/// copy's sequence and whether it was whole.
template <class Write, class MakeReader>
Hammered hammer(std::uint64_t writes, Write write, MakeReader make_reader) {
  std::atomic<bool> done{false};
  std::atomic<std::uint64_t> torn{0}, backwards{0}, reads{0};
  auto reader = [&] {
    auto read = make_reader();
    std::uint64_t last = 0, seq = 0;
    bool whole = false;
    while (!done.load(std::memory_order_acquire)) {
      if (!read(seq, whole)) continue;
      reads.fetch_add(1, std::memory_order_relaxed);
      if (!whole) torn.fetch_add(1);
      if (seq < last) backwards.fetch_add(1);
      last = seq;
    }
  };
  std::thread r1(reader), r2(reader);
  for (std::uint64_t i = 1; i <= writes; ++i) write(i);
  done.store(true, std::memory_order_release);
  r1.join();
  r2.join();
  return {torn.load(), backwards.load(), reads.load()};
}
}  // namespace

TEST_CASE("SeqLock: one writer, two readers hammering: no torn copy, never backwards") {
  SeqLock<Payload> s;
  constexpr std::uint64_t kWrites = 2'000'000;
  Payload v;
  const Hammered h = hammer(
      kWrites,
      [&](std::uint64_t i) {
        v.seq = i;
        for (std::uint64_t k = 0; k < 7; ++k) v.words[k] = i * (k + 1);
        s.store(v);
      },
      [&] {
        return [&s, p = Payload{}](std::uint64_t& seq, bool& whole) mutable {
          if (!s.load(p)) return false;
          seq = p.seq;
          whole = consistent(p);
          return true;
        };
      });
  CHECK(h.torn == 0);
  CHECK(h.backwards == 0);
  CHECK(h.reads > 0);
  Payload last;
  REQUIRE(s.load(last));
  CHECK(last.seq == kWrites);
}

namespace {
struct BigPayload {  // over SeqLock's kStackBytes: read in place
  std::uint64_t seq = 0;
  std::uint64_t words[255] = {};  // words[i] = seq * (i + 1) for i < used, the rest from earlier stores
};
static_assert(sizeof(BigPayload) > SeqLock<BigPayload>::kStackBytes);
}  // namespace

TEST_CASE("SeqLock: a large payload stored in prefixes: no torn prefix, never backwards") {
  auto s = std::make_unique<SeqLock<BigPayload>>();
  auto v = std::make_unique<BigPayload>();
  const Hammered h = hammer(
      200'000,
      [&](std::uint64_t i) {
        v->seq = i;
        const std::uint64_t used = 1 + i % 200;
        for (std::uint64_t k = 0; k < used; ++k) v->words[k] = i * (k + 1);
        s->store(*v, 8 * (1 + used));
      },
      [&] {
        return [&s, p = std::make_unique<BigPayload>()](std::uint64_t& seq, bool& whole) {
          if (!s->load(*p)) return false;
          seq = p->seq;
          const std::uint64_t used = 1 + p->seq % 200;  // what the writer stored of this one
          whole = true;
          for (std::uint64_t i = 0; i < used && whole; ++i) whole = p->words[i] == p->seq * (i + 1);
          return true;
        };
      });
  CHECK(h.torn == 0);
  CHECK(h.backwards == 0);
  CHECK(h.reads > 0);
}
