// One frame's way through the pipeline, shared by `fovead run` (one thread) and
// the service's foveation stage: back-projection into the stage's own cloud,
// the foveation configuration the gaze policy chose (applied only when it
// changes), foveation into the caller's output. Everything is allocated by
// create(); a frame allocates nothing.
#pragma once

#include <cstdint>

#include "core/clock.h"
#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/point_cloud.h"

namespace fovea::firmware {

class FrameFoveator {
 public:
  static Result<FrameFoveator> create(const pipeline::PipelineCapacity& capacity,
                                      const pipeline::FoveationConfig& config, const pipeline::DepthRange& range);

  // Back-projects a frame into cloud() (kCapacityExceeded for a frame larger
  // than the capacity).
  Status backproject(const hal::RgbdFrame& frame, pipeline::BackprojectCounts& counts) {
    return backprojector_.run(frame, range_, cloud_, counts);
  }
  // Makes `config` the foveation in use. The gaze policy hands out pointers to
  // its own configurations, so a pointer equal to the one in use means no change
  // (invalidate() forces the next call to apply, e.g. after the policy's
  // configuration was replaced in place). On error the previous one stays.
  Status use(const pipeline::FoveationConfig* config) {
    if (config == in_use_) return Status::ok();
    if (Status s = foveator_.setConfig(*config); !s) return s;
    in_use_ = config;
    return Status::ok();
  }
  void invalidate() { in_use_ = nullptr; }
  // Foveates the last back-projected cloud.
  Status foveate(const pipeline::Gaze& gaze, pipeline::FoveatedCloud& out, pipeline::FoveationStats& stats) {
    return foveator_.foveate(cloud_, gaze, out, stats);
  }

  const pipeline::PointCloud& cloud() const { return cloud_; }
  pipeline::Foveator& foveator() { return foveator_; }
  const pipeline::DepthRange& range() const { return range_; }

 private:
  FrameFoveator(pipeline::Foveator foveator, const pipeline::PipelineCapacity& capacity,
                const pipeline::DepthRange& range)
      : foveator_(std::move(foveator)),
        backprojector_(capacity.threads, capacity.kernels),
        cloud_(capacity.max_points),
        range_(range) {}

  pipeline::Foveator foveator_;
  pipeline::Backprojector backprojector_;
  pipeline::PointCloud cloud_;
  pipeline::DepthRange range_;
  const pipeline::FoveationConfig* in_use_ = nullptr;
};

inline Result<FrameFoveator> FrameFoveator::create(const pipeline::PipelineCapacity& capacity,
                                                   const pipeline::FoveationConfig& config,
                                                   const pipeline::DepthRange& range) {
  if (Status s = range.validate(); !s) return s;
  Result<pipeline::Foveator> foveator = pipeline::Foveator::create(capacity, config);
  if (!foveator) return foveator.status();
  return FrameFoveator(std::move(foveator.value()), capacity, range);
}

}  // namespace fovea::firmware
