// An array that ends right before a page the process may not touch, so that a
// kernel reading or writing past its end faults at once, with or without a
// sanitizer. For the stores that load and rewrite a whole vector (Highway's
// BlendedStore on NEON, pipeline/kernels/store_first_lanes-inl.h), which write
// back what they read and so leave no wrong value behind to compare.
#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdlib>

namespace fovea::test {

template <class T>
class GuardedArray {
 public:
  explicit GuardedArray(std::size_t n) : size_(n) {
    const std::size_t page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
    const std::size_t data_bytes = (n * sizeof(T) + page - 1) / page * page;
    mapped_bytes_ = data_bytes + page;
    void* base = mmap(nullptr, mapped_bytes_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (base == MAP_FAILED || mprotect(static_cast<char*>(base) + data_bytes, page, PROT_NONE) != 0) std::abort();
    base_ = static_cast<char*>(base);
    data_ = reinterpret_cast<T*>(base_ + data_bytes - n * sizeof(T));
  }
  ~GuardedArray() { munmap(base_, mapped_bytes_); }
  GuardedArray(const GuardedArray&) = delete;
  GuardedArray& operator=(const GuardedArray&) = delete;

  T* data() { return data_; }
  std::size_t size() const { return size_; }
  T& operator[](std::size_t i) { return data_[i]; }

 private:
  std::size_t size_;
  std::size_t mapped_bytes_ = 0;
  char* base_ = nullptr;
  T* data_ = nullptr;
};

}  // namespace fovea::test
