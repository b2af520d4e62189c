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
//     The terms are weighted by Cauchy's kernel (iteratively reweighted least
//     squares), and afterwards the pixels of something moving in front of the
//     map are marked (moving_pixels.h), which the map does not fuse.
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
#include <vector>

#include <Eigen/Core>

#include "core/kernel_set.h"
#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/map/carried_pixels.h"
#include "pipeline/map/moving_pixels.h"

namespace fovea::pipeline::map {

class SurfelMap;

struct TrackerConfig {
  int max_width = 640;
  int max_height = 480;
  // Gauss-Newton iterations per pyramid level, finest (full size) first, at most:
  // a level stops once a step moves less than converged_step (metres, and
  // radians). 3e-4 (0.3 mm, 0.017 degrees): on TUM teddy and the mock orbit
  // the ATE is the same as at 1e-6 or lower, and tracking 3x faster (1e-6 ran
  // every iteration; docs/tracking.md).
  std::array<int, 3> iterations = {10, 5, 4};
  double converged_step = 3e-4;
  // Projective association: a frame's vertex and the model's at most this far
  // apart (at the finest level; coarser levels allow level + 1 times more) and
  // their normals within this angle.
  double icp_max_distance_m = 0.10;
  double icp_max_normal_deg = 30.0;
  // The photometric term's weight against ICP's (squared residuals: intensity
  // in [0, 1], ICP's residual in metres, noise-weighted below). ElasticFusion's
  // 0.1 measured worse here on the mock orbit and TUM teddy than 0.001
  // (docs/tracking.md).
  double photometric_weight = 0.001;
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
  // A residual jump is only one when the ICP RMS is also above this (a running
  // median of 1 mm on a still camera must not make 4 mm lost).
  double residual_jump_floor_m = 0.01;
  // Pixels of the new frame farther than this take no part (0: all): a
  // Kinect-class sensor's depth at 4 m is quantised in 3 cm steps and its noise
  // is 2.6 cm, which biases point-to-plane ICP (ElasticFusion cuts at 3 m too).
  double max_depth_m = 0.0;
  // ICP's residuals weighted by the sensor's noise at their depth against its
  // noise at 1 m (depthSigma(), surfel_map.h; tracker_kernels.h).
  bool icp_noise_weighting = true;
  // Photometric residuals beyond this (intensity, 0..1) are occlusions or
  // specularities, not misalignment: left out.
  double max_photometric_residual = 0.3;
  // Robust weights (Cauchy's kernel, tracker_kernels.h; 0: least squares): the
  // scale of ICP's noise-weighted residual and of the intensity difference.
  // Chosen on fovea-track (docs/tracking.md, "A world that moves"): 2 mm and
  // 0.06 took the balloon from 145 to 6 mm ATE, TUM teddy and the orbit to
  // less than before; TUM with every other frame dropped got worse (2.8 to
  // 4.7 mm). Relocalising, each level runs least squares until it converges first.
  double icp_robust_scale_m = 0.002;
  double photometric_robust_scale = 0.06;
  // Per-pixel residuals and the reduction: the scalar reference or Highway's.
  KernelSet kernels = defaultKernelSet();
  // The pixels in front of the map's surface, which are not fused (moving_pixels.h).
  // Found after the alignment, they are left out of the inliers' share (its
  // min_gap_m at least icp_max_distance_m: the finest level never used them); ...
  MovingPixelsConfig moving;
  // ... a frame with more than this share of its valid pixels moving is lost
  // (kMostlyMoving): what static remains is too little to trust.
  double max_moving_share = 0.75;
  // The pixels still in the image while the rest of it changes: carried with
  // the camera (carried_pixels.h). Found before the alignment and left out of
  // it; with `moving` enabled they join the moving pixels (not fused) and
  // count in max_moving_share.
  CarriedPixelsConfig carried;

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
  kMostlyMoving,  // more of the view moving than TrackerConfig::max_moving_share
};
std::string_view lostReasonName(LostReason reason);

// The angle of the rotation R in degrees, in [0, 180] (for motions and disagreements).
double rotationAngleDeg(const Eigen::Matrix3d& R);

struct TrackStats {
  TrackOutcome outcome = TrackOutcome::kFirstFrame;
  LostReason lost_reason = LostReason::kNone;
  int iterations = 0;               // Gauss-Newton iterations run, all levels
  uint32_t valid_pixels = 0;        // finest level, with depth
  uint32_t inliers = 0;             // finest level, associated at the last iteration
  double inlier_fraction = 0.0;     // of the valid pixels not moving
  double icp_rms_m = 0.0;           // point-to-plane RMS over the inliers
  double photometric_rms = 0.0;     // intensity RMS (0..1) over the inliers
  double min_eigenvalue = 0.0;      // of the normalised J^T J at the last iteration
  // Against the prior, when one was given; PoseEstimator then measures them
  // against the outside pose itself (track+socket, track+fixed).
  double prior_disagreement_m = 0.0;
  double prior_disagreement_deg = 0.0;
  int relocalise_candidates = 0;    // poses tried by relocalisation (0: not lost)
  // The pixels found moving after the alignment (in front of the map's
  // surface, not settled: moving_pixels.h; or carried, below), and their share
  // of the valid pixels; 0 on a frame lost before that (no model, no depth).
  uint32_t moving_pixels = 0;
  double moving_share = 0.0;
  // Of those, the finest level's pixels with depth found carried with the
  // camera before the alignment (carried_pixels.h), and that finding's share
  // of the pixels with depth not still for long.
  uint32_t carried_pixels = 0;
  double changed_share = 0.0;
  int64_t track_ns = 0;             // all of track()
  int64_t pyramid_ns = 0;           // step 1
  int64_t moving_ns = 0;            // finding the moving pixels and checking without them
  int64_t carried_ns = 0;           // finding the carried pixels and clearing them from the pyramid
  // Building the model for the next frame from the fused map (modelFused(),
  // after fusion; Mapper::addFrame times it): tracking's cost besides track().
  int64_t model_ns = 0;
};

struct TrackerCounters {
  uint64_t frames = 0, tracked = 0, lost = 0, relocalised = 0;
};

class FrameToModelTracker {
 public:
  static Result<FrameToModelTracker> create(const TrackerConfig& config);

  // The pose of `frame` (camera to world) into `pose`. prior: the estimate's
  // start; PoseEstimator (pose_tracking.h) passes the outside pose itself for
  // the first frame and after that the last tracked pose moved by the outside
  // pose's increment since then (track+socket, track+fixed); nullptr: the last
  // tracked pose (tracking alone, or an implausible increment). The first frame, without a model, takes the prior or the
  // identity. Never allocates.
  TrackOutcome track(const hal::RgbdFrame& frame, const hal::Pose* prior, hal::Pose& pose, TrackStats& stats);

  // After `map` fused `frame` at `pose` (the frame track() just posed): takes the
  // map's prediction at that pose as the next frame's model. moving (null:
  // none): the frame's moving pixels, which the map did not fuse and the model
  // does not take from the frame either. Never allocates.
  void modelFused(const hal::RgbdFrame& frame, const hal::Pose& pose, const SurfelMap& map,
                  const uint8_t* moving = nullptr);

  // Forgets the model and the last pose (the next frame is a first frame).
  void reset();

  // The finest level of the model the next frame is tracked against, as
  // modelFused() left it (tests): vertices and normals in the camera at its
  // pose, intensity, and from_surfel 1 where a surfel gave the pixel.
  struct ModelView {
    int width = 0, height = 0;
    const float *x = nullptr, *y = nullptr, *z = nullptr, *nx = nullptr, *ny = nullptr, *nz = nullptr;
    const float* intensity = nullptr;
    const uint8_t* from_surfel = nullptr;
  };
  ModelView finestModel() const;

  // The last tracked frame's moving pixels (none after a first or lost frame),
  // which the map does not fuse; the carried ones among them.
  const MovingPixels& moving() const { return moving_; }
  const CarriedPixels& carried() const { return carried_; }
  bool lost() const { return lost_; }
  const hal::Pose& lastGoodPose() const { return last_good_; }
  const TrackerConfig& config() const { return config_; }
  const TrackerCounters& counters() const { return counters_; }
  std::size_t memoryBytes() const;

 private:
  FrameToModelTracker(const TrackerConfig& config, MovingPixels moving, CarriedPixels carried);

  static constexpr int kLevels = 3;
  // One pyramid level (of the new frame or of the model), structure of arrays.
  struct Level {
    int width = 0, height = 0;
    float fx = 0.0f, fy = 0.0f, cx = 0.0f, cy = 0.0f;
    std::vector<float> x, y, z, nx, ny, nz, intensity, gx, gy;
    // The finest level's (u - cx) / fx per column and (v - cy) / fy per row,
    // made by setCamera(): setMeasured()'s divisions, once a frame.
    std::vector<float> ray_u, ray_v;
    void allocate(std::size_t pixels, bool gradients);
    void allocateRays(int max_width, int max_height);
    std::size_t bytes() const;
    // The finest level's size and camera from a frame's (at most allocateRays()'s size).
    void setCamera(int w, int h, const hal::CameraIntrinsics& k);
    // Pixel i = (u, v) from its measurement: the vertex of its raw depth
    // (zeros, and false, without a valid one up to max_z) and its intensity.
    bool setMeasured(std::size_t i, int u, int v, uint16_t raw, float scale, float max_z, float intensity_value);
    void downsampleFrom(const Level& from, bool normals, KernelSet kernels);
    void copyPixel(std::size_t from, std::size_t to);  // vertex, normal and intensity
  };
  float maxDepth() const;  // config_.max_depth_m, infinity when 0 (off)
  // The result of one coarse-to-fine Gauss-Newton run from a start estimate.
  struct Solve {
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // new camera -> model camera
    Eigen::Vector3d t = Eigen::Vector3d::Zero();
    int iterations = 0;
    uint32_t inliers = 0;
    double icp_rms = 0.0, photometric_rms = 0.0, min_eigenvalue = 0.0;
    bool finite = true;
  };
  bool buildFramePyramid(const hal::RgbdFrame& frame);  // false: no valid depth
  // modelFused()'s finest level from the map's index map (nullptr: none at the frame's size).
  void modelFromIndexMap(const hal::RgbdFrame& frame, const hal::Pose& pose, const SurfelMap& map,
                         const uint32_t* index, const uint8_t* moving);
  Solve solve(const Eigen::Matrix3d& R0, const Eigen::Vector3d& t0, bool photometric);
  // The inliers' share of the valid pixels less left_out (moving: not counted against them).
  double inlierFraction(uint32_t inliers, uint32_t left_out) const;
  // The checks of step 3 on a solve from the estimate (R, t of the world pose).
  // left_out: the valid pixels the solve did not use (moving), not counted against its inliers.
  LostReason check(const Solve& s, const hal::Pose& pose, const hal::Pose& reference, uint32_t left_out) const;
  // track()'s steps: a solve from a start pose with its world pose and checks,
  // relocalisation's search over starts, the stats of the attempt taken.
  struct Attempt {
    Solve solve;
    hal::Pose pose;
    LostReason reason = LostReason::kNone;
    uint32_t left_out = 0;  // valid pixels found moving: not counted against the inliers
  };
  bool frameUsable(const hal::RgbdFrame& frame) const;
  Attempt attemptFrom(const hal::Pose& start, bool photometric);
  Attempt relocalise(const hal::Pose* prior, bool photometric, TrackStats& stats);
  void recordAttempt(const Attempt& best, const hal::Pose* prior, TrackStats& stats) const;
  double medianResidual() const;
  // The tracked frame's moving pixels from the solve that posed it.
  void markMoving(const Solve& s, TrackStats& stats);
  // The moving pixels after the attempt's alignment, and the attempt checked
  // anew without them.
  void leaveOutMovers(Attempt& a, TrackStats& stats);
  // Before the alignment: the frame's carried pixels, their depth cleared in
  // the frame pyramid (carried_left_out_: the finest level's with depth).
  void leaveOutCarried(TrackStats& stats);

  TrackerConfig config_;
  TrackerCounters counters_;
  bool lost_ = false;
  hal::Pose last_good_;
  bool have_model_ = false;
  hal::Pose model_pose_;  // the model's camera (world)
  std::array<Level, kLevels> frame_;
  std::array<Level, kLevels> model_;
  std::vector<uint8_t> model_from_surfel_;  // finest model level: 1 where a surfel gave the pixel
  MovingPixels moving_;
  CarriedPixels carried_;
  uint32_t carried_left_out_ = 0;
  std::array<double, 15> residual_history_{};
  int residual_count_ = 0;
  uint32_t valid_pixels_ = 0;
};

}  // namespace fovea::pipeline::map
