#include "tools/eval/quality/held_error.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <numbers>
#include <unordered_map>
#include <vector>

#include <Eigen/Geometry>

#include "pipeline/acuity.h"

namespace fovea::tools::eval {

double heldShareAboveMar(const pipeline::PointCloud& input, const pipeline::PointCloud& drawn, const EyeCamera& eye,
                         const Eigen::Vector3d& gaze_direction, double slope, std::size_t* seen_out) {
  constexpr double kCell = 0.02;
  constexpr int kRings = 5;  // 10 cm
  const auto cellOf = [](const Eigen::Vector3d& p) {
    return Eigen::Vector3i(static_cast<int>(std::floor(p.x() / kCell)), static_cast<int>(std::floor(p.y() / kCell)),
                           static_cast<int>(std::floor(p.z() / kCell)));
  };
  const auto cellKey = [](const Eigen::Vector3i& c) {
    return (static_cast<int64_t>(c.x() & 0x1fffff) << 42) | (static_cast<int64_t>(c.y() & 0x1fffff) << 21) |
           static_cast<int64_t>(c.z() & 0x1fffff);
  };
  std::unordered_map<int64_t, std::vector<uint32_t>> grid;
  grid.reserve(drawn.size() / 8 + 1);
  for (std::size_t i = 0; i < drawn.size(); ++i) grid[cellKey(cellOf(drawn.world(i)))].push_back(static_cast<uint32_t>(i));
  const Eigen::Vector3d l = gaze_direction.normalized();
  std::size_t above = 0, seen = 0;
  for (std::size_t t = 0; t < input.size(); ++t) {
    const Eigen::Vector3d p = input.world(t);
    Eigen::Vector2d pixel;
    if (!p.allFinite() || !eye.project(p, pixel) || pixel.x() < 0 || pixel.y() < 0 || pixel.x() >= eye.width ||
        pixel.y() >= eye.height) {
      continue;  // outside the image: not drawn, not judged
    }
    const Eigen::Vector3i c = cellOf(p);
    double best = std::numeric_limits<double>::infinity();
    Eigen::Vector3d nearest = Eigen::Vector3d::Zero();
    for (int r = 0; r <= kRings && !(best <= (r - 1) * kCell); ++r) {
      for (int dx = -r; dx <= r; ++dx) {
        for (int dy = -r; dy <= r; ++dy) {
          for (int dz = -r; dz <= r; ++dz) {
            if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;  // the shell only
            const auto it = grid.find(cellKey(c + Eigen::Vector3i(dx, dy, dz)));
            if (it == grid.end()) continue;
            for (uint32_t i : it->second) {
              const Eigen::Vector3d q = drawn.world(i);
              const double d = (q - p).norm();
              if (d < best) {
                best = d;
                nearest = q;
              }
            }
          }
        }
      }
    }
    ++seen;
    if (!(best <= kRings * kCell)) {
      ++above;  // nothing drawn within 10 cm
      continue;
    }
    const Eigen::Vector3d a = p - eye.position_m, b = nearest - eye.position_m;
    if (a.isZero() || b.isZero()) {
      --seen;  // no direction at the eye (pipeline/error_metrics.h's at_eye)
      continue;
    }
    // pipeline/error_metrics.h's angles (Eq. 1), in degrees.
    const double alpha = std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / std::numbers::pi;
    const double ecc = std::atan2(a.cross(l).norm(), a.dot(l)) * 180.0 / std::numbers::pi;
    above += alpha > pipeline::marDeg(slope, ecc) ? 1 : 0;
  }
  if (seen_out != nullptr) *seen_out = seen;
  return seen > 0 ? static_cast<double>(above) / static_cast<double>(seen) : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace fovea::tools::eval
