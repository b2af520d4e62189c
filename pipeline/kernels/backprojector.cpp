#include "pipeline/kernels/backprojector.h"

#include <algorithm>
#include <string>

#include "pipeline/kernels/foveation_simd.h"

namespace fovea::pipeline {

namespace {

struct BackprojectJob {
  const kernels::BackprojectParams* params;
  void* parts;  // Backprojector::Part[parts]
  bool write;   // false: count, true: write
};

}  // namespace

Backprojector::Backprojector(int threads, KernelSet kernels) : kernels_(kernels) {
  threads = std::clamp(threads, 1, kMaxPipelineThreads);
  if (kernels == KernelSet::kRef) {
    run_ = [](Backprojector&, const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out,
              BackprojectCounts& counts) { return backprojectRef(frame, range, out, counts); };
    kernel_name_ = "backprojectRef";
  } else if (threads == 1) {
    run_ = [](Backprojector&, const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out,
              BackprojectCounts& counts) { return backprojectSimd(frame, range, out, counts); };
    kernel_name_ = "backprojectSimd";
  } else {
    pool_ = std::make_unique<WorkerPool>(threads);
    parts_.resize(static_cast<std::size_t>(threads));
    run_ = runPooled;
    kernel_name_ = "backprojectRows/pool";
  }
}

Status Backprojector::runPooled(Backprojector& self, const hal::RgbdFrame& frame, const DepthRange& range,
                                PointCloud& out, BackprojectCounts& counts) {
  counts = {};
  out.clear();
  kernels::BackprojectParams p;
  if (Status s = kernels::prepareBackprojection(frame, range, p); !s) return s;
  out.origin_m = frame.T_world_cam.t_world_cam;
  out.has_color = frame.has_rgb;
  counts.pixels = static_cast<std::size_t>(p.width) * p.height;
  p.out_x = out.x();
  p.out_y = out.y();
  p.out_z = out.z();
  p.out_rgb = out.rgb();

  BackprojectJob job{&p, self.parts_.data(), false};
  auto task = [](void* ctx, int part, int parts) {
    auto* j = static_cast<BackprojectJob*>(ctx);
    auto* all = static_cast<Part*>(j->parts);
    const int h = j->params->height;
    const int row0 = static_cast<int>(WorkerPool::rangeBegin(static_cast<std::size_t>(h), part, parts));
    const int row1 = static_cast<int>(WorkerPool::rangeBegin(static_cast<std::size_t>(h), part + 1, parts));
    Part& mine = all[part];
    if (!j->write) {
      mine = Part{};
      mine.valid = kernels::backprojectCountRows(*j->params, row0, row1, &mine.no_depth, &mine.out_of_range);
    } else {
      kernels::backprojectRows(*j->params, row0, row1, mine.offset, mine.offset + mine.valid);
    }
  };
  self.pool_->run(task, &job);
  std::size_t valid = 0;
  for (Part& part : self.parts_) {
    part.offset = valid;
    valid += part.valid;
    counts.no_depth += part.no_depth;
    counts.out_of_range += part.out_of_range;
  }
  if (valid > out.capacity()) {
    return {ErrorCode::kCapacityExceeded, "backproject: frame has more valid pixels than the cloud capacity " +
                                              std::to_string(out.capacity()) + ": raise pipeline.max_points"};
  }
  job.write = true;
  self.pool_->run(task, &job);
  counts.valid = valid;
  (void)out.resize(valid);
  return Status::ok();
}

}  // namespace fovea::pipeline
