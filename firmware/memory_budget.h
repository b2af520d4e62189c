// The service's memory plan as it reports it (the memory log line, fovead serve's
// breakdown): what each pool allocated at start-up, measured as the C heap's
// growth around its allocation, so that no component needs a size method.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace fovea::firmware {

inline constexpr double kMiB = 1024.0 * 1024.0;

// Bytes the C heap has handed out (the sanitizer's allocator under a sanitizer).
std::size_t heapInUse();
// Bytes the heap grew by since heapInUse() read `before` (0 if it shrank).
std::size_t heapGrowthSince(std::size_t before);

// The memory the service allocated at start-up, pool by pool.
struct MemoryPool {
  const char* name = "";
  std::size_t count = 0;  // items (slots, buffers)
  std::size_t bytes = 0;  // all of them together
};

// Every pool added is kept: a fixed table of 12 once dropped the 13th and
// later pools (the streamer's among them) from the total without a word.
struct MemoryBudget {
  // Room for every pool the service adds, reserved up front so that an add()
  // inside a pool's measurement never counts the table's own growth.
  MemoryBudget() { pools.reserve(32); }

  std::vector<MemoryPool> pools;

  void add(const char* name, std::size_t count, std::size_t bytes);
  std::size_t totalBytes() const;
  // "memory: 41.2 MiB in 7 pools"
  std::string summary() const;
  // One line per pool: "  frame slots      4 x   1.17 MiB =   4.69 MiB"
  std::string breakdown() const;
};

}  // namespace fovea::firmware
