#include "pipeline/acuity_levels.h"

#include <cmath>

namespace fovea::pipeline {

LevelBounds LevelBounds::fromModel(const RegionModel& model) {
  LevelBounds b;
  b.slope = static_cast<float>(model.slope());
  for (int n = 1; n < kMaxRegions; ++n) {
    b.min_allowed_m[n] = static_cast<float>(model.levelMargin() * model.voxelSizeM(n, 0.0));
  }
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
    b.floor_a_m = static_cast<float>(model.floorM());
    b.floor_b_per_m2 = static_cast<float>(model.floorPerM2());
    for (int n = 1; n < kMaxRegions; ++n) b.voxel_m[n] = static_cast<float>(model.voxelSizeM(n, 0.0));
  }
  if (model.viewCull() != ViewCull::kOff) {
    b.cull_region = model.viewCull() == ViewCull::kDrop ? kRegionCulled : static_cast<uint8_t>(kMaxRegions - 1);
    b.cull_cos = static_cast<float>(std::cos(model.viewCullDeg() * (3.14159265358979323846 / 180.0)));
  }
  return b;
}

uint8_t LevelBounds::classify(float r_m, float ecc_deg) const {
  const float allowed = r_m * sinSpec((slope * ecc_deg + kLevelsMar0Deg) * kLevelsDegToRad);
  uint8_t level = 0;
  for (int n = 1; n < kMaxRegions; ++n) level += min_allowed_m[n] <= allowed ? 1 : 0;
  return level < floor_level ? floor_level : level;
}

uint8_t LevelBounds::noiseFloorLevel(float s2_m2) const {
  if (!(floor_b_per_m2 > 0.0f)) return 0;
  const float floor = floor_a_m + floor_b_per_m2 * s2_m2;
  uint8_t lift = 1;
  for (int n = 1; n < kMaxRegions; ++n) lift += voxel_m[n] < floor ? 1 : 0;
  return lift > kMaxRegions - 1 ? static_cast<uint8_t>(kMaxRegions - 1) : lift;
}

void assignLevelsRef(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, uint8_t* region_out,
                     PartitionCounts& counts) {
  counts = {};
  // P - H = (origin - H) + p: the large parts cancel in double, the rest is float.
  const Eigen::Vector3f ome = (cloud.origin_m - gaze.origin_m).cast<float>();
  const Eigen::Vector3f l = gaze.direction.cast<float>();
  const Eigen::Vector3f f = gaze.view_forward.cast<float>();
  const float growth = static_cast<float>(gaze.fovea_growth_deg);
  const bool cull = bounds.cull_region != 0 && gaze.view_known;
  const float* x = cloud.x();
  const float* y = cloud.y();
  const float* z = cloud.z();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (!std::isfinite(x[i]) || !std::isfinite(y[i]) || !std::isfinite(z[i])) {
      region_out[i] = kRegionInvalid;
      ++counts.invalid;
      continue;
    }
    const float vx = ome.x() + x[i];
    const float vy = ome.y() + y[i];
    const float vz = ome.z() + z[i];
    // t along the gaze, d from its axis (axialRadial's expressions, in float).
    const float t = vx * l.x() + vy * l.y() + vz * l.z();
    const float rx = vx - t * l.x();
    const float ry = vy - t * l.y();
    const float rz = vz - t * l.z();
    const float d = std::sqrt(rx * rx + ry * ry + rz * rz);
    const float r = std::sqrt(vx * vx + vy * vy + vz * vz);
    float ecc = eccentricitySpecDeg(t, d) - growth;
    ecc = ecc < 0.0f ? 0.0f : ecc;
    uint8_t level = bounds.classify(r, ecc);
    if (bounds.floor_b_per_m2 > 0.0f) {
      const uint8_t lift = bounds.noiseFloorLevel(x[i] * x[i] + y[i] * y[i] + z[i] * z[i]);
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
