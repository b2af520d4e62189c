#include "pipeline/eye_speed.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <Eigen/Geometry>

namespace fovea::pipeline {

void EyeSpeed::observe(const Eigen::Vector3d& direction, int64_t stamp_ns) {
  if (have_previous_ && stamp_ns == previous_stamp_ns_) return;
  const double norm = direction.allFinite() ? direction.norm() : 0.0;
  if (!(norm > 0.0)) {
    reset();
    return;
  }
  const Eigen::Vector3d unit = direction / norm;
  // Stamps come from the operator: compare first, then subtract unsigned, so that
  // stamps far apart cannot overflow.
  if (have_previous_ && stamp_ns > previous_stamp_ns_) {
    const uint64_t dt_ns = static_cast<uint64_t>(stamp_ns) - static_cast<uint64_t>(previous_stamp_ns_);
    // atan2 of the cross and dot products: accurate for small angles too (acos is not).
    const double angle_deg = std::atan2(previous_.cross(unit).norm(), previous_.dot(unit)) * 180.0 / std::numbers::pi;
    speed_deg_s_ = std::min(kMaxEyeSpeedDegS, angle_deg / (static_cast<double>(dt_ns) * 1e-9));
  } else {
    speed_deg_s_ = 0.0;
  }
  have_previous_ = true;
  previous_ = unit;
  previous_stamp_ns_ = stamp_ns;
}

void EyeSpeed::reset() { *this = EyeSpeed{}; }

double foveaGrowthDeg(double speed_deg_s, int64_t age_ns, int64_t lead_ns, double max_deg) {
  const double ahead_s = static_cast<double>(std::max<int64_t>(0, age_ns) + lead_ns) * 1e-9;
  return std::min(max_deg, speed_deg_s * ahead_s);
}

}  // namespace fovea::pipeline
