// One frame foveated once, the input of the encoding benchmarks
// (fovea-bench-codec, fovea-bench-foxglove): the frame back-projected with the
// reference kernels and foveated for its gaze. Start-up code: allocates,
// returns errors as values.
#pragma once

#include "bench/bench_input.h"
#include "core/result.h"
#include "pipeline/foveator.h"
#include "pipeline/point_cloud.h"

namespace fovea::bench {

struct FoveatedFrame {
  pipeline::FoveatedCloud cloud;
  pipeline::FoveationStats stats;
};

// `input`'s frame back-projected (the default depth range) and foveated with
// `config` for `input`'s gaze.
Result<FoveatedFrame> foveateFrame(const FrameInput& input, const pipeline::FoveationConfig& config);

}  // namespace fovea::bench
