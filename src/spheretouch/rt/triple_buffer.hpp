// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// TripleBuffer<T>: wait-free single-producer single-consumer exchange of the latest value.
//
// After HadrienG2/triple-buffer: three slots, each side owns one, and one atomic byte holds the
// third ("back") slot's index plus a dirty bit. Both sides swap that byte with acq_rel: the
// writer must acquire the reader's release of the slot it gets back (the Acquire-only swap of
// early triple-buffer versions was a data race), the reader must acquire the writer's payload.
// No side ever waits or retries; the layout keeps every slot and the atomic on its own cache
// line (rigtorp/SPSCQueue style), and is address-free, so it can live in shared memory.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include <spheretouch/rt/constants.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Latest-value SPSC exchange. Exactly one writer thread and one reader thread.
/// Payloads should carry a sequence number and a monotonic timestamp so the reader knows how
/// old its data is (PoseSample, geom::ContactModel do).
template <class T>
class TripleBuffer {
  static_assert(std::is_trivially_copyable_v<T>,
                "TripleBuffer payloads are trivially copyable (copied by value, may sit in shared memory)");
  static_assert(std::atomic<std::uint8_t>::is_always_lock_free,
                "the back-buffer byte must be lock-free (and thus address-free for shared memory)");

 public:
  TripleBuffer() noexcept {
    static_assert(alignof(TripleBuffer) == kCacheLine, "slots and atomic each start a cache line");
    static_assert(sizeof(Slot) % kCacheLine == 0, "a slot fills whole cache lines");
    static_assert(sizeof(TripleBuffer) == 3 * kCacheLine + 3 * sizeof(Slot),
                  "layout: atomic, writer index, reader index, three slots, one line each at least");
  }
  TripleBuffer(const TripleBuffer&) = delete;             ///< shared state: not copyable
  TripleBuffer& operator=(const TripleBuffer&) = delete;  ///< shared state: not assignable

  /// Writer: the slot to fill before publish(); only the writer touches it.
  T& input() noexcept { return slots_[bounded(writer_.index)].value; }
  /// Writer: makes input() the newest value and takes the old back slot as the next input. Wait-free.
  void publish() noexcept {
    const std::uint8_t former =
        back_.exchange(static_cast<std::uint8_t>(bounded(writer_.index) | kDirty), std::memory_order_acq_rel);
    writer_.index = bounded(former & kIndexMask);
  }
  /// Writer: copy v into the input slot and publish it.
  void write(const T& v) noexcept {
    input() = v;
    publish();
  }

  /// Reader: true when a value newer than output() has been published (a hint; may race).
  bool has_update() const noexcept { return (back_.load(std::memory_order_relaxed) & kDirty) != 0; }
  /// Reader: takes the newest published value into output() if there is one; true when it did.
  bool update() noexcept {
    // Relaxed is enough for the check: a stale "clean" only delays us by one call, and the
    // acq_rel swap below is what orders the payload.
    if ((back_.load(std::memory_order_relaxed) & kDirty) == 0) return false;
    const std::uint8_t former = back_.exchange(bounded(reader_.index), std::memory_order_acq_rel);
    reader_.index = bounded(former & kIndexMask);
    return true;
  }
  /// Reader: the value taken by the last update() (value-initialised T before the first).
  const T& output() const noexcept { return slots_[bounded(reader_.index)].value; }
  /// Reader: update() then copy output() into out; returns update()'s answer.
  bool read(T& out) noexcept {
    const bool fresh = update();
    out = output();
    return fresh;
  }

 private:
  static constexpr std::uint8_t kIndexMask = 0x3;  ///< low two bits: slot index 0..2
  static constexpr std::uint8_t kDirty = 0x4;      ///< set by publish, cleared by update
  /// Every index read from the (possibly shared, possibly corrupted) state is mapped into 0..2
  /// before it addresses a slot: a stray byte written into a shared-memory segment can garble
  /// values but never make either side read or write outside the three slots. One compare and a
  /// conditional move.
  static std::uint8_t bounded(std::uint8_t i) noexcept { return i < 3 ? i : 0; }

  struct alignas(kCacheLine) Slot {
    T value{};
  };
  struct alignas(kCacheLine) Side {
    std::uint8_t index;  ///< slot owned by this side
  };

  alignas(kCacheLine) std::atomic<std::uint8_t> back_{1};  ///< back slot index | kDirty (shared line)
  Side writer_{0};                                         ///< writer's slot (writer's line)
  Side reader_{2};                                         ///< reader's slot (reader's line)
  Slot slots_[3];                                          ///< the payloads, one or more lines each
};

}  // namespace st::rt
