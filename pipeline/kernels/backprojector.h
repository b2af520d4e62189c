// Back-projection with the selected kernel and, for the SIMD kernel, rows split
// across a fixed pool of threads (created here, never per frame).
//
// With `threads` > 1 each thread first counts the valid pixels of its block of
// rows; the prefix sums give every block its place in the output, so the cloud is
// identical, point for point, to the single-threaded one (and to backprojectRef).
// The reference kernel set always runs on the calling thread: it is the spec.
#pragma once

#include <memory>
#include <string_view>
#include <vector>

#include "core/kernel_set.h"
#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/backproject.h"
#include "pipeline/kernels/worker_pool.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline {

inline constexpr int kMaxPipelineThreads = 64;

class Backprojector {
 public:
  // threads is clamped to [1, kMaxPipelineThreads]; the pool exists only for the
  // SIMD kernel on more than one thread (the reference is the spec: one thread).
  explicit Backprojector(int threads = 1, KernelSet kernels = defaultKernelSet());

  // Same contract as backprojectRef. Never allocates.
  Status run(const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out, BackprojectCounts& counts) {
    return run_(*this, frame, range, out, counts);
  }

  // The threads a frame is split across.
  int threads() const { return pool_ ? pool_->parts() : 1; }
  KernelSet kernels() const { return kernels_; }
  // The kernel run() calls, chosen once by the constructor (logs, tests).
  std::string_view kernelName() const { return kernel_name_; }

 private:
  struct Part {
    std::size_t valid = 0, no_depth = 0, out_of_range = 0, offset = 0;
  };
  // backprojectSimd's rows split across pool_.
  static Status runPooled(Backprojector& self, const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out,
                          BackprojectCounts& counts);

  KernelSet kernels_;
  std::unique_ptr<WorkerPool> pool_;
  std::vector<Part> parts_;
  // Takes the Backprojector as an argument, so a moved one stays valid.
  Status (*run_)(Backprojector&, const hal::RgbdFrame&, const DepthRange&, PointCloud&, BackprojectCounts&) = nullptr;
  std::string_view kernel_name_;
};

}  // namespace fovea::pipeline
