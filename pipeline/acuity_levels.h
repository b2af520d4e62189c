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
// sensor's noise and pitch carries nothing), or, with floor_per_m2 > 0, reaches
// floor_m + floor_per_m2 * s^2, s^2 = x^2 + y^2 + z^2 of the point's coordinates
// relative to the cloud's origin (the camera: its noise grows with the square of
// the distance from the sensor, not from the eye): the level is lifted to
// min(kMaxRegions - 1, 1 + the number of levels whose voxel is below that). Points with a non-finite coordinate
// get kRegionInvalid and are counted.
//
// Two inputs from the gaze (partition.h) widen or narrow what is kept:
// - the fovea's growth g (Gaze::fovea_growth_deg): the eccentricity is taken as
//   max(0, E - g), so everything within g of the gaze is kept at the fovea's acuity
//   and the whole falloff moves out by g (a saccade in flight lands on detail);
// - the view cull (AcuityConfig::view_cull, when Gaze::view_known): with F the
//   head's unit forward axis and c = cos(view_cull_deg), a point with a.F < r c lies
//   outside the field of view and goes to the coarsest level or to kRegionCulled.
//
// The arithmetic below is the specification that the SIMD kernel reproduces bit
// for bit (double, this order, no FMA): atan and sin are fixed polynomials
// (atanUnit, sinSpec), not libm's, whose results differ between libraries and
// from any vector implementation. Their errors (under 1e-5 rad) are far below
// what the model needs.
#pragma once

#include <array>
#include <cstdint>

#include "pipeline/acuity.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline {

// atan(q) for q in [0, 1]: an odd minimax polynomial in Horner form (Mul then Add).
inline constexpr double kAtanCoefficients[6] = {0.99997726, -0.33262347, 0.19354346,
                                               -0.11643287, 0.05265332, -0.01172120};
inline double atanUnit(double q) {
  const double q2 = q * q;
  double p = kAtanCoefficients[5];
  for (int k = 4; k >= 0; --k) p = p * q2 + kAtanCoefficients[k];
  return p * q;
}

// atan2(d, t) in degrees for d >= 0 (0 at the eye, d = t = 0), from atanUnit by octant.
inline constexpr double kLevelsPi = 3.14159265358979323846;
inline double eccentricitySpecDeg(double t, double d) {
  const double at = t < 0.0 ? -t : t;
  const double hi = at > d ? at : d;
  const double lo = at > d ? d : at;
  if (!(hi > 0.0)) return 0.0;
  double a = atanUnit(lo / hi);
  if (d > at) a = kLevelsPi / 2.0 - a;
  if (t < 0.0) a = kLevelsPi - a;
  return a * (180.0 / kLevelsPi);
}

// sin(x) for x in [0, pi/2]; larger x is taken as pi/2 (a MAR beyond 90 degrees allows
// anything: sin stays at 1 and the level stays monotone). Taylor to x^13 in Horner form.
inline constexpr double kSinCoefficients[7] = {1.0,
                                              -1.0 / 6.0,
                                              1.0 / 120.0,
                                              -1.0 / 5040.0,
                                              1.0 / 362880.0,
                                              -1.0 / 39916800.0,
                                              1.0 / 6227020800.0};
inline double sinSpec(double x) {
  const double y = x < kLevelsPi / 2.0 ? x : kLevelsPi / 2.0;
  const double y2 = y * y;
  double p = kSinCoefficients[6];
  for (int k = 5; k >= 0; --k) p = p * y2 + kSinCoefficients[k];
  return p * y;
}

struct LevelBounds {
  double slope = kDefaultSlope;
  // k * v_n for n = 1 .. kMaxRegions - 1 (index 0 unused).
  std::array<double, kMaxRegions> min_allowed_m{};
  uint8_t floor_level = 0;  // no point below this level (0: no floor)
  // The distance-dependent floor (0: none): floor_a_m + floor_b_per_m2 s^2 against v_n.
  double floor_a_m = 0.0;
  double floor_b_per_m2 = 0.0;
  std::array<double, kMaxRegions> voxel_m{};  // v_n (index 0 unused)
  // The view cull: what a point outside the field of view gets (0: no cull;
  // kMaxRegions - 1, or kRegionCulled), and cos(view_cull_deg).
  uint8_t cull_region = 0;
  double cull_cos = -1.0;

  static LevelBounds fromModel(const RegionModel& model);

  // The level of a point at distance r_m from the eye, eccentricity ecc_deg: the
  // number of levels n >= 1 whose k v_n fits under r sin(MAR) (they grow with n),
  // lifted to the floor.
  uint8_t classify(double r_m, double ecc_deg) const;
  // The distance-dependent floor's level for a point at s2_m2 = s^2 from the sensor
  // (0 when floor_b_per_m2 is 0).
  uint8_t noiseFloorLevel(double s2_m2) const;
};

// Scalar reference. gaze must come from normalizeGaze(). Writes cloud.size()
// levels to region_out.
void assignLevelsRef(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, uint8_t* region_out,
                     PartitionCounts& counts);

}  // namespace fovea::pipeline
