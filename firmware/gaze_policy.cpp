#include "firmware/gaze_policy.h"

#include <cmath>
#include <string>

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

GazePolicy::Decision GazePolicy::decide(const OperatorGaze& newest, int64_t now_ns, const hal::Pose& camera) {
  Decision d;
  if (newest.valid) {
    d.age_ns = now_ns - newest.received_ns;
    d.source = d.age_ns <= config_.timeout_ns ? GazeSource::kOperator : GazeSource::kStale;
    eye_speed_.observe(newest.gaze.direction, newest.stamp_ns);
    d.eye_speed_deg_s = eye_speed_.speedDegS();
  } else {
    d.source = GazeSource::kNoGazeYet;
    eye_speed_.reset();
  }
  if (d.source == GazeSource::kOperator) {
    d.gaze = newest.gaze;
    d.gaze.fovea_growth_deg =
        pipeline::foveaGrowthDeg(d.eye_speed_deg_s, d.age_ns, config_.lead_ns, config_.growth_max_deg);
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
