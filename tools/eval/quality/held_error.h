// fovea-eval's above-MAR share for a cloud given as drawn, without
// representatives: what fovea-operator held at a frame (MAP-DELTA, docs/eval.md).
#pragma once

#include <cstddef>

#include <Eigen/Core>

#include "pipeline/point_cloud.h"
#include "tools/eval/quality/splat_renderer.h"

namespace fovea::tools::eval {

// The share of `input`'s points inside the eye's image (in front of its near
// plane and projecting into its width x height) whose nearest point of `drawn`
// is displaced, seen from the eye, by more than the MAR at the input point's
// eccentricity around the unit gaze (MAR = slope x ecc + 1 arcmin, strictly
// greater; pipeline/error_metrics.h's angles), as fovea-map-delta measures it
// (bench/map_delta.cpp). An input point with no drawn point within 10 cm counts
// as above; one at the eye (no direction) is left out. Nearest by a hash grid of
// 2 cm cells, searched in shells out to 10 cm. NaN when no input point is judged.
// Allocates (the grid). `seen` (optional): the input points judged.
double heldShareAboveMar(const pipeline::PointCloud& input, const pipeline::PointCloud& drawn, const EyeCamera& eye,
                         const Eigen::Vector3d& gaze_direction, double slope, std::size_t* seen = nullptr);

}  // namespace fovea::tools::eval
