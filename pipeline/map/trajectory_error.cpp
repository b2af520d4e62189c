#include "pipeline/map/trajectory_error.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Geometry>

namespace fovea::pipeline::map {

Result<TrajectoryError> absoluteTrajectoryError(std::span<const Eigen::Vector3d> estimated,
                                                std::span<const Eigen::Vector3d> truth) {
  if (estimated.size() != truth.size()) {
    return Result<TrajectoryError>(ErrorCode::kInvalidArgument,
                                   "trajectory error: " + std::to_string(estimated.size()) + " estimated positions against " +
                                       std::to_string(truth.size()) + " true ones");
  }
  const std::size_t n = estimated.size();
  if (n < 3) return Result<TrajectoryError>(ErrorCode::kInvalidArgument, "trajectory error: fewer than 3 pairs");
  Eigen::Matrix3Xd src(3, static_cast<Eigen::Index>(n)), dst(3, static_cast<Eigen::Index>(n));
  for (std::size_t i = 0; i < n; ++i) {
    if (!estimated[i].allFinite() || !truth[i].allFinite()) {
      return Result<TrajectoryError>(ErrorCode::kInvalidArgument,
                                     "trajectory error: pair " + std::to_string(i) + " has a non-finite coordinate");
    }
    src.col(static_cast<Eigen::Index>(i)) = estimated[i];
    dst.col(static_cast<Eigen::Index>(i)) = truth[i];
  }
  const Eigen::Matrix4d T = Eigen::umeyama(src, dst, /*with_scaling=*/false);
  TrajectoryError e;
  e.pairs = n;
  e.R = T.topLeftCorner<3, 3>();
  e.t = T.topRightCorner<3, 1>();
  std::vector<double> d(n);
  double sq = 0.0, sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    d[i] = (e.R * estimated[i] + e.t - truth[i]).norm();
    sq += d[i] * d[i];
    sum += d[i];
    e.max_m = std::max(e.max_m, d[i]);
  }
  e.rmse_m = std::sqrt(sq / static_cast<double>(n));
  e.mean_m = sum / static_cast<double>(n);
  std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(n / 2), d.end());
  e.median_m = d[n / 2];
  return e;
}

}  // namespace fovea::pipeline::map
