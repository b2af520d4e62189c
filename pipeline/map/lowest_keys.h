// The k smallest of a stream of 32-bit keys, found without storing the keys:
// two counting passes over 16-bit halves (a radix select) give the k-th
// smallest key, and a third pass, the caller's, takes every key below it and
// the first few equal to it in index order. The map's eviction uses it so that
// its pool needs no per-surfel sort scratch (8 bytes a surfel of capacity
// before; docs/map.md, "Memory").
//
// The keys must be the same in every pass: the caller computes them from state
// it does not change between the calls.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace fovea::pipeline::map {

// Keys below `key` are among the k smallest, and so are the first `at_key`
// (in index order) of those equal to it; nothing else is.
struct KeyThreshold {
  uint32_t key = 0;
  std::size_t at_key = 0;
  bool takes(uint32_t k, std::size_t& taken_at_key) const {
    if (k < key) return true;
    if (k != key || taken_at_key == at_key) return false;
    ++taken_at_key;
    return true;
  }
};

inline constexpr std::size_t kKeyHistogramSize = std::size_t{1} << 16;

// key_at(i, key) -> bool: index i's key, false when i has none (skipped).
// `histogram` holds kKeyHistogramSize counters (the caller's, allocated once).
// k larger than the number of keys takes them all; k == 0 takes none.
template <class KeyAt>
KeyThreshold kthSmallestKey(std::size_t n, std::size_t k, KeyAt&& key_at, std::span<uint32_t> histogram) {
  if (k == 0 || histogram.size() < kKeyHistogramSize) return {};
  auto count = [&](auto&& bucket_of) {
    for (uint32_t& c : histogram.first(kKeyHistogramSize)) c = 0;
    for (std::size_t i = 0; i < n; ++i) {
      uint32_t key = 0;
      if (!key_at(i, key)) continue;
      uint32_t bucket = 0;
      if (bucket_of(key, bucket)) ++histogram[bucket];
    }
  };
  // The bucket holding the rank-th smallest (1-based); rank becomes its rank in the bucket.
  auto find = [&](std::size_t& rank, bool& found) {
    for (uint32_t b = 0; b < kKeyHistogramSize; ++b) {
      if (rank <= histogram[b]) {
        found = true;
        return b;
      }
      rank -= histogram[b];
    }
    found = false;
    return uint32_t{0};
  };
  std::size_t rank = k;
  bool found = false;
  count([](uint32_t key, uint32_t& bucket) {
    bucket = key >> 16;
    return true;
  });
  const uint32_t high = find(rank, found);
  if (!found) return {0xffffffffu, n};  // fewer keys than k: all of them
  count([high](uint32_t key, uint32_t& bucket) {
    bucket = key & 0xffffu;
    return (key >> 16) == high;
  });
  const uint32_t low = find(rank, found);
  return {(high << 16) | low, rank};
}

}  // namespace fovea::pipeline::map
