// fovea-error-report's eye: where it is and where it looks on each frame, and how
// the report states that. One place, so that the gaze measured and the gaze the
// report names cannot drift apart.
#pragma once

#include <string>

#include "hal/camera.h"
#include "pipeline/partition.h"
#include "tools/error_report/options.h"

namespace fovea::tools {

// Where the eye is and where it looks, as the report states it.
std::string describeGaze(const Options& options, const hal::CameraInfo& info);

// The gaze on a frame: from the eye towards the scene's focus point (or along the
// optical axis), and the head along it, turned about the camera's up axis
// (ACUITY's view cull).
pipeline::Gaze gazeOn(const hal::RgbdFrame& frame, const Options& options, const hal::CameraInfo& info);

}  // namespace fovea::tools
