// A single-producer single-consumer ring of slot indices into a preallocated
// pool, "latest wins": FIFO, and when the consumer falls behind the producer
// drops the OLDEST queued slot (counted) instead of blocking, so the queue never
// holds more than `depth` slots and latency never builds up. depth 1 means the
// consumer always gets the newest slot.
//
// Slots and who holds them. The pool has depth + 1 + consumer_holds slots, each
// in exactly one place at any time:
//   producer      tryAcquire() -> fill -> publish()    (or cancel())
//   queue         at most `depth` published slots, oldest first
//   consumer      tryTake() -> read -> release()        (at most consumer_holds at once)
//   free          released slots on their way back (a second SPSC queue,
//                 consumer -> producer) and slots the producer dropped (its
//                 private stash)
// So while the consumer holds at most consumer_holds slots, tryAcquire() finds
// a slot; it returns false only in the instant after a release() whose store the
// producer does not see yet, or when the consumer holds more than promised.
//
// The race between "drop the oldest" and "take the oldest". Both sides advance
// the queue's head with a compare-and-swap from h to h + 1; exactly one of them
// wins, and the winner owns the slot index stored at position h. Each side reads
// that index BEFORE its CAS: the producer may overwrite position h (as position
// h + depth) only after it has seen head > h, i.e. after the CAS that moved head
// past h, so a read followed by a successful CAS read the right index, and a read
// followed by a failed CAS is discarded (the cells are relaxed atomics, so such a
// stale read is not a data race either). Head and tail are 64-bit positions that
// only grow (no ABA, no wrap in practice). The producer drops only when the
// queue is full, and its CAS can only fail because the consumer took the oldest,
// which leaves room: publish() always succeeds in a bounded number of steps.
//
// Layout as in rigtorp's SPSCQueue: each index on its own cache line, each side
// caching the other's index so the shared line is read only when the cached
// value says "empty" or "full". No allocation after construction, no locks.
#pragma once

#include <atomic>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <memory>

namespace fovea {

// Pinned rather than std::hardware_destructive_interference_size (which GCC 12
// gives as 256 on aarch64 and warns about when used in headers).
inline constexpr std::size_t kCacheLineBytes = 64;

using SlotIndex = uint32_t;

struct RingCounters {
  uint64_t published = 0;         // publish() calls
  uint64_t dropped = 0;           // oldest queued slots dropped to make room
  uint64_t taken = 0;             // slots the consumer took
  uint64_t acquire_failures = 0;  // tryAcquire() found no free slot
};

class SlotRing {
 public:
  // depth >= 1: published slots waiting at most; consumer_holds >= 1: slots the
  // consumer may hold at once. Both come from validated configuration.
  explicit SlotRing(std::size_t depth, std::size_t consumer_holds = 1)
      : depth_(depth),
        slot_count_(depth + 1 + consumer_holds),
        queue_(new std::atomic<SlotIndex>[depth]),
        free_(new SlotIndex[slot_count_]),
        stash_(new SlotIndex[slot_count_]) {
    assert(depth >= 1 && consumer_holds >= 1);
    for (std::size_t i = 0; i < depth_; ++i) queue_[i].store(0, std::memory_order_relaxed);
    // Every slot starts in the producer's stash, highest index on top.
    for (std::size_t i = 0; i < slot_count_; ++i) stash_[i] = static_cast<SlotIndex>(slot_count_ - 1 - i);
    stash_size_ = slot_count_;
  }
  SlotRing(const SlotRing&) = delete;
  SlotRing& operator=(const SlotRing&) = delete;

  std::size_t depth() const { return depth_; }
  std::size_t slotCount() const { return slot_count_; }

  // ---- producer thread ----

  // A free slot to fill; false when none is free (counted).
  [[nodiscard]] bool tryAcquire(SlotIndex& slot) {
    if (stash_size_ > 0) {
      slot = stash_[--stash_size_];
      return true;
    }
    const uint64_t head = free_head_.load(std::memory_order_relaxed);
    if (head == free_tail_cache_) {
      free_tail_cache_ = free_tail_.load(std::memory_order_acquire);
      if (head == free_tail_cache_) {
        bump(acquire_failures_);
        return false;
      }
    }
    slot = free_[head % slot_count_];
    free_head_.store(head + 1, std::memory_order_release);
    return true;
  }

  // Gives back an acquired slot without publishing it.
  void cancel(SlotIndex slot) {
    assert(slot < slot_count_ && stash_size_ < slot_count_);
    stash_[stash_size_++] = slot;
  }

  // Queues an acquired, filled slot. When `depth` slots are already queued the
  // oldest is dropped first (counted; its slot goes back to the producer).
  // Never blocks and never fails.
  void publish(SlotIndex slot) {
    assert(slot < slot_count_);
    const uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (tail - head_cache_ >= depth_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      while (tail - head_cache_ >= depth_) {
        const SlotIndex oldest = queue_[head_cache_ % depth_].load(std::memory_order_relaxed);
        // On failure head_cache_ receives the consumer's newer head and the loop
        // ends: the consumer made room.
        if (head_.compare_exchange_weak(head_cache_, head_cache_ + 1, std::memory_order_acq_rel,
                                        std::memory_order_acquire)) {
          ++head_cache_;
          stash_[stash_size_++] = oldest;
          bump(dropped_);
        }
      }
    }
    queue_[tail % depth_].store(slot, std::memory_order_relaxed);
    tail_.store(tail + 1, std::memory_order_release);
    bump(published_);
  }

  // ---- consumer thread ----

  // The oldest queued slot; false when the queue is empty.
  [[nodiscard]] bool tryTake(SlotIndex& slot) {
    uint64_t head = head_.load(std::memory_order_acquire);
    for (;;) {
      // The producer's drops can move head past the cached tail: >= not ==.
      if (head >= tail_cache_) {
        tail_cache_ = tail_.load(std::memory_order_acquire);
        if (head >= tail_cache_) return false;
      }
      const SlotIndex candidate = queue_[head % depth_].load(std::memory_order_relaxed);
      if (head_.compare_exchange_weak(head, head + 1, std::memory_order_acq_rel, std::memory_order_acquire)) {
        slot = candidate;
        bump(taken_);
        return true;
      }
      // Lost to a drop (or a spurious failure): head now holds the current value.
    }
  }

  // Returns a taken slot to the producer. False only for a bug (an index out of
  // range, or more releases than takes), never silently.
  [[nodiscard]] bool release(SlotIndex slot) {
    if (slot >= slot_count_) return false;
    const uint64_t tail = free_tail_.load(std::memory_order_relaxed);
    if (tail - free_head_cache_ >= slot_count_) {
      free_head_cache_ = free_head_.load(std::memory_order_acquire);
      if (tail - free_head_cache_ >= slot_count_) return false;
    }
    free_[tail % slot_count_] = slot;
    free_tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  // ---- any thread ----

  RingCounters counters() const {
    RingCounters c;
    c.published = published_.load(std::memory_order_relaxed);
    c.dropped = dropped_.load(std::memory_order_relaxed);
    c.taken = taken_.load(std::memory_order_relaxed);
    c.acquire_failures = acquire_failures_.load(std::memory_order_relaxed);
    return c;
  }
  // Queued slots right now (approximate while both sides run).
  std::size_t sizeApprox() const {
    const uint64_t head = head_.load(std::memory_order_acquire);
    const uint64_t tail = tail_.load(std::memory_order_acquire);
    return tail > head ? static_cast<std::size_t>(tail - head) : 0;
  }

 private:
  // Each counter has a single writer: no read-modify-write needed.
  static void bump(std::atomic<uint64_t>& counter) {
    counter.store(counter.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }

  // Read-only after construction.
  const std::size_t depth_;
  const std::size_t slot_count_;
  const std::unique_ptr<std::atomic<SlotIndex>[]> queue_;  // written by the producer only
  const std::unique_ptr<SlotIndex[]> free_;                // written by the consumer only
  const std::unique_ptr<SlotIndex[]> stash_;               // producer only

  // The queue's positions: head moved by both sides (CAS), tail by the producer.
  alignas(kCacheLineBytes) std::atomic<uint64_t> head_{0};
  alignas(kCacheLineBytes) std::atomic<uint64_t> tail_{0};
  // The free queue's positions: tail moved by the consumer, head by the producer.
  alignas(kCacheLineBytes) std::atomic<uint64_t> free_tail_{0};
  alignas(kCacheLineBytes) std::atomic<uint64_t> free_head_{0};

  // Producer-private state and counters.
  alignas(kCacheLineBytes) uint64_t head_cache_ = 0;
  uint64_t free_tail_cache_ = 0;
  std::size_t stash_size_ = 0;
  std::atomic<uint64_t> published_{0};
  std::atomic<uint64_t> dropped_{0};
  std::atomic<uint64_t> acquire_failures_{0};

  // Consumer-private state and counters.
  alignas(kCacheLineBytes) uint64_t tail_cache_ = 0;
  uint64_t free_head_cache_ = 0;
  std::atomic<uint64_t> taken_{0};
};

// A SlotRing with its pool of T: every slot is a copy of the prototype, made once
// at construction (e.g. an RgbdFrame sized for the camera), so the frame path
// only moves indices.
template <typename T>
class SlotPoolRing {
 public:
  SlotPoolRing(std::size_t depth, std::size_t consumer_holds, const T& prototype)
      : ring_(depth, consumer_holds), slots_(new T[ring_.slotCount()]) {
    for (std::size_t i = 0; i < ring_.slotCount(); ++i) slots_[i] = prototype;
  }

  SlotRing& ring() { return ring_; }
  const SlotRing& ring() const { return ring_; }
  T& slot(SlotIndex index) {
    assert(index < ring_.slotCount());
    return slots_[index];
  }
  std::size_t slotCount() const { return ring_.slotCount(); }

 private:
  SlotRing ring_;
  std::unique_ptr<T[]> slots_;
};

}  // namespace fovea
