// Inputs shared by the benchmark programs: the mock living-room frame (the
// README's demo view) with its default gaze, and TUM frames when the backend is
// built. Start-up code: allocates, returns errors as values.
#pragma once

#include <string>

#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/partition.h"

namespace fovea::bench {

struct FrameInput {
  hal::RgbdFrame frame;
  pipeline::Gaze gaze;      // not normalised
  std::string description;  // "mock:living-room 640x480, gaze camera -> scene centre"
};

// The first frame of mock:living-room at width x height, gaze from the camera
// towards the scene's focus point (what `fovead run` does by default).
Result<FrameInput> mockLivingRoom(int width = 640, int height = 480);

// The value after `name` on a command line ("--frames 90"), or `fallback`.
std::string option(int argc, char** argv, const char* name, const char* fallback);

// A reference frame's depth (metres) at the sub-pixel (u, v), bilinear between
// the four pixels around it; NaN where one is missing or they straddle a depth
// step (an edge, where a point a pixel off would be judged against the wrong
// surface). The benches that judge a map against a frame's measured surface.
double trueDepthAt(const hal::RgbdFrame& truth, double u, double v);

// Frame `index` (0-based) of a TUM sequence folder, gaze along the camera's
// optical axis. kNotFound when the TUM backend is not built.
Result<FrameInput> tumFrame(const std::string& path, int index);

}  // namespace fovea::bench
