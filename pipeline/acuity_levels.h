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
// for bit: single precision from the eye's offset on (P - H is formed in double,
// where the large parts of the coordinates cancel, then rounded to float), this
// order, no FMA. Float carries 7 digits, far more than a level decision needs (the
// thresholds are a factor of 2 apart), and doubles the lanes of every vector. atan
// and sin are fixed polynomials (atanUnit, sinSpec), not libm's, whose results
// differ between libraries and from any vector implementation. Their errors (under
// 1e-5 rad) are far below what the model needs.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

#include "pipeline/acuity.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline {

inline constexpr float kLevelsPi = 3.14159265358979323846f;
inline constexpr float kLevelsHalfPi = 1.57079632679489661923f;
inline constexpr float kLevelsRadToDeg = static_cast<float>(180.0 / 3.14159265358979323846);
inline constexpr float kLevelsDegToRad = static_cast<float>(3.14159265358979323846 / 180.0);
inline constexpr float kLevelsMar0Deg = static_cast<float>(kMar0Deg);

// atan(q) for q in [0, 1]: an odd minimax polynomial in Horner form (Mul then Add).
inline constexpr float kAtanCoefficients[6] = {0.99997726f, -0.33262347f, 0.19354346f,
                                              -0.11643287f, 0.05265332f,  -0.01172120f};
inline float atanUnit(float q) {
  const float q2 = q * q;
  float p = kAtanCoefficients[5];
  for (int k = 4; k >= 0; --k) p = p * q2 + kAtanCoefficients[k];
  return p * q;
}

// atan2(d, t) in degrees for d >= 0 (0 at the eye, d = t = 0), from atanUnit by octant.
inline float eccentricitySpecDeg(float t, float d) {
  const float at = t < 0.0f ? -t : t;
  const float hi = at > d ? at : d;
  const float lo = at > d ? d : at;
  if (!(hi > 0.0f)) return 0.0f;
  float a = atanUnit(lo / hi);
  if (d > at) a = kLevelsHalfPi - a;
  if (t < 0.0f) a = kLevelsPi - a;
  return a * kLevelsRadToDeg;
}

// sin(x) for x in [0, pi/2]; larger x is taken as pi/2 (a MAR beyond 90 degrees allows
// anything: sin stays at 1 and the level stays monotone). Taylor to x^11 in Horner form
// (the next term is below float's rounding on [0, pi/2]).
inline constexpr float kSinCoefficients[6] = {1.0f,
                                             static_cast<float>(-1.0 / 6.0),
                                             static_cast<float>(1.0 / 120.0),
                                             static_cast<float>(-1.0 / 5040.0),
                                             static_cast<float>(1.0 / 362880.0),
                                             static_cast<float>(-1.0 / 39916800.0)};
inline float sinSpec(float x) {
  const float y = x < kLevelsHalfPi ? x : kLevelsHalfPi;
  const float y2 = y * y;
  float p = kSinCoefficients[5];
  for (int k = 4; k >= 0; --k) p = p * y2 + kSinCoefficients[k];
  return p * y;
}

// How the eye sees a point at v = P - H (float, the specification's order): its
// distance r and its eccentricity less the fovea's growth, clamped at 0.
struct EyeView {
  float r_m = 0.0f;
  float ecc_deg = 0.0f;
};
inline EyeView eyeViewSpec(float vx, float vy, float vz, const Eigen::Vector3f& l, float growth_deg) {
  // t along the gaze, d from its axis (axialRadial's expressions, in float).
  const float t = vx * l.x() + vy * l.y() + vz * l.z();
  const float rx = vx - t * l.x();
  const float ry = vy - t * l.y();
  const float rz = vz - t * l.z();
  const float d = std::sqrt(rx * rx + ry * ry + rz * rz);
  EyeView view;
  view.r_m = std::sqrt(vx * vx + vy * vy + vz * vz);
  const float ecc = eccentricitySpecDeg(t, d) - growth_deg;
  view.ecc_deg = ecc < 0.0f ? 0.0f : ecc;
  return view;
}

struct LevelBounds {
  float slope = static_cast<float>(kDefaultSlope);
  // k * v_n for n = 1 .. kMaxRegions - 1 (index 0 unused).
  std::array<float, kMaxRegions> min_allowed_m{};
  uint8_t floor_level = 0;  // no point below this level (0: no floor)
  // The distance-dependent floor (0: none): floor_a_m + floor_b_per_m2 s^2 against v_n.
  float floor_a_m = 0.0f;
  float floor_b_per_m2 = 0.0f;
  std::array<float, kMaxRegions> voxel_m{};  // v_n (index 0 unused)
  // The view cull: what a point outside the field of view gets (0: no cull;
  // kMaxRegions - 1, or kRegionCulled), and cos(view_cull_deg).
  uint8_t cull_region = 0;
  float cull_cos = -1.0f;

  static LevelBounds fromModel(const RegionModel& model);

  // The level of a point at distance r_m from the eye, eccentricity ecc_deg: the
  // number of levels n >= 1 whose k v_n fits under r sin(MAR) (they grow with n),
  // lifted to the floor.
  uint8_t classify(float r_m, float ecc_deg) const;
  // r sin(MAR(E)): how far a point may move, seen from the eye, unresolved.
  float allowedM(float r_m, float ecc_deg) const {
    return r_m * sinSpec((slope * ecc_deg + kLevelsMar0Deg) * kLevelsDegToRad);
  }
  // The distance-dependent floor's level for a point at s2_m2 = s^2 from the sensor
  // (0 when floor_b_per_m2 is 0).
  uint8_t noiseFloorLevel(float s2_m2) const;
  // The lowest level a point at s2_m2 from the sensor may have: floor_level or the
  // distance floor's, whichever is higher.
  uint8_t lowestLevel(float s2_m2) const;
};

// Scalar reference. gaze must come from normalizeGaze(). Writes cloud.size()
// levels to region_out.
void assignLevelsRef(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, uint8_t* region_out,
                     PartitionCounts& counts);

// Error-driven refinement (AcuityConfig::refine_passes; docs/acuity-levels.md):
// the margin k sizes a level from the worst case (a centroid at its voxel's far
// corner), which most voxels are far from, so at a low share above the MAR a small
// k with refinement keeps fewer points than a large k alone. A pass has two steps,
// after a sampling of `cloud` into `out` (representative[i]: point i's output point):
//
// 1. refineTestRef gives every point a state. kRefineStay: it cannot leave its
//    level (raw, invalid or culled, no representative, on its floor's level -
//    floor_level or the distance floor - or put on the coarsest level by the view
//    cull). Otherwise kRefineBeyond when its representative R is seen from the eye
//    more than MAR(E) away from it, else kRefineWithin: sin(alpha) = |e x a| /
//    (|a| |b|) with a = P - H, e = P - R, b = a - e (float, formed as P - H is; the
//    growth taken as in assignLevelsRef), and alpha <= MAR when a.b > 0 and
//    |e x a|^2 <= |b|^2 allowedM(r, E)^2. A move along the eye's ray is not seen,
//    so only the across part counts: the error report's measure. Returns the
//    points beyond. refineTestSimd (pipeline/kernels/foveation_simd.h) gives the
//    same states.
// 2. moveRefinedVoxels moves every point that can move one level down (level 1:
//    raw) when any point of its voxel is beyond: the whole voxel, not only the
//    points beyond, so that a voxel kept at a level holds all its points (moving
//    only those left small clusters in coarse voxels, which a viewer draws at the
//    voxel's size: blocks in fovea-eval's images). Sample again when it moved any.
//
// Once no point is beyond, none is above its MAR.
inline constexpr uint8_t kRefineStay = 0;
inline constexpr uint8_t kRefineWithin = 1;
inline constexpr uint8_t kRefineBeyond = 2;
std::size_t refineTestRef(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, const PointCloud& out,
                          const uint32_t* representative, const uint8_t* region, uint8_t* state);
// voxel_beyond: scratch of out_size bytes. Updates region and counts.per_region;
// returns the points moved.
std::size_t moveRefinedVoxels(const uint8_t* state, const uint32_t* representative, std::size_t n,
                              std::size_t out_size, uint8_t* voxel_beyond, uint8_t* region, PartitionCounts& counts);

}  // namespace fovea::pipeline
