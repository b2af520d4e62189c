// Frame-to-model tracking on the CPU: the camera's pose for a new frame,
// estimated against the surfel map's prediction at the last fused pose
// (ElasticFusion's tracker, without a GPU; docs/tracking.md).
//
// Per frame:
//  1. the new frame's pyramid (three levels, 2x2 block averages that never
//     mix across a depth step): metric depth, vertices, normals, intensity and
//     its gradients;
//  2. from coarse to fine, Gauss-Newton iterations on a 6-DoF twist: each
//     iteration sums one 6x6 system (J^T J, J^T r) over every pixel of
//       - point-to-plane ICP: the frame's vertex, moved by the estimate, against
//         the model's vertex and normal at the pixel it projects to (projective
//         association, rejected beyond a distance and a normal angle);
//       - photometric: the model's intensity against the frame's at the same
//         projection (weighted by photometric_weight, ElasticFusion's w_rgb);
//     the per-pixel residuals and the reduction are a kernel (tracker_kernels.h:
//     the scalar reference and Highway's, compared in tests), summed stably
//     (compensated or pairwise: 300 000 squared residuals in float lose digits);
//  3. the outcome: tracked, or lost when too few pixels associate, the
//     residual jumps against its running level, the system is degenerate (a
//     white wall constrains three of six axes) or the motion is implausible.
//     While lost, each frame tries the last good pose and a small search
//     around it against the same model (relocalisation); the map fuses
//     nothing meanwhile, so the model waits for the view to return.
//
// The model: after the map fused frame k (SurfelMap::fuse), modelFused()
// takes the map's index map at pose k (the surfel each pixel saw, as merged)
// and, where no surfel is, frame k's own measurement; that is what frame k+1
// is tracked against. Nothing is rendered twice.
//
// Memory: every buffer is sized by create() from max_width x max_height;
// track() and modelFused() allocate nothing.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "core/kernel_set.h"
#include "core/result.h"
#include "hal/frame.h"

namespace fovea::pipeline::map {

class SurfelMap;

struct TrackerConfig {
  int max_width = 640;
  int max_height = 480;
  // Gauss-Newton iterations per pyramid level, finest (full size) first.
  std::array<int, 3> iterations = {10, 5, 4};
  // Projective association: a frame's vertex and the model's at most this far
  // apart (at the finest level; coarser levels allow level + 1 times more) and
  // their normals within this angle.
  double icp_max_distance_m = 0.10;
  double icp_max_normal_deg = 30.0;
  // The photometric term's weight against ICP's (ElasticFusion: 0.1 of ICP's 1,
  // after scaling intensity to [0, 1] and ICP's residual to metres).
  double photometric_weight = 0.1;
  // Lost: fewer than this share of the frame's valid pixels associated at the
  // finest level, ...
  double min_inlier_fraction = 0.15;
  // ... an ICP RMS residual above this many times its running median, ...
  double max_residual_jump = 4.0;
  // ... the smallest eigenvalue of J^T J (normalised by the inliers) below
  // this (a plane, a textureless wall: unconstrained axes), ...
  double min_eigenvalue = 1e-4;
  // ... or a motion between two frames beyond these.
  double max_motion_m = 0.30;
  double max_motion_deg = 30.0;
  // Relocalisation: tried around the last good pose at these rotation offsets
  // (degrees, about each axis, both signs) besides the pose itself.
  double relocalise_search_deg = 10.0;
  // Per-pixel residuals and the reduction: the scalar reference or Highway's.
  KernelSet kernels = defaultKernelSet();

  Status validate() const;
};

enum class TrackOutcome : uint8_t {
  kFirstFrame,   // no model yet: the prior (or the identity) is the pose
  kTracked,
  kRelocalised,  // was lost; this frame tracked against the last good model again
  kLost,         // not tracked: the frame must not be fused
};
std::string_view trackOutcomeName(TrackOutcome outcome);

// Why the last lost frame was lost (TrackStats::lost_reason).
enum class LostReason : uint8_t {
  kNone,
  kFewInliers,
  kResidualJump,
  kDegenerate,
  kImplausibleMotion,
  kNoValidDepth,
};
std::string_view lostReasonName(LostReason reason);

struct TrackStats {
  TrackOutcome outcome = TrackOutcome::kFirstFrame;
  LostReason lost_reason = LostReason::kNone;
  int iterations = 0;               // Gauss-Newton iterations run, all levels
  uint32_t valid_pixels = 0;        // finest level, with depth
  uint32_t inliers = 0;             // finest level, associated at the last iteration
  double inlier_fraction = 0.0;
  double icp_rms_m = 0.0;           // point-to-plane RMS over the inliers
  double photometric_rms = 0.0;     // intensity RMS (0..1) over the inliers
  double min_eigenvalue = 0.0;      // of the normalised J^T J at the last iteration
  // Against the prior, when one was given (track+socket, track+fixed).
  double prior_disagreement_m = 0.0;
  double prior_disagreement_deg = 0.0;
  int64_t track_ns = 0;             // all of track()
  int64_t pyramid_ns = 0;           // step 1
};

struct TrackerCounters {
  uint64_t frames = 0, tracked = 0, lost = 0, relocalised = 0;
};

class FrameToModelTracker {
 public:
  static Result<FrameToModelTracker> create(const TrackerConfig& config);

  // The pose of `frame` (camera to world) into `pose`. prior: the outside
  // pose for this frame (track+socket, track+fixed), the estimate's start and
  // what the disagreement is measured against; nullptr: the last tracked pose
  // (tracking alone). The first frame, without a model, takes the prior or the
  // identity. Never allocates.
  TrackOutcome track(const hal::RgbdFrame& frame, const hal::Pose* prior, hal::Pose& pose, TrackStats& stats);

  // After `map` fused `frame` at `pose` (the frame track() just posed): takes the
  // map's prediction at that pose as the next frame's model. Never allocates.
  void modelFused(const hal::RgbdFrame& frame, const hal::Pose& pose, const SurfelMap& map);

  // Forgets the model and the last pose (the next frame is a first frame).
  void reset();

  bool lost() const { return lost_; }
  const hal::Pose& lastGoodPose() const { return last_good_; }
  const TrackerConfig& config() const { return config_; }
  const TrackerCounters& counters() const { return counters_; }
  std::size_t memoryBytes() const;

 private:
  explicit FrameToModelTracker(const TrackerConfig& config);
  // The implementation's buffers (pyramids, model maps) are members added here.
  TrackerConfig config_;
  TrackerCounters counters_;
  bool lost_ = false;
  hal::Pose last_good_;
};

}  // namespace fovea::pipeline::map
