// fovea-error-report's measurement: the camera opened and every buffer sized
// once, the map warmed up (--sources with map), every configuration on every
// measured frame side by side, then the figures over time on the camera's next
// frames (dynamics.h). What it gathers is what the report is written from.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "hal/camera.h"
#include "tools/error_report/config_run.h"
#include "tools/error_report/dynamics.h"
#include "tools/error_report/options.h"

namespace fovea::tools {

// What a run measured.
struct Measurement {
  std::vector<ConfigRun> runs;  // in planRuns' order
  hal::CameraInfo info;         // the camera's
  std::string gaze;             // describeGaze's words for the gaze
  double load_before = 0.0;     // the 1-minute load average when the camera started
  long frames = 0;              // the frames measured (captured)
  std::optional<DynamicsReport> dynamics;  // the figures over time, unless --dynamics-frames 0
};

// Measures what `options` asks for into `measurement`. Returns kExitOk, or the
// exit code (exit_code.h) of a run that cannot go on, having said why on
// standard error.
int measure(const Options& options, Measurement& measurement);

}  // namespace fovea::tools
