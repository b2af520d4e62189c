// fovea-compare's input: the frame or cloud every method starts from, with the
// gaze and configuration, loaded once from the command line before any method
// is made.
#pragma once

#include <cstddef>
#include <string>

#include "bench/compare_options.h"
#include "hal/frame.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"

namespace fovea::bench::compare {

struct Input {
  bool has_frame = false;
  hal::RgbdFrame frame;         // has_frame: the RGB-D frame every method starts from
  pipeline::PointCloud cloud;   // !has_frame: the PLY cloud every method starts from
  pipeline::Gaze gaze;          // normalised
  pipeline::DepthRange range;   // back-projection range (fovead's default 0.1..10 m)
  pipeline::FoveationConfig config;
  double acuity_floor_per_m2 = 0.001;  // the floor of acuity-floor-simd-1t and acuity-features-simd-1t
  double pyramid_margin = 0.0;         // the pyramid rows' margin (0: ACUITY's level_margin)
  std::string description;
  std::size_t input_points = 0;  // valid points after back-projection (the ns/point denominator)
};

// Loads the input the options name (the mock living-room frame, a TUM frame or a
// PLY cloud), normalises the gaze and counts the valid points. Returns 0, or the
// exit status 1 after printing why it failed.
int loadInput(const CompareOptions& options, Input& input);

}  // namespace fovea::bench::compare
