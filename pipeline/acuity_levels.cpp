#include "pipeline/acuity_levels.h"

#include <algorithm>
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
  const float allowed = allowedM(r_m, ecc_deg);
  uint8_t level = 0;
  for (int n = 1; n < kMaxRegions; ++n) level += min_allowed_m[n] <= allowed ? 1 : 0;
  return level < floor_level ? floor_level : level;
}

uint8_t LevelBounds::lowestLevel(float s2_m2) const {
  const uint8_t lift = noiseFloorLevel(s2_m2);
  return lift < floor_level ? floor_level : lift;
}

uint8_t LevelBounds::noiseFloorLevel(float s2_m2) const {
  if (!(floor_b_per_m2 > 0.0f)) return 0;
  const float floor = floor_a_m + floor_b_per_m2 * s2_m2;
  uint8_t lift = 1;
  for (int n = 1; n < kMaxRegions; ++n) lift += voxel_m[n] < floor ? 1 : 0;
  return lift > kMaxRegions - 1 ? static_cast<uint8_t>(kMaxRegions - 1) : lift;
}

namespace {

// The gaze as the specification uses it, in float.
struct GazeSpec {
  Eigen::Vector3f origin_minus_eye;  // P - H = (origin - H) + p: the large parts cancel in double
  Eigen::Vector3f direction;
  Eigen::Vector3f forward;  // the head's axis (the view cull)
  float growth_deg = 0.0f;
  bool cull = false;
  float cull_cos = -1.0f;

  // The view cull's test for v = P - H at distance r: v.F < r cos(view_cull_deg).
  bool outsideView(float vx, float vy, float vz, float r) const {
    return cull && vx * forward.x() + vy * forward.y() + vz * forward.z() < r * cull_cos;
  }
};

GazeSpec gazeSpec(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds) {
  GazeSpec g;
  g.origin_minus_eye = (cloud.origin_m - gaze.origin_m).cast<float>();
  g.direction = gaze.direction.cast<float>();
  g.forward = gaze.view_forward.cast<float>();
  g.growth_deg = static_cast<float>(gaze.fovea_growth_deg);
  g.cull = bounds.cull_region != 0 && gaze.view_known;
  g.cull_cos = bounds.cull_cos;
  return g;
}

}  // namespace

void assignLevelsRef(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, uint8_t* region_out,
                     PartitionCounts& counts) {
  counts = {};
  const GazeSpec g = gazeSpec(cloud, gaze, bounds);
  const float* x = cloud.x();
  const float* y = cloud.y();
  const float* z = cloud.z();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (!std::isfinite(x[i]) || !std::isfinite(y[i]) || !std::isfinite(z[i])) {
      region_out[i] = kRegionInvalid;
      ++counts.invalid;
      continue;
    }
    const float vx = g.origin_minus_eye.x() + x[i];
    const float vy = g.origin_minus_eye.y() + y[i];
    const float vz = g.origin_minus_eye.z() + z[i];
    const EyeView view = eyeViewSpec(vx, vy, vz, g.direction, g.growth_deg);
    uint8_t level = bounds.classify(view.r_m, view.ecc_deg);
    const uint8_t lowest = bounds.lowestLevel(x[i] * x[i] + y[i] * y[i] + z[i] * z[i]);
    level = level < lowest ? lowest : level;
    if (g.outsideView(vx, vy, vz, view.r_m)) level = bounds.cull_region;
    region_out[i] = level;
    if (level == kRegionCulled) {
      ++counts.culled;
    } else {
      ++counts.per_region[level];
    }
  }
}

std::size_t refineTestRef(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, const PointCloud& out,
                          const uint32_t* representative, const uint8_t* region, uint8_t* state) {
  const GazeSpec g = gazeSpec(cloud, gaze, bounds);
  // P - R = (cloud's origin - out's origin) + p - q, formed as P - H is.
  const Eigen::Vector3f oo = (cloud.origin_m - out.origin_m).cast<float>();
  const float* x = cloud.x();
  const float* y = cloud.y();
  const float* z = cloud.z();
  const float* ox = out.x();
  const float* oy = out.y();
  const float* oz = out.z();
  std::size_t beyond = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    state[i] = kRefineStay;
    const uint8_t level = region[i];
    if (level == 0 || level >= kMaxRegions) continue;  // raw, invalid or culled
    if (level <= bounds.lowestLevel(x[i] * x[i] + y[i] * y[i] + z[i] * z[i])) continue;
    const uint32_t o = representative[i];
    if (o >= out.size()) continue;  // no representative: nothing to measure
    const float vx = g.origin_minus_eye.x() + x[i];
    const float vy = g.origin_minus_eye.y() + y[i];
    const float vz = g.origin_minus_eye.z() + z[i];
    const EyeView view = eyeViewSpec(vx, vy, vz, g.direction, g.growth_deg);
    if (g.outsideView(vx, vy, vz, view.r_m)) continue;
    const float ex = oo.x() + x[i] - ox[o];
    const float ey = oo.y() + y[i] - oy[o];
    const float ez = oo.z() + z[i] - oz[o];
    const float bx = vx - ex;
    const float by = vy - ey;
    const float bz = vz - ez;
    const float cx = ey * vz - ez * vy;
    const float cy = ez * vx - ex * vz;
    const float cz = ex * vy - ey * vx;
    const float allowed = bounds.allowedM(view.r_m, view.ecc_deg);
    const float b2 = bx * bx + by * by + bz * bz;
    const bool ahead = vx * bx + vy * by + vz * bz > 0.0f;
    const float c2 = cx * cx + cy * cy + cz * cz;
    const bool within = ahead && c2 <= b2 * (allowed * allowed);
    state[i] = within ? kRefineWithin : kRefineBeyond;
    beyond += within ? 0 : 1;
  }
  return beyond;
}

std::size_t moveRefinedVoxels(const uint8_t* state, const uint32_t* representative, std::size_t n,
                              std::size_t out_size, uint8_t* voxel_beyond, uint8_t* region, PartitionCounts& counts) {
  std::fill(voxel_beyond, voxel_beyond + out_size, uint8_t{0});
  for (std::size_t i = 0; i < n; ++i) {
    if (state[i] == kRefineBeyond) voxel_beyond[representative[i]] = 1;
  }
  // One level at a time: dropping as many levels as the ratio alpha / MAR asks
  // overshoots (measured, moving single points: 46 337 points against 41 348 for the
  // same error after 3 passes), since the centroid of what stays moves too.
  std::size_t moved = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (state[i] == kRefineStay || voxel_beyond[representative[i]] == 0) continue;
    const uint8_t level = region[i];
    region[i] = static_cast<uint8_t>(level - 1);
    --counts.per_region[level];
    ++counts.per_region[level - 1];
    ++moved;
  }
  return moved;
}

}  // namespace fovea::pipeline
