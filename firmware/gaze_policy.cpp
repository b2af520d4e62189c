#include "firmware/gaze_policy.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include <Eigen/Geometry>

namespace fovea::firmware {

Status GazePolicyConfig::validate() const {
  if (timeout_ns <= 0) return {ErrorCode::kInvalidArgument, "gaze timeout: must be positive"};
  if (!(fallback_voxel_m >= 0.001 && fallback_voxel_m <= 1.0)) {
    return {ErrorCode::kInvalidArgument, "fallback voxel: must be within 0.001 .. 1 m"};
  }
  if (!(growth_max_deg >= 0.0 && growth_max_deg <= 90.0)) {
    return {ErrorCode::kInvalidArgument, "gaze growth bound: must be within 0 .. 90 degrees"};
  }
  if (lead_ns < 0 || lead_ns > 10'000'000'000) {
    return {ErrorCode::kInvalidArgument, "gaze lead: must be within 0 .. 10 s"};
  }
  return Status::ok();
}

std::string_view gazeSourceName(GazeSource source) {
  switch (source) {
    case GazeSource::kOperator: return "operator";
    case GazeSource::kNoGazeYet: return "no operator gaze (fallback)";
    case GazeSource::kStale: return "stale gaze (fallback)";
  }
  return "?";
}

pipeline::FoveationConfig uniformFoveationConfig(double voxel_m) {
  pipeline::FoveationConfig config;
  config.acuity.preset = pipeline::Preset::kCustom;
  config.acuity.custom_bounds_deg = {0.001};
  config.acuity.slope = pipeline::kDefaultSlope;
  config.acuity.far_ecc_deg = pipeline::kDefaultFarEccDeg;
  // Region 1 is the last: v_1 = d0 * tan(MAR0) * MAR(far_ecc) / MAR0 (Eq. 5-6).
  const double scale = pipeline::marDeg(config.acuity.slope, config.acuity.far_ecc_deg) / pipeline::kMar0Deg;
  config.fixation.mode = pipeline::FixationMode::kFixed;
  config.fixation.fixed_m = voxel_m / (pipeline::foveaVoxelSizeM(1.0) * scale);
  config.fixation.min_m = std::min(config.fixation.min_m, config.fixation.fixed_m);
  return config;
}

GazePolicy::GazePolicy(const GazePolicyConfig& config, const pipeline::FoveationConfig& operator_config)
    : config_(config), operator_config_(operator_config), fallback_config_(uniformFoveationConfig(config.fallback_voxel_m)) {}

namespace {
// Faster than any saccade: a larger figure comes from clock jitter between two
// samples stamped close together.
constexpr double kMaxEyeSpeedDegS = 1000.0;
}  // namespace

GazePolicy::Decision GazePolicy::decide(const OperatorGaze& newest, int64_t now_ns, const hal::Pose& camera) {
  Decision d;
  if (newest.valid) {
    d.age_ns = now_ns - newest.received_ns;
    d.source = d.age_ns <= config_.timeout_ns ? GazeSource::kOperator : GazeSource::kStale;
    if (!have_previous_ || newest.stamp_ns != previous_stamp_ns_) {
      const Eigen::Vector3d direction = newest.gaze.direction.normalized();
      const int64_t dt_ns = newest.stamp_ns - previous_stamp_ns_;
      if (have_previous_ && dt_ns > 0 && direction.allFinite()) {
        const double angle_deg =
            std::atan2(previous_direction_.cross(direction).norm(), previous_direction_.dot(direction)) * 180.0 /
            std::numbers::pi;
        eye_speed_deg_s_ = std::min(kMaxEyeSpeedDegS, angle_deg / (static_cast<double>(dt_ns) * 1e-9));
      } else {
        eye_speed_deg_s_ = 0.0;
      }
      have_previous_ = direction.allFinite();
      previous_direction_ = direction;
      previous_stamp_ns_ = newest.stamp_ns;
    }
    d.eye_speed_deg_s = eye_speed_deg_s_;
  } else {
    d.source = GazeSource::kNoGazeYet;
    have_previous_ = false;
    eye_speed_deg_s_ = 0.0;
  }
  if (d.source == GazeSource::kOperator) {
    d.gaze = newest.gaze;
    const double ahead_s = static_cast<double>(std::max<int64_t>(0, d.age_ns) + config_.lead_ns) * 1e-9;
    d.gaze.fovea_growth_deg = std::min(config_.growth_max_deg, eye_speed_deg_s_ * ahead_s);
    d.foveation = &operator_config_;
  } else {
    d.gaze.origin_m = camera.t_world_cam;
    d.gaze.direction = camera.R_world_cam.col(2);
    d.foveation = &fallback_config_;
  }
  d.changed = first_ || d.source != last_;
  first_ = false;
  last_ = d.source;
  return d;
}

}  // namespace fovea::firmware
