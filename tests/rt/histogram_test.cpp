// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/histogram.hpp: bin edges, percentile precision, extremes.
#include <spheretouch/rt/histogram.hpp>

#include <doctest/doctest.h>

#include <memory>

using st::rt::LatencyHistogram;

TEST_CASE("LatencyHistogram: bins are contiguous and within 1.6 %") {
  std::uint64_t prev_bin = 0;
  for (std::uint64_t v = 1; v < (1u << 22); v += 1 + v / 1000) {
    const std::size_t b = LatencyHistogram::bin_of(v);
    CHECK(b >= prev_bin);
    CHECK(LatencyHistogram::upper_edge(b) >= v);
    if (b > 0) CHECK(LatencyHistogram::upper_edge(b - 1) < v);
    CHECK(static_cast<double>(LatencyHistogram::upper_edge(b) - v) <= 0.016 * static_cast<double>(v) + 1);
    prev_bin = b;
  }
  CHECK(LatencyHistogram::bin_of(UINT64_MAX) == LatencyHistogram::kBins - 1);
}

TEST_CASE("LatencyHistogram: percentiles, min, max, negative values") {
  auto h = std::make_unique<LatencyHistogram>();
  CHECK(h->percentile_ns(0.5) == 0);
  for (int i = 1; i <= 1000; ++i) h->record(i * 1000);
  h->record(-5);  // counts as 0
  CHECK(h->count() == 1001);
  CHECK(h->min_ns() == 0);
  CHECK(h->max_ns() == 1'000'000);
  CHECK(h->percentile_ns(0.5) == doctest::Approx(500'000).epsilon(0.02));
  CHECK(h->percentile_ns(0.99) == doctest::Approx(990'000).epsilon(0.02));
  CHECK(h->percentile_ns(1.0) == 1'000'000);
  CHECK(h->percentile_ns(0.999) <= 1'000'000);
  auto g = std::make_unique<LatencyHistogram>();
  g->record(5'000'000);
  h->merge(*g);
  CHECK(h->max_ns() == 5'000'000);
  h->reset();
  CHECK(h->count() == 0);
}
