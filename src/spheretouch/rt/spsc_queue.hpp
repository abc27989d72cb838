// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// SpscQueue<T>: bounded wait-free single-producer single-consumer ring, after rigtorp/SPSCQueue:
/// head and tail on their own cache lines, each side caching the other's index to cut cache-line
/// traffic, explicit acquire/release at every shared access, storage allocated once up front.
/// try_push/try_pop never block and never allocate. (moodycamel's ReaderWriterQueue would do the
/// same job; its standalone fences are opaque to ThreadSanitizer, this is TSan-clean.)
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstddef>
#include <memory>
#include <type_traits>

#include <spheretouch/rt/constants.hpp>
#include <spheretouch/geom/check.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Bounded SPSC queue of trivially copyable values.
template <class T>
class SpscQueue {
  static_assert(std::is_trivially_copyable_v<T>, "SpscQueue holds plain data");

 public:
  /// Room for `capacity` values (>= 1), allocated here.
  explicit SpscQueue(std::size_t capacity) : slots_(capacity + 1), buf_(std::make_unique<T[]>(capacity + 1)) {}
  SpscQueue(const SpscQueue&) = delete;
  SpscQueue& operator=(const SpscQueue&) = delete;

  /// Producer: appends v; false when full (the caller counts the drop).
  [[nodiscard]] bool try_push(const T& v) noexcept {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    ST_ASSERT(tail < slots_, "the producer's index stays inside the ring");
    std::size_t next = tail + 1;
    if (next == slots_) next = 0;
    if (next == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (next == head_cache_) return false;
    }
    buf_[tail] = v;
    tail_.store(next, std::memory_order_release);
    return true;
  }
  /// Consumer: takes the oldest value into out; false when empty.
  [[nodiscard]] bool try_pop(T& out) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head == tail_cache_) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head == tail_cache_) return false;
    }
    ST_ASSERT(head < slots_, "the consumer's index stays inside the ring");
    out = buf_[head];
    std::size_t next = head + 1;
    if (next == slots_) next = 0;
    head_.store(next, std::memory_order_release);
    return true;
  }
  /// Values it can hold.
  std::size_t capacity() const noexcept { return slots_ - 1; }

 private:
  const std::size_t slots_;
  std::unique_ptr<T[]> buf_;
  alignas(kCacheLine) std::atomic<std::size_t> tail_{0};  ///< producer writes
  std::size_t head_cache_ = 0;                            ///< producer's copy of head_
  alignas(kCacheLine) std::atomic<std::size_t> head_{0};  ///< consumer writes
  std::size_t tail_cache_ = 0;                            ///< consumer's copy of tail_
  char pad_[kCacheLine - sizeof(std::size_t)] = {};       ///< keep the next object off our line
};

}  // namespace st::rt
