// Test clouds and an independent brute-force reference of the foveation method,
// written the obvious way (long double, atan2, std::map) to check the kernels.
#pragma once

#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <tuple>
#include <vector>

#include <Eigen/Core>

#include "pipeline/acuity.h"
#include "pipeline/point_cloud.h"

namespace fovea::test {

using pipeline::PointCloud;

// A validated region model (aborts on an invalid one: a bug in the test).
inline pipeline::RegionModel regionModel(pipeline::Preset preset, std::vector<double> custom_bounds_deg = {},
                                         double far_ecc_deg = 90.0) {
  pipeline::AcuityConfig config;
  config.preset = preset;
  config.custom_bounds_deg = std::move(custom_bounds_deg);
  config.far_ecc_deg = far_ecc_deg;
  return pipeline::RegionModel::create(config).value();
}

inline std::vector<double> boundsOf(const pipeline::RegionModel& model) {
  std::vector<double> bounds;
  for (int j = 0; j < model.boundCount(); ++j) bounds.push_back(model.boundDeg(j));
  return bounds;
}

// n points uniform in origin +- half_extent (each axis), random colours.
inline PointCloud randomCloud(std::size_t n, const Eigen::Vector3d& origin_m, float half_extent_m, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> coord(-half_extent_m, half_extent_m);
  std::uniform_int_distribution<uint32_t> colour(0, 0xFFFFFF);
  PointCloud cloud(n);
  cloud.origin_m = origin_m;
  for (std::size_t i = 0; i < n; ++i) {
    const float x = coord(rng), y = coord(rng), z = coord(rng);
    (void)cloud.push(x, y, z, colour(rng));
  }
  return cloud;
}

inline Eigen::Vector3d randomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Vector3d v(g(rng), g(rng), g(rng));
  return v.normalized();
}

// Eccentricity of world point p seen from eye h along unit gaze l, in degrees.
inline long double bruteEccentricityDeg(const Eigen::Vector3d& origin, float px, float py, float pz,
                                        const Eigen::Vector3d& h, const Eigen::Vector3d& l) {
  const long double vx = (static_cast<long double>(origin.x()) + px) - h.x();
  const long double vy = (static_cast<long double>(origin.y()) + py) - h.y();
  const long double vz = (static_cast<long double>(origin.z()) + pz) - h.z();
  const long double t = vx * l.x() + vy * l.y() + vz * l.z();
  const long double cx = vy * l.z() - vz * l.y();
  const long double cy = vz * l.x() - vx * l.z();
  const long double cz = vx * l.y() - vy * l.x();
  const long double cross = std::sqrt(cx * cx + cy * cy + cz * cz);
  if (cross == 0.0L && t == 0.0L) return 0.0L;  // the eye itself
  return std::atan2(cross, t) * 180.0L / 3.14159265358979323846264338327950288L;
}

inline int bruteRegion(long double ecc_deg, const std::vector<double>& bounds_deg) {
  for (std::size_t j = 0; j < bounds_deg.size(); ++j) {
    if (ecc_deg <= bounds_deg[j]) return static_cast<int>(j);
  }
  return static_cast<int>(bounds_deg.size());
}

struct BruteVoxel {
  uint64_t count = 0;
  long double sx = 0, sy = 0, sz = 0;  // world coordinates
  uint64_t sr = 0, sg = 0, sb = 0;
};
using BruteKey = std::tuple<int, int64_t, int64_t, int64_t>;  // region, i, j, k

inline BruteKey bruteKey(int region, long double wx, long double wy, long double wz, double voxel_m) {
  return {region, static_cast<int64_t>(std::floor(wx / voxel_m)), static_cast<int64_t>(std::floor(wy / voxel_m)),
          static_cast<int64_t>(std::floor(wz / voxel_m))};
}

}  // namespace fovea::test
