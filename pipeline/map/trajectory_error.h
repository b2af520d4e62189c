// Absolute trajectory error (ATE), as the TUM RGB-D benchmark defines it
// (Sturm et al. 2012, its evaluate_ate.py): the estimated camera positions are
// rigidly aligned to the ground truth's (rotation and translation, no scale:
// Horn's closed form, here Eigen's Umeyama with scaling off, which solves the
// same least-squares problem), then the translational differences are
// summarised. Pairs are given already associated (same frame, same stamp).
// An evaluation tool: it allocates.
#pragma once

#include <cstddef>
#include <span>

#include <Eigen/Core>

#include "core/result.h"

namespace fovea::pipeline::map {

struct TrajectoryError {
  std::size_t pairs = 0;
  double rmse_m = 0.0;
  double mean_m = 0.0;
  double median_m = 0.0;
  double max_m = 0.0;
  // The alignment: truth ~= R * estimated + t.
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
};

// kInvalidArgument when the spans differ in length, hold fewer than 3 pairs or a
// non-finite coordinate. Degenerate inputs (all positions on one line) still
// give the least-squares alignment Umeyama finds; their error is then what it is.
Result<TrajectoryError> absoluteTrajectoryError(std::span<const Eigen::Vector3d> estimated,
                                                std::span<const Eigen::Vector3d> truth);

}  // namespace fovea::pipeline::map
