// The fixation distance d0: the paper's centroid, the gaze hit, and fallbacks.
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/fixation.h"

namespace fovea::pipeline {
namespace {

struct Scene {
  PointCloud cloud{64};
  std::vector<uint8_t> region;
  std::vector<double> scratch;

  // Partitions with F1 for a gaze +z from the origin.
  void partition() {
    AcuityConfig config;
    config.preset = Preset::kF1;
    const RegionModel model = RegionModel::create(config).value();
    region.assign(cloud.size(), 0);
    scratch.assign(cloud.size(), 0.0);
    PartitionCounts counts;
    partitionRef(cloud, Gaze{}, ConeBounds::fromModel(model), region.data(), counts);
  }
  Fixation fixation(const FixationConfig& config) {
    partition();
    return computeFixation(cloud, region.data(), Gaze{}, config, scratch.data());
  }
};

TEST(Fixation, CentroidIsThePapersD0) {
  Scene s;
  // Four fovea points around (0, 0, 2) and one at 40 degrees (parafovea or beyond).
  (void)s.cloud.push(0.01f, 0.0f, 2.0f, 0);
  (void)s.cloud.push(-0.01f, 0.0f, 2.0f, 0);
  (void)s.cloud.push(0.0f, 0.02f, 2.1f, 0);
  (void)s.cloud.push(0.0f, -0.02f, 2.1f, 0);
  (void)s.cloud.push(2.0f, 0.0f, 2.0f, 0);
  FixationConfig config;
  config.mode = FixationMode::kCentroid;
  const Fixation f = s.fixation(config);
  EXPECT_EQ(f.source, FixationSource::kCentroid);
  EXPECT_EQ(f.support, 4u);
  EXPECT_NEAR(f.d0_m, 2.05, 1e-6);  // centroid (0, 0, 2.05)
}

TEST(Fixation, HitSeesTheNearSurfaceWhereTheCentroidFloatsInMidAir) {
  Scene s;
  // A silhouette inside the fovea: a near object at 1 m on the axis, a wall at 5 m.
  for (int i = 0; i < 10; ++i) (void)s.cloud.push(0.001f * i, 0.0f, 1.0f, 0);
  for (int i = 0; i < 10; ++i) (void)s.cloud.push(0.2f + 0.01f * i, 0.0f, 5.0f, 0);
  FixationConfig config;
  config.mode = FixationMode::kCentroid;
  EXPECT_NEAR(s.fixation(config).d0_m, 3.0, 0.02);  // nothing is at 3 m
  config.mode = FixationMode::kHit;
  const Fixation hit = s.fixation(config);
  EXPECT_EQ(hit.source, FixationSource::kHit);
  EXPECT_EQ(hit.support, 10u);  // the wall points are 2.3..3.3 degrees off: outside the 1-degree cone
  EXPECT_NEAR(hit.d0_m, 1.0, 1e-6);
}

TEST(Fixation, HitIgnoresALoneFlyingPixel) {
  Scene s;
  (void)s.cloud.push(0.0f, 0.0f, 0.3f, 0);  // one outlier near the eye
  for (int i = 0; i < 40; ++i) (void)s.cloud.push(0.0005f * i, 0.0f, 2.0f + 0.001f * i, 0);
  FixationConfig config;
  config.hit_percentile = 0.05;
  const Fixation f = s.fixation(config);
  EXPECT_EQ(f.support, 41u);
  EXPECT_NEAR(f.d0_m, 2.001, 1e-6);  // element 2 of 41 sorted: the outlier is element 0
}

TEST(Fixation, EmptyConeFallsBackToCentroidThenToFallback) {
  Scene s;
  (void)s.cloud.push(0.1f, 0.0f, 2.0f, 0);  // 2.9 degrees: fovea, outside the hit cone
  (void)s.cloud.push(3.0f, 0.0f, 2.0f, 0);  // periphery
  FixationConfig config;
  Fixation f = s.fixation(config);
  EXPECT_EQ(f.source, FixationSource::kCentroid);
  EXPECT_NEAR(f.d0_m, std::sqrt(0.01 + 4.0), 1e-6);

  Scene empty_fovea;
  (void)empty_fovea.cloud.push(3.0f, 0.0f, 2.0f, 0);
  config.fallback_m = 1.75;
  f = empty_fovea.fixation(config);
  EXPECT_EQ(f.source, FixationSource::kFallback);
  EXPECT_EQ(f.d0_m, 1.75);
  config.mode = FixationMode::kCentroid;
  EXPECT_EQ(empty_fovea.fixation(config).source, FixationSource::kFallback);

  Scene nothing;
  EXPECT_EQ(nothing.fixation(FixationConfig{}).d0_m, 2.0);
}

TEST(Fixation, FixedAndClamped) {
  Scene s;
  (void)s.cloud.push(0.0f, 0.0f, 0.01f, 0);  // 1 cm from the eye
  FixationConfig config;
  config.mode = FixationMode::kFixed;
  config.fixed_m = 3.5;
  EXPECT_EQ(s.fixation(config).d0_m, 3.5);
  config.mode = FixationMode::kHit;
  const Fixation f = s.fixation(config);
  EXPECT_TRUE(f.clamped);
  EXPECT_EQ(f.d0_m, config.min_m);
}

TEST(Fixation, ValidateNamesTheField) {
  FixationConfig config;
  EXPECT_TRUE(config.validate().isOk());
  config.hit_cone_deg = 0.0;
  EXPECT_NE(config.validate().message().find("hit_cone_deg"), std::string::npos);
  config = {};
  config.fixed_m = NAN;
  EXPECT_NE(config.validate().message().find("fixed_m"), std::string::npos);
  config = {};
  config.hit_percentile = 1.5;
  EXPECT_NE(config.validate().message().find("hit_percentile"), std::string::npos);
  EXPECT_FALSE(parseFixationMode("middle").isOk());
  EXPECT_EQ(parseFixationMode("centroid").value(), FixationMode::kCentroid);
}

}  // namespace
}  // namespace fovea::pipeline
