// fovea-error-report's command line: what a run measures and where it writes it,
// checked in full before anything is measured (a bad value costs no camera time).
#pragma once

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"
#include "firmware/frame_foveator.h"
#include "pipeline/acuity.h"
#include "tools/error_report/dynamics.h"

namespace fovea::tools {

struct Options {
  std::string camera = "mock:living-room";
  long frames = 30;
  std::string out_dir = "docs/report";
  std::vector<pipeline::Preset> presets = {pipeline::Preset::kF1, pipeline::Preset::kF2, pipeline::Preset::kF3,
                                           pipeline::Preset::kFRef, pipeline::Preset::kAcuity};
  std::vector<double> slopes = {0.022, 0.028, 0.034};
  // ACUITY's level margins k (AcuityConfig::level_margin): sqrt(3) guarantees
  // every point under its MAR; smaller ones trade a share above it for bytes.
  std::vector<double> acuity_margins = {1.7320508075688772, 0.7, 0.5, 0.42};
  // ... and refined rows: margin k and refinement passes (AcuityConfig::refine_passes).
  std::vector<std::pair<double, int>> acuity_refined = {{0.3, 1}, {0.12, 2}, {0.15, 7}};
  // ... and sensor floors in mm (0: none), a row each margin x floor.
  std::vector<double> acuity_floors_mm = {0.0};
  std::vector<double> acuity_noise_floors_mm = {};  // per m^2 of distance
  // ACUITY's view cull (foveation.view_cull_deg's default), a row each, and the
  // head's turn from the gaze about the camera's up axis.
  std::vector<pipeline::ViewCull> view_culls = {pipeline::ViewCull::kOff};
  double head_turn_deg = 0.0;
  double reference_slope = pipeline::kDefaultSlope;
  bool plot = true;
  std::string replot_from;  // non-empty: redraw this directory's plots, measure nothing
  Eigen::Vector3d eye_offset_cam = Eigen::Vector3d::Zero();
  DynamicsOptions dynamics;
  // What is foveated (--sources), and the frames fused into the map first.
  std::vector<firmware::FoveationSource> sources = {firmware::FoveationSource::kFrame};
  long map_warmup = 60;
  bool hasMap() const {
    return std::find(sources.begin(), sources.end(), firmware::FoveationSource::kMap) != sources.end();
  }
};

// The --help text; main appends the cameras' list (firmware::cameraSpecHelp).
extern const char* const kHelp;

// The options argv gives (argv[0] is the program). help: --help or -h was given
// (the other flags are still checked). kInvalidArgument naming the flag when a
// value does not fit, a flag lacks its value or is unknown.
Result<Options> parseArgs(int argc, char** argv, bool& help);

}  // namespace fovea::tools
