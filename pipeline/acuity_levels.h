// Level assignment of the acuity mode (Preset::kAcuity, issue 13; docs/acuity-levels.md).
//
// Instead of cones with one voxel size each (the paper's regions), every point P
// gets the coarsest level of a nested, world-anchored lattice (level n's voxel is
// 2^(n-1) times level 1's) on which its displacement stays below what the eye
// resolves at P's own eccentricity and distance. With a = P - H (H the eye), L the
// unit gaze, t = a.L, d = |a - tL| (axialRadial, as the partition), the point's
// eccentricity is E = atan2(d, t) in degrees and its distance r = |a|. A voxel
// sampled point moves to its voxel's centroid, at most sqrt(3) v away; seen from
// the eye that is an angle of at most asin(sqrt(3) v / r) while r > sqrt(3) v. So
// the point may use level n when
//     k * v_n <= r * sin(MAR(E))           MAR(E) = m E + MAR0 (Eq. 1)
// with k = sqrt(3) (AcuityConfig::level_margin; smaller k trades a measured share
// above the MAR for bytes), and goes to the largest such n (at most kMaxRegions - 1). A point for which no
// level holds stays raw (region 0), unless the sensor floor lifts it: no point is
// kept finer than the first level whose voxel reaches floor_m (finer than the
// sensor's noise and pitch carries nothing). Points with a non-finite coordinate
// get kRegionInvalid and are counted.
//
// The arithmetic below is the specification (double, this order, no FMA).
#pragma once

#include <array>
#include <cstdint>

#include "pipeline/acuity.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline {

struct LevelBounds {
  double slope = kDefaultSlope;
  // k * v_n for n = 1 .. kMaxRegions - 1 (index 0 unused).
  std::array<double, kMaxRegions> min_allowed_m{};
  uint8_t floor_level = 0;  // no point below this level (0: no floor)

  static LevelBounds fromModel(const RegionModel& model);

  // The level of a point at distance r_m from the eye, eccentricity ecc_deg.
  uint8_t classify(double r_m, double ecc_deg) const;
};

// Scalar reference. gaze must come from normalizeGaze(). Writes cloud.size()
// levels to region_out.
void assignLevelsRef(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, uint8_t* region_out,
                     PartitionCounts& counts);

}  // namespace fovea::pipeline
