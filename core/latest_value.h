// A single-writer single-reader "latest value" mailbox: a triple buffer. The
// writer fills its private buffer and swaps it with the shared middle one (one
// atomic exchange); the reader, when the middle one is fresh, swaps it with its
// own. Neither side waits, copies the other's buffer or can see a torn value,
// and the reader sees only the newest value written (older ones are
// overwritten, which is what a gaze sample or a set of parameters wants).
// T is any copyable type; its buffers are made at construction, so writing a
// value allocates only when T's copy does (e.g. a vector growing past what a
// buffer held before).
#pragma once

#include <atomic>
#include <cstdint>

#include "core/ring.h"

namespace fovea {

template <typename T>
class LatestValue {
 public:
  LatestValue() = default;
  explicit LatestValue(const T& initial) {
    for (T& b : buffers_) b = initial;
  }
  LatestValue(const LatestValue&) = delete;
  LatestValue& operator=(const LatestValue&) = delete;

  // ---- writer thread ----
  // The buffer to fill, then publish(); or write() to do both.
  T& writeBuffer() { return buffers_[write_]; }
  void publish() {
    const uint8_t old = middle_.exchange(static_cast<uint8_t>(write_ | kFresh), std::memory_order_acq_rel);
    write_ = old & kIndexMask;
    writes_.store(writes_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }
  void write(const T& value) {
    writeBuffer() = value;
    publish();
  }

  // ---- reader thread ----
  // Takes the newest value if one was published since the last call (true).
  [[nodiscard]] bool update() {
    if ((middle_.load(std::memory_order_acquire) & kFresh) == 0) return false;
    const uint8_t old = middle_.exchange(read_, std::memory_order_acq_rel);
    read_ = old & kIndexMask;
    return true;
  }
  // The value update() took last (the initial value before any).
  const T& current() const { return buffers_[read_]; }

  // ---- any thread ----
  uint64_t writes() const { return writes_.load(std::memory_order_relaxed); }

 private:
  static constexpr uint8_t kIndexMask = 0x3;
  static constexpr uint8_t kFresh = 0x4;
  T buffers_[3]{};
  // Writer-private, shared, reader-private indices: always a permutation of 0, 1, 2.
  alignas(kCacheLineBytes) uint8_t write_ = 0;
  alignas(kCacheLineBytes) std::atomic<uint8_t> middle_{1};
  alignas(kCacheLineBytes) uint8_t read_ = 2;
  std::atomic<uint64_t> writes_{0};
};

}  // namespace fovea
