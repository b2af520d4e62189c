// A cell of an integer grid, and an open-addressing index from cells to the
// slots of an array that holds them: the map's bricks (pipeline/map/
// surfel_map.h), the streamer's brick slots (firmware/streamer.h) and the
// operator's brick cache (net/brick_cache.h) each keep one. Linear probing on
// gridHash() (core/grid_hash.h) in a power-of-two table of at least twice the
// entries, so a probe stays short; erase() shifts back the entries that probed
// past the erased one (no tombstones, so a table that churns stays fast).
//
// The table stores slots, not keys: `key_of(slot)` gives a slot's key from the
// owner's own array. Memory: the cells, sized by the constructor.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/grid_hash.h"

namespace fovea {

struct GridKey {
  int32_t x = 0, y = 0, z = 0;
  bool operator==(const GridKey&) const = default;
};

class GridTable {
 public:
  GridTable() = default;
  // Room for max_entries keys.
  explicit GridTable(std::size_t max_entries)
      : cells_(std::bit_ceil(std::max<std::size_t>(2 * max_entries, 2)), 0) {}

  // The cell holding `key`, or the empty cell where it would go.
  template <class KeyOf>
  std::size_t probe(const GridKey& key, KeyOf&& key_of) const {
    const std::size_t mask = cells_.size() - 1;
    std::size_t i = home(key);
    while (cells_[i] != 0 && !(key_of(cells_[i] - 1) == key)) i = (i + 1) & mask;
    return i;
  }
  // The slot of `key`, or -1.
  template <class KeyOf>
  int32_t find(const GridKey& key, KeyOf&& key_of) const {
    return static_cast<int32_t>(cells_[probe(key, key_of)]) - 1;
  }
  // The slot in `cell` (probe()'s), or -1 for an empty cell.
  int32_t slotAt(std::size_t cell) const { return static_cast<int32_t>(cells_[cell]) - 1; }
  // Puts `slot` in `cell` (an empty cell probe() gave for its key).
  void place(std::size_t cell, uint32_t slot) { cells_[cell] = slot + 1; }
  // Takes `key` out (nothing when absent).
  template <class KeyOf>
  void erase(const GridKey& key, KeyOf&& key_of) {
    const std::size_t mask = cells_.size() - 1;
    std::size_t hole = probe(key, key_of);
    if (cells_[hole] == 0) return;
    cells_[hole] = 0;
    for (std::size_t j = (hole + 1) & mask; cells_[j] != 0; j = (j + 1) & mask) {
      const std::size_t h = home(key_of(cells_[j] - 1));
      // The entry at j may fill the hole when its home is not in (hole, j] (cyclically).
      const bool home_between = hole <= j ? (h > hole && h <= j) : (h > hole || h <= j);
      if (!home_between) {
        cells_[hole] = cells_[j];
        cells_[j] = 0;
        hole = j;
      }
    }
  }
  void clear() { std::fill(cells_.begin(), cells_.end(), 0u); }
  std::size_t memoryBytes() const { return cells_.capacity() * sizeof(uint32_t); }

 private:
  std::size_t home(const GridKey& k) const { return gridHash(k.x, k.y, k.z) & (cells_.size() - 1); }

  std::vector<uint32_t> cells_;  // slot + 1; 0: empty
};

}  // namespace fovea
