// How a frame gets its pose when the map tracks the camera (camera.pose.source
// = track, track+socket, track+fixed; docs/tracking.md): the one place that
// the service's foveation stage, `fovead run`, `fovead map` and the bench share.
//
// Per frame: PoseEstimator::poseFrame() before SurfelMap::fuse(), then, if the
// map fused the frame, PoseEstimator::fused(). A frame the tracker lost keeps a
// pose to be shown by but must not be fused (poseFrame() returns false).
//
// The outside pose as a prior (track+X): its motion since the last frame
// tracked (odometry's increment, which is locally good even when it drifts)
// moves the last tracked pose to the tracker's starting estimate; an increment
// beyond the tracker's max_motion a frame (a jump of the socket's pose) is not
// believed, and tracking starts from the last pose instead. The disagreement reported is the
// tracked pose against the outside pose itself: the drift, or the jump.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/map/tracker.h"

namespace fovea::pipeline::map {

class SurfelMap;

enum class PoseTracking : uint8_t {
  kOff,     // the outside pose as it is (none, fixed, socket)
  kAlone,   // track: the tracker alone; the frame's own pose is ignored
  kRefine,  // track+socket, track+fixed, track+camera: the outside pose is the prior tracking refines
};

// camera.pose.source split in two: the outside source ("none", "fixed",
// "socket") and the tracking. nullopt for anything else.
struct PoseSourceChoice {
  std::string_view outside;
  PoseTracking tracking = PoseTracking::kOff;
};
std::optional<PoseSourceChoice> parsePoseSourceChoice(std::string_view source);

class PoseEstimator {
 public:
  // mode kOff is an error: without tracking there is nothing to estimate.
  static Result<PoseEstimator> create(PoseTracking mode, const TrackerConfig& config);

  // Poses `frame` (frame.T_world_cam) by the tracker; outside_pose_valid: the
  // frame's pose from the pose source is usable (kRefine takes it as the
  // prior). Returns true when the pose is the tracker's (tracked, relocalised,
  // or the first frame); false when the tracker is lost: the frame then holds
  // the outside pose (kRefine, when valid) or the last good pose, for showing
  // it beside the map, never for fusing it. Never allocates.
  bool poseFrame(hal::RgbdFrame& frame, bool outside_pose_valid, TrackStats& stats);
  // After `map` fused the frame poseFrame() posed, without its moving pixels
  // (null: none). Never allocates.
  void fused(const hal::RgbdFrame& frame, const SurfelMap& map, const uint8_t* moving = nullptr) {
    tracker_.modelFused(frame, frame.T_world_cam, map, moving);
  }

  PoseTracking mode() const { return mode_; }
  const FrameToModelTracker& tracker() const { return tracker_; }
  std::size_t memoryBytes() const { return tracker_.memoryBytes(); }

 private:
  PoseEstimator(FrameToModelTracker tracker, PoseTracking mode) : tracker_(std::move(tracker)), mode_(mode) {}

  FrameToModelTracker tracker_;
  PoseTracking mode_;
  // kRefine: the outside pose of the last frame tracked, and the frames since.
  hal::Pose anchor_;
  bool have_anchor_ = false;
  uint32_t frames_since_anchor_ = 0;
};

}  // namespace fovea::pipeline::map
