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

// Frame `index` (0-based) of a TUM sequence folder, gaze along the camera's
// optical axis. kNotFound when the TUM backend is not built.
Result<FrameInput> tumFrame(const std::string& path, int index);

}  // namespace fovea::bench
