// Counts heap allocations in this test binary. alloc_counter.cpp replaces the C
// allocator (malloc, calloc, realloc, aligned variants) and, through it, every
// operator new, so nothing that allocates can hide. Under AddressSanitizer or
// ThreadSanitizer, which own the allocator, it counts through the sanitizer's
// allocation hook instead, so these tests run and assert under them too.
#pragma once

#include <cstdint>

namespace fovea::test {

// Allocations made since the process started (counted only while enabled).
uint64_t allocationCount();
void setAllocationCounting(bool enabled);
// Allocations the calling thread made while counting was enabled (to tell a
// backend's own allocations from those of a library's threads).
uint64_t threadAllocationCount();

// Counts the allocations made in its scope.
class AllocationScope {
 public:
  AllocationScope() : start_(allocationCount()) { setAllocationCounting(true); }
  ~AllocationScope() { setAllocationCounting(false); }
  uint64_t allocations() const { return allocationCount() - start_; }

 private:
  uint64_t start_;
};

}  // namespace fovea::test
