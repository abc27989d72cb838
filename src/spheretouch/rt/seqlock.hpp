// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// SeqLock<T>: one writer publishes a plain struct, any number of readers copy it without ever
/// blocking the writer (the live status in the shared-memory segment, read by `spheretouch
/// monitor` through a read-only mapping, which a TripleBuffer's single reader cannot allow).
/// After Boehm, "Can seqlocks get along with programming language memory models?" (MSPC 2012):
/// the payload is stored as relaxed atomic words, so a reader racing a write is not a data race;
/// a release fence after the odd sequence store and an acquire fence before the re-check order it.
/// The writer is wait-free (one store per word); a reader retries while a write is in progress.
/// Payloads from a few words (status) to 128 KiB (rt::ViewFrame) use it.
#pragma once
#include <spheretouch/abi.hpp>
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include <spheretouch/rt/constants.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Single-writer, multi-reader latest value. Address-free: may live in shared memory.
template <class T>
class alignas(kCacheLine) SeqLock {
  static_assert(std::is_trivially_copyable_v<T> && sizeof(T) % 8 == 0, "payload: plain data, whole 8-byte words");
  static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "words must be address-free for shared memory");
  static constexpr std::size_t kWords = sizeof(T) / 8;

 public:
  /// Payloads up to this size are read through a stack copy (out untouched on failure).
  static constexpr std::size_t kStackBytes = 1024;

  /// Writer only: publishes v. Wait-free, no allocation, no system call.
  void store(const T& v) noexcept { store(v, sizeof(T)); }
  /// Writer only: publishes v's first `bytes` bytes (rounded up to whole words, at most
  /// sizeof(T)); readers see the remaining words as earlier stores left them. For a large
  /// payload of which only a prefix is in use (a view frame's face lists), so that a store costs
  /// what it carries.
  void store(const T& v, std::size_t bytes) noexcept {
    const std::size_t n = std::min(kWords, (bytes + 7) / 8);
    const auto* src = reinterpret_cast<const unsigned char*>(&v);
    const std::uint64_t s = seq_.load(std::memory_order_relaxed);
    seq_.store(s + 1, std::memory_order_relaxed);  // odd: write in progress
    std::atomic_thread_fence(std::memory_order_release);
    for (std::size_t i = 0; i < n; ++i) {
      std::uint64_t w;
      std::memcpy(&w, src + 8 * i, 8);
      words_[i].store(w, std::memory_order_relaxed);
    }
    seq_.store(s + 2, std::memory_order_release);
  }
  /// Any reader: copies a consistent value into out; false if none was published yet or a
  /// writer kept it busy for `max_tries` attempts. A payload over kStackBytes is copied into
  /// `out` in place (no large stack buffer): after a false return from a busy writer, `out`
  /// then holds unspecified bytes (copy into a scratch value and keep the last good one).
  bool load(T& out, int max_tries = 1000) const noexcept {
    for (int t = 0; t < max_tries; ++t) {
      const std::uint64_t s1 = seq_.load(std::memory_order_acquire);
      if (s1 == 0) return false;  // never written: stable (a write makes it odd first)
      if (s1 & 1) continue;
      if constexpr (sizeof(T) <= kStackBytes) {
        std::uint64_t w[kWords];
        for (std::size_t i = 0; i < kWords; ++i) w[i] = words_[i].load(std::memory_order_relaxed);
        std::atomic_thread_fence(std::memory_order_acquire);
        if (seq_.load(std::memory_order_relaxed) != s1) continue;
        std::memcpy(&out, w, sizeof(T));
      } else {
        auto* dst = reinterpret_cast<unsigned char*>(&out);
        for (std::size_t i = 0; i < kWords; ++i) {
          const std::uint64_t w = words_[i].load(std::memory_order_relaxed);
          std::memcpy(dst + 8 * i, &w, 8);
        }
        std::atomic_thread_fence(std::memory_order_acquire);
        if (seq_.load(std::memory_order_relaxed) != s1) continue;
      }
      return true;
    }
    return false;
  }
  /// Number of completed stores (any thread; a hint).
  std::uint64_t version() const noexcept { return seq_.load(std::memory_order_relaxed) / 2; }

 private:
  std::atomic<std::uint64_t> seq_{0};  ///< even: stable, odd: write in progress
  std::atomic<std::uint64_t> words_[kWords] = {};
};

}  // namespace st::rt
