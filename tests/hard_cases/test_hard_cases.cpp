// Degenerate and extreme inputs, each named after what it would break.
#include <cmath>
#include <limits>
#include <numbers>

#include <gtest/gtest.h>

#include "hal/camera/registration/registration.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "tests/support/clouds.h"

namespace fovea::pipeline {
namespace {

using hal::DepthToColourRegistration;
using hal::RegistrationCounts;
using hal::RegistrationParams;

using test::regionModel;

std::vector<uint8_t> partition(const PointCloud& cloud, const Gaze& gaze, const RegionModel& m,
                               PartitionCounts* counts_out = nullptr) {
  std::vector<uint8_t> region(cloud.size());
  PartitionCounts counts;
  partitionRef(cloud, normalizeGaze(gaze).value(), ConeBounds::fromModel(m), region.data(), counts);
  if (counts_out) *counts_out = counts;
  return region;
}

Gaze gazeAlong(const Eigen::Vector3d& dir, const Eigen::Vector3d& eye = Eigen::Vector3d::Zero()) {
  Gaze g;
  g.origin_m = eye;
  g.direction = dir;
  return g;
}

TEST(HardCases, GazeAlongEachAxisExactly) {
  const RegionModel f3 = regionModel(Preset::kF3);
  const Eigen::Vector3d axes[] = {Eigen::Vector3d::UnitX(),  -Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                  -Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(),  -Eigen::Vector3d::UnitZ()};
  for (const Eigen::Vector3d& axis : axes) {
    PointCloud cloud(4);
    // On the axis ahead, 10 degrees off, perpendicular, behind.
    const Eigen::Vector3d side = std::abs(axis.x()) > 0 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitX();
    const double off = std::tan(10.0 * std::numbers::pi / 180.0);
    const Eigen::Vector3d pts[] = {3.0 * axis, 3.0 * axis + 3.0 * off * side, side, -2.0 * axis};
    for (const auto& p : pts) (void)cloud.push(float(p.x()), float(p.y()), float(p.z()), 0);
    const auto region = partition(cloud, gazeAlong(axis), f3);
    EXPECT_EQ(region[0], 0);
    EXPECT_EQ(region[1], 2);  // 10 degrees: perifovea
    EXPECT_EQ(region[2], 5);  // 90 degrees: beyond 60
    EXPECT_EQ(region[3], 5);  // behind
  }
}

TEST(HardCases, PointExactlyOnARegionBoundaryBelongsToTheInnerRegion) {
  const RegionModel f1 = regionModel(Preset::kF1);
  const ConeBounds bounds = ConeBounds::fromModel(f1);
  for (int j = 0; j < bounds.count; ++j) {
    // t = 2 (a power of two) makes d = tan(e) * t exact, and |(d, 0, 0)| = d exactly.
    const double d = bounds.tan_e[j] * 2.0;
    PointCloud cloud(2);
    (void)cloud.push(0.0f, 0.0f, 2.0f, 0);
    cloud.x()[0] = static_cast<float>(d);
    // Use double origin so the boundary point is exact: the point is (d, 0, 2) in world.
    cloud.origin_m = Eigen::Vector3d(d - static_cast<double>(static_cast<float>(d)), 0, 0);
    (void)cloud.push(0.0f, 0.0f, 2.0f, 0);
    cloud.x()[1] = std::nextafter(static_cast<float>(d), 1e9f);  // just outside
    const auto region = partition(cloud, gazeAlong(Eigen::Vector3d::UnitZ()), f1);
    EXPECT_EQ(region[0], j) << "on bound " << f1.boundDeg(j);
    EXPECT_EQ(region[1], j + 1) << "just past bound " << f1.boundDeg(j);
  }
}

TEST(HardCases, PointAtTheEyeGoesToTheFoveaWithoutNaN) {
  PointCloud cloud(1);
  cloud.origin_m = Eigen::Vector3d(5, 6, 7);
  (void)cloud.push(0.0f, 0.0f, 0.0f, 0);
  const auto region = partition(cloud, gazeAlong(Eigen::Vector3d(1, 1, 0), Eigen::Vector3d(5, 6, 7)), regionModel(Preset::kF3));
  EXPECT_EQ(region[0], 0);
  Foveator f = Foveator::create({1, 1}, {}).value();
  FoveatedCloud out(1);
  FoveationStats stats;
  ASSERT_TRUE(f.foveate(cloud, gazeAlong(Eigen::Vector3d(1, 1, 0), Eigen::Vector3d(5, 6, 7)), out, stats).isOk());
  EXPECT_TRUE(std::isfinite(stats.fixation.d0_m));
  EXPECT_EQ(out.size(), 1u);
}

TEST(HardCases, PointsBehindTheEyeGoToTheOutermostRegion) {
  PointCloud cloud(3);
  (void)cloud.push(0.0f, 0.0f, -1.0f, 0);     // straight behind
  (void)cloud.push(0.0f, 5.0f, -1e-6f, 0);    // just behind the eye's plane
  (void)cloud.push(0.0f, 1e-7f, -100.0f, 0);  // far behind, near the axis
  for (Preset p : {Preset::kF1, Preset::kF2, Preset::kF3}) {
    const RegionModel m = regionModel(p);
    for (uint8_t r : partition(cloud, gazeAlong(Eigen::Vector3d::UnitZ()), m)) EXPECT_EQ(r, m.regionCount() - 1);
  }
}

TEST(HardCases, PointAtExactly90Degrees) {
  PointCloud cloud(2);
  (void)cloud.push(1.0f, 0.0f, 0.0f, 0);  // t = 0 exactly
  (void)cloud.push(0.0f, 1e30f, 0.0f, 0);
  // A 90-degree bound includes its boundary; with bounds below 90 it is outermost.
  const RegionModel m = regionModel(Preset::kCustom, {10.0, 90.0, 120.0}, 130.0);
  auto region = partition(cloud, gazeAlong(Eigen::Vector3d::UnitZ()), m);
  EXPECT_EQ(region[0], 1);
  EXPECT_EQ(region[1], 1);
  region = partition(cloud, gazeAlong(Eigen::Vector3d::UnitZ()), regionModel(Preset::kF3));
  EXPECT_EQ(region[0], 5);
}

TEST(HardCases, FarPointNearTheAxisKeepsItsEccentricity) {
  // 10 km along the gaze, 0.5 m off it: 0.00286 degrees, well inside the fovea.
  // sqrt(|v|^2 - t^2) would give 0 or garbage here in float; the rejection vector does not.
  PointCloud cloud(2);
  cloud.origin_m = Eigen::Vector3d(0, 0, 10000);
  (void)cloud.push(0.5f, 0.0f, 0.0f, 0);
  const double off = 10000.0 * std::tan(5.0 * std::numbers::pi / 180.0);
  (void)cloud.push(static_cast<float>(off + 0.01), 0.0f, 0.0f, 0);  // just outside 5 degrees
  const auto region = partition(cloud, gazeAlong(Eigen::Vector3d::UnitZ()), regionModel(Preset::kF1));
  EXPECT_EQ(region[0], 0);
  EXPECT_EQ(region[1], 1);
}

TEST(HardCases, PointExactlyOnAVoxelFaceBelongsToTheUpperVoxel) {
  // Voxel 0.25 m (exact in binary): x = 0.5 is the lower face of voxel 2.
  PointCloud cloud(3);
  cloud.origin_m = Eigen::Vector3d(0.25, 0, 0);
  (void)cloud.push(0.25f, 0.1f, 0.1f, packRgb(10, 0, 0));
  (void)cloud.push(0.3f, 0.1f, 0.1f, packRgb(30, 0, 0));
  (void)cloud.push(std::nextafter(0.25f, 0.0f), 0.1f, 0.1f, packRgb(200, 0, 0));  // just below the face
  const std::vector<uint8_t> region(3, 1);
  VoxelSampler sampler(3, 3);
  FoveatedCloud out(3);
  SampleCounts counts;
  ASSERT_TRUE(sampler.sample(cloud, region.data(), 2, {0, 0.25}, out, counts).isOk());
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out.weight[0], 1u);  // voxel 1: [0.25, 0.5)
  EXPECT_EQ(rgbRed(out.points.rgb()[0]), 200);
  EXPECT_EQ(out.weight[1], 2u);  // voxel 2: [0.5, 0.75)
  EXPECT_EQ(rgbRed(out.points.rgb()[1]), 20);
  EXPECT_GE(out.points.world(1).x(), 0.5);
}

TEST(HardCases, CoordinatesOffsetBy1e4Metres) {
  // The same local cloud at the world origin and 10 km away (x, y, z) gives the
  // same sampled cloud, shifted. Voxel 0.125 m divides 1e4 exactly.
  PointCloud near = test::randomCloud(20000, Eigen::Vector3d::Zero(), 2.0f, 21);
  PointCloud far = near;
  far.origin_m = Eigen::Vector3d(1e4, -1e4, 1e4);
  const std::vector<uint8_t> region(near.size(), 1);
  VoxelSampler sampler(near.size(), near.size());
  FoveatedCloud a(near.size()), b(near.size());
  SampleCounts counts;
  ASSERT_TRUE(sampler.sample(near, region.data(), 2, {0, 0.125}, a, counts).isOk());
  ASSERT_TRUE(sampler.sample(far, region.data(), 2, {0, 0.125}, b, counts).isOk());
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t o = 0; o < a.size(); ++o) {
    EXPECT_EQ(a.points.x()[o], b.points.x()[o]);
    EXPECT_EQ(a.points.y()[o], b.points.y()[o]);
    EXPECT_EQ(a.weight[o], b.weight[o]);
  }
}

TEST(HardCases, AMillionPointsInOneVoxel) {
  constexpr std::size_t kN = 1000000;
  PointCloud cloud(kN);
  cloud.origin_m = Eigen::Vector3d(1e4 + 0.5, 0.5, 0.5);
  // A symmetric pattern around the voxel centre, so the exact centroid is known.
  double sum_x = 0;
  for (std::size_t i = 0; i < kN; ++i) {
    const float d = 0.001f * static_cast<float>(i % 200) - 0.0995f;  // -0.0995 .. 0.1005
    (void)cloud.push(d, -d, 0.25f * d, packRgb(static_cast<uint8_t>(i % 256), 128, 3));
    sum_x += d;
  }
  const std::vector<uint8_t> region(kN, 1);
  VoxelSampler sampler(kN, 16);
  FoveatedCloud out(kN);
  SampleCounts counts;
  ASSERT_TRUE(sampler.sample(cloud, region.data(), 2, {0, 1.0}, out, counts).isOk());
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out.weight[0], kN);
  EXPECT_NEAR(out.points.x()[0], sum_x / kN, 1e-7);
  EXPECT_NEAR(out.points.world(0).x(), 1e4 + 0.5 + sum_x / kN, 1e-7);
  EXPECT_EQ(rgbGreen(out.points.rgb()[0]), 128);
  EXPECT_EQ(rgbBlue(out.points.rgb()[0]), 3);
}

TEST(HardCases, EmptyCloud) {
  PointCloud cloud(10);
  Foveator f = Foveator::create({10, 10}, {}).value();
  FoveatedCloud out(10);
  FoveationStats stats;
  ASSERT_TRUE(f.foveate(cloud, Gaze{}, out, stats).isOk());
  EXPECT_EQ(out.size(), 0u);
  EXPECT_EQ(stats.fixation.source, FixationSource::kFallback);
}

TEST(HardCases, EmptyFoveaStillSamplesThePeriphery) {
  PointCloud cloud = test::randomCloud(5000, Eigen::Vector3d::Zero(), 3.0f, 23);
  Foveator f = Foveator::create({5000, 5000}, {}).value();
  FoveatedCloud out(5000);
  FoveationStats stats;
  // Looking at the sky: every point is more than 5 degrees off.
  ASSERT_TRUE(f.foveate(cloud, gazeAlong(Eigen::Vector3d::UnitZ(), Eigen::Vector3d(0, 0, 100)), out, stats).isOk());
  EXPECT_EQ(stats.regions[0].points_in, 0u);
  EXPECT_EQ(stats.fixation.source, FixationSource::kFallback);
  EXPECT_GT(out.size(), 0u);
}

TEST(HardCases, AllDepthInvalidGivesAnEmptyFoveatedFrame) {
  hal::RgbdFrame frame(8, 6);
  frame.intrinsics = {8, 6, 5.0, 5.0, 3.5, 2.5};
  for (std::size_t i = 0; i < frame.pixelCount(); ++i) frame.depth()[i] = (i % 2) ? 0 : 65535;  // none or too far
  PointCloud cloud(48);
  BackprojectCounts bc;
  ASSERT_TRUE(backprojectRef(frame, DepthRange{}, cloud, bc).isOk());
  EXPECT_EQ(cloud.size(), 0u);
  Foveator f = Foveator::create({48, 48}, {}).value();
  FoveatedCloud out(48);
  FoveationStats stats;
  ASSERT_TRUE(f.foveate(cloud, Gaze{}, out, stats).isOk());
  EXPECT_EQ(out.size(), 0u);
}

TEST(HardCases, NonFiniteCoordinatesAreCountedAndNeverPropagated) {
  PointCloud cloud = test::randomCloud(1000, Eigen::Vector3d::Zero(), 3.0f, 25);
  cloud.x()[3] = std::numeric_limits<float>::quiet_NaN();
  cloud.y()[500] = std::numeric_limits<float>::infinity();
  cloud.z()[999] = -std::numeric_limits<float>::infinity();
  Foveator f = Foveator::create({1000, 1000}, {}).value();
  FoveatedCloud out(1000);
  FoveationStats stats;
  ASSERT_TRUE(f.foveate(cloud, Gaze{}, out, stats).isOk());
  EXPECT_EQ(stats.dropped_nonfinite, 3u);
  EXPECT_EQ(stats.points_in, 997u);
  uint64_t weight = 0;
  for (std::size_t o = 0; o < out.size(); ++o) {
    ASSERT_TRUE(std::isfinite(out.points.x()[o]) && std::isfinite(out.points.y()[o]) && std::isfinite(out.points.z()[o]));
    weight += out.weight[o];
  }
  EXPECT_EQ(weight, 997u);
}

TEST(HardCases, NonFiniteOrZeroGazeIsRejected) {
  PointCloud cloud = test::randomCloud(10, Eigen::Vector3d::Zero(), 1.0f, 27);
  Foveator f = Foveator::create({10, 10}, {}).value();
  FoveatedCloud out(10);
  FoveationStats stats;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const Gaze bad[] = {gazeAlong(Eigen::Vector3d(nan, 0, 1)), gazeAlong(Eigen::Vector3d(0, 0, inf)),
                      gazeAlong(Eigen::Vector3d::UnitZ(), Eigen::Vector3d(nan, 0, 0)),
                      gazeAlong(Eigen::Vector3d::Zero()), gazeAlong(Eigen::Vector3d(1e-300, 0, 0))};
  for (const Gaze& g : bad) {
    Status s = f.foveate(cloud, g, out, stats);
    EXPECT_EQ(s.code(), ErrorCode::kInvalidInput);
    EXPECT_EQ(out.size(), 0u);
  }
  EXPECT_NE(f.foveate(cloud, gazeAlong(Eigen::Vector3d::Zero()), out, stats).message().find("zero length"),
            std::string::npos);
}

TEST(HardCases, NonFinitePoseIsRejectedBeforeAnyPointIsMade) {
  hal::RgbdFrame frame(4, 4);
  frame.intrinsics = {4, 4, 3.0, 3.0, 1.5, 1.5};
  for (std::size_t i = 0; i < 16; ++i) frame.depth()[i] = 1500;
  frame.T_world_cam.R_world_cam(2, 0) = std::numeric_limits<double>::quiet_NaN();
  PointCloud cloud(16);
  BackprojectCounts bc;
  EXPECT_EQ(backprojectRef(frame, DepthRange{}, cloud, bc).code(), ErrorCode::kInvalidInput);
  EXPECT_EQ(cloud.size(), 0u);
}

TEST(HardCases, VoxelIndexSpanOverflowIsRefusedNotWrapped) {
  // 2 km of cloud at 1 mm voxels is 2e6 voxels along x: more than 2^20.
  PointCloud cloud(2);
  (void)cloud.push(-1000.0f, 0.0f, 0.0f, 0);
  (void)cloud.push(1000.0f, 0.0f, 0.0f, 0);
  const std::vector<uint8_t> region(2, 1);
  VoxelSampler sampler(2, 2);
  FoveatedCloud out(2);
  SampleCounts counts;
  Status s = sampler.sample(cloud, region.data(), 2, {0, 0.001}, out, counts);
  EXPECT_EQ(s.code(), ErrorCode::kRangeExceeded);
  EXPECT_NE(s.message().find("along x"), std::string::npos) << s.message();
  // A coordinate whose index does not fit 52 bits at all.
  PointCloud huge(1);
  (void)huge.push(3e38f, 0.0f, 0.0f, 0);
  const std::vector<uint8_t> one(1, 1);
  EXPECT_EQ(sampler.sample(huge, one.data(), 2, {0, 1e-3}, out, counts).code(), ErrorCode::kRangeExceeded);
  // Just within the span is fine: 2^20 voxels of 1/1024 m from 0.
  PointCloud edge(2);
  (void)edge.push(0.0f, 0.0f, 0.0f, 0);
  (void)edge.push(1023.999f, 0.0f, 0.0f, 0);
  EXPECT_TRUE(sampler.sample(edge, region.data(), 2, {0, 1.0 / 1024}, out, counts).isOk());
}

TEST(HardCases, DenormalAndTinyCoordinates) {
  PointCloud cloud(3);
  (void)cloud.push(std::numeric_limits<float>::denorm_min(), 0.0f, 1.0f, 0);
  (void)cloud.push(-std::numeric_limits<float>::denorm_min(), 1e-38f, 1.0f, 0);
  (void)cloud.push(0.0f, -0.0f, 1.0f, 0);
  Foveator f = Foveator::create({3, 3}, {}).value();
  FoveatedCloud out(3);
  FoveationStats stats;
  ASSERT_TRUE(f.foveate(cloud, Gaze{}, out, stats).isOk());
  EXPECT_EQ(stats.regions[0].points_in, 3u);
  EXPECT_NEAR(stats.fixation.d0_m, 1.0, 1e-9);
}

// ---- colour registration ------------------------------------------------------

RegistrationParams sameCameras(int w, int h) {
  RegistrationParams p;
  p.depth.intrinsics = {w, h, 100.0, 100.0, (w - 1) / 2.0, (h - 1) / 2.0};
  p.colour = p.depth;
  return p;
}

TEST(HardCases, RegistrationWithNoDepthAtAllIsBlackAndCountsNothing) {
  const DepthToColourRegistration reg = DepthToColourRegistration::create(sameCameras(37, 11)).value();
  const std::vector<uint16_t> depth(37 * 11, 0);
  const std::vector<uint8_t> colour(37 * 11 * 3, 200);
  for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
    std::vector<uint8_t> out(colour.size(), 1);
    const RegistrationCounts c = reg.apply(depth.data(), colour.data(), out.data(), ks);
    EXPECT_EQ(c.with_depth, 0u);
    EXPECT_EQ(c.coloured, 0u);
    EXPECT_EQ(out, std::vector<uint8_t>(colour.size(), 0)) << kernelSetName(ks);
  }
}

// The last half pixel: a projection at width - 0.5 exactly is outside (pixel k
// covers [k - 0.5, k + 0.5)), one float below it is the last column.
TEST(HardCases, RegistrationProjectionOnTheImageEdgeHalfPixel) {
  RegistrationParams p = sameCameras(8, 1);
  p.depth.intrinsics = {8, 1, 64.0, 64.0, 0.0, 0.0};
  // Colour u = depth u + shift: depth u = 0 lands at shift.
  for (const auto& [shift, want] : {std::pair{7.5, -1}, std::pair{7.4999995, 7}, std::pair{-0.5, 0},
                                    std::pair{-0.50000006, -1}}) {
    p.colour.intrinsics = {8, 1, 64.0, 64.0, shift, 0.0};
    const DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
    const std::vector<uint16_t> depth = {1000, 0, 0, 0, 0, 0, 0, 0};
    std::vector<uint8_t> colour(8 * 3);
    for (int i = 0; i < 8; ++i) colour[3 * i] = static_cast<uint8_t>(10 + i);
    for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
      std::vector<uint8_t> out(8 * 3, 99);
      const RegistrationCounts c = reg.apply(depth.data(), colour.data(), out.data(), ks);
      EXPECT_EQ(out[0], want < 0 ? 0 : 10 + want) << "shift " << shift << " " << kernelSetName(ks);
      EXPECT_EQ(c.coloured, want < 0 ? 0u : 1u) << "shift " << shift;
      EXPECT_EQ(c.outside_colour, want < 0 ? 1u : 0u) << "shift " << shift;
    }
  }
}

// 65535 units at 1 m a unit is 65.5 km: far, but finite, and registered.
TEST(HardCases, RegistrationOfTheLargestDepthValue) {
  RegistrationParams p = sameCameras(16, 16);
  p.depth_scale_m = 1.0;
  p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.05, 0.0, 0.0);  // disparity 7.6e-5 px: none
  const DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
  const std::vector<uint16_t> depth(256, 65535);
  std::vector<uint8_t> colour(256 * 3);
  for (std::size_t i = 0; i < colour.size(); ++i) colour[i] = static_cast<uint8_t>(i * 7 + 1);
  for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
    std::vector<uint8_t> out(colour.size());
    EXPECT_EQ(reg.apply(depth.data(), colour.data(), out.data(), ks).coloured, 256u);
    EXPECT_EQ(out, colour) << kernelSetName(ks);
  }
}

// A one-pixel colour camera: every depth pixel whose ray meets that pixel gets it.
TEST(HardCases, RegistrationIntoAOnePixelColourImage) {
  RegistrationParams p = sameCameras(9, 9);
  // The colour pixel covers 25 x/z + 0.1 in [-0.5, 0.5): x/z in [-0.024, 0.016).
  p.colour.intrinsics = {1, 1, 25.0, 25.0, 0.1, 0.1};
  const DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
  const std::vector<uint16_t> depth(81, 2000);
  const std::vector<uint8_t> colour = {1, 2, 3};
  for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
    std::vector<uint8_t> out(81 * 3);
    // Depth rays: (u - 4) / 100, inside for u = 2, 3, 4, 5 (and v alike): 4 x 4 pixels.
    EXPECT_EQ(reg.apply(depth.data(), colour.data(), out.data(), ks).coloured, 16u) << kernelSetName(ks);
    EXPECT_EQ(out[3 * 40 + 2], 3);
    EXPECT_EQ(out[3 * 0 + 2], 0);
  }
}

}  // namespace
}  // namespace fovea::pipeline
