// Every SIMD kernel against its scalar reference, bit for bit, on every Highway
// target compiled in and supported here. The test cases are generated from the
// list of targets (TargetTest/<Kernel>/<TARGET>), so CTest shows which targets ran.
#include <array>
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

#include "tests/support/simd_targets.h"
#include "hal/camera/registration/registration.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/kernels/worker_pool.h"
#include "pipeline/partition.h"
#include "pipeline/pyramid_sampler.h"
#include "pipeline/voxel_sampler.h"
#include "tests/support/clouds.h"
#include "tests/support/guarded_array.h"

namespace fovea::pipeline {
namespace {

using hal::DepthToColourRegistration;
using hal::RegistrationCounts;
using hal::RegistrationParams;

constexpr float kNaNf = std::numeric_limits<float>::quiet_NaN();
constexpr float kInff = std::numeric_limits<float>::infinity();
constexpr float kDenormf = std::numeric_limits<float>::denorm_min();

using test::TargetTest;
using test::simdTargetsHere;

TEST(SimdTargets, ListWhichTargetsRun) {
  const std::vector<int64_t> targets = simdTargetsHere();
  ASSERT_FALSE(targets.empty());
  std::string names;
  for (int64_t t : targets) names += std::string(names.empty() ? "" : " ") + simdTargetName(t);
  std::printf("Highway targets compiled and supported here (each runs every equivalence test): %s\n", names.c_str());
  std::printf("dispatch picks: %s\n", simdTargetName(activeSimdTarget()));
  std::printf("SVE vector: %d bytes\n", test::sveVectorBytes());
  RecordProperty("targets", names);
  RecordProperty("sve_vector_bytes", test::sveVectorBytes());
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
  // A cloud exactly as large as the frame's valid pixels: the kernel's whole-vector
  // stores must give way to masked ones near its end (ASan sees any write past it).
  if (capacity != cr.valid && cr.valid > 0) expectSameBackprojection(frame, range, cr.valid);
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

// Rows back-projected into outputs that end exactly at their last point, before a
// page the process may not touch, cut into row ranges as Backprojector's threads cut
// them: nothing past a range's end is read or written (a store that loads and
// rewrites a whole vector would undo the next thread's points), and the ranges
// together are the reference's cloud.
TEST_P(TargetTest, BackprojectRowsTouchNothingPastTheirEnd) {
  std::mt19937_64 rng(13);
  const int sizes[][2] = {{7, 3}, {1, 5}, {33, 1}, {17, 4}, {129, 17}, {640, 6}};
  for (const auto& s : sizes) {
    const hal::RgbdFrame frame = randomFrame(s[0], s[1], rng);
    const DepthRange range{0.0, 1e9};
    PointCloud ref(frame.pixelCount());
    BackprojectCounts cr;
    ASSERT_TRUE(backprojectRef(frame, range, ref, cr).isOk());
    kernels::BackprojectParams p;
    ASSERT_TRUE(kernels::prepareBackprojection(frame, range, p).isOk());
    for (int parts = 1; parts <= 4; ++parts) {
      std::size_t done = 0;
      for (int part = 0; part < parts; ++part) {
        const auto h = static_cast<std::size_t>(frame.height());
        const int row0 = static_cast<int>(WorkerPool::rangeBegin(h, part, parts));
        const int row1 = static_cast<int>(WorkerPool::rangeBegin(h, part + 1, parts));
        std::size_t no_depth = 0, out_of_range = 0;
        const std::size_t valid = kernels::backprojectCountRows(p, row0, row1, &no_depth, &out_of_range);
        test::GuardedArray<float> x(valid), y(valid), z(valid);
        test::GuardedArray<uint32_t> rgb(valid);
        p.out_x = x.data(), p.out_y = y.data(), p.out_z = z.data(), p.out_rgb = rgb.data();
        kernels::backprojectRows(p, row0, row1, 0, valid);
        ASSERT_LE(done + valid, ref.size());
        for (std::size_t i = 0; i < valid; ++i) {
          const std::size_t r = done + i;
          ASSERT_EQ(std::bit_cast<uint32_t>(x[i]), std::bit_cast<uint32_t>(ref.x()[r])) << s[0] << "x" << s[1];
          ASSERT_EQ(std::bit_cast<uint32_t>(y[i]), std::bit_cast<uint32_t>(ref.y()[r]));
          ASSERT_EQ(std::bit_cast<uint32_t>(z[i]), std::bit_cast<uint32_t>(ref.z()[r]));
          ASSERT_EQ(rgb[i], ref.rgb()[r]);
        }
        done += valid;
      }
      EXPECT_EQ(done, ref.size()) << s[0] << "x" << s[1] << " in " << parts << " parts";
    }
  }
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

// ---- ACUITY's levels ------------------------------------------------------------

std::vector<LevelBounds> allLevelBounds() {
  std::vector<LevelBounds> all;
  // The view cull's variants take turns rather than multiply the list.
  const std::pair<ViewCull, double> culls[] = {
      {ViewCull::kOff, 70.0}, {ViewCull::kCoarsest, 70.0}, {ViewCull::kDrop, 40.0}, {ViewCull::kDrop, 120.0}};
  for (double slope : {0.022, 1.0}) {  // 1.0: MARs beyond 90 degrees (sin held at 1)
    for (double margin : {std::sqrt(3.0), 0.5}) {
      for (double floor_m : {0.0, 0.008}) {
        AcuityConfig config;
        config.preset = Preset::kAcuity;
        config.slope = slope;
        config.level_margin = margin;
        config.floor_m = floor_m;
        // A floor growing with the squared distance on every other model.
        config.floor_per_m2 = all.size() % 3 == 1 ? 0.002 : 0.0;
        config.view_cull = culls[all.size() % 4].first;
        config.view_cull_deg = culls[all.size() % 4].second;
        all.push_back(LevelBounds::fromModel(RegionModel::create(config).value()));
      }
    }
  }
  return all;
}

// The gaze with a fovea growth and a head of its own (or none), chosen by seed.
Gaze withHead(Gaze gaze, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const double growths[] = {0.0, 0.0, 2.5, 30.0, 180.0};
  gaze.fovea_growth_deg = growths[rng() % 5];
  gaze.view_known = rng() % 4 != 0;
  // The head mostly near the gaze, sometimes anywhere (the cull then takes most).
  gaze.view_forward = rng() % 2 ? gaze.direction + 0.3 * test::randomUnit(rng) : test::randomUnit(rng);
  if (gaze.view_forward.norm() < 1e-3) gaze.view_forward = gaze.direction;
  return gaze;
}

void expectSameLevels(const PointCloud& cloud, const Gaze& raw_gaze, const LevelBounds& bounds, const char* what) {
  static uint64_t seed = 1;
  const Gaze gaze = normalizeGaze(withHead(raw_gaze, seed++)).value();
  std::vector<uint8_t> ref(cloud.size() + 1, 0xAB), simd(cloud.size() + 1, 0xAB);
  PartitionCounts cr, cs;
  assignLevelsRef(cloud, gaze, bounds, ref.data(), cr);
  assignLevelsSimd(cloud, gaze, bounds, simd.data(), cs);
  for (std::size_t i = 0; i < ref.size(); ++i) {
    ASSERT_EQ(ref[i], simd[i]) << what << ": point " << i << " of " << cloud.size() << " (" << cloud.x()[i] << ", "
                               << cloud.y()[i] << ", " << cloud.z()[i] << ")";  // [size] checks nothing is overrun
  }
  EXPECT_EQ(cr.per_region, cs.per_region) << what;
  EXPECT_EQ(cr.invalid, cs.invalid) << what;
  EXPECT_EQ(cr.culled, cs.culled) << what;
}

TEST_P(TargetTest, LevelsRandomClouds) {
  std::mt19937_64 rng(41);
  const std::vector<LevelBounds> all = allLevelBounds();
  for (std::size_t n : {0, 1, 2, 3, 5, 7, 9, 15, 17, 33, 1000, 20011}) {
    for (const Eigen::Vector3d& origin : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1e4, -1e4, 1e4)}) {
      // Clouds of a few metres and of a few hundred: every level is used.
      for (float extent : {3.0f, 300.0f}) {
        const PointCloud cloud = test::randomCloud(n, origin, extent, rng());
        for (const LevelBounds& b : all) {
          expectSameLevels(cloud, gazeAlong(test::randomUnit(rng), origin + 0.5 * test::randomUnit(rng)), b, "random");
        }
      }
    }
  }
}

// The hard clouds of ACUITY's kernels: a random one 20 m across, NaN, Inf, denormals and
// 3e38 in every combination, points on the gaze axis ahead and behind, at the eye and at
// exactly 90 degrees, and a cloud 10 km out; and the six axes.
struct HardClouds {
  PointCloud cloud, specials, axis_points, far;
  std::array<Eigen::Vector3d, 6> axes = {Eigen::Vector3d::UnitX(),  -Eigen::Vector3d::UnitX(),
                                         Eigen::Vector3d::UnitY(),  -Eigen::Vector3d::UnitY(),
                                         Eigen::Vector3d::UnitZ(),  -Eigen::Vector3d::UnitZ()};
};

HardClouds hardClouds(std::mt19937_64& rng, uint64_t seed) {
  HardClouds h{test::randomCloud(5003, Eigen::Vector3d::Zero(), 20.0f, seed), PointCloud(4000), PointCloud(64),
               test::randomCloud(3001, Eigen::Vector3d(1e4, 1e4, -1e4), 50.0f, seed + 1)};
  const float values[] = {kNaNf, -kNaNf, kInff, -kInff, kDenormf, -kDenormf, 1e-38f, 0.0f, -0.0f,
                          3e38f, -3e38f, 1.0f, -2.5f, 1e4f, -1e4f};
  std::uniform_int_distribution<int> pick(0, 14);
  for (int i = 0; i < 4000; ++i) (void)h.specials.push(values[pick(rng)], values[pick(rng)], values[pick(rng)], 0);
  for (float z : {0.0f, -0.0f, 0.001f, 1.0f, 3.0f, 1e3f, -0.001f, -1.0f, -3.0f}) (void)h.axis_points.push(0.0f, 0.0f, z, 0);
  for (float x : {0.001f, 1.0f, 100.0f}) (void)h.axis_points.push(x, 0.0f, 0.0f, 0);
  return h;
}

TEST_P(TargetTest, LevelsGazeAlongAxesSpecialsAndFarPoints) {
  std::mt19937_64 rng(42);
  const HardClouds h = hardClouds(rng, 43);
  for (const LevelBounds& b : allLevelBounds()) {
    for (const auto& axis : h.axes) expectSameLevels(h.cloud, gazeAlong(axis), b, "axis");
    expectSameLevels(h.specials, gazeAlong(Eigen::Vector3d(1, 2, 3)), b, "specials");
    expectSameLevels(h.specials, gazeAlong(Eigen::Vector3d::UnitZ(), Eigen::Vector3d(0, 0, 1e4)), b, "specials far");
    expectSameLevels(h.axis_points, gazeAlong(Eigen::Vector3d::UnitZ()), b, "on the axis");
    expectSameLevels(h.far, gazeAlong(Eigen::Vector3d(1, 1, -1), Eigen::Vector3d::Zero()), b, "far");
    expectSameLevels(h.far, gazeAlong(test::randomUnit(rng), Eigen::Vector3d(1e4, 1e4, -1e4)), b, "far, eye inside");
  }
}

// ---- ACUITY's refinement ---------------------------------------------------------

// refineTestSimd against refineTestRef on the levels of `cloud`, with
// representatives that are the points themselves moved by 10 um to 1 m (across the
// MAR's threshold for every level), none, one past the output's end or another
// point's; the output cloud has an origin of its own.
void expectSameRefinement(const PointCloud& cloud, const Gaze& raw_gaze, const LevelBounds& bounds, uint64_t seed,
                          const char* what) {
  const Gaze gaze = normalizeGaze(withHead(raw_gaze, seed)).value();
  std::mt19937_64 rng(seed);
  std::vector<uint8_t> levels(cloud.size());
  PartitionCounts counts;
  assignLevelsRef(cloud, gaze, bounds, levels.data(), counts);
  PointCloud out(cloud.size() + 1);
  out.origin_m = cloud.origin_m + Eigen::Vector3d(0.25, -3.0, 1e3 * static_cast<double>(seed % 2));
  const Eigen::Vector3f shift = (cloud.origin_m - out.origin_m).cast<float>();
  std::uniform_real_distribution<float> log_size(-5.0f, 0.0f);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f e = std::pow(10.0f, log_size(rng)) * test::randomUnit(rng).cast<float>();
    (void)out.push(cloud.x()[i] + shift.x() + e.x(), cloud.y()[i] + shift.y() + e.y(), cloud.z()[i] + shift.z() + e.z(), 0);
  }
  std::vector<uint32_t> rep(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const uint64_t pick = rng() % 20;
    rep[i] = pick == 0   ? kNoRepresentative
             : pick == 1 ? static_cast<uint32_t>(out.size())
             : pick == 2 ? static_cast<uint32_t>(rng() % std::max<std::size_t>(1, out.size()))
                         : static_cast<uint32_t>(i);
  }
  std::vector<uint8_t> ref(cloud.size() + 1, 0xAB), simd(cloud.size() + 1, 0xAB);
  const std::size_t br = refineTestRef(cloud, gaze, bounds, out, rep.data(), levels.data(), ref.data());
  const std::size_t bs = refineTestSimd(cloud, gaze, bounds, out, rep.data(), levels.data(), simd.data());
  for (std::size_t i = 0; i < ref.size(); ++i) {  // [size] checks nothing is overrun
    ASSERT_EQ(ref[i], simd[i]) << what << ": point " << i << " of " << cloud.size() << " level " << int(levels[i]);
  }
  EXPECT_EQ(br, bs) << what;
}

TEST_P(TargetTest, RefinementRandomClouds) {
  std::mt19937_64 rng(51);
  const std::vector<LevelBounds> all = allLevelBounds();
  std::size_t moved = 0, kept = 0;
  for (std::size_t n : {0, 1, 2, 3, 5, 7, 9, 15, 17, 33, 1000, 20011}) {
    for (const Eigen::Vector3d& origin : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1e4, -1e4, 1e4)}) {
      for (float extent : {3.0f, 300.0f}) {
        const PointCloud cloud = test::randomCloud(n, origin, extent, rng());
        for (const LevelBounds& b : all) {
          expectSameRefinement(cloud, gazeAlong(test::randomUnit(rng), origin + 0.5 * test::randomUnit(rng)), b, rng(),
                               "random");
        }
      }
    }
  }
  // Not vacuous: on one cloud, the test finds points beyond their MAR and within it.
  const PointCloud cloud = test::randomCloud(20011, Eigen::Vector3d::Zero(), 3.0f, 52);
  const Gaze gaze = normalizeGaze(gazeAlong(Eigen::Vector3d::UnitZ())).value();
  std::vector<uint8_t> levels(cloud.size());
  PartitionCounts counts;
  const LevelBounds& b = all.front();
  assignLevelsRef(cloud, gaze, b, levels.data(), counts);
  PointCloud out(cloud.size());
  out.origin_m = cloud.origin_m;
  for (std::size_t i = 0; i < cloud.size(); ++i) (void)out.push(cloud.x()[i] + 0.004f * static_cast<float>(i % 7), cloud.y()[i], cloud.z()[i], 0);
  std::vector<uint32_t> rep(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) rep[i] = static_cast<uint32_t>(i);
  std::vector<uint8_t> state(cloud.size());
  moved = refineTestSimd(cloud, gaze, b, out, rep.data(), levels.data(), state.data());
  for (std::size_t i = 0; i < cloud.size(); ++i) kept += state[i] == kRefineWithin;
  EXPECT_GT(moved, 100u);
  EXPECT_GT(kept, 100u);
}

TEST_P(TargetTest, RefinementGazeAlongAxesSpecialsAndFarPoints) {
  std::mt19937_64 rng(53);
  const HardClouds h = hardClouds(rng, 54);
  for (const LevelBounds& b : allLevelBounds()) {
    for (const auto& axis : h.axes) expectSameRefinement(h.cloud, gazeAlong(axis), b, rng(), "axis");
    expectSameRefinement(h.specials, gazeAlong(Eigen::Vector3d(1, 2, 3)), b, rng(), "specials");
    expectSameRefinement(h.axis_points, gazeAlong(Eigen::Vector3d::UnitZ()), b, rng(), "on the axis");
    expectSameRefinement(h.far, gazeAlong(Eigen::Vector3d(1, 1, -1), Eigen::Vector3d::Zero()), b, rng(), "far");
    expectSameRefinement(h.far, gazeAlong(test::randomUnit(rng), Eigen::Vector3d(1e4, 1e4, -1e4)), b, rng(),
                         "far, eye inside");
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

// ---- colour registration ------------------------------------------------------

void expectSameRegistration(const RegistrationParams& params, const std::vector<uint16_t>& depth,
                            const std::vector<uint8_t>& colour, const std::string& what) {
  Result<DepthToColourRegistration> reg = DepthToColourRegistration::create(params);
  ASSERT_TRUE(reg) << what << ": " << reg.status().toString();
  // One byte past the image on each side: neither kernel writes outside it.
  std::vector<uint8_t> ref(depth.size() * 3 + 2, 0xA5), simd(depth.size() * 3 + 2, 0xA5);
  const RegistrationCounts cr = reg->registerRef(depth.data(), colour.data(), ref.data() + 1);
  const RegistrationCounts cs = reg->registerSimd(depth.data(), colour.data(), simd.data() + 1);
  EXPECT_EQ(cr.with_depth, cs.with_depth) << what;
  EXPECT_EQ(cr.coloured, cs.coloured) << what;
  EXPECT_EQ(cr.outside_colour, cs.outside_colour) << what;
  EXPECT_EQ(ref.front(), 0xA5);
  EXPECT_EQ(ref.back(), 0xA5);
  for (std::size_t i = 0; i < ref.size(); ++i) {
    ASSERT_EQ(ref[i], simd[i]) << what << ": byte " << i << " (pixel " << (i - 1) / 3 << " of " << depth.size()
                               << ", depth " << (i > 0 && i <= 3 * depth.size() ? depth[(i - 1) / 3] : 0) << ")";
  }
}

hal::StreamCalibration randomCamera(int w, int h, std::mt19937_64& rng, int distortion) {
  hal::StreamCalibration c;
  std::uniform_real_distribution<double> f(0.3, 2.0), off(-0.2, 0.2);
  c.intrinsics = {w, h, f(rng) * w, f(rng) * w, w * (0.5 + off(rng)), h * (0.5 + off(rng))};
  if (distortion > 0) {
    c.distortion.model = hal::Distortion::Model::kPlumbBob;
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const double strength = distortion == 1 ? 0.1 : 3.0;  // realistic, or strong (fisheye-like folding)
    c.distortion.coeffs = {u(rng) * strength, u(rng) * strength, u(rng) * strength * 0.05,
                           u(rng) * strength * 0.05, u(rng) * strength};
  }
  return c;
}

// A rotation from the test's own generator (Eigen's UnitRandom uses std::rand,
// whose state would differ from one target's test to the next).
Eigen::Matrix3d randomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  return q.normalized().toRotationMatrix();
}

std::vector<uint8_t> randomColour(int w, int h, std::mt19937_64& rng) {
  std::vector<uint8_t> rgb(static_cast<std::size_t>(w) * h * 3);
  for (auto& b : rgb) b = static_cast<uint8_t>(rng() >> 13);
  return rgb;
}

TEST_P(TargetTest, RegistrationRandomScenes) {
  std::mt19937_64 rng(41);
  // Depth widths around every vector width (1..64 lanes) exercise the tails.
  const int sizes[][2] = {{640, 480}, {1, 1}, {3, 2}, {7, 5}, {15, 3}, {17, 4}, {31, 2}, {33, 3},
                          {63, 2}, {65, 3}, {129, 2}, {1000, 1}, {1, 37}, {97, 61}};
  const int colour_sizes[][2] = {{1280, 720}, {320, 240}, {1, 1}, {17, 3}, {640, 480}};
  for (const auto& s : sizes) {
    for (int rep = 0; rep < 4; ++rep) {
      RegistrationParams p;
      const auto& cs = colour_sizes[rng() % 5];
      p.depth = randomCamera(s[0], s[1], rng, 0);
      p.colour = randomCamera(cs[0], cs[1], rng, rep % 3);
      // Large rotations too: any orientation, baselines up to a metre.
      p.T_colour_depth.R_world_cam = rep == 0 ? Eigen::Matrix3d::Identity()
                                              : randomRotation(rng);
      std::uniform_real_distribution<double> t(-1.0, 1.0);
      p.T_colour_depth.t_world_cam = Eigen::Vector3d(t(rng), t(rng), t(rng)) * (rep == 3 ? 1.0 : 0.05);
      const double scales[] = {0.001, 1.0 / 5000.0, 0.0001, 0.01};
      p.depth_scale_m = scales[rng() % 4];
      std::vector<uint16_t> depth(static_cast<std::size_t>(s[0]) * s[1]);
      for (auto& d : depth) {
        const uint64_t r = rng();
        d = (r % 7 == 0) ? 0 : (r % 11 == 0) ? 65535 : (r % 13 == 0) ? 1 : static_cast<uint16_t>(r >> 20);
      }
      expectSameRegistration(p, depth, randomColour(cs[0], cs[1], rng),
                             std::to_string(s[0]) + "x" + std::to_string(s[1]) + " rep " + std::to_string(rep));
    }
  }
}

TEST_P(TargetTest, RegistrationEveryDepthValue) {
  std::mt19937_64 rng(42);
  std::vector<uint16_t> depth(256 * 256);
  for (std::size_t i = 0; i < depth.size(); ++i) depth[i] = static_cast<uint16_t>(i);
  for (int distortion = 0; distortion < 3; ++distortion) {
    RegistrationParams p;
    p.depth = randomCamera(256, 256, rng, 0);
    p.colour = randomCamera(1280, 720, rng, distortion);
    p.T_colour_depth.R_world_cam = randomRotation(rng);
    p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.05, -0.3, 0.2);
    for (double scale : {0.001, 1.0 / 5000.0, 1e-6}) {
      p.depth_scale_m = scale;
      expectSameRegistration(p, depth, randomColour(1280, 720, rng), "every depth, distortion " +
                                                                         std::to_string(distortion));
    }
  }
}

// Ill-conditioned on purpose: telephoto cameras 45 degrees apart, the colour
// image far off its optical axis (fx * a ~ 1e5, cx ~ -1e5), so one float ulp
// anywhere moves a projection by about 0.01 px and about one pixel in a hundred
// to its neighbour. A kernel that fused or reordered any operation fails here.
TEST_P(TargetTest, RegistrationIllConditioned) {
  std::mt19937_64 rng(45);
  std::vector<uint16_t> depth(640 * 480);
  for (auto& d : depth) d = static_cast<uint16_t>(300 + rng() % 20000);
  // No distortion; every plumb-bob term large enough that its last bit shows.
  const std::array<double, 5> distortions[] = {{0, 0, 0, 0, 0}, {0.2, -0.05, 0.1, 0.15, 0.01},
                                               {-0.3, 0.08, -0.12, 0.2, -0.02}};
  for (const auto& coeffs : distortions) {
    RegistrationParams p;
    std::uniform_real_distribution<double> small(-1e-4, 1e-4);
    p.depth.intrinsics = {640, 480, 1e5, 1e5, 319.5 + 1e4 * small(rng), 239.5};
    p.colour.intrinsics = {1280, 720, 1e5, 1e5, 0.0, 0.0};
    p.colour.distortion.model = hal::Distortion::Model::kPlumbBob;
    p.colour.distortion.coeffs = coeffs;
    p.T_colour_depth.R_world_cam =
        (Eigen::AngleAxisd(std::numbers::pi / 4 + small(rng), Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(small(rng), Eigen::Vector3d::UnitX()))
            .toRotationMatrix();
    p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.01, 0.002, -0.003);
    // Put the principal point where the depth camera's axis lands plus the image
    // centre, so the view falls on the image (the plumb-bob formula, in double).
    const Eigen::Vector3d axis = p.T_colour_depth.R_world_cam * Eigen::Vector3d(0, 0, 1);
    const double a = axis.x() / axis.z(), b = axis.y() / axis.z(), r2 = a * a + b * b;
    const auto& k = coeffs;
    const double radial = 1 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]));
    const double ad = a * radial + 2 * k[2] * a * b + k[3] * (r2 + 2 * a * a);
    const double bd = b * radial + k[2] * (r2 + 2 * b * b) + 2 * k[3] * a * b;
    p.colour.intrinsics.cx = 640.0 - 1e5 * ad;
    p.colour.intrinsics.cy = 360.0 - 1e5 * bd;
    const DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
    std::vector<uint8_t> colour = randomColour(1280, 720, rng), out(depth.size() * 3);
    const RegistrationCounts counts = reg.registerRef(depth.data(), colour.data(), out.data());
    EXPECT_GT(counts.coloured, depth.size() / 10) << "the view should land on the image";
    expectSameRegistration(p, depth, colour, "ill-conditioned, k1 " + std::to_string(coeffs[0]));
  }
}

// Projections exactly on the rounding boundary between two colour pixels (and on
// the image's own edges, -0.5 and width - 0.5), and their float neighbours.
TEST_P(TargetTest, RegistrationOnPixelBorders) {
  std::mt19937_64 rng(43);
  const int w = 67, h = 13;
  std::vector<uint16_t> depth(static_cast<std::size_t>(w) * h);
  for (std::size_t i = 0; i < depth.size(); ++i) depth[i] = static_cast<uint16_t>(1 + i % 5000);
  for (double shift : {0.5, -0.5, 0.25, 1.5, 66.5, -66.5}) {
    for (double nudge : {0.0, 1e-7, -1e-7, 1e-5, -1e-5}) {
      RegistrationParams p;
      p.depth.intrinsics = {w, h, 64.0, 64.0, 33.0, 6.0};
      p.colour = p.depth;
      // Identity extrinsics: colour u = depth u + shift, so hu = u + shift + 0.5.
      p.colour.intrinsics.cx += shift + nudge;
      p.colour.intrinsics.cy += shift + nudge;
      expectSameRegistration(p, depth, randomColour(w, h, rng), "shift " + std::to_string(shift + nudge));
      // The same with a baseline giving a half-pixel disparity at some depths.
      p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.5 / 64.0, 0.0, 0.0);
      expectSameRegistration(p, depth, randomColour(w, h, rng), "baseline, shift " + std::to_string(shift + nudge));
    }
  }
}

// Overflow, NaN and huge values inside the kernel from parameters create()
// accepts: both kernels must agree on black for them (and never convert them).
TEST_P(TargetTest, RegistrationFarOutsideAndOverflow) {
  std::mt19937_64 rng(44);
  const int w = 41, h = 9;
  std::vector<uint16_t> depth(static_cast<std::size_t>(w) * h);
  for (auto& d : depth) d = static_cast<uint16_t>(rng());
  depth[0] = 65535;
  depth[1] = 1;
  depth[2] = 0;
  const std::vector<uint8_t> colour = randomColour(64, 48, rng);
  RegistrationParams base;
  base.depth.intrinsics = {w, h, 30.0, 30.0, 20.0, 4.0};
  base.colour.intrinsics = {64, 48, 50.0, 50.0, 32.0, 24.0};
  struct Case {
    const char* what;
    void (*apply)(RegistrationParams&);
  };
  const Case cases[] = {
      {"far away", [](RegistrationParams& p) { p.T_colour_depth.t_world_cam = Eigen::Vector3d(1e3, -1e3, 0.0); }},
      {"far ahead", [](RegistrationParams& p) { p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.0, 0.0, 1e30); }},
      {"grazing", [](RegistrationParams& p) { p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.0, 0.0, -0.9999); }},
      {"huge focal", [](RegistrationParams& p) { p.colour.intrinsics.fx = 3e38; }},
      {"tiny focal", [](RegistrationParams& p) { p.colour.intrinsics.fy = 1e-38; }},
      {"huge scale (inf - inf)",
       [](RegistrationParams& p) {
         p.depth_scale_m = 3e38;
         p.T_colour_depth.t_world_cam = Eigen::Vector3d(-3e38, 3e38, -3e38);
       }},
      {"huge distortion",
       [](RegistrationParams& p) {
         p.colour.distortion.model = hal::Distortion::Model::kPlumbBob;
         p.colour.distortion.coeffs = {1e30, -1e30, 1e20, -1e20, 3e38};
       }},
      {"far centre", [](RegistrationParams& p) { p.colour.intrinsics.cx = -1e9; }},
      {"sideways", [](RegistrationParams& p) {
         p.T_colour_depth.R_world_cam = Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
       }},
  };
  for (const Case& c : cases) {
    RegistrationParams p = base;
    c.apply(p);
    for (double scale : {0.001, 1.0}) {
      if (p.depth_scale_m == 0.001) p.depth_scale_m = scale;
      expectSameRegistration(p, depth, colour, c.what);
    }
  }
}

TEST(Registration, NaNProducingParametersAreRefused) {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  RegistrationParams base;
  base.depth.intrinsics = {64, 48, 50.0, 50.0, 32.0, 24.0};
  base.colour = base.depth;
  ASSERT_TRUE(DepthToColourRegistration::create(base));
  double* fields[] = {&base.depth.intrinsics.fx, &base.depth.intrinsics.cy, &base.colour.intrinsics.fy,
                      &base.colour.intrinsics.cx, &base.colour.distortion.coeffs[1],
                      &base.T_colour_depth.t_world_cam.x(), &base.T_colour_depth.R_world_cam(2, 1),
                      &base.depth_scale_m};
  for (double* field : fields) {
    for (double bad : {kNaN, kInf, -kInf, 1e39 /* infinite as float */}) {
      const double saved = *field;
      *field = bad;
      base.colour.distortion.model = hal::Distortion::Model::kPlumbBob;
      EXPECT_FALSE(DepthToColourRegistration::create(base)) << "field #" << (field - fields[0]) << " = " << bad;
      *field = saved;
    }
  }
}


// ---- the image pyramid's rule ------------------------------------------------------

// pyramidMergeSimd against pyramidMergeRef on `cells` (six arrays of `count`), bit for bit.
// Returns how many cells merge.
std::size_t expectSameMerge(const kernels::PyramidMergeParams& p, const std::vector<std::vector<float>>& sums,
                            const char* what) {
  const std::size_t count = sums[0].size();
  const kernels::PyramidCellSums cells{sums[0].data(), sums[1].data(), sums[2].data(),
                                       sums[3].data(), sums[4].data(), sums[5].data()};
  std::vector<float> ref(count + 1, -1.0f), simd(count + 1, -1.0f);
  pyramidMergeRef(p, cells, count, ref.data());
  kernels::pyramidMergeSimd(p, cells, count, simd.data());
  EXPECT_EQ(simd[count], -1.0f) << what << ": wrote past the end";
  std::size_t merged = 0;
  for (std::size_t i = 0; i < count; ++i) {
    merged += ref[i] != 0.0f;
    EXPECT_EQ(std::bit_cast<uint32_t>(ref[i]), std::bit_cast<uint32_t>(simd[i]))
        << what << ": cell " << i << " of " << count << " (n " << sums[0][i] << ", m " << sums[1][i] << " "
        << sums[2][i] << " " << sums[3][i] << ", m2 " << sums[4][i] << ", zmax " << sums[5][i] << ")";
    if (::testing::Test::HasFailure()) break;
  }
  return merged;
}

kernels::PyramidMergeParams randomMergeParams(std::mt19937_64& rng, bool floors) {
  kernels::PyramidMergeParams p;
  const Eigen::Matrix3d r = Eigen::Quaterniond(Eigen::Vector4d::Random().normalized()).toRotationMatrix();
  const Eigen::Vector3d l = test::randomUnit(rng);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (int a = 0; a < 3; ++a) {
    p.eye.l[a] = static_cast<float>(l[a]);
    p.eye.origin_minus_eye[a] = 0.3f * (unit(rng) - 0.5f);
    for (int b = 0; b < 3; ++b) p.r[3 * a + b] = static_cast<float>(r(a, b));
  }
  p.eye.bounds.slope = 0.01f + 0.04f * unit(rng);
  p.growth_deg = unit(rng) < 0.5f ? 0.0f : 10.0f * unit(rng);
  p.margin = 0.1f + unit(rng);
  p.floors = floors;
  p.floor_m = floors ? 0.01f * unit(rng) : 0.0f;
  p.floor_per_m2 = floors ? 0.003f * unit(rng) : 0.0f;
  p.lateral = static_cast<float>(1 << (1 + rng() % 7)) / (100.0f + 600.0f * unit(rng));
  return p;
}

// Cells as a camera gives them: n pixels at depths 0.2 to 20 m, their sums, a spread.
std::vector<std::vector<float>> randomCells(std::mt19937_64& rng, std::size_t count) {
  std::vector<std::vector<float>> sums(6, std::vector<float>(count));
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (std::size_t i = 0; i < count; ++i) {
    const float n = static_cast<float>(1 + rng() % 1024);
    const float z = 0.2f + 20.0f * unit(rng) * unit(rng);
    sums[0][i] = n;
    sums[1][i] = n * z * (unit(rng) - 0.5f);
    sums[2][i] = n * z * (unit(rng) - 0.5f);
    sums[3][i] = n * z;
    sums[4][i] = n * (0.01f * z * unit(rng)) * (0.01f * z * unit(rng));
    sums[5][i] = z * (1.0f + 0.1f * unit(rng));
  }
  return sums;
}

TEST_P(TargetTest, PyramidRuleRandomCells) {
  std::mt19937_64 rng(61);
  std::size_t cells = 0, merged = 0;
  for (std::size_t count : {0, 1, 2, 3, 5, 7, 8, 9, 15, 16, 17, 31, 33, 1000, 4099}) {
    for (bool floors : {false, true}) {
      merged += expectSameMerge(randomMergeParams(rng, floors), randomCells(rng, count), "random");
      cells += count;
    }
  }
  // Both verdicts are well represented, so both ways through the rule were compared.
  EXPECT_GT(merged, cells / 10);
  EXPECT_LT(merged, cells - cells / 10);
}

// Empty cells (n = 0: NaN everywhere), zero spread, the eye inside a cell, cells on
// the gaze axis and behind the eye, and values that over- or underflow float.
TEST_P(TargetTest, PyramidRuleHardCells) {
  std::mt19937_64 rng(62);
  const float values[] = {0.0f, -0.0f, 1.0f, 1e-38f, kDenormf, 3e38f, -3e38f, kInff, kNaNf, 0.5f, 1024.0f, 4096.0f};
  std::uniform_int_distribution<int> pick(0, 11);
  std::vector<std::vector<float>> specials(6, std::vector<float>(3000));
  for (std::size_t i = 0; i < 3000; ++i) {
    for (int a = 0; a < 6; ++a) specials[a][i] = values[pick(rng)];
  }
  for (bool floors : {false, true}) expectSameMerge(randomMergeParams(rng, floors), specials, "specials");
  // On the gaze axis, ahead and behind, and at the eye: the eye at the camera, the
  // gaze along +z, cells at (0, 0, z) for z of both signs, m2 = 0.
  kernels::PyramidMergeParams p = randomMergeParams(rng, false);
  for (int a = 0; a < 9; ++a) p.r[a] = (a % 4 == 0) ? 1.0f : 0.0f;
  p.eye.origin_minus_eye[0] = p.eye.origin_minus_eye[1] = p.eye.origin_minus_eye[2] = 0.0f;
  p.eye.l[0] = p.eye.l[1] = 0.0f, p.eye.l[2] = 1.0f;
  std::vector<std::vector<float>> axis(6);
  for (float z : {-5.0f, -0.001f, 0.0f, 1e-6f, 0.001f, 0.5f, 3.0f, 1e3f}) {
    axis[0].push_back(1.0f), axis[1].push_back(0.0f), axis[2].push_back(0.0f), axis[3].push_back(z);
    axis[4].push_back(0.0f), axis[5].push_back(z);
  }
  expectSameMerge(p, axis, "on the axis");
}

INSTANTIATE_TEST_SUITE_P(Targets, TargetTest, ::testing::ValuesIn(simdTargetsHere()), test::simdTargetName);

}  // namespace
}  // namespace fovea::pipeline
