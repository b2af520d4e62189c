#include "pipeline/partition.h"

#include <numbers>

namespace fovea::pipeline {

Result<Gaze> normalizeGaze(const Gaze& gaze) {
  if (!gaze.origin_m.allFinite()) {
    return Result<Gaze>(ErrorCode::kInvalidInput, "gaze: origin is not finite");
  }
  if (!gaze.direction.allFinite()) {
    return Result<Gaze>(ErrorCode::kInvalidInput, "gaze: direction is not finite");
  }
  const double norm = gaze.direction.norm();
  // Below this the direction is noise, and 1/norm could overflow.
  if (!(norm > 1e-12)) {
    return Result<Gaze>(ErrorCode::kInvalidInput, "gaze: direction has zero length");
  }
  Gaze unit = gaze;
  unit.direction = gaze.direction / norm;
  if (!(gaze.fovea_growth_deg >= 0.0 && gaze.fovea_growth_deg <= 180.0)) {
    return Result<Gaze>(ErrorCode::kInvalidInput, "gaze: fovea growth is outside [0, 180] degrees");
  }
  if (gaze.view_known) {
    const double view_norm = gaze.view_forward.allFinite() ? gaze.view_forward.norm() : 0.0;
    if (!(view_norm > 1e-12)) {
      return Result<Gaze>(ErrorCode::kInvalidInput, "gaze: view direction is not finite or has zero length");
    }
    unit.view_forward = gaze.view_forward / view_norm;
  }
  return unit;
}

ConeBounds ConeBounds::fromModel(const RegionModel& model) {
  ConeBounds bounds;
  bounds.count = model.boundCount();
  for (int j = 0; j < bounds.count; ++j) {
    const double e = model.boundDeg(j);
    if (e < 90.0) {
      bounds.kind[j] = Kind::kBelow90;
      bounds.tan_e[j] = std::tan(e * std::numbers::pi / 180.0);
    } else if (e == 90.0) {
      bounds.kind[j] = Kind::kAt90;
      bounds.tan_e[j] = 0.0;
    } else {
      bounds.kind[j] = Kind::kAbove90;
      bounds.tan_e[j] = std::tan((180.0 - e) * std::numbers::pi / 180.0);
    }
  }
  return bounds;
}

void partitionRef(const PointCloud& cloud, const Gaze& gaze, const ConeBounds& bounds,
                  uint8_t* region_out, PartitionCounts& counts) {
  counts = {};
  // P - H = (origin - H) + p: the large parts cancel in double before the small
  // float offset is added.
  const Eigen::Vector3d origin_minus_eye = cloud.origin_m - gaze.origin_m;
  const float* x = cloud.x();
  const float* y = cloud.y();
  const float* z = cloud.z();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (!std::isfinite(x[i]) || !std::isfinite(y[i]) || !std::isfinite(z[i])) {
      region_out[i] = kRegionInvalid;
      ++counts.invalid;
      continue;
    }
    const double vx = origin_minus_eye.x() + static_cast<double>(x[i]);
    const double vy = origin_minus_eye.y() + static_cast<double>(y[i]);
    const double vz = origin_minus_eye.z() + static_cast<double>(z[i]);
    const AxialRadial ar = axialRadial(vx, vy, vz, gaze.direction);
    const uint8_t region = bounds.classify(ar.t, ar.d);
    region_out[i] = region;
    ++counts.per_region[region];
  }
}

}  // namespace fovea::pipeline
