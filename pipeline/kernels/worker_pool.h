// A fixed pool of worker threads for splitting one frame's per-point work.
//
// The threads are created by the constructor and joined by the destructor; run()
// hands every thread one part of the work and returns when all parts are done.
// Nothing is allocated and no thread is created after construction: a task is a
// plain function pointer and a context pointer (no std::function).
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

namespace fovea::pipeline {

class WorkerPool {
 public:
  using Task = void (*)(void* ctx, int part, int parts);

  // `parts` >= 1 ways of splitting: parts - 1 worker threads plus the caller.
  explicit WorkerPool(int parts);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int parts() const { return parts_; }

  // Calls task(ctx, p, parts()) for every p in [0, parts()): part 0 on the calling
  // thread, the others on the workers; returns when all have returned. One run()
  // at a time (the pipeline calls it from one thread).
  void run(Task task, void* ctx);

  // [begin, end) of `part` when n items are split into `parts` contiguous ranges.
  static std::size_t rangeBegin(std::size_t n, int part, int parts) {
    return n * static_cast<std::size_t>(part) / static_cast<std::size_t>(parts);
  }

 private:
  void workerLoop(int part);

  int parts_ = 1;
  std::mutex mutex_;
  std::condition_variable start_cv_;
  std::condition_variable done_cv_;
  uint64_t generation_ = 0;
  int pending_ = 0;
  bool stop_ = false;
  Task task_ = nullptr;
  void* ctx_ = nullptr;
  std::vector<std::thread> threads_;
};

}  // namespace fovea::pipeline
