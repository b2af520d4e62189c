// The map shared between the thread that fuses frames into it and the thread
// that reads it for each frame sent (the plan of the operator's bricks, the
// last fused view, the map's counters): a mutex the fusing thread holds for a whole
// fusion and lets a waiting reader through at safe points, where every
// surfel, brick list and counter is whole (SurfelMap yields between splat
// batches, rows of the association and of new surfels). A reader so waits for
// at most one such step of fusion (tens of microseconds at 640x480), not for
// the fusion in flight (tens of milliseconds on this machine), which is what
// keeps a new gaze from waiting for fusion (issue 41, part 3; docs/map.md).
// A reader sees the map part way through a fusion: some pixels merged, others
// not yet. Whatever it sends then is a consistent map, and a brick changed
// after it was sampled changes its counter, so it is due again.
//
// Readers lock() and unlock() as a mutex (MapReadLock); the writer holds the gate
// with lock() too and calls yield() at its safe points. Without a writer
// thread (fusion on the reader's thread) it is an uncontended mutex.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <thread>

namespace fovea::pipeline::map {

class MapGate {
 public:
  void lock() {
    // While the holder lets the waiting readers through, a new one waits for
    // it to take the gate back: a reader that locks again and again must not
    // keep fusion out.
    while (holder_returning_.load(std::memory_order_acquire)) std::this_thread::yield();
    waiting_.fetch_add(1, std::memory_order_acq_rel);
    mutex_.lock();
    waiting_.fetch_sub(1, std::memory_order_acq_rel);
  }
  void unlock() { mutex_.unlock(); }

  // The holder, at a safe point: when another thread waits for the gate,
  // hands it over and takes it back once they are done.
  void yield() {
    if (waiting_.load(std::memory_order_acquire) == 0) return;
    yields_.fetch_add(1, std::memory_order_relaxed);
    // Those waiting now go through; one who comes after waits for the holder.
    holder_returning_.store(true, std::memory_order_release);
    mutex_.unlock();
    // Until every waiter got the mutex (each leaves the count once it holds it).
    while (waiting_.load(std::memory_order_acquire) > 0) std::this_thread::yield();
    mutex_.lock();
    holder_returning_.store(false, std::memory_order_release);
  }

  // How often the holder let a waiter through (tests).
  uint64_t yields() const { return yields_.load(std::memory_order_relaxed); }

 private:
  std::mutex mutex_;
  std::atomic<uint32_t> waiting_{0};
  std::atomic<bool> holder_returning_{false};
  std::atomic<uint64_t> yields_{0};
};

// The gate held for reading for a scope.
using MapReadLock = std::lock_guard<MapGate>;

}  // namespace fovea::pipeline::map
