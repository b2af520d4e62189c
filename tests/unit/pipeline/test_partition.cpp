// Algorithm 1 against hand-placed points and against a brute-force reference.
#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "pipeline/partition.h"
#include "tests/support/clouds.h"

namespace fovea::pipeline {
namespace {

using test::boundsOf;
using test::regionModel;

// Point at eccentricity ecc_deg, distance r from the eye, gaze +z from the origin.
PointCloud pointAt(double ecc_deg, double r) {
  PointCloud cloud(1);
  const double a = ecc_deg * std::numbers::pi / 180.0;
  (void)cloud.push(static_cast<float>(r * std::sin(a)), 0.0f, static_cast<float>(r * std::cos(a)), 0);
  return cloud;
}

uint8_t regionOf(const PointCloud& cloud, const RegionModel& model, const Gaze& gaze = {}) {
  uint8_t region = 0;
  PartitionCounts counts;
  partitionRef(cloud, normalizeGaze(gaze).value(), ConeBounds::fromModel(model), &region, counts);
  return region;
}

TEST(Partition, HandPlacedPointsFallInTableIRegions) {
  const RegionModel f3 = regionModel(Preset::kF3);
  // Midway inside each band of Table I, and beyond 60 degrees.
  const double ecc[] = {2.0, 6.5, 12.0, 25.0, 45.0, 75.0, 120.0, 179.0};
  const int expected[] = {0, 1, 2, 3, 4, 5, 5, 5};
  for (int i = 0; i < 8; ++i) EXPECT_EQ(regionOf(pointAt(ecc[i], 3.0), f3), expected[i]) << ecc[i] << " deg";
  // F1 puts everything beyond the perifovea in its fourth region.
  const RegionModel f1 = regionModel(Preset::kF1);
  EXPECT_EQ(regionOf(pointAt(25.0, 3.0), f1), 3);
  EXPECT_EQ(regionOf(pointAt(170.0, 3.0), f1), 3);
  // FREF: one region.
  EXPECT_EQ(regionOf(pointAt(170.0, 3.0), regionModel(Preset::kFRef)), 0);
}

TEST(Partition, BoundsBeyond90DegreesReachBehindTheEye) {
  const RegionModel model = regionModel(Preset::kCustom, {30.0, 90.0, 135.0}, 150.0);
  EXPECT_EQ(regionOf(pointAt(10.0, 1.0), model), 0);
  EXPECT_EQ(regionOf(pointAt(60.0, 1.0), model), 1);
  EXPECT_EQ(regionOf(pointAt(100.0, 1.0), model), 2);
  EXPECT_EQ(regionOf(pointAt(134.0, 1.0), model), 2);
  EXPECT_EQ(regionOf(pointAt(136.0, 1.0), model), 3);
  EXPECT_EQ(regionOf(pointAt(180.0, 1.0), model), 3);
}

TEST(Partition, CountsPerRegionAddUp) {
  PointCloud cloud = test::randomCloud(5000, Eigen::Vector3d::Zero(), 4.0f, 3);
  const RegionModel model = regionModel(Preset::kF3);
  std::vector<uint8_t> region(cloud.size());
  PartitionCounts counts;
  Gaze gaze;
  gaze.direction = Eigen::Vector3d(0.2, -0.1, 1.0).normalized();
  partitionRef(cloud, gaze, ConeBounds::fromModel(model), region.data(), counts);
  uint32_t total = 0;
  for (int r = 0; r < model.regionCount(); ++r) {
    total += counts.per_region[r];
    EXPECT_EQ(counts.per_region[r], std::count(region.begin(), region.end(), r));
  }
  EXPECT_EQ(total, cloud.size());
  EXPECT_EQ(counts.invalid, 0u);
}

struct BruteCase {
  Preset preset;
  std::vector<double> custom;
  double origin_offset_m;
  float half_extent_m;
  uint64_t seed;
};

void PrintTo(const BruteCase& c, std::ostream* os) {
  *os << presetName(c.preset) << "_offset" << c.origin_offset_m << "_seed" << c.seed;
}

class PartitionMatchesBruteForce : public ::testing::TestWithParam<BruteCase> {};

// Property: on random clouds, every point gets exactly the region that the
// brute-force angle computation (long double atan2) gives.
TEST_P(PartitionMatchesBruteForce, EveryPoint) {
  const BruteCase& c = GetParam();
  std::mt19937_64 rng(c.seed);
  const RegionModel model = regionModel(c.preset, c.custom, 179.0);
  const std::vector<double> bounds = boundsOf(model);
  const Eigen::Vector3d origin(c.origin_offset_m, -0.5 * c.origin_offset_m, 0.25 * c.origin_offset_m);
  for (int trial = 0; trial < 8; ++trial) {
    PointCloud cloud = test::randomCloud(20000, origin, c.half_extent_m, c.seed * 100 + trial);
    Gaze gaze;
    std::uniform_real_distribution<double> jitter(-1.0, 1.0);
    gaze.origin_m = origin + Eigen::Vector3d(jitter(rng), jitter(rng), jitter(rng));
    gaze.direction = test::randomUnit(rng);
    std::vector<uint8_t> region(cloud.size());
    PartitionCounts counts;
    partitionRef(cloud, gaze, ConeBounds::fromModel(model), region.data(), counts);
    int mismatches = 0;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const long double ecc = test::bruteEccentricityDeg(cloud.origin_m, cloud.x()[i], cloud.y()[i], cloud.z()[i],
                                                         gaze.origin_m, gaze.direction);
      const int expected = test::bruteRegion(ecc, bounds);
      if (region[i] != expected && ++mismatches < 5) {
        ADD_FAILURE() << "point " << i << " ecc " << static_cast<double>(ecc) << " deg: region "
                      << int{region[i]} << ", expected " << expected;
      }
    }
    EXPECT_EQ(mismatches, 0);
  }
}

INSTANTIATE_TEST_SUITE_P(
    RandomClouds, PartitionMatchesBruteForce,
    ::testing::Values(BruteCase{Preset::kF1, {}, 0.0, 5.0f, 1}, BruteCase{Preset::kF2, {}, 0.0, 5.0f, 2},
                      BruteCase{Preset::kF3, {}, 0.0, 5.0f, 3}, BruteCase{Preset::kF3, {}, 1e4, 5.0f, 4},
                      BruteCase{Preset::kF3, {}, 0.0, 0.01f, 5},
                      BruteCase{Preset::kCustom, {1.0, 45.0, 90.0, 135.0, 170.0}, 0.0, 3.0f, 6},
                      BruteCase{Preset::kCustom, {0.5, 2.0, 89.999}, 1e4, 50.0f, 7}));

}  // namespace
}  // namespace fovea::pipeline
