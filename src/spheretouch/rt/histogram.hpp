// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// LatencyHistogram: fixed-size log-linear histogram of nanosecond values (HdrHistogram's bucket
/// scheme, cut down): 64 bins per octave, so any reported percentile is within 1.6 % of the
/// true value; exact count, min, max and sum. record() is O(1), allocation-free, noexcept: it is
/// what the haptic tick uses. Not thread-safe: one writer; read after the writer has stopped.
#pragma once
#include <spheretouch/abi.hpp>
#include <array>
#include <bit>
#include <cstdint>

#include <spheretouch/rt/constants.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Histogram of non-negative nanosecond values (negative values count as 0).
class LatencyHistogram {
 public:
  static constexpr int kSub = 1 << kHistSubBits;                                             ///< bins per octave
  static constexpr std::size_t kBins = 2 * kSub + (kHistOctaves - kHistSubBits - 1) * kSub;  ///< total bins

  /// Adds one value.
  void record(std::int64_t ns) noexcept {
    const std::uint64_t v = ns < 0 ? 0 : static_cast<std::uint64_t>(ns);
    ++bins_[bin_of(v)];
    ++count_;
    sum_ += v;
    if (v > max_) max_ = v;
    if (v < min_) min_ = v;
  }
  /// Values recorded.
  std::uint64_t count() const noexcept { return count_; }
  /// Largest value, ns (0 when empty).
  std::int64_t max_ns() const noexcept { return static_cast<std::int64_t>(max_); }
  /// Smallest value, ns (0 when empty).
  std::int64_t min_ns() const noexcept { return count_ ? static_cast<std::int64_t>(min_) : 0; }
  /// Mean, ns (0 when empty).
  double mean_ns() const noexcept { return count_ ? static_cast<double>(sum_) / static_cast<double>(count_) : 0.0; }
  /// Value at quantile q in [0,1], ns: the upper edge of the bin holding it, capped at max_ns().
  std::int64_t percentile_ns(double q) const noexcept {
    if (count_ == 0) return 0;
    if (!(q > 0)) return min_ns();
    if (q >= 1) return max_ns();
    auto rank = static_cast<std::uint64_t>(q * static_cast<double>(count_));
    if (rank >= count_) rank = count_ - 1;
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < kBins; ++i) {
      seen += bins_[i];
      if (seen > rank) {
        const std::uint64_t hi = upper_edge(i);
        return static_cast<std::int64_t>(hi < max_ ? hi : max_);
      }
    }
    return max_ns();
  }
  /// Adds another histogram's values.
  void merge(const LatencyHistogram& o) noexcept {
    for (std::size_t i = 0; i < kBins; ++i) bins_[i] += o.bins_[i];
    count_ += o.count_;
    sum_ += o.sum_;
    if (o.max_ > max_) max_ = o.max_;
    if (o.min_ < min_) min_ = o.min_;
  }
  /// Forgets everything.
  void reset() noexcept { *this = LatencyHistogram{}; }

  /// Bin of a value (exposed for tests).
  static std::size_t bin_of(std::uint64_t v) noexcept {
    if (v < 2u * kSub) return static_cast<std::size_t>(v);
    const int msb = 63 - std::countl_zero(v);  // v in [2^msb, 2^(msb+1)), msb >= kHistSubBits+1
    const int shift = msb - kHistSubBits;      // >= 1
    std::size_t i = 2u * kSub + static_cast<std::size_t>(shift - 1) * kSub + static_cast<std::size_t>((v >> shift) - kSub);
    return i < kBins ? i : kBins - 1;
  }
  /// Largest value that falls in bin i (exposed for tests).
  static std::uint64_t upper_edge(std::size_t i) noexcept {
    if (i < 2u * kSub) return i;
    const std::size_t j = i - 2u * kSub;
    const int shift = static_cast<int>(j / kSub) + 1;
    const std::uint64_t top = kSub + j % kSub;
    return ((top + 1) << shift) - 1;
  }

 private:
  std::array<std::uint64_t, kBins> bins_{};
  std::uint64_t count_ = 0;
  std::uint64_t sum_ = 0;
  std::uint64_t max_ = 0;
  std::uint64_t min_ = UINT64_MAX;
};

}  // namespace st::rt
