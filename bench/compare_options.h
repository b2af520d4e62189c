// fovea-compare's command line: what to run on which input. Parsed apart from the
// run so that the run reads as its steps; start-up code, errors go to usage().
#pragma once

#include <optional>
#include <string>

#include <Eigen/Core>

#include "pipeline/acuity.h"

namespace fovea::bench::compare {

struct CompareOptions {
  int runs = 20;
  std::string tum_path, ply_path;
  std::string preset_name = "F1";  // as given, for the header line
  pipeline::Preset preset{};       // preset_name parsed
  int frame_index = 0;
  double acuity_floor_mm = 1.0;
  std::string only_methods;  // ",a,b," or empty: every method
  double pyramid_margin = 0.0;
  std::optional<Eigen::Vector3d> gaze_origin, gaze_dir;
};

// Prints `message` (if any) and the usage to stderr; returns the exit status 2.
int usage(const char* message);

// Fills `options` from the command line. Returns the exit status when the
// program is to stop here (0 after --help, 2 after a usage error), else nothing.
std::optional<int> parseOptions(int argc, char** argv, CompareOptions& options);

}  // namespace fovea::bench::compare
