#include "pipeline/acuity_levels.h"

#include <cmath>

namespace fovea::pipeline {

namespace {
constexpr double kDegToRad = kLevelsPi / 180.0;
}  // namespace

LevelBounds LevelBounds::fromModel(const RegionModel& model) {
  LevelBounds b;
  b.slope = model.slope();
  for (int n = 1; n < kMaxRegions; ++n) b.min_allowed_m[n] = model.levelMargin() * model.voxelSizeM(n, 0.0);
  if (model.floorM() > 0.0) {
    b.floor_level = kMaxRegions - 1;
    for (int n = 1; n < kMaxRegions; ++n) {
      if (model.voxelSizeM(n, 0.0) >= model.floorM()) {
        b.floor_level = static_cast<uint8_t>(n);
        break;
      }
    }
  }
  if (model.floorPerM2() > 0.0) {
    b.floor_a_m = model.floorM();
    b.floor_b_per_m2 = model.floorPerM2();
    for (int n = 1; n < kMaxRegions; ++n) b.voxel_m[n] = model.voxelSizeM(n, 0.0);
  }
  if (model.viewCull() != ViewCull::kOff) {
    b.cull_region = model.viewCull() == ViewCull::kDrop ? kRegionCulled : static_cast<uint8_t>(kMaxRegions - 1);
    b.cull_cos = std::cos(model.viewCullDeg() * kDegToRad);
  }
  return b;
}

uint8_t LevelBounds::classify(double r_m, double ecc_deg) const {
  const double allowed = r_m * sinSpec((slope * ecc_deg + kMar0Deg) * kDegToRad);
  uint8_t level = 0;
  for (int n = 1; n < kMaxRegions; ++n) level += min_allowed_m[n] <= allowed ? 1 : 0;
  return level < floor_level ? floor_level : level;
}

uint8_t LevelBounds::noiseFloorLevel(double s2_m2) const {
  if (!(floor_b_per_m2 > 0.0)) return 0;
  const double floor = floor_a_m + floor_b_per_m2 * s2_m2;
  uint8_t lift = 1;
  for (int n = 1; n < kMaxRegions; ++n) lift += voxel_m[n] < floor ? 1 : 0;
  return lift > kMaxRegions - 1 ? static_cast<uint8_t>(kMaxRegions - 1) : lift;
}

void assignLevelsRef(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, uint8_t* region_out,
                     PartitionCounts& counts) {
  counts = {};
  // P - H = (origin - H) + p: the large parts cancel in double first (as the partition).
  const Eigen::Vector3d origin_minus_eye = cloud.origin_m - gaze.origin_m;
  const bool cull = bounds.cull_region != 0 && gaze.view_known;
  const Eigen::Vector3d& f = gaze.view_forward;
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
    const double r = std::sqrt(vx * vx + vy * vy + vz * vz);
    double ecc = eccentricitySpecDeg(ar.t, ar.d) - gaze.fovea_growth_deg;
    ecc = ecc < 0.0 ? 0.0 : ecc;
    uint8_t level = bounds.classify(r, ecc);
    if (bounds.floor_b_per_m2 > 0.0) {
      const double px = x[i], py = y[i], pz = z[i];
      const uint8_t lift = bounds.noiseFloorLevel(px * px + py * py + pz * pz);
      level = level < lift ? lift : level;
    }
    if (cull && vx * f.x() + vy * f.y() + vz * f.z() < r * bounds.cull_cos) level = bounds.cull_region;
    region_out[i] = level;
    if (level == kRegionCulled) {
      ++counts.culled;
    } else {
      ++counts.per_region[level];
    }
  }
}

}  // namespace fovea::pipeline
