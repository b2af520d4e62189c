#include "pipeline/kernels/worker_pool.h"

#include <algorithm>

namespace fovea::pipeline {

WorkerPool::WorkerPool(int parts) : parts_(std::max(parts, 1)) {
  threads_.reserve(static_cast<std::size_t>(parts_ - 1));
  for (int p = 1; p < parts_; ++p) threads_.emplace_back([this, p] { workerLoop(p); });
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  start_cv_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void WorkerPool::run(Task task, void* ctx) {
  if (parts_ == 1) {
    task(ctx, 0, 1);
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    task_ = task;
    ctx_ = ctx;
    pending_ = parts_ - 1;
    ++generation_;
  }
  start_cv_.notify_all();
  task(ctx, 0, parts_);
  std::unique_lock<std::mutex> lock(mutex_);
  done_cv_.wait(lock, [this] { return pending_ == 0; });
}

void WorkerPool::workerLoop(int part) {
  uint64_t seen = 0;
  for (;;) {
    Task task;
    void* ctx;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      start_cv_.wait(lock, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
      task = task_;
      ctx = ctx_;
    }
    task(ctx, part, parts_);
    bool last;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      last = (--pending_ == 0);
    }
    if (last) done_cv_.notify_one();
  }
}

}  // namespace fovea::pipeline
