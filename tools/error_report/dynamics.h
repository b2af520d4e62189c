// fovea-error-report's figures over time (issue 13): what a configuration does
// from frame to frame, and where the eye is when a frame arrives.
//
// Temporal stability: consecutive frames of the camera (the mock room is static
// with per-frame sensor noise), a fixed gaze and one drifting at a constant rate;
// the share of each frame's output points that the previous frame's output did
// not have. An output point is identified by what it stands for: a voxel (region
// and world lattice cell; every preset's lattice is anchored at the world origin)
// or a raw point (its pixel). Noise that only moves a centroid is no change; a
// voxel that appears, or a point that changes level or region, is.
//
// Latency-corrected fovea coverage: a scripted scan of fixations and saccades
// (fovea-operator's --gaze scan: script), sampled by the operator at gaze_hz and
// stamped on its clock, reaches the robot `up` later; each frame is foveated with
// the newest sample there (and, for ACUITY with growth, the fovea growth the
// gaze policy computes from it: pipeline/eye_speed.h) and shown `down` after its
// capture. Of the points within 5 degrees of where the eye is at that moment, the
// share that were sent at least as finely as a gaze there would have sent them
// (region, or ACUITY level, no greater than that gaze's). Frames whose gaze was
// more than 1 degree off the eye at display are the "moving" ones.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"
#include "hal/camera.h"
#include "pipeline/foveator.h"
#include "tools/error_report/report.h"

namespace fovea::tools {

struct DynamicsOptions {
  int stability_frames = 30;
  double drift_deg_s = 2.0;
  double fps = 30.0;              // the camera's, for the drift and the coverage's frame times
  double coverage_seconds = 3.6;  // two rounds of the default scan
  double coverage_radius_deg = 5.0;
  double gaze_hz = 90.0;
  double up_ms = 1.0;      // operator to robot (loopback; a network adds its one-way delay)
  double down_ms = 13.0;   // capture to decoded: the stream's measured p50 on loopback
  double growth_max_deg = 10.0;  // ACUITY's growth: firmware/gaze_policy.h's defaults
  double lead_ms = 30.0;
  Eigen::Vector3d eye_offset_cam = Eigen::Vector3d::Zero();  // fovea-error-report --eye-offset
};

// One configuration of the dynamic figures.
struct DynamicsConfig {
  std::string name;
  pipeline::FoveationConfig config;
  bool growth = false;  // ACUITY: the gaze policy's fovea growth applied
};

struct StabilityResult {
  std::string name;
  double changed_fixed = 0.0;  // mean over frame pairs
  double changed_drift = 0.0;
  double points_fixed = 0.0;   // mean output points per frame
};

struct CoverageResult {
  std::string name;
  double coverage_all = 0.0;     // points pooled over every frame
  double coverage_moving = 0.0;  // over the moving frames only (NaN: none)
  double worst_frame = 0.0;      // the lowest frame's coverage
  double bytes_per_frame = 0.0;  // wire bytes (net/codec.h), mean
  double growth_mean_deg = 0.0;
  int frames = 0;
  int moving_frames = 0;
};

struct DynamicsReport {
  std::vector<StabilityResult> stability;
  std::vector<CoverageResult> coverage;
  std::string script;  // the scan, as fovea-operator --gaze takes it
  DynamicsOptions options;
  int stability_pairs = 0;
};

// The configurations the figures compare: the paper's presets at m and ACUITY
// at the service's defaults, without and with growth, and with growth at each of
// `floors` that has a floor.
std::vector<DynamicsConfig> dynamicsConfigs(double slope, const std::vector<AcuityFloor>& floors,
                                            const std::vector<std::pair<double, int>>& refined = {});

// Runs both figures on `camera` (open and started), from its next frames.
Result<DynamicsReport> measureDynamics(hal::Camera& camera, const std::vector<DynamicsConfig>& configs,
                                       const DynamicsOptions& options);

// The Markdown section and the CSV (one row per configuration).
std::string dynamicsMarkdown(const DynamicsReport& report);
Status writeDynamicsCsv(const std::string& path, const DynamicsReport& report);

}  // namespace fovea::tools
