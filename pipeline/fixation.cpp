#include "pipeline/fixation.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

namespace fovea::pipeline {

std::string_view fixationModeName(FixationMode mode) {
  switch (mode) {
    case FixationMode::kHit: return "hit";
    case FixationMode::kCentroid: return "centroid";
    case FixationMode::kFixed: return "fixed";
  }
  return "?";
}

std::string_view fixationSourceName(FixationSource source) {
  switch (source) {
    case FixationSource::kHit: return "hit";
    case FixationSource::kCentroid: return "centroid";
    case FixationSource::kFixed: return "fixed";
    case FixationSource::kFallback: return "fallback";
    case FixationSource::kNone: return "none";
  }
  return "?";
}

Result<FixationMode> parseFixationMode(std::string_view text) {
  if (text == "hit") return FixationMode::kHit;
  if (text == "centroid") return FixationMode::kCentroid;
  if (text == "fixed") return FixationMode::kFixed;
  return Result<FixationMode>(ErrorCode::kInvalidArgument,
                              "fixation: unknown mode '" + std::string(text) + "' (use hit, centroid or fixed)");
}

Status FixationConfig::validate() const {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(fixed_m)) return {ErrorCode::kInvalidArgument, "fixation.fixed_m: must be a positive distance"};
  if (!positive(fallback_m)) return {ErrorCode::kInvalidArgument, "fixation.fallback_m: must be a positive distance"};
  if (!positive(min_m)) return {ErrorCode::kInvalidArgument, "fixation.min_m: must be a positive distance"};
  if (!(std::isfinite(hit_cone_deg) && hit_cone_deg > 0.0 && hit_cone_deg < 90.0)) {
    return {ErrorCode::kInvalidArgument, "fixation.hit_cone_deg: must be in (0, 90) degrees"};
  }
  if (!(hit_percentile >= 0.0 && hit_percentile <= 1.0)) {
    return {ErrorCode::kInvalidArgument, "fixation.hit_percentile: must be in [0, 1]"};
  }
  return Status::ok();
}

namespace {

Fixation centroidFixation(const PointCloud& cloud, const uint8_t* region, const Gaze& gaze) {
  const Eigen::Vector3d origin_minus_eye = cloud.origin_m - gaze.origin_m;
  // Sum the small offsets in double; add the large origin difference once.
  double sx = 0.0, sy = 0.0, sz = 0.0;
  uint32_t n = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (region[i] != 0) continue;
    sx += cloud.x()[i];
    sy += cloud.y()[i];
    sz += cloud.z()[i];
    ++n;
  }
  Fixation f;
  if (n == 0) return f;
  const Eigen::Vector3d centroid_minus_eye = origin_minus_eye + Eigen::Vector3d(sx / n, sy / n, sz / n);
  f.d0_m = centroid_minus_eye.norm();
  f.source = FixationSource::kCentroid;
  f.support = n;
  return f;
}

Fixation hitFixation(const PointCloud& cloud, const uint8_t* region, const Gaze& gaze,
                     const FixationConfig& config, double* t_scratch) {
  const double tan_cone = std::tan(config.hit_cone_deg * std::numbers::pi / 180.0);
  const Eigen::Vector3d origin_minus_eye = cloud.origin_m - gaze.origin_m;
  std::size_t n = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (region[i] != 0) continue;  // the hit cone never reaches past the fovea
    const AxialRadial ar = axialRadial(origin_minus_eye.x() + cloud.x()[i], origin_minus_eye.y() + cloud.y()[i],
                                       origin_minus_eye.z() + cloud.z()[i], gaze.direction);
    if (ar.t > 0.0 && ar.d <= tan_cone * ar.t) t_scratch[n++] = ar.t;
  }
  Fixation f;
  if (n == 0) return f;
  const auto k = static_cast<std::size_t>(config.hit_percentile * static_cast<double>(n - 1));
  std::nth_element(t_scratch, t_scratch + k, t_scratch + n);
  f.d0_m = t_scratch[k];
  f.source = FixationSource::kHit;
  f.support = static_cast<uint32_t>(n);
  return f;
}

}  // namespace

Fixation computeFixation(const PointCloud& cloud, const uint8_t* region, const Gaze& gaze,
                         const FixationConfig& config, double* t_scratch) {
  Fixation f;
  switch (config.mode) {
    case FixationMode::kFixed:
      f.d0_m = config.fixed_m;
      f.source = FixationSource::kFixed;
      break;
    case FixationMode::kHit:
      f = hitFixation(cloud, region, gaze, config, t_scratch);
      if (f.support == 0) f = centroidFixation(cloud, region, gaze);
      break;
    case FixationMode::kCentroid:
      f = centroidFixation(cloud, region, gaze);
      break;
  }
  if (f.source != FixationSource::kFixed && f.support == 0) {
    f.d0_m = config.fallback_m;
    f.source = FixationSource::kFallback;
  }
  if (!(f.d0_m >= config.min_m)) {
    f.d0_m = config.min_m;
    f.clamped = true;
  }
  return f;
}

}  // namespace fovea::pipeline
