// Every SIMD kernel against its scalar reference, bit for bit, on every Highway
// target compiled in and supported here. The test cases are generated from the
// list of targets (TargetTest/<Kernel>/<TARGET>), so CTest shows which targets ran.
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/partition.h"
#include "pipeline/voxel_sampler.h"
#include "tests/support/clouds.h"

namespace fovea::pipeline {
namespace {

constexpr float kNaNf = std::numeric_limits<float>::quiet_NaN();
constexpr float kInff = std::numeric_limits<float>::infinity();
constexpr float kDenormf = std::numeric_limits<float>::denorm_min();

// Restricts Highway's dispatch to one target for the test's duration.
class TargetTest : public ::testing::TestWithParam<int64_t> {
 protected:
  void SetUp() override { forceSimdTarget(GetParam()); }
  void TearDown() override { forceSimdTarget(0); }
};

std::vector<int64_t> targetsHere() {
  forceSimdTarget(0);
  return simdTargets();
}

TEST(SimdTargets, ListWhichTargetsRun) {
  const std::vector<int64_t> targets = targetsHere();
  ASSERT_FALSE(targets.empty());
  std::string names;
  for (int64_t t : targets) names += std::string(names.empty() ? "" : " ") + simdTargetName(t);
  std::printf("Highway targets compiled and supported here (each runs every equivalence test): %s\n", names.c_str());
  std::printf("dispatch picks: %s\n", simdTargetName(activeSimdTarget()));
  RecordProperty("targets", names);
  // forceSimdTarget really switches the dispatch.
  for (int64_t t : targets) {
    forceSimdTarget(t);
    EXPECT_EQ(activeSimdTarget(), t);
  }
  forceSimdTarget(0);
}

TEST(KernelSelection, TheEnvironmentChoosesTheDefaultOnce) {
  EXPECT_EQ(parseKernelSet("ref"), KernelSet::kRef);
  EXPECT_EQ(parseKernelSet("simd"), KernelSet::kSimd);
  EXPECT_EQ(parseKernelSet("SIMD"), std::nullopt);
  const char* env = std::getenv("FOVEA_FORCE_KERNEL");
  const KernelSet expected = (env != nullptr && std::string(env) == "ref") ? KernelSet::kRef : KernelSet::kSimd;
  EXPECT_EQ(defaultKernelSet(), expected) << "FOVEA_FORCE_KERNEL=" << (env ? env : "(unset)");
  EXPECT_EQ(PipelineCapacity{}.kernels, expected);
  std::printf("default kernel set: %s\n", std::string(kernelSetName(defaultKernelSet())).c_str());
}

// ---- back-projection --------------------------------------------------------

::testing::AssertionResult sameCloud(const PointCloud& a, const PointCloud& b) {
  if (a.size() != b.size()) return ::testing::AssertionFailure() << "size " << a.size() << " vs " << b.size();
  if (a.origin_m != b.origin_m || a.has_color != b.has_color) return ::testing::AssertionFailure() << "origin/colour";
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::bit_cast<uint32_t>(a.x()[i]) != std::bit_cast<uint32_t>(b.x()[i]) ||
        std::bit_cast<uint32_t>(a.y()[i]) != std::bit_cast<uint32_t>(b.y()[i]) ||
        std::bit_cast<uint32_t>(a.z()[i]) != std::bit_cast<uint32_t>(b.z()[i]) || a.rgb()[i] != b.rgb()[i]) {
      return ::testing::AssertionFailure() << "point " << i << ": (" << a.x()[i] << ", " << a.y()[i] << ", "
                                           << a.z()[i] << ", " << a.rgb()[i] << ") vs (" << b.x()[i] << ", "
                                           << b.y()[i] << ", " << b.z()[i] << ", " << b.rgb()[i] << ")";
    }
  }
  return ::testing::AssertionSuccess();
}

hal::RgbdFrame randomFrame(int w, int h, std::mt19937_64& rng) {
  hal::RgbdFrame frame(w, h);
  std::uniform_real_distribution<double> f(200.0, 700.0), c(-10.0, 10.0);
  frame.intrinsics = {w, h, f(rng), f(rng), w / 2.0 + c(rng), h / 2.0 + c(rng)};
  const double scales[] = {0.001, 1.0 / 5000.0, 0.0001, 0.00025};
  frame.depth_scale_m = scales[rng() % 4];
  const Eigen::Quaterniond q = Eigen::Quaterniond::UnitRandom();
  frame.T_world_cam.R_world_cam = q.toRotationMatrix();
  frame.T_world_cam.t_world_cam = Eigen::Vector3d(c(rng) * 1e3, c(rng), c(rng) * 1e2);
  frame.has_rgb = (rng() % 4) != 0;
  for (std::size_t i = 0; i < frame.pixelCount(); ++i) {
    const uint64_t r = rng();
    frame.depth()[i] = (r % 7 == 0) ? 0 : static_cast<uint16_t>(r >> 16);  // holes, all ranges
    frame.rgb()[3 * i] = static_cast<uint8_t>(r >> 8);
    frame.rgb()[3 * i + 1] = static_cast<uint8_t>(r >> 40);
    frame.rgb()[3 * i + 2] = static_cast<uint8_t>(r >> 56);
  }
  return frame;
}

void expectSameBackprojection(const hal::RgbdFrame& frame, const DepthRange& range, std::size_t capacity) {
  PointCloud ref(capacity), simd(capacity);
  BackprojectCounts cr, cs;
  const Status sr = backprojectRef(frame, range, ref, cr);
  const Status ss = backprojectSimd(frame, range, simd, cs);
  ASSERT_EQ(sr.code(), ss.code()) << sr.toString() << " vs " << ss.toString();
  EXPECT_TRUE(sameCloud(ref, simd)) << frame.width() << "x" << frame.height();
  if (!sr) return;
  EXPECT_EQ(cr.pixels, cs.pixels);
  EXPECT_EQ(cr.valid, cs.valid);
  EXPECT_EQ(cr.no_depth, cs.no_depth);
  EXPECT_EQ(cr.out_of_range, cs.out_of_range);
}

TEST_P(TargetTest, BackprojectRandomFrames) {
  std::mt19937_64 rng(11);
  // Widths around every vector width (1..64 lanes) exercise the tails.
  const int sizes[][2] = {{640, 480}, {1, 1}, {3, 2}, {7, 5}, {15, 3}, {17, 4}, {31, 2}, {33, 3}, {63, 2},
                          {65, 3}, {129, 2}, {1000, 1}, {1, 37}, {320, 240}};
  for (const auto& s : sizes) {
    for (int rep = 0; rep < 3; ++rep) {
      const hal::RgbdFrame frame = randomFrame(s[0], s[1], rng);
      const DepthRange ranges[] = {{}, {0.5, 3.0}, {0.0, 1e9}, {1.0, 1.0 + 1e-12}};
      for (const DepthRange& range : ranges) expectSameBackprojection(frame, range, frame.pixelCount());
    }
  }
}

TEST_P(TargetTest, BackprojectEveryRawDepthAndRangeEdges) {
  hal::RgbdFrame frame(256, 256);
  frame.intrinsics = {256, 256, 300.0, 310.0, 127.3, 128.9};
  for (std::size_t i = 0; i < frame.pixelCount(); ++i) frame.depth()[i] = static_cast<uint16_t>(i);
  for (double scale : {0.001, 1.0 / 5000.0, 0.1}) {
    frame.depth_scale_m = scale;
    for (const DepthRange& range : {DepthRange{}, DepthRange{0.1, 0.1 + 1e-3}, DepthRange{0.3, 0.30000000000000004},
                                    DepthRange{65.535, 1e6}, DepthRange{0.0, 65.535}}) {
      expectSameBackprojection(frame, range, frame.pixelCount());
    }
  }
}

TEST_P(TargetTest, BackprojectErrorsMatch) {
  std::mt19937_64 rng(12);
  hal::RgbdFrame frame = randomFrame(37, 5, rng);
  expectSameBackprojection(frame, DepthRange{0.0, 1e9}, 10);  // capacity exceeded
  expectSameBackprojection(frame, DepthRange{2.0, 1.0}, 185);  // bad range
  frame.T_world_cam.R_world_cam(1, 1) = std::numeric_limits<double>::quiet_NaN();
  expectSameBackprojection(frame, DepthRange{}, 185);  // bad pose
}

// ---- partition --------------------------------------------------------------

RegionModel model(Preset preset, std::vector<double> custom = {}, double far = 90.0) {
  AcuityConfig config;
  config.preset = preset;
  config.custom_bounds_deg = std::move(custom);
  config.far_ecc_deg = far;
  return RegionModel::create(config).value();
}

std::vector<RegionModel> allModels() {
  return {model(Preset::kF1),
          model(Preset::kF2),
          model(Preset::kF3),
          model(Preset::kFRef),
          model(Preset::kCustom, {10.0, 90.0, 120.0}, 130.0),
          model(Preset::kCustom, {5.0, 45.0, 89.999, 90.0, 90.001, 135.0, 179.9}, 179.95),
          model(Preset::kCustom, {100.0, 170.0}, 175.0)};
}

void expectSamePartition(const PointCloud& cloud, const Gaze& raw_gaze, const RegionModel& m, const char* what) {
  const Gaze gaze = normalizeGaze(raw_gaze).value();
  const ConeBounds bounds = ConeBounds::fromModel(m);
  std::vector<uint8_t> ref(cloud.size() + 1, 0xAB), simd(cloud.size() + 1, 0xAB);
  PartitionCounts cr, cs;
  partitionRef(cloud, gaze, bounds, ref.data(), cr);
  partitionSimd(cloud, gaze, bounds, simd.data(), cs);
  for (std::size_t i = 0; i < ref.size(); ++i) {
    ASSERT_EQ(ref[i], simd[i]) << what << ": point " << i << " of " << cloud.size() << " (" << cloud.x()[i] << ", "
                               << cloud.y()[i] << ", " << cloud.z()[i] << ")";  // [size] checks nothing is overrun
  }
  EXPECT_EQ(cr.per_region, cs.per_region) << what;
  EXPECT_EQ(cr.invalid, cs.invalid) << what;
}

Gaze gazeAlong(const Eigen::Vector3d& dir, const Eigen::Vector3d& eye = Eigen::Vector3d::Zero()) {
  Gaze g;
  g.origin_m = eye;
  g.direction = dir;
  return g;
}

TEST_P(TargetTest, PartitionRandomClouds) {
  std::mt19937_64 rng(21);
  const std::vector<RegionModel> models = allModels();
  for (std::size_t n : {0, 1, 2, 3, 5, 7, 9, 15, 17, 31, 33, 1000, 20011}) {
    for (const Eigen::Vector3d& origin : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1e4, -1e4, 1e4)}) {
      const PointCloud cloud = test::randomCloud(n, origin, 5.0f, rng());
      for (const RegionModel& m : models) {
        Gaze gaze = gazeAlong(test::randomUnit(rng), origin + 0.5 * test::randomUnit(rng));
        expectSamePartition(cloud, gaze, m, "random");
      }
    }
  }
}

TEST_P(TargetTest, PartitionGazeAlongAxes) {
  std::mt19937_64 rng(22);
  const PointCloud cloud = test::randomCloud(5003, Eigen::Vector3d::Zero(), 3.0f, 23);
  const Eigen::Vector3d axes[] = {Eigen::Vector3d::UnitX(),  -Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                  -Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(),  -Eigen::Vector3d::UnitZ()};
  for (const RegionModel& m : allModels()) {
    for (const auto& axis : axes) expectSamePartition(cloud, gazeAlong(axis), m, "axis");
  }
}

TEST_P(TargetTest, PartitionPointsExactlyOnConeBoundaries) {
  // t a power of two makes d = tan(e) * t exact; the points on, just inside and just
  // outside each bound, for bounds below, at and beyond 90 degrees, on each axis.
  for (const RegionModel& m : allModels()) {
    const ConeBounds bounds = ConeBounds::fromModel(m);
    PointCloud cloud(2000);
    for (int j = 0; j < bounds.count; ++j) {
      for (int e = -6; e <= 12; e += 3) {
        const double t = std::ldexp(1.0, e);
        for (double sign : {1.0, -1.0}) {  // ahead, and behind (the > 90 degree cones)
          const double d = bounds.tan_e[j] * t;
          const auto df = static_cast<float>(d);
          for (float x : {df, std::nextafter(df, 0.0f), std::nextafter(df, 1e30f)}) {
            (void)cloud.push(x, 0.0f, static_cast<float>(sign * t), 0);
            (void)cloud.push(0.0f, -x, static_cast<float>(sign * t), 0);
          }
        }
      }
    }
    (void)cloud.push(1.0f, 0.0f, 0.0f, 0);  // exactly 90 degrees
    (void)cloud.push(0.0f, 0.0f, 0.0f, 0);  // at the eye
    (void)cloud.push(0.0f, 0.0f, -0.0f, 0);
    expectSamePartition(cloud, gazeAlong(Eigen::Vector3d::UnitZ()), m, "boundary");
    // The same with the exact double boundary: the origin carries the float's rounding.
    for (int j = 0; j < bounds.count; ++j) {
      PointCloud exact(1);
      const double d = bounds.tan_e[j] * 2.0;
      exact.origin_m = Eigen::Vector3d(d - static_cast<double>(static_cast<float>(d)), 0, 0);
      (void)exact.push(static_cast<float>(d), 0.0f, 2.0f, 0);
      expectSamePartition(exact, gazeAlong(Eigen::Vector3d::UnitZ()), m, "exact boundary");
    }
  }
}

TEST_P(TargetTest, PartitionNonFiniteDenormalAndFarPoints) {
  std::mt19937_64 rng(24);
  PointCloud cloud(4000);
  const float specials[] = {kNaNf, -kNaNf, kInff, -kInff, kDenormf, -kDenormf, 1e-38f, 0.0f, -0.0f,
                            3e38f, -3e38f, 1.0f, -2.5f, 1e4f, -1e4f};
  std::uniform_int_distribution<int> pick(0, 14);
  for (int i = 0; i < 4000; ++i) {
    (void)cloud.push(specials[pick(rng)], specials[pick(rng)], specials[pick(rng)], 0);
  }
  for (const RegionModel& m : allModels()) {
    expectSamePartition(cloud, gazeAlong(Eigen::Vector3d(1, 2, 3)), m, "specials");
    expectSamePartition(cloud, gazeAlong(Eigen::Vector3d::UnitZ(), Eigen::Vector3d(0, 0, 1e4)), m, "specials far");
  }
  // 10 km from the world origin, seen from near and far eyes.
  PointCloud far = test::randomCloud(3001, Eigen::Vector3d(1e4, 1e4, -1e4), 50.0f, 25);
  for (const RegionModel& m : allModels()) {
    expectSamePartition(far, gazeAlong(Eigen::Vector3d(1, 1, -1), Eigen::Vector3d::Zero()), m, "far");
    expectSamePartition(far, gazeAlong(test::randomUnit(rng), Eigen::Vector3d(1e4, 1e4, -1e4)), m, "far, eye inside");
  }
}

// ---- voxel indices ------------------------------------------------------------

void expectSameVoxelIndices(const std::vector<float>& coord, const std::vector<uint8_t>& region, double origin,
                            const std::vector<double>& inv, const char* what) {
  ASSERT_EQ(inv.size(), 256u);
  std::vector<double> simd(coord.size() + 1, -7.0);
  voxelIndexSimd(coord.data(), region.data(), coord.size(), origin, inv.data(), simd.data());
  for (std::size_t i = 0; i < coord.size(); ++i) {
    const double ref = voxelIndex(origin, coord[i], inv[region[i]]);
    if (std::isnan(ref) && std::isnan(simd[i])) continue;  // NaN payloads are not part of the contract
    ASSERT_EQ(std::bit_cast<uint64_t>(ref), std::bit_cast<uint64_t>(simd[i]))
        << what << ": point " << i << " coord " << coord[i] << " origin " << origin << " inv " << inv[region[i]]
        << ": " << ref << " vs " << simd[i];
  }
  EXPECT_EQ(simd[coord.size()], -7.0) << what << ": wrote past the end";
}

std::vector<double> invTable(std::mt19937_64& rng) {
  std::vector<double> inv(256, 0.0);
  std::uniform_real_distribution<double> size(0.0005, 0.3);
  for (int r = 1; r < kMaxRegions; ++r) inv[r] = 1.0 / size(rng);
  inv[3] = 4.0;  // 0.25 m: exact faces
  inv[4] = 1024.0;
  return inv;
}

TEST_P(TargetTest, VoxelIndexRandomAndTails) {
  std::mt19937_64 rng(31);
  for (std::size_t n : {0, 1, 2, 3, 4, 5, 7, 8, 9, 15, 16, 17, 33, 10007}) {
    std::uniform_real_distribution<float> c(-20.0f, 20.0f);
    std::vector<float> coord(n);
    std::vector<uint8_t> region(n);
    for (std::size_t i = 0; i < n; ++i) {
      coord[i] = c(rng);
      region[i] = static_cast<uint8_t>(rng() % 9 == 8 ? kRegionInvalid : rng() % kMaxRegions);
    }
    const std::vector<double> inv = invTable(rng);
    for (double origin : {0.0, 0.5, -3.25, 1e4, -1e4, 12345.678}) expectSameVoxelIndices(coord, region, origin, inv, "random");
  }
}

TEST_P(TargetTest, VoxelIndexOnFacesAndSpecials) {
  std::mt19937_64 rng(32);
  std::vector<float> coord;
  // Multiples of 0.25 and 1/1024 are exact voxel faces; and their float neighbours.
  for (int k = -400; k <= 400; ++k) {
    for (float base : {0.25f * k, static_cast<float>(k) / 1024.0f}) {
      coord.push_back(base);
      coord.push_back(std::nextafter(base, -1e30f));
      coord.push_back(std::nextafter(base, 1e30f));
    }
  }
  for (float s : {kNaNf, kInff, -kInff, kDenormf, -kDenormf, 1e-38f, -1e-38f, 0.0f, -0.0f, 3e38f, -3e38f}) {
    coord.push_back(s);
  }
  std::vector<uint8_t> region(coord.size());
  for (std::size_t i = 0; i < coord.size(); ++i) region[i] = static_cast<uint8_t>(1 + i % 7);
  const std::vector<double> inv = invTable(rng);
  for (double origin : {0.0, -0.0, 0.25, -0.75, 1e4, -1e4, 1e4 + 0.125}) {
    expectSameVoxelIndices(coord, region, origin, inv, "faces");
  }
}

std::string targetName(const ::testing::TestParamInfo<int64_t>& info) { return simdTargetName(info.param); }

INSTANTIATE_TEST_SUITE_P(Targets, TargetTest, ::testing::ValuesIn(targetsHere()), targetName);

}  // namespace
}  // namespace fovea::pipeline
