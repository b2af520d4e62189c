// Whether this build runs under a sanitizer that brings its own allocator
// (AddressSanitizer, ThreadSanitizer, MemorySanitizer; toolchain/run-sanitizers),
// and the parts of its allocator interface fovea uses. glibc's malloc statistics
// (mallinfo2) read zero there and a replaced malloc breaks it, so whatever
// measures or counts the heap asks the sanitizer instead. Header-only: the
// runtimes (libasan, libtsan) export these functions; GCC 12 ships no header
// for them (clang's is sanitizer/allocator_interface.h).
#pragma once

#include <cstddef>

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define FOVEA_SANITIZER_ALLOCATOR 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define FOVEA_SANITIZER_ALLOCATOR 1
#endif
#endif

// AddressSanitizer (with LeakSanitizer): hal/camera/openni2 keeps OpenNI2's
// drivers loaded so that LeakSanitizer can name them (toolchain/lsan.supp).
#if defined(__SANITIZE_ADDRESS__)
#define FOVEA_ADDRESS_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define FOVEA_ADDRESS_SANITIZER 1
#endif
#endif

// ThreadSanitizer keeps shadow memory, per-thread traces and a table of
// synchronisation objects that grow with the addresses and history a program
// touches: a bound on the resident set does not hold under it.
#if defined(__SANITIZE_THREAD__)
#define FOVEA_THREAD_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define FOVEA_THREAD_SANITIZER 1
#endif
#endif

#ifdef FOVEA_SANITIZER_ALLOCATOR
extern "C" {
// Bytes the sanitizer's allocator has handed out and not had back.
std::size_t __sanitizer_get_current_allocated_bytes();
// Calls malloc_hook on every allocation and free_hook on every free; 0 when refused.
int __sanitizer_install_malloc_and_free_hooks(void (*malloc_hook)(const volatile void*, std::size_t),
                                              void (*free_hook)(const volatile void*));
}
#endif
