// The whole foveation of a cloud against the brute-force reference.
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>
#include <string>
#include <utility>

#include <gtest/gtest.h>

#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "tests/support/clouds.h"

namespace fovea::pipeline {
namespace {

FoveationConfig configFor(Preset preset, double slope = 0.022, FixationMode mode = FixationMode::kHit) {
  FoveationConfig config;
  config.acuity.preset = preset;
  config.acuity.slope = slope;
  config.fixation.mode = mode;
  return config;
}

struct Case {
  Preset preset;
  double slope;
  double offset_m;
  uint64_t seed;
};

void PrintTo(const Case& c, std::ostream* os) {
  *os << presetName(c.preset) << "_m" << c.slope << "_offset" << c.offset_m;
}

class FoveatorMatchesBruteForce : public ::testing::TestWithParam<Case> {};

// Property: regions, voxel set, counts and centroids equal a reference that
// partitions with atan2 in long double and groups with a std::map.
TEST_P(FoveatorMatchesBruteForce, RandomCloud) {
  const Case& c = GetParam();
  std::mt19937_64 rng(c.seed);
  const Eigen::Vector3d origin(c.offset_m, c.offset_m * 0.5, 1.0);
  PointCloud in = test::randomCloud(40000, origin, 4.0f, c.seed);
  Gaze gaze;
  gaze.origin_m = origin + Eigen::Vector3d(0.1, -0.2, 0.05);
  gaze.direction = test::randomUnit(rng);
  Foveator foveator = Foveator::create({in.size(), in.size()}, configFor(c.preset, c.slope)).value();
  FoveatedCloud out(in.size());
  FoveationStats stats;
  ASSERT_TRUE(foveator.foveate(in, gaze, out, stats).isOk());

  const RegionModel& model = foveator.model();
  const std::vector<double> bounds = test::boundsOf(model);
  const double d0 = stats.fixation.d0_m;
  std::map<test::BruteKey, test::BruteVoxel> voxels;
  std::vector<std::size_t> fovea;
  for (std::size_t i = 0; i < in.size(); ++i) {
    const int r = test::bruteRegion(
        test::bruteEccentricityDeg(in.origin_m, in.x()[i], in.y()[i], in.z()[i], gaze.origin_m, gaze.direction.normalized()),
        bounds);
    ASSERT_EQ(foveator.lastRegions()[i], r) << "point " << i;
    if (r == 0) {
      fovea.push_back(i);
      continue;
    }
    const Eigen::Vector3d w = in.world(i);
    auto& v = voxels[test::bruteKey(r, w.x(), w.y(), w.z(), model.voxelSizeM(r, d0))];
    ++v.count;
    v.sx += w.x();
    v.sy += w.y();
    v.sz += w.z();
  }
  ASSERT_EQ(out.size(), fovea.size() + voxels.size());
  for (std::size_t o = 0; o < fovea.size(); ++o) EXPECT_EQ(out.points.x()[o], in.x()[fovea[o]]);
  auto it = voxels.begin();
  for (std::size_t o = fovea.size(); o < out.size(); ++o, ++it) {
    // Both are in (region, i, j, k) order.
    const Eigen::Vector3d w = out.points.world(o);
    const int r = out.region[o];
    ASSERT_EQ(test::bruteKey(r, w.x(), w.y(), w.z(), model.voxelSizeM(r, d0)), it->first);
    EXPECT_EQ(out.weight[o], it->second.count);
    EXPECT_NEAR(w.x(), static_cast<double>(it->second.sx / it->second.count), 1e-5);
    EXPECT_NEAR(w.y(), static_cast<double>(it->second.sy / it->second.count), 1e-5);
    EXPECT_NEAR(w.z(), static_cast<double>(it->second.sz / it->second.count), 1e-5);
  }
  // The statistics agree with the output.
  uint32_t total_in = 0, total_out = 0;
  for (int r = 0; r < stats.region_count; ++r) {
    total_in += stats.regions[r].points_in;
    total_out += stats.regions[r].points_out;
  }
  EXPECT_EQ(total_in, in.size());
  EXPECT_EQ(total_out, out.size());
  EXPECT_EQ(stats.regions[0].points_in, stats.regions[0].points_out);
}

INSTANTIATE_TEST_SUITE_P(Presets, FoveatorMatchesBruteForce,
                         ::testing::Values(Case{Preset::kF1, 0.022, 0.0, 1}, Case{Preset::kF2, 0.028, 0.0, 2},
                                           Case{Preset::kF3, 0.034, 0.0, 3}, Case{Preset::kF3, 0.022, 1e4, 4},
                                           Case{Preset::kFRef, 0.022, 0.0, 5}));

TEST(Foveator, FrefPassesEveryPointThrough) {
  PointCloud in = test::randomCloud(1000, Eigen::Vector3d::Zero(), 3.0f, 7);
  Foveator foveator = Foveator::create({1000, 1000}, configFor(Preset::kFRef)).value();
  FoveatedCloud out(1000);
  FoveationStats stats;
  ASSERT_TRUE(foveator.foveate(in, Gaze{}, out, stats).isOk());
  ASSERT_EQ(out.size(), in.size());
  for (std::size_t i = 0; i < in.size(); ++i) EXPECT_EQ(out.points.z()[i], in.z()[i]);
}

TEST(Foveator, FoveationReducesThePeriphery) {
  PointCloud in = test::randomCloud(50000, Eigen::Vector3d::Zero(), 3.0f, 8);
  // d0 = 40 m: outermost voxels of 1.4 m, coarse enough for this sparse cloud.
  FoveationConfig config = configFor(Preset::kF1, 0.022, FixationMode::kFixed);
  config.fixation.fixed_m = 40.0;
  Foveator foveator = Foveator::create({50000, 50000}, config).value();
  FoveatedCloud out(50000);
  FoveationStats stats;
  ASSERT_TRUE(foveator.foveate(in, Gaze{}, out, stats).isOk());
  EXPECT_NEAR(stats.regions[3].voxel_size_m, 40.0 * std::tan(kMar0Deg * M_PI / 180.0) * 119.8, 1e-12);
  EXPECT_LT(stats.regions[3].points_out, stats.regions[3].points_in / 10);
  for (int r = 1; r < 4; ++r) EXPECT_GT(stats.regions[r].voxel_size_m, stats.regions[r - 1].voxel_size_m);
}

TEST(Foveator, SetConfigSwitchesPresetAndKeepsOldOnError) {
  Foveator foveator = Foveator::create({10, 10}, configFor(Preset::kF1)).value();
  EXPECT_EQ(foveator.model().regionCount(), 4);
  ASSERT_TRUE(foveator.setConfig(configFor(Preset::kF3)).isOk());
  EXPECT_EQ(foveator.model().regionCount(), 6);
  FoveationConfig bad = configFor(Preset::kF1, -1.0);
  EXPECT_EQ(foveator.setConfig(bad).code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(foveator.model().regionCount(), 6);
}

TEST(Foveator, RejectsCloudsOverCapacity) {
  PointCloud in = test::randomCloud(100, Eigen::Vector3d::Zero(), 1.0f, 9);
  Foveator foveator = Foveator::create({50, 50}, configFor(Preset::kF1)).value();
  FoveatedCloud out(100);
  FoveationStats stats;
  EXPECT_EQ(foveator.foveate(in, Gaze{}, out, stats).code(), ErrorCode::kCapacityExceeded);
  EXPECT_FALSE(Foveator::create({0, 10}, configFor(Preset::kF1)).isOk());
}

// ---- over the capacity: the voxels doubled until the frame fits ----

// The occupied voxels of the brute-force grouping (as RandomCloud above) of the
// points `regions` names, at the regions' edges times `scale`.
std::size_t bruteVoxelCount(const PointCloud& in, const uint8_t* regions, const FoveationStats& stats, double scale) {
  std::map<test::BruteKey, int> voxels;
  for (std::size_t i = 0; i < in.size(); ++i) {
    const int r = regions[i];
    if (r == 0 || r >= stats.region_count) continue;
    const Eigen::Vector3d w = in.world(i);
    ++voxels[test::bruteKey(r, w.x(), w.y(), w.z(), stats.regions[r].voxel_size_m * scale)];
  }
  return voxels.size();
}

// A wall of 40 000 points 5 mm apart, 2 m ahead (the surface a depth camera
// sees), under F1 at a fixation of 2 m: its inner regions' voxels are smaller
// than the spacing, so the frame takes thousands.
PointCloud wall() {
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<float> jitter(-0.001f, 0.001f);
  PointCloud cloud(40000);
  for (int v = 0; v < 160; ++v) {
    for (int u = 0; u < 250; ++u) {
      (void)cloud.push(-0.625f + 0.005f * static_cast<float>(u), -0.4f + 0.005f * static_cast<float>(v),
                       2.0f + jitter(rng), 0x808080u);
    }
  }
  return cloud;
}

class FoveatorOverCapacity : public ::testing::TestWithParam<KernelSet> {
 protected:
  static FoveationConfig config() {
    FoveationConfig c = configFor(Preset::kF1, 0.022, FixationMode::kFixed);
    c.fixation.fixed_m = 2.0;
    return c;
  }
  PointCloud in_ = wall();
  Gaze gaze_;  // from the origin along +z
};

// A frame with more voxels than max_voxels is sampled again with every edge
// doubled, the fewest times that fit: with room for the voxels of edges four
// times as large, twice, and the output is the brute-force grouping at them.
TEST_P(FoveatorOverCapacity, IsSampledAtDoubledVoxelsTheFewestTimesThatFit) {
  PipelineCapacity roomy{in_.size(), in_.size(), GetParam()};
  Foveator reference = Foveator::create(roomy, config()).value();
  FoveatedCloud full(in_.size());
  FoveationStats full_stats;
  ASSERT_TRUE(reference.foveate(in_, gaze_, full, full_stats).isOk());
  EXPECT_EQ(full_stats.coarsened, 0);
  const std::size_t fovea = full_stats.regions[0].points_out;
  const uint8_t* regions = reference.lastRegions();
  ASSERT_EQ(full.size() - fovea, bruteVoxelCount(in_, regions, full_stats, 1.0));
  const std::size_t at2 = bruteVoxelCount(in_, regions, full_stats, 2.0);
  const std::size_t at4 = bruteVoxelCount(in_, regions, full_stats, 4.0);
  ASSERT_GT(full.size() - fovea, at2);
  ASSERT_GT(at2, at4);

  PipelineCapacity tight = roomy;
  tight.max_voxels = at4;
  Foveator foveator = Foveator::create(tight, config()).value();
  FoveatedCloud out(in_.size());
  FoveationStats stats;
  ASSERT_TRUE(foveator.foveate(in_, gaze_, out, stats).isOk());
  EXPECT_EQ(stats.coarsened, 2);
  for (int r = 1; r < stats.region_count; ++r) {
    EXPECT_EQ(stats.regions[r].voxel_size_m, full_stats.regions[r].voxel_size_m * 4.0) << "region " << r;
    EXPECT_EQ(stats.regions[r].points_in, full_stats.regions[r].points_in) << "region " << r;
  }
  EXPECT_EQ(stats.regions[0].points_out, fovea) << "the fovea stays whole";
  EXPECT_EQ(out.size() - fovea, at4);
}

TEST_P(FoveatorOverCapacity, WithoutCoarseningsOrBeyondThemTheFrameIsRefused) {
  PipelineCapacity none{in_.size(), 100, GetParam()};
  none.max_coarsenings = 0;
  Foveator refusing = Foveator::create(none, config()).value();
  FoveatedCloud out(in_.size());
  FoveationStats stats;
  EXPECT_EQ(refusing.foveate(in_, gaze_, out, stats).code(), ErrorCode::kCapacityExceeded);
  EXPECT_EQ(stats.coarsened, 0);

  PipelineCapacity one_voxel{in_.size(), 1, GetParam()};  // several regions hold points: never fits
  Foveator trying = Foveator::create(one_voxel, config()).value();
  EXPECT_EQ(trying.foveate(in_, gaze_, out, stats).code(), ErrorCode::kCapacityExceeded);
  EXPECT_EQ(stats.coarsened, one_voxel.max_coarsenings);

  PipelineCapacity bad{in_.size(), 100, GetParam()};
  bad.max_coarsenings = 17;
  EXPECT_EQ(Foveator::create(bad, config()).status().code(), ErrorCode::kInvalidArgument);
  bad.max_coarsenings = -1;
  EXPECT_EQ(Foveator::create(bad, config()).status().code(), ErrorCode::kInvalidArgument);

  // The hash sampler's 32-bit colour sums bound the points a frame: refused
  // before anything is allocated for them.
  PipelineCapacity too_many{HashVoxelSampler::kMaxPoints + 1, 100, GetParam()};
  const Status refused = Foveator::create(too_many, config()).status();
  EXPECT_EQ(refused.code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("colour sums"), std::string::npos) << refused.message();
}

INSTANTIATE_TEST_SUITE_P(Kernels, FoveatorOverCapacity, ::testing::Values(KernelSet::kRef, KernelSet::kSimd),
                         [](const ::testing::TestParamInfo<KernelSet>& info) {
                           return std::string(kernelSetName(info.param));
                         });

// ---- the kernel table: chosen once, from the kernel set and the thread count ----

StageKernels stageKernelsFor(KernelSet set, int threads) {
  // The names are string literals: they outlive the Foveator.
  return Foveator::create({1000, 1000, set, threads}, FoveationConfig{}).value().stageKernels();
}

void expectReferences(const StageKernels& k) {
  EXPECT_EQ(k.partition, "partitionRef");
  EXPECT_EQ(k.levels, "assignLevelsRef");
  EXPECT_EQ(k.fixation, "computeFixation");
  EXPECT_EQ(k.sample, "VoxelSampler");
  EXPECT_EQ(k.refine_test, "refineTestRef");
}

TEST(FoveatorKernels, RefPicksTheReferencesOnAnyThreadCount) {
  // The reference is the specification: it never runs on the pool.
  for (int threads : {1, 2, 4}) {
    SCOPED_TRACE(threads);
    expectReferences(stageKernelsFor(KernelSet::kRef, threads));
    Backprojector bp(threads, KernelSet::kRef);
    EXPECT_EQ(bp.kernelName(), "backprojectRef");
    EXPECT_EQ(bp.threads(), 1);
  }
}

TEST(FoveatorKernels, SimdOnOneThreadPicksTheSimdKernels) {
  const StageKernels k = stageKernelsFor(KernelSet::kSimd, 1);
  EXPECT_EQ(k.partition, "partitionSimd");
  EXPECT_EQ(k.levels, "assignLevelsSimd");
  EXPECT_EQ(k.fixation, "computeFixationSimd");
  EXPECT_EQ(k.sample, "HashVoxelSampler");
  EXPECT_EQ(k.refine_test, "refineTestSimd");
  Backprojector bp(1, KernelSet::kSimd);
  EXPECT_EQ(bp.kernelName(), "backprojectSimd");
  EXPECT_EQ(bp.threads(), 1);
}

TEST(FoveatorKernels, SimdOnThreadsPicksThePool) {
  for (int threads : {2, 3}) {
    SCOPED_TRACE(threads);
    const StageKernels k = stageKernelsFor(KernelSet::kSimd, threads);
    EXPECT_EQ(k.partition, "partitionRange/pool");
    EXPECT_EQ(k.levels, "levelRange/pool");
    EXPECT_EQ(k.fixation, "computeFixationSimd");  // one percentile: no threaded form
    EXPECT_EQ(k.sample, "HashVoxelSampler/pool");
    EXPECT_EQ(k.refine_test, "refineTestRange/pool");
    Backprojector bp(threads, KernelSet::kSimd);
    EXPECT_EQ(bp.kernelName(), "backprojectRows/pool");
    EXPECT_EQ(bp.threads(), threads);
  }
}

// The default capacity follows FOVEA_FORCE_KERNEL; CTest runs this once more with
// FOVEA_FORCE_KERNEL=ref and looks for the references in the printed line.
TEST(FoveatorKernels, DefaultFollowsForceKernel) {
  const char* env = std::getenv("FOVEA_FORCE_KERNEL");
  const bool ref = env != nullptr && std::string(env) == "ref";
  const StageKernels k = Foveator::create({1000, 1000}, FoveationConfig{}).value().stageKernels();
  const Backprojector bp;
  if (ref) {
    expectReferences(k);
    EXPECT_EQ(bp.kernelName(), "backprojectRef");
  } else {
    EXPECT_EQ(k.partition, "partitionSimd");
    EXPECT_EQ(k.sample, "HashVoxelSampler");
    EXPECT_EQ(bp.kernelName(), "backprojectSimd");
  }
  std::printf("default stage kernels: %.*s %.*s %.*s %.*s %.*s, %.*s\n", static_cast<int>(k.partition.size()),
              k.partition.data(), static_cast<int>(k.levels.size()), k.levels.data(),
              static_cast<int>(k.fixation.size()), k.fixation.data(), static_cast<int>(k.sample.size()),
              k.sample.data(), static_cast<int>(k.refine_test.size()), k.refine_test.data(),
              static_cast<int>(bp.kernelName().size()), bp.kernelName().data());
}

// The table's entries take the Foveator as an argument: a moved Foveator (and a
// moved-to one) runs its own stages, on its own buffers, with the same output.
TEST(FoveatorKernels, MovedFoveatorKeepsItsTable) {
  PointCloud in = test::randomCloud(5000, Eigen::Vector3d::Zero(), 3.0f, 10);
  FoveationConfig config = configFor(Preset::kAcuity);
  config.acuity.level_margin = 0.15;
  config.acuity.refine_passes = kMaxRefinePasses;
  for (KernelSet set : {KernelSet::kRef, KernelSet::kSimd}) {
    for (int threads : {1, 3}) {
      SCOPED_TRACE(std::string(kernelSetName(set)) + " on " + std::to_string(threads));
      Foveator first = Foveator::create({5000, 5000, set, threads}, config).value();
      FoveatedCloud a(5000), b(5000);
      FoveationStats sa, sb;
      ASSERT_TRUE(first.foveate(in, Gaze{}, a, sa).isOk());
      Foveator moved(std::move(first));
      ASSERT_TRUE(moved.foveate(in, Gaze{}, b, sb).isOk());
      ASSERT_EQ(a.size(), b.size());
      for (std::size_t o = 0; o < a.size(); ++o) {
        ASSERT_EQ(a.points.x()[o], b.points.x()[o]) << o;
        ASSERT_EQ(a.weight[o], b.weight[o]) << o;
      }
      EXPECT_EQ(sa.refined, sb.refined);
    }
  }
}

// The cones' fixation and ACUITY's refinement share one per-point scratch: a
// foveator switched between them frame by frame gives each frame what a fresh
// foveator of that configuration gives (nothing read from the other's use).
TEST(FoveatorKernels, FixationAndRefinementShareTheirScratchWithoutLeaks) {
  PointCloud in = test::randomCloud(5000, Eigen::Vector3d(0.2, -0.1, 0.5), 3.0f, 11);
  FoveationConfig acuity = configFor(Preset::kAcuity);
  acuity.acuity.level_margin = 0.15;
  acuity.acuity.refine_passes = kMaxRefinePasses;
  const FoveationConfig cones = configFor(Preset::kF1);
  for (KernelSet set : {KernelSet::kRef, KernelSet::kSimd}) {
    SCOPED_TRACE(std::string(kernelSetName(set)));
    Foveator switched = Foveator::create({5000, 5000, set, 1}, cones).value();
    for (const FoveationConfig* config : std::array<const FoveationConfig*, 4>{&cones, &acuity, &cones, &acuity}) {
      ASSERT_TRUE(switched.setConfig(*config).isOk());
      Foveator fresh = Foveator::create({5000, 5000, set, 1}, *config).value();
      FoveatedCloud a(5000), b(5000);
      FoveationStats sa, sb;
      ASSERT_TRUE(switched.foveate(in, Gaze{}, a, sa).isOk());
      ASSERT_TRUE(fresh.foveate(in, Gaze{}, b, sb).isOk());
      ASSERT_EQ(a.size(), b.size());
      for (std::size_t o = 0; o < a.size(); ++o) {
        ASSERT_EQ(a.points.x()[o], b.points.x()[o]) << o;
        ASSERT_EQ(a.points.z()[o], b.points.z()[o]) << o;
        ASSERT_EQ(a.region[o], b.region[o]) << o;
        ASSERT_EQ(a.weight[o], b.weight[o]) << o;
      }
      EXPECT_EQ(sa.fixation.d0_m, sb.fixation.d0_m);
      EXPECT_EQ(sa.refined, sb.refined);
      if (config == &acuity) {
        EXPECT_GT(sa.refined, 0u);  // the refinement's arrays were used
      }
    }
  }
}

// A cloud made without weights (the service's slots) gets the same points and
// regions from every sampler, and no weights.
TEST(FoveatorKernels, ACloudWithoutWeightsGetsTheSamePoints) {
  PointCloud in = test::randomCloud(5000, Eigen::Vector3d(0.1, 0.0, 0.4), 3.0f, 12);
  FoveationConfig acuity = configFor(Preset::kAcuity);
  acuity.acuity.refine_passes = kMaxRefinePasses;
  for (const FoveationConfig& config : {configFor(Preset::kF1), configFor(Preset::kF3), acuity}) {
    for (KernelSet set : {KernelSet::kRef, KernelSet::kSimd}) {
      SCOPED_TRACE(std::string(kernelSetName(set)) + " " + std::string(presetName(config.acuity.preset)));
      Foveator foveator = Foveator::create({5000, 5000, set, 1}, config).value();
      FoveatedCloud with(5000), without(5000, FoveatedCloud::Weights::kNone);
      FoveationStats sa, sb;
      ASSERT_TRUE(foveator.foveate(in, Gaze{}, with, sa).isOk());
      ASSERT_TRUE(foveator.foveate(in, Gaze{}, without, sb).isOk());
      EXPECT_TRUE(with.hasWeights());
      EXPECT_FALSE(without.hasWeights());
      ASSERT_EQ(with.size(), without.size());
      ASSERT_GT(with.size(), 0u);
      for (std::size_t o = 0; o < with.size(); ++o) {
        ASSERT_EQ(with.points.x()[o], without.points.x()[o]) << o;
        ASSERT_EQ(with.points.y()[o], without.points.y()[o]) << o;
        ASSERT_EQ(with.points.rgb()[o], without.points.rgb()[o]) << o;
        ASSERT_EQ(with.region[o], without.region[o]) << o;
      }
    }
  }
}

}  // namespace
}  // namespace fovea::pipeline
