// The fixation distance d0 that scales every voxel (Eq. 2-5).
//
// centroid: the paper's d0, the distance from the eye H to the centroid of the
//   fovea's points (Eq. 3-4). Meaningless when the fovea straddles a silhouette
//   (a near object in front of a far wall puts the centroid in mid-air).
// hit (default): the distance along the gaze to the first surface it meets (the
//   paper's point G), taken as a low percentile of t over the points inside a
//   narrow cone around the gaze so that one flying pixel does not decide it.
// fixed: a configured distance (tests, and users who know their working distance).
// Fallbacks: hit -> centroid when the hit cone is empty; centroid -> fallback_m
// when the fovea is empty (gaze at the sky, or at a hole in the depth image).
// The result is clamped to at least min_m, which also bounds the voxel index range.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include "core/result.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline {

enum class FixationMode { kHit, kCentroid, kFixed };
// kNone: no d0 was computed (the acuity mode sizes each point's voxel by its own distance).
enum class FixationSource { kHit, kCentroid, kFixed, kFallback, kNone };

std::string_view fixationModeName(FixationMode mode);
std::string_view fixationSourceName(FixationSource source);
Result<FixationMode> parseFixationMode(std::string_view text);

struct FixationConfig {
  FixationMode mode = FixationMode::kHit;
  double fixed_m = 2.0;         // d0 for FixationMode::kFixed
  double hit_cone_deg = 1.0;    // half-angle of the cone searched for the hit (capped at the fovea)
  double hit_percentile = 0.05; // of t over the points in that cone
  double fallback_m = 2.0;      // d0 when no point supports the chosen mode
  double min_m = 0.05;          // lower clamp of d0

  // The message names the offending field.
  Status validate() const;
};

struct Fixation {
  double d0_m = 0.0;
  FixationSource source = FixationSource::kFallback;
  uint32_t support = 0;   // points the estimate rests on
  bool clamped = false;   // d0 was raised to min_m
};

// Computes d0 from a partitioned cloud (regions from partitionRef; region 0 is the
// fovea). t_scratch must hold cloud.size() values; it is the only memory used.
Fixation computeFixation(const PointCloud& cloud, const uint8_t* region, const Gaze& gaze,
                         const FixationConfig& config, double* t_scratch);

}  // namespace fovea::pipeline
