// GridTable (core/grid_table.h) against a brute-force reference written here
// (a linear list of the keys held): random inserts, finds and erases on a full
// and a sparse table, and keys chosen to share one home cell so that probes
// run long and wrap around the table's end, where erase() must shift back
// entries that probed past the erased one.
#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/grid_table.h"

namespace fovea {
namespace {

// The table and its slots' keys, checked after every step against `held`.
struct Rig {
  explicit Rig(std::size_t max) : table(max), keys(max), used(max, false) {}
  GridTable table;
  std::vector<GridKey> keys;
  std::vector<bool> used;
  int32_t find(const GridKey& k) const {
    return table.find(k, [this](uint32_t s) -> const GridKey& { return keys[s]; });
  }
  bool insert(const GridKey& k) {
    const std::size_t cell = table.probe(k, [this](uint32_t s) -> const GridKey& { return keys[s]; });
    if (table.slotAt(cell) >= 0) return false;
    const auto free = std::find(used.begin(), used.end(), false);
    if (free == used.end()) return false;
    const auto slot = static_cast<uint32_t>(free - used.begin());
    keys[slot] = k;
    used[slot] = true;
    table.place(cell, slot);
    return true;
  }
  void erase(const GridKey& k) {
    const int32_t slot = find(k);
    table.erase(k, [this](uint32_t s) -> const GridKey& { return keys[s]; });
    if (slot >= 0) used[static_cast<std::size_t>(slot)] = false;
  }
  // Every held key found at its slot, every other key (of `universe`) absent.
  void expectMatches(const std::vector<GridKey>& universe) const {
    for (const GridKey& k : universe) {
      const int32_t slot = find(k);
      bool held = false;
      for (std::size_t s = 0; s < keys.size(); ++s) held = held || (used[s] && keys[s] == k);
      ASSERT_EQ(slot >= 0, held) << k.x << " " << k.y << " " << k.z;
      if (held) {
        ASSERT_TRUE(used[static_cast<std::size_t>(slot)]);
        ASSERT_EQ(keys[static_cast<std::size_t>(slot)], k);
      }
    }
  }
};

// Keys whose home cell in a table of `cells` cells is `home`, found by search.
std::vector<GridKey> keysAtHome(std::size_t cells, std::size_t home, std::size_t n) {
  std::vector<GridKey> out;
  for (int32_t x = -100000; out.size() < n; ++x) {
    if ((gridHash(x, 7, -3) & (cells - 1)) == home) out.push_back({x, 7, -3});
  }
  return out;
}

TEST(GridTable, MatchesABruteForceListUnderRandomInsertsAndErases) {
  std::mt19937 rng(3);
  for (const std::size_t max : {std::size_t{1}, std::size_t{5}, std::size_t{64}}) {
    std::vector<GridKey> universe;
    for (int i = 0; i < static_cast<int>(3 * max + 4); ++i) {
      universe.push_back({static_cast<int32_t>(rng() % 9) - 4, static_cast<int32_t>(rng() % 9) - 4, i % 3});
    }
    Rig rig(max);
    for (int step = 0; step < 2000; ++step) {
      const GridKey& k = universe[rng() % universe.size()];
      if (rng() % 3 == 0) {
        rig.erase(k);
      } else {
        rig.insert(k);
      }
      rig.expectMatches(universe);
      if (testing::Test::HasFatalFailure()) return;
    }
  }
}

TEST(GridTable, KeysSharingAHomeCellProbeAcrossTheEndAndEraseShiftsThemBack) {
  const std::size_t max = 8;  // 16 cells
  for (const std::size_t home : {std::size_t{0}, std::size_t{13}, std::size_t{15}}) {
    SCOPED_TRACE(testing::Message() << "home cell " << home);
    const std::vector<GridKey> same = keysAtHome(16, home, max);
    Rig rig(max);
    for (const GridKey& k : same) ASSERT_TRUE(rig.insert(k));
    EXPECT_FALSE(rig.insert({1, 2, 3}));  // full
    rig.expectMatches(same);
    // Erasing from the front, the middle and the end of the run.
    for (const std::size_t i : {std::size_t{0}, std::size_t{4}, std::size_t{7}}) {
      rig.erase(same[i]);
      rig.expectMatches(same);
    }
    rig.erase(same[0]);  // absent: nothing happens
    rig.expectMatches(same);
    rig.table.clear();
    std::fill(rig.used.begin(), rig.used.end(), false);
    rig.expectMatches(same);
  }
}

}  // namespace
}  // namespace fovea
