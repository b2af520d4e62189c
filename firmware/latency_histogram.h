// A stage's latency as a histogram that its thread writes and the supervisor
// reads without a lock, and the quantile the status line reports from it.
#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>

namespace fovea::firmware {

// Latency of one stage as a histogram of 0.1 ms buckets (the last one: 200 ms
// and more), written by the stage's thread with relaxed atomics, read by the
// supervisor as the difference between two snapshots.
class LatencyHistogram {
 public:
  static constexpr std::size_t kBuckets = 2001;
  static constexpr int64_t kBucketNs = 100'000;
  void add(int64_t ns) {
    const std::size_t b = ns <= 0 ? 0 : std::min<std::size_t>(static_cast<std::size_t>(ns / kBucketNs), kBuckets - 1);
    counts_[b].store(counts_[b].load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }
  // Copies the counts into `into` (kBuckets entries).
  void snapshot(uint64_t* into) const {
    for (std::size_t i = 0; i < kBuckets; ++i) into[i] = counts_[i].load(std::memory_order_relaxed);
  }

 private:
  std::array<std::atomic<uint64_t>, kBuckets> counts_{};
};

// The nearest-rank quantile of the counts in [0, buckets), as the bucket's upper edge in ms; -1 when empty.
inline double histogramQuantileMs(const uint64_t* counts, std::size_t buckets, double q) {
  uint64_t total = 0;
  for (std::size_t i = 0; i < buckets; ++i) total += counts[i];
  if (total == 0) return -1.0;
  const auto rank = static_cast<uint64_t>(std::max(1.0, std::ceil(q * static_cast<double>(total))));
  uint64_t seen = 0;
  for (std::size_t i = 0; i < buckets; ++i) {
    seen += counts[i];
    if (seen >= rank) return static_cast<double>((i + 1) * LatencyHistogram::kBucketNs) * 1e-6;
  }
  return static_cast<double>(buckets * LatencyHistogram::kBucketNs) * 1e-6;
}

}  // namespace fovea::firmware
