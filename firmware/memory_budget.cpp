// The service's memory budget: the heap measurement its start-up takes around
// each pool, and the pools' summary and breakdown lines.
#include "firmware/memory_budget.h"

#include <malloc.h>

#include <cstdio>

#include "core/sanitizer.h"

namespace fovea::firmware {

// The start-up phase measures each pool as the difference around its
// allocation (what the components really reserve, including their own
// bookkeeping, without asking each for a size method).
std::size_t heapInUse() {
#ifdef FOVEA_SANITIZER_ALLOCATOR
  // The sanitizer's allocator serves malloc; glibc's statistics would read zero.
  return __sanitizer_get_current_allocated_bytes();
#else
  const struct mallinfo2 m = mallinfo2();
  return m.uordblks + m.hblkhd;
#endif
}

std::size_t heapGrowthSince(std::size_t before) {
  const std::size_t after = heapInUse();
  return after > before ? after - before : 0;
}

void MemoryBudget::add(const char* name, std::size_t count, std::size_t bytes) {
  pools.push_back({name, count, bytes});
}

std::size_t MemoryBudget::totalBytes() const {
  std::size_t total = 0;
  for (const MemoryPool& p : pools) total += p.bytes;
  return total;
}

std::string MemoryBudget::summary() const {
  char line[96];
  std::snprintf(line, sizeof line, "memory: %.1f MiB in %zu pools", static_cast<double>(totalBytes()) / kMiB,
                pools.size());
  return line;
}

std::string MemoryBudget::breakdown() const {
  std::string out;
  for (const MemoryPool& p : pools) {
    char line[160];
    std::snprintf(line, sizeof line, "  %-42s %3zu x %8.3f MiB = %8.3f MiB\n", p.name, p.count,
                  p.count ? static_cast<double>(p.bytes) / static_cast<double>(p.count) / kMiB : 0.0,
                  static_cast<double>(p.bytes) / kMiB);
    out += line;
  }
  return out;
}

}  // namespace fovea::firmware
