#include "tests/support/alloc_counter.h"

#include "core/sanitizer.h"

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <new>

// AddressSanitizer and ThreadSanitizer bring their own allocator and intercept
// malloc themselves: replacing malloc here (forwarding to glibc's __libc_malloc)
// hands them blocks they never allocated, and the binary crashes before main
// (at test discovery). Under them the count comes from the sanitizer's own
// allocation hook instead, which sees every allocation its allocator makes:
// the same calls the replacement below sees, so the zero-allocation assertions
// keep their meaning under the sanitizers. UBSan alone keeps glibc's allocator.

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

#ifdef FOVEA_SANITIZER_ALLOCATOR

namespace {
void onMalloc(const volatile void*, std::size_t) { note(); }
void onFree(const volatile void*) {}

// Installed before main: a binary that cannot count must fail, never pass silently.
const bool g_hooks_installed = [] {
  if (__sanitizer_install_malloc_and_free_hooks(onMalloc, onFree) == 0) {
    std::fprintf(stderr, "alloc_counter: the sanitizer refused the allocation hooks: cannot count allocations\n");
    std::abort();
  }
  return true;
}();
}  // namespace

#else

// glibc's own entry points, which the replacements forward to.
extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t n, std::size_t size);
void* __libc_realloc(void* p, std::size_t size);
void* __libc_memalign(std::size_t alignment, std::size_t size);
void __libc_free(void* p);
}

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

#endif
