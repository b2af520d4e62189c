#include "pipeline/map/pose_tracking.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace fovea::pipeline::map {

std::optional<PoseSourceChoice> parsePoseSourceChoice(std::string_view source) {
  PoseSourceChoice choice;
  if (source == "track") {
    choice.outside = "none";
    choice.tracking = PoseTracking::kAlone;
    return choice;
  }
  constexpr std::string_view kTrackPlus = "track+";
  if (source.substr(0, kTrackPlus.size()) == kTrackPlus) {
    source.remove_prefix(kTrackPlus.size());
    if (source != "socket" && source != "fixed" && source != "camera") return std::nullopt;
    choice.outside = source == "camera" ? std::string_view("none") : source;  // camera: its own pose
    choice.tracking = PoseTracking::kRefine;
    return choice;
  }
  if (source != "none" && source != "fixed" && source != "socket") return std::nullopt;
  choice.outside = source;
  return choice;
}

Result<PoseEstimator> PoseEstimator::create(PoseTracking mode, const TrackerConfig& config) {
  if (mode == PoseTracking::kOff) {
    return Result<PoseEstimator>(ErrorCode::kInvalidArgument, "pose estimator: tracking is off");
  }
  Result<FrameToModelTracker> tracker = FrameToModelTracker::create(config);
  if (!tracker) return tracker.status();
  return PoseEstimator(std::move(tracker.value()), mode);
}

bool PoseEstimator::poseFrame(hal::RgbdFrame& frame, bool outside_pose_valid, TrackStats& stats) {
  const hal::Pose outside = frame.T_world_cam;
  const bool have_prior = mode_ == PoseTracking::kRefine && outside_pose_valid;
  // The starting estimate: the last tracked pose moved by the outside pose's
  // increment, when that increment is plausible; the first frame takes the
  // outside pose itself (the map's world is then the robot's).
  hal::Pose start;
  const hal::Pose* start_ptr = nullptr;
  const bool first = tracker_.counters().frames == 0;
  if (have_prior && first) {
    start = outside;
    start_ptr = &start;
  } else if (have_prior && have_anchor_) {
    // The outside pose's motion since the last frame tracked (its anchor), in
    // that frame's camera coordinates, applied to the last good pose.
    const Eigen::Matrix3d dR = anchor_.R_world_cam.transpose() * outside.R_world_cam;
    const Eigen::Vector3d dt = anchor_.R_world_cam.transpose() * (outside.t_world_cam - anchor_.t_world_cam);
    const TrackerConfig& c = tracker_.config();
    const double frames = static_cast<double>(frames_since_anchor_ + 1);
    if (dt.norm() <= c.max_motion_m * frames && rotationAngleDeg(dR) <= c.max_motion_deg * frames) {
      const hal::Pose& last = tracker_.lastGoodPose();
      start.R_world_cam = last.R_world_cam * dR;
      start.t_world_cam = last.t_world_cam + last.R_world_cam * dt;
      start_ptr = &start;
    }
  }
  hal::Pose pose;
  const TrackOutcome outcome = tracker_.track(frame, start_ptr, pose, stats);
  if (have_prior) {
    // Against the outside pose itself, not the starting estimate made from it.
    const hal::Pose& reported = outcome == TrackOutcome::kLost ? tracker_.lastGoodPose() : pose;
    stats.prior_disagreement_m = (reported.t_world_cam - outside.t_world_cam).norm();
    stats.prior_disagreement_deg = rotationAngleDeg(outside.R_world_cam.transpose() * reported.R_world_cam);
  } else {
    stats.prior_disagreement_m = stats.prior_disagreement_deg = 0.0;
  }
  if (outcome == TrackOutcome::kLost) {
    ++frames_since_anchor_;
    frame.T_world_cam = have_prior ? outside : tracker_.lastGoodPose();
    return false;
  }
  if (have_prior) {
    anchor_ = outside;
    have_anchor_ = true;
    frames_since_anchor_ = 0;
  }
  frame.T_world_cam = pose;
  return true;
}

}  // namespace fovea::pipeline::map
