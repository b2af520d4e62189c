// One frame foveated once, the input of the encoding benchmarks.
#include "bench/foveated_frame.h"

#include "pipeline/backproject.h"

namespace fovea::bench {

Result<FoveatedFrame> foveateFrame(const FrameInput& input, const pipeline::FoveationConfig& config) {
  const hal::RgbdFrame& frame = input.frame;
  const std::size_t pixels = static_cast<std::size_t>(frame.width()) * frame.height();
  pipeline::PointCloud cloud(pixels);
  pipeline::BackprojectCounts counts;
  if (Status s = pipeline::backprojectRef(frame, pipeline::DepthRange{}, cloud, counts); !s) return s;
  Result<pipeline::Foveator> foveator = pipeline::Foveator::create({pixels, pixels}, config);
  if (!foveator) return foveator.status();
  FoveatedFrame out{pipeline::FoveatedCloud(pixels), {}};
  if (Status s = foveator->foveate(cloud, input.gaze, out.cloud, out.stats); !s) return s;
  return out;
}

}  // namespace fovea::bench
