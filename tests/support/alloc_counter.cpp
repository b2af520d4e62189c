#include "tests/support/alloc_counter.h"

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <new>

// glibc's own entry points, which the replacements forward to.
extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t n, std::size_t size);
void* __libc_realloc(void* p, std::size_t size);
void* __libc_memalign(std::size_t alignment, std::size_t size);
void __libc_free(void* p);
}

namespace {
std::atomic<uint64_t> g_count{0};
std::atomic<bool> g_enabled{false};
thread_local uint64_t t_count = 0;  // the executable's static TLS: no allocation to reach it
inline void note() {
  if (g_enabled.load(std::memory_order_relaxed)) {
    g_count.fetch_add(1, std::memory_order_relaxed);
    ++t_count;
  }
}
}  // namespace

namespace fovea::test {
uint64_t allocationCount() { return g_count.load(); }
void setAllocationCounting(bool enabled) { g_enabled.store(enabled); }
uint64_t threadAllocationCount() { return t_count; }
}  // namespace fovea::test

extern "C" {
void* malloc(std::size_t size) {
  note();
  return __libc_malloc(size);
}
void* calloc(std::size_t n, std::size_t size) {
  note();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t size) {
  note();
  return __libc_realloc(p, size);
}
void free(void* p) { __libc_free(p); }
void* memalign(std::size_t alignment, std::size_t size) {
  note();
  return __libc_memalign(alignment, size);
}
void* aligned_alloc(std::size_t alignment, std::size_t size) {
  note();
  return __libc_memalign(alignment, size);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t size) {
  note();
  void* p = __libc_memalign(alignment, size);
  if (!p) return ENOMEM;
  *out = p;
  return 0;
}
}
