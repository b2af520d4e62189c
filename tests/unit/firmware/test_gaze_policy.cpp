// The streamed frame's gaze: the operator's while fresh, else the uniform fallback.
#include "firmware/gaze_policy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <set>
#include <tuple>

#include "tests/support/clouds.h"

namespace fovea::firmware {
namespace {

constexpr int64_t kMs = 1'000'000;

TEST(GazePolicy, FreshOperatorGazeWinsStaleFallsBackAndChangesAreFlaggedOnce) {
  GazePolicyConfig config;  // 100 ms
  pipeline::FoveationConfig op;
  op.acuity.preset = pipeline::Preset::kF2;
  GazePolicy policy(config, op);
  hal::Pose camera;
  camera.t_world_cam = {1, 2, 3};
  camera.R_world_cam << 0, 0, 1, 0, 1, 0, -1, 0, 0;  // optical axis (column 2) along +x

  auto d = policy.decide(OperatorGaze{}, 0, camera);
  EXPECT_EQ(d.source, GazeSource::kNoGazeYet);
  EXPECT_TRUE(d.changed);
  EXPECT_EQ(d.foveation, &policy.fallbackConfig());
  EXPECT_EQ(d.gaze.origin_m, camera.t_world_cam);
  EXPECT_EQ(d.gaze.direction, Eigen::Vector3d(1, 0, 0));
  EXPECT_FALSE(policy.decide(OperatorGaze{}, 10 * kMs, camera).changed);

  OperatorGaze g{true, {}, 1000 * kMs, 7};
  g.gaze.origin_m = {0, 0, 1.6};
  g.gaze.direction = {0, 1, 0};
  d = policy.decide(g, 1050 * kMs, camera);
  EXPECT_EQ(d.source, GazeSource::kOperator);
  EXPECT_TRUE(d.changed);
  EXPECT_EQ(d.age_ns, 50 * kMs);
  EXPECT_EQ(d.gaze.direction, g.gaze.direction);
  EXPECT_EQ(d.gaze.fovea_growth_deg, 0.0);  // one sample: no speed yet
  EXPECT_EQ(d.foveation->acuity.preset, pipeline::Preset::kF2);
  // Exactly at the timeout still counts as fresh; one nanosecond later it is stale.
  EXPECT_EQ(policy.decide(g, 1100 * kMs, camera).source, GazeSource::kOperator);
  d = policy.decide(g, 1100 * kMs + 1, camera);
  EXPECT_EQ(d.source, GazeSource::kStale);
  EXPECT_TRUE(d.changed);
  EXPECT_EQ(d.foveation, &policy.fallbackConfig());
}

// The fovea grows with the eye's speed between the operator's last two samples
// (on the operator's clock) times the sample's age plus the lead, up to the bound;
// a fixating eye and the fallbacks get none.
TEST(GazePolicy, FoveaGrowsWithTheEyesSpeedAndTheSamplesAgeUpToTheBound) {
  GazePolicyConfig config;
  config.growth_max_deg = 10.0;
  config.lead_ns = 30 * kMs;
  GazePolicy policy(config, pipeline::FoveationConfig{});
  const hal::Pose camera;
  OperatorGaze g{true, {}, 0, 1000 * kMs};
  g.gaze.direction = {0, 0, 1};
  EXPECT_EQ(policy.decide(g, 0, camera).gaze.fovea_growth_deg, 0.0);
  // 1 degree in 10 ms of the operator's clock: 100 deg/s. Age 20 ms + lead 30 ms: 5 degrees.
  const double a = 1.0 * std::numbers::pi / 180.0;
  g.gaze.direction = {std::sin(a), 0, std::cos(a)};
  g.stamp_ns += 10 * kMs;
  g.received_ns = 100 * kMs;
  GazePolicy::Decision d = policy.decide(g, 120 * kMs, camera);
  EXPECT_NEAR(d.eye_speed_deg_s, 100.0, 1e-6);
  EXPECT_NEAR(d.gaze.fovea_growth_deg, 5.0, 1e-6);
  // The same sample later: the same speed, more age, capped at 10 degrees.
  EXPECT_NEAR(policy.decide(g, 150 * kMs, camera).gaze.fovea_growth_deg, 8.0, 1e-6);
  EXPECT_EQ(policy.decide(g, 190 * kMs, camera).gaze.fovea_growth_deg, 10.0);
  // The eye holds still: no growth.
  g.stamp_ns += 10 * kMs;
  g.received_ns = 200 * kMs;
  d = policy.decide(g, 200 * kMs, camera);
  EXPECT_EQ(d.eye_speed_deg_s, 0.0);
  EXPECT_EQ(d.gaze.fovea_growth_deg, 0.0);
  // Stale: the fallback, no growth; a stamp that goes backwards measures nothing.
  EXPECT_EQ(policy.decide(g, 400 * kMs, camera).gaze.fovea_growth_deg, 0.0);
  g.stamp_ns -= 50 * kMs;
  g.gaze.direction = {1, 0, 0};
  g.received_ns = 500 * kMs;
  EXPECT_EQ(policy.decide(g, 500 * kMs, camera).eye_speed_deg_s, 0.0);
  // A jump stamped 1 us after the last: clock jitter, not an eye; held at 1000 deg/s.
  g.stamp_ns += 1000;
  g.gaze.direction = {0, 0, 1};
  g.received_ns = 600 * kMs;
  EXPECT_EQ(policy.decide(g, 600 * kMs, camera).eye_speed_deg_s, 1000.0);
  // Stamps at the ends of the clock's range: no overflow (UBSan checks), speed ~0.
  g.stamp_ns = INT64_MIN;
  (void)policy.decide(g, 600 * kMs, camera);
  g.stamp_ns = INT64_MAX;
  g.gaze.direction = {1, 0, 0};
  d = policy.decide(g, 600 * kMs, camera);
  EXPECT_GE(d.eye_speed_deg_s, 0.0);
  EXPECT_LT(d.eye_speed_deg_s, 1e-6);
  g.stamp_ns = 2000 * kMs;  // back to ordinary stamps
  // growth_max_deg = 0 turns it off.
  config.growth_max_deg = 0.0;
  GazePolicy off(config, pipeline::FoveationConfig{});
  (void)off.decide(g, 600 * kMs, camera);
  g.stamp_ns += 10 * kMs;
  g.gaze.direction = {0, 1, 0};
  EXPECT_EQ(off.decide(g, 600 * kMs, camera).gaze.fovea_growth_deg, 0.0);
}

TEST(GazePolicy, ConfigValidation) {
  GazePolicyConfig c;
  EXPECT_TRUE(c.validate().isOk());
  c.timeout_ns = 0;
  EXPECT_FALSE(c.validate().isOk());
  c = {};
  c.fallback_voxel_m = 0.0;
  EXPECT_FALSE(c.validate().isOk());
  c.fallback_voxel_m = NAN;
  EXPECT_FALSE(c.validate().isOk());
  c = {};
  c.growth_max_deg = -1.0;
  EXPECT_FALSE(c.validate().isOk());
  c.growth_max_deg = NAN;
  EXPECT_FALSE(c.validate().isOk());
  c = {};
  c.lead_ns = -1;
  EXPECT_FALSE(c.validate().isOk());
}

// The fallback samples the cloud on one lattice of the requested voxel size:
// checked against a brute-force count of occupied voxels.
TEST(UniformFoveationConfig, SamplesEveryPointOnOneLatticeOfTheRequestedSize) {
  for (double voxel_m : {0.01, 0.02, 0.05}) {
    const pipeline::FoveationConfig config = uniformFoveationConfig(voxel_m);
    const pipeline::PointCloud cloud = test::randomCloud(20000, Eigen::Vector3d(0, 0, 0), 1.0f, 11);
    auto foveator = pipeline::Foveator::create({cloud.size(), cloud.size()}, config);
    ASSERT_TRUE(foveator.isOk()) << foveator.status().message();
    pipeline::FoveatedCloud out(cloud.size());
    pipeline::FoveationStats stats;
    pipeline::Gaze gaze;
    gaze.origin_m = {0, 0, -5};
    gaze.direction = {0.3, 0.2, 1.0};
    ASSERT_TRUE(foveator->foveate(cloud, gaze, out, stats).isOk());
    ASSERT_EQ(stats.region_count, 2);
    EXPECT_NEAR(stats.regions[1].voxel_size_m, voxel_m, voxel_m * 1e-12);
    EXPECT_LE(stats.regions[0].points_in, 2u);  // 0.001 degrees around the axis
    std::set<std::tuple<long, long, long>> voxels;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      if (foveator->lastRegions()[i] != 1) continue;
      const Eigen::Vector3d w = cloud.world(i);
      voxels.emplace(std::lround(std::floor(w.x() / stats.regions[1].voxel_size_m)),
                     std::lround(std::floor(w.y() / stats.regions[1].voxel_size_m)),
                     std::lround(std::floor(w.z() / stats.regions[1].voxel_size_m)));
    }
    EXPECT_EQ(stats.regions[1].points_out, voxels.size()) << voxel_m;
  }
}

}  // namespace
}  // namespace fovea::firmware
