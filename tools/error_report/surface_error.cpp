#include "tools/error_report/surface_error.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "pipeline/acuity.h"
#include "pipeline/error_metrics.h"

namespace fovea::tools {

// Leaves of at most this many points are searched linearly.
constexpr std::size_t kSurfaceLeafPoints = 8;

SurfaceErrorEvaluator::SurfaceErrorEvaluator(std::size_t max_sent) : max_sent_(max_sent) {
  points_.reserve(max_sent);
  axis_.reserve(max_sent);
}

// An implicit k-d tree: the node of [lo, hi) is its median at (lo + hi) / 2,
// split on `axis` (cycling x, y, z), the halves left and right of it.
void SurfaceErrorEvaluator::build(std::size_t lo, std::size_t hi, int axis) {
  if (hi - lo <= kSurfaceLeafPoints) return;
  const std::size_t mid = lo + (hi - lo) / 2;
  std::nth_element(points_.begin() + static_cast<std::ptrdiff_t>(lo), points_.begin() + static_cast<std::ptrdiff_t>(mid),
                   points_.begin() + static_cast<std::ptrdiff_t>(hi),
                   [axis](const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return a[axis] < b[axis]; });
  axis_[mid] = static_cast<uint8_t>(axis);
  build(lo, mid, (axis + 1) % 3);
  build(mid + 1, hi, (axis + 1) % 3);
}

void SurfaceErrorEvaluator::nearest(std::size_t lo, std::size_t hi, const Eigen::Vector3d& q, double& best_d2,
                                    std::size_t& best) const {
  if (hi - lo <= kSurfaceLeafPoints) {
    for (std::size_t i = lo; i < hi; ++i) {
      const double d2 = (points_[i] - q).squaredNorm();
      if (d2 < best_d2) best_d2 = d2, best = i;
    }
    return;
  }
  const std::size_t mid = lo + (hi - lo) / 2;
  const double d2 = (points_[mid] - q).squaredNorm();
  if (d2 < best_d2) best_d2 = d2, best = mid;
  const double diff = q[axis_[mid]] - points_[mid][axis_[mid]];
  if (diff < 0.0) {
    nearest(lo, mid, q, best_d2, best);
    if (diff * diff < best_d2) nearest(mid + 1, hi, q, best_d2, best);
  } else {
    nearest(mid + 1, hi, q, best_d2, best);
    if (diff * diff < best_d2) nearest(lo, mid, q, best_d2, best);
  }
}

Status SurfaceErrorEvaluator::evaluate(const pipeline::PointCloud& truth, const pipeline::PointCloud& sent,
                                       const pipeline::Gaze& gaze, double slope, double reference_slope,
                                       SurfaceError& error) {
  error = {};
  if (sent.size() > max_sent_) {
    return {ErrorCode::kCapacityExceeded, "surface error: " + std::to_string(sent.size()) + " sent points, room for " +
                                              std::to_string(max_sent_)};
  }
  const double norm = gaze.direction.norm();
  if (!gaze.origin_m.allFinite() || !gaze.direction.allFinite() || norm == 0.0) {
    return {ErrorCode::kInvalidInput, "surface error: the gaze has no usable origin or direction"};
  }
  const Eigen::Vector3d l = gaze.direction / norm;
  // Everything relative to the truth's origin, in double.
  const Eigen::Vector3d shift = sent.origin_m - truth.origin_m;
  points_.resize(sent.size());
  axis_.assign(sent.size(), 0);
  for (std::size_t i = 0; i < sent.size(); ++i) {
    points_[i] = shift + Eigen::Vector3d(sent.x()[i], sent.y()[i], sent.z()[i]);
  }
  build(0, points_.size(), 0);
  const Eigen::Vector3d truth_to_eye = truth.origin_m - gaze.origin_m;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const Eigen::Vector3d p(truth.x()[i], truth.y()[i], truth.z()[i]);
    const Eigen::Vector3d a = truth_to_eye + p;
    ++error.points;
    if (points_.empty()) {
      if (a.isZero(0.0)) continue;
      ++error.seen, ++error.above_mar, ++error.above_reference_mar;
      continue;
    }
    double best_d2 = std::numeric_limits<double>::infinity();
    std::size_t best = 0;
    nearest(0, points_.size(), p, best_d2, best);
    ++error.with_nearest;
    error.sum_sq_m2 += best_d2;
    const Eigen::Vector3d b = truth_to_eye + points_[best];
    if (a.isZero(0.0) || b.isZero(0.0)) continue;
    const double alpha_deg = pipeline::angleBetweenDeg(a, b);
    const double ecc_deg = pipeline::eccentricityDeg(a, l);
    ++error.seen;
    error.above_mar += alpha_deg > pipeline::marDeg(slope, ecc_deg) ? 1u : 0u;
    error.above_reference_mar += alpha_deg > pipeline::marDeg(reference_slope, ecc_deg) ? 1u : 0u;
  }
  return Status::ok();
}

}  // namespace fovea::tools
