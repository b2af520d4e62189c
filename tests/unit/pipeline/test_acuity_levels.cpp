// The acuity mode's level assignment (Preset::kAcuity, pipeline/acuity_levels.h):
// against an independent long-double reference written here, its guarantee
// (at the default margin, no point is displaced by more than its MAR, measured
// by the error metrics), monotonicity, the sensor floor, hard cases, and the
// model's validation.
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/acuity_levels.h"
#include "pipeline/error_metrics.h"
#include "pipeline/foveator.h"
#include "tests/support/clouds.h"

namespace fovea::pipeline {
namespace {

using LD = long double;

AcuityConfig acuityConfig(double margin = std::sqrt(3.0), double floor_m = 0.0, double slope = kDefaultSlope) {
  AcuityConfig a;
  a.preset = Preset::kAcuity;
  a.level_margin = margin;
  a.floor_m = floor_m;
  a.slope = slope;
  return a;
}

// The level from first principles, in long double: the eccentricity from the
// angle between P - H and the gaze (acos of the normalised dot product, not the
// kernel's atan2 of the axial and radial parts), the largest level whose margin
// times voxel fits under r sin(MAR); the floor lifts it. `slack` reports how
// close the decision was (relative distance of `allowed` to the nearest threshold).
// The gaze's growth lowers the eccentricity (not below 0); with a view cull and a
// known head, a point whose angle to the head's axis exceeds view_cull_deg gets
// the cull's region (view_slack: how close that angle was, in degrees).
int bruteForceLevel(const AcuityConfig& a, const Eigen::Vector3d& p, const Eigen::Vector3d& sensor, const Gaze& g,
                    LD& slack, LD& view_slack) {
  const LD vx = p.x() - g.origin_m.x(), vy = p.y() - g.origin_m.y(), vz = p.z() - g.origin_m.z();
  const LD r = std::sqrt(vx * vx + vy * vy + vz * vz);
  const LD dx = g.direction.x(), dy = g.direction.y(), dz = g.direction.z();
  const LD dn = std::sqrt(dx * dx + dy * dy + dz * dz);
  LD ecc = 0;
  if (r > 0) {
    LD c = (vx * dx + vy * dy + vz * dz) / (r * dn);
    c = std::max<LD>(-1, std::min<LD>(1, c));
    ecc = std::acos(c) * 180 / std::numbers::pi_v<LD>;
  }
  ecc = std::max<LD>(0, ecc - static_cast<LD>(g.fovea_growth_deg));
  const LD allowed = r * std::sin((static_cast<LD>(a.slope) * ecc + static_cast<LD>(1.0 / 60.0)) * std::numbers::pi_v<LD> / 180);
  int level = 0;
  slack = 1;
  for (int n = 1; n < kMaxRegions; ++n) {
    const LD threshold = static_cast<LD>(a.level_margin) * static_cast<LD>(a.level_voxel_m) * (LD{1} * (1 << (n - 1)));
    slack = std::min(slack, std::fabs(allowed - threshold) / threshold);
    if (threshold <= allowed) level = n;
  }
  // The distance-dependent floor counts from the sensor (the cloud's origin).
  const Eigen::Vector3d local = p - sensor;
  const LD s2 = static_cast<LD>(local.squaredNorm());
  const LD floor = static_cast<LD>(a.floor_m) + static_cast<LD>(a.floor_per_m2) * s2;
  if (floor > 0) {
    for (int n = 1; n < kMaxRegions; ++n) {
      if (static_cast<LD>(a.level_voxel_m) * (1 << (n - 1)) >= floor || n == kMaxRegions - 1) {
        level = std::max(level, n);
        break;
      }
    }
  }
  view_slack = 180;
  if (a.view_cull != ViewCull::kOff && g.view_known && r > 0) {
    const LD fx = g.view_forward.x(), fy = g.view_forward.y(), fz = g.view_forward.z();
    LD c = (vx * fx + vy * fy + vz * fz) / (r * std::sqrt(fx * fx + fy * fy + fz * fz));
    c = std::max<LD>(-1, std::min<LD>(1, c));
    const LD angle = std::acos(c) * 180 / std::numbers::pi_v<LD>;
    view_slack = std::fabs(angle - static_cast<LD>(a.view_cull_deg));
    if (angle > static_cast<LD>(a.view_cull_deg)) level = a.view_cull == ViewCull::kDrop ? kRegionCulled : kMaxRegions - 1;
  }
  return level;
}
int bruteForceLevel(const AcuityConfig& a, const Eigen::Vector3d& p, const Eigen::Vector3d& sensor, const Gaze& g,
                    LD& slack) {
  LD view_slack = 0;
  return bruteForceLevel(a, p, sensor, g, slack, view_slack);
}

TEST(AcuityLevels, MatchAnIndependentReferenceOnRandomClouds) {
  for (double margin : {std::sqrt(3.0), 0.5}) {
    for (double floor_m : {0.0, 0.008, -1.0}) {  // -1: a floor of 0.004 r^2 (m)
      AcuityConfig a = acuityConfig(margin, std::max(floor_m, 0.0));
      if (floor_m < 0) a.floor_per_m2 = 0.004;
      const RegionModel model = RegionModel::create(a).value();
      const LevelBounds bounds = LevelBounds::fromModel(model);
      std::mt19937_64 rng(7);
      for (const Eigen::Vector3d& origin : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1e4, -1e4, 30)}) {
        PointCloud cloud = test::randomCloud(20000, origin, 6.0f, rng());
        Gaze gaze;
        gaze.origin_m = origin + Eigen::Vector3d(0.3, -0.2, 0.1);
        gaze.direction = Eigen::Vector3d(0.2, 1.0, -0.3).normalized();
        std::vector<uint8_t> level(cloud.size());
        PartitionCounts counts;
        assignLevelsRef(cloud, gaze, bounds, level.data(), counts);
        std::size_t close_calls = 0;
        for (std::size_t i = 0; i < cloud.size(); ++i) {
          LD slack = 0;
          const int expected = bruteForceLevel(a, cloud.world(i), cloud.origin_m, gaze, slack);
          if (level[i] != expected) {
            // Only where the specification's polynomials (errors under 1e-5) and long
            // double's libm decide a threshold differently.
            ASSERT_LT(slack, 1e-4L) << "point " << i << ": level " << int(level[i]) << ", expected " << expected;
            ++close_calls;
          }
        }
        EXPECT_LE(close_calls, 20u);
        uint32_t total = 0;
        for (uint32_t c : counts.per_region) total += c;
        EXPECT_EQ(total, cloud.size());
        EXPECT_EQ(counts.invalid, 0u);
      }
    }
  }
}

// The fovea's growth and the view cull, against the same independent reference.
TEST(AcuityLevels, GrowthAndViewCullMatchTheIndependentReference) {
  std::mt19937_64 rng(8);
  for (ViewCull cull : {ViewCull::kOff, ViewCull::kCoarsest, ViewCull::kDrop}) {
    for (double growth : {0.0, 4.0, 25.0}) {
      AcuityConfig a = acuityConfig(0.5);
      a.view_cull = cull;
      a.view_cull_deg = 35.0;
      const LevelBounds bounds = LevelBounds::fromModel(RegionModel::create(a).value());
      const PointCloud cloud = test::randomCloud(8000, Eigen::Vector3d(5, 5, 5), 6.0f, rng());
      Gaze gaze;
      gaze.origin_m = Eigen::Vector3d(5.5, 4.5, 5.1);
      gaze.direction = Eigen::Vector3d(0.2, 1.0, -0.3).normalized();
      gaze.fovea_growth_deg = growth;
      gaze.view_known = true;
      gaze.view_forward = (gaze.direction + Eigen::Vector3d(0.5, 0, 0)).normalized();
      std::vector<uint8_t> level(cloud.size());
      PartitionCounts counts;
      assignLevelsRef(cloud, gaze, bounds, level.data(), counts);
      std::size_t close_calls = 0, culled = 0;
      for (std::size_t i = 0; i < cloud.size(); ++i) {
        LD slack = 0, view_slack = 0;
        const int expected = bruteForceLevel(a, cloud.world(i), cloud.origin_m, gaze, slack, view_slack);
        culled += expected == kRegionCulled;
        if (level[i] != expected) {
          ASSERT_TRUE(slack < 1e-4L || view_slack < 1e-9L)
              << "point " << i << ": level " << int(level[i]) << ", expected " << expected;
          ++close_calls;
        }
      }
      EXPECT_LE(close_calls, 20u);
      EXPECT_EQ(counts.culled, std::count(level.begin(), level.end(), kRegionCulled));
      if (cull == ViewCull::kDrop) {
        EXPECT_GT(culled, 400u);  // the cull really cuts
      }
      uint32_t total = counts.culled;
      for (uint32_t c : counts.per_region) total += c;
      EXPECT_EQ(total, cloud.size());
    }
  }
}

// A grown fovea keeps every point within the growth at the fovea's acuity (the
// level of eccentricity 0 at its distance), and no point coarser than without it.
TEST(AcuityLevels, GrowthKeepsTheFoveaWithinItAndNeverCoarsens) {
  const LevelBounds b = LevelBounds::fromModel(RegionModel::create(acuityConfig(0.5)).value());
  const PointCloud cloud = test::randomCloud(20000, Eigen::Vector3d(0, 0, 3), 4.0f, 9);
  Gaze plain;  // at the origin, along +z
  Gaze grown = plain;
  grown.fovea_growth_deg = 10.0;
  std::vector<uint8_t> l0(cloud.size()), l1(cloud.size());
  PartitionCounts counts;
  assignLevelsRef(cloud, plain, b, l0.data(), counts);
  assignLevelsRef(cloud, grown, b, l1.data(), counts);
  std::size_t inside = 0, finer = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d p = cloud.world(i);
    EXPECT_LE(l1[i], l0[i]) << i;
    finer += l1[i] < l0[i];
    const double ecc = std::acos(std::clamp(p.z() / p.norm(), -1.0, 1.0)) * 180.0 / std::numbers::pi;
    if (ecc < 9.99) {
      ++inside;
      EXPECT_EQ(l1[i], b.classify(p.norm(), 0.0)) << i;
    }
  }
  EXPECT_GT(inside, 200u);
  EXPECT_GT(finer, 500u);
}

// The view cull's hard cases: an empty field of view (the head turned away), the
// head along each axis, a point at the eye (no direction: kept), a non-finite one.
TEST(AcuityLevels, ViewCullHardCases) {
  AcuityConfig a = acuityConfig(0.5);
  a.view_cull = ViewCull::kDrop;
  a.view_cull_deg = 50.0;
  const LevelBounds b = LevelBounds::fromModel(RegionModel::create(a).value());
  PointCloud cloud(8);
  ASSERT_TRUE(cloud.push(0, 0, 0, 0));   // at the eye
  ASSERT_TRUE(cloud.push(0, 0, 3, 0));   // ahead
  ASSERT_TRUE(cloud.push(0, 0, -3, 0));  // behind
  ASSERT_TRUE(cloud.push(3, 0, 0, 0));   // at 90 degrees
  ASSERT_TRUE(cloud.push(std::numeric_limits<float>::quiet_NaN(), 0, 1, 0));
  Gaze gaze;
  gaze.view_known = true;
  std::vector<uint8_t> level(cloud.size());
  PartitionCounts counts;
  assignLevelsRef(cloud, gaze, b, level.data(), counts);
  EXPECT_NE(level[0], kRegionCulled);
  EXPECT_NE(level[1], kRegionCulled);
  EXPECT_EQ(level[2], kRegionCulled);
  EXPECT_EQ(level[3], kRegionCulled);
  EXPECT_EQ(level[4], kRegionInvalid);
  EXPECT_EQ(counts.culled, 2u);
  EXPECT_EQ(counts.invalid, 1u);
  // The head turned away: only the point at the eye is left; without a known
  // head nothing is culled.
  gaze.view_forward = -Eigen::Vector3d::UnitX();
  assignLevelsRef(cloud, gaze, b, level.data(), counts);
  EXPECT_EQ(counts.culled, 3u);
  gaze.view_known = false;
  assignLevelsRef(cloud, gaze, b, level.data(), counts);
  EXPECT_EQ(counts.culled, 0u);
  // Coarsest instead of drop: the same points at the coarsest level.
  a.view_cull = ViewCull::kCoarsest;
  const LevelBounds c = LevelBounds::fromModel(RegionModel::create(a).value());
  gaze.view_known = true;
  gaze.view_forward = Eigen::Vector3d::UnitZ();
  assignLevelsRef(cloud, gaze, c, level.data(), counts);
  EXPECT_EQ(level[2], kMaxRegions - 1);
  EXPECT_EQ(level[3], kMaxRegions - 1);
  EXPECT_EQ(counts.culled, 0u);
  // A gaze whose growth or head is unusable is refused, not foveated.
  Gaze bad;
  bad.fovea_growth_deg = -1.0;
  EXPECT_FALSE(normalizeGaze(bad).isOk());
  bad.fovea_growth_deg = std::nan("");
  EXPECT_FALSE(normalizeGaze(bad).isOk());
  bad = Gaze{};
  bad.view_known = true;
  bad.view_forward = Eigen::Vector3d::Zero();
  EXPECT_FALSE(normalizeGaze(bad).isOk());
  bad.view_forward = Eigen::Vector3d(std::numeric_limits<double>::infinity(), 0, 1);
  EXPECT_FALSE(normalizeGaze(bad).isOk());
  bad.view_forward = Eigen::Vector3d(0, 0, 5);
  EXPECT_NEAR(normalizeGaze(bad).value().view_forward.norm(), 1.0, 1e-15);
}

// At the default margin (sqrt(3), a voxel's diagonal) no point is displaced, seen
// from the eye, by more than the MAR at its own eccentricity, whatever its distance
// or eccentricity; and the mode uses the coarse levels where the eye allows them.
TEST(AcuityLevels, DefaultMarginKeepsEveryPointUnderItsMar) {
  // A wall 6 m x 3 m sampled every 5 mm, 4 m in front of the eye, and a random
  // scatter in front of it; 40 m from the world origin.
  const Eigen::Vector3d origin(40.0, 12.0, 1.5);
  PointCloud scatter = test::randomCloud(20000, origin, 3.0f, 3);
  PointCloud in(20000 + 1200 * 600);
  in.origin_m = origin;
  for (std::size_t i = 0; i < scatter.size(); ++i) {
    ASSERT_TRUE(in.push(scatter.x()[i], scatter.y()[i], scatter.z()[i], scatter.rgb()[i]));
  }
  for (int u = 0; u < 1200; ++u) {
    for (int v = 0; v < 600; ++v) {
      ASSERT_TRUE(in.push(-3.0f + 0.005f * static_cast<float>(u), 3.0f, -1.5f + 0.005f * static_cast<float>(v), 0x808080));
    }
  }
  Gaze gaze;
  gaze.origin_m = origin + Eigen::Vector3d(0.0, -1.0, 0.2);
  gaze.direction = Eigen::Vector3d(0.1, 1.0, -0.05).normalized();
  FoveationConfig config;
  config.acuity = acuityConfig();
  Foveator foveator = Foveator::create({in.size(), in.size()}, config).value();
  FoveatedCloud out(in.size());
  FoveationStats stats;
  std::vector<uint32_t> rep(in.size());
  ASSERT_TRUE(foveator.foveate(in, gaze, out, stats, rep.data()).isOk());
  ErrorModel error_model{&foveator.model(), {}};
  for (int r = 0; r < stats.region_count; ++r) error_model.voxel_size_m[r] = stats.regions[r].voxel_size_m;
  ErrorEvaluator evaluator = ErrorEvaluator::create(in.size()).value();
  ErrorMetrics m;
  ASSERT_TRUE(evaluator.evaluate(in, foveator.lastRegions(), rep.data(), out.points, gaze, error_model, m).isOk());
  EXPECT_EQ(m.all.above_mar, 0u);
  EXPECT_LE(m.all.ratio_max, 1.0);
  EXPECT_GT(m.all.seen, in.size() / 2);
  // Not vacuous: points were thinned, on several levels, some displaced by a good part of their MAR.
  EXPECT_LT(out.size(), in.size() / 2);
  EXPECT_GT(m.all.ratio_max, 0.3);
  int used = 0;
  for (int r = 1; r < kMaxRegions; ++r) used += stats.regions[r].points_in > 0;
  EXPECT_GE(used, 3);
  EXPECT_EQ(stats.regions[3].voxel_size_m, 0.008);
}

// Farther or more eccentric never means finer: the level is monotone in both.
// The specification's atan and sin (float) against libm in double at the same float
// inputs, over their whole ranges.
TEST(AcuityLevels, SpecificationPolynomialsAreAccurate) {
  double worst_atan = 0.0, worst_sin = 0.0;
  for (int i = 0; i <= 100000; ++i) {
    const auto q = static_cast<float>(i / 100000.0);
    worst_atan = std::max(worst_atan, std::fabs(atanUnit(q) - std::atan(double{q})));
    const auto x = static_cast<float>(q * std::numbers::pi / 2.0);
    worst_sin = std::max(worst_sin, std::fabs(sinSpec(x) - std::sin(double{x})));
  }
  EXPECT_LT(worst_atan, 1e-5);
  EXPECT_LT(worst_sin, 3e-7);  // a few float roundings (its unit at 1 is 6e-8)
  EXPECT_EQ(sinSpec(3.0), sinSpec(std::numbers::pi / 2.0));  // held at 1 beyond 90 degrees
  // The eccentricity in every octant, at the eye and on the axes.
  for (double angle = 0.0; angle <= 180.0; angle += 0.37) {
    const double rad = angle * std::numbers::pi / 180.0;
    EXPECT_NEAR(eccentricitySpecDeg(std::cos(rad) * 2.5, std::sin(rad) * 2.5), angle, 1e-3) << angle;
  }
  EXPECT_EQ(eccentricitySpecDeg(0.0, 0.0), 0.0);
  EXPECT_NEAR(eccentricitySpecDeg(0.0, 1.0), 90.0, 1e-9);
  EXPECT_NEAR(eccentricitySpecDeg(-1.0, 0.0), 180.0, 1e-9);
}

TEST(AcuityLevels, LevelGrowsWithDistanceAndEccentricity) {
  const LevelBounds b = LevelBounds::fromModel(RegionModel::create(acuityConfig()).value());
  uint8_t previous = 0;
  for (double r = 0.0; r <= 100.0; r += 0.01) {
    const uint8_t level = b.classify(r, 10.0);
    EXPECT_GE(level, previous) << r;
    previous = level;
  }
  EXPECT_EQ(previous, kMaxRegions - 1);
  previous = 0;
  for (double ecc = 0.0; ecc <= 180.0; ecc += 0.05) {
    const uint8_t level = b.classify(3.0, ecc);
    EXPECT_GE(level, previous) << ecc;
    previous = level;
  }
  EXPECT_EQ(b.classify(3.0, 0.0), 0);  // 1 arcmin at 3 m is under 1 mm: raw
}

TEST(AcuityLevels, TheSensorFloorLiftsFinePointsToItsLevel) {
  const LevelBounds none = LevelBounds::fromModel(RegionModel::create(acuityConfig()).value());
  const LevelBounds floor8 = LevelBounds::fromModel(RegionModel::create(acuityConfig(std::sqrt(3.0), 0.008)).value());
  EXPECT_EQ(floor8.floor_level, 3);  // 2, 4, 8 mm
  EXPECT_EQ(none.classify(1.0, 0.0), 0);
  EXPECT_EQ(floor8.classify(1.0, 0.0), 3);
  EXPECT_EQ(floor8.classify(0.0, 0.0), 3);  // at the eye too
  // Coarser than the floor: unchanged.
  EXPECT_EQ(floor8.classify(10.0, 60.0), none.classify(10.0, 60.0));
  // A floor coarser than every level: the coarsest.
  const LevelBounds huge = LevelBounds::fromModel(RegionModel::create(acuityConfig(std::sqrt(3.0), 0.9)).value());
  EXPECT_EQ(huge.floor_level, kMaxRegions - 1);
}

TEST(AcuityLevels, HardCases) {
  const LevelBounds b = LevelBounds::fromModel(RegionModel::create(acuityConfig()).value());
  PointCloud cloud(16);
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  ASSERT_TRUE(cloud.push(0, 0, 0, 0));      // at the eye: no direction, raw
  ASSERT_TRUE(cloud.push(0, 0, 3, 0));      // on the gaze axis
  ASSERT_TRUE(cloud.push(0, 0, -3, 0));     // behind the eye: MAR keeps growing
  ASSERT_TRUE(cloud.push(3, 0, 0, 0));      // at 90 degrees
  ASSERT_TRUE(cloud.push(nan, 0, 1, 0));
  ASSERT_TRUE(cloud.push(0, inf, 1, 0));
  ASSERT_TRUE(cloud.push(0, 0, -inf, 0));
  Gaze gaze;  // at the origin, along +z
  std::vector<uint8_t> level(cloud.size());
  PartitionCounts counts;
  assignLevelsRef(cloud, gaze, b, level.data(), counts);
  EXPECT_EQ(level[0], 0);
  EXPECT_EQ(level[1], 0);  // 3 m on the axis: 0.87 mm < 2 mm * sqrt(3)
  EXPECT_GT(level[2], level[3]);
  EXPECT_GT(level[3], level[1]);
  for (int i = 4; i < 7; ++i) EXPECT_EQ(level[i], kRegionInvalid) << i;
  EXPECT_EQ(counts.invalid, 3u);
  // A gaze along each axis sees a point on it at the same level.
  for (const Eigen::Vector3d& axis :
       {Eigen::Vector3d(Eigen::Vector3d::UnitX()), Eigen::Vector3d(Eigen::Vector3d::UnitY()), Eigen::Vector3d(-Eigen::Vector3d::UnitZ())}) {
    PointCloud one(1);
    ASSERT_TRUE(one.push(static_cast<float>(5 * axis.x()), static_cast<float>(5 * axis.y()), static_cast<float>(5 * axis.z()), 0));
    Gaze g;
    g.direction = axis;
    uint8_t l = 0;
    assignLevelsRef(one, g, b, &l, counts);
    EXPECT_EQ(l, b.classify(5.0, 0.0));
  }
}

// ---- error-driven refinement (AcuityConfig::refine_passes, refineTestRef, moveRefinedVoxels) ----

// A wall 4 m in front of the eye with depth noise along the camera's rays (the
// camera 0.3 m beside the eye, so the noise is partly seen across), and a scatter.
PointCloud noisyWall(uint64_t seed) {
  const Eigen::Vector3d origin(40.0, 12.0, 1.5);
  PointCloud scatter = test::randomCloud(5000, origin, 3.0f, seed);
  PointCloud in(5000 + 600 * 300);
  in.origin_m = origin;
  for (std::size_t i = 0; i < scatter.size(); ++i) {
    EXPECT_TRUE(in.push(scatter.x()[i], scatter.y()[i], scatter.z()[i], scatter.rgb()[i]));
  }
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> noise(0.0f, 0.02f);
  for (int u = 0; u < 600; ++u) {
    for (int v = 0; v < 300; ++v) {
      const Eigen::Vector3f p(-3.0f + 0.01f * static_cast<float>(u), 3.0f, -1.5f + 0.01f * static_cast<float>(v));
      const Eigen::Vector3f ray = (p - Eigen::Vector3f(0.3f, -1.0f, 0.2f)).normalized();
      const Eigen::Vector3f q = p + noise(rng) * ray;
      EXPECT_TRUE(in.push(q.x(), q.y(), q.z(), 0x808080));
    }
  }
  return in;
}

struct Foveated {
  FoveatedCloud out;
  FoveationStats stats;
  std::vector<uint32_t> rep;
  std::vector<uint8_t> region;
  ErrorMetrics metrics;
};

Foveated foveateAndMeasure(const PointCloud& in, const Gaze& gaze, const AcuityConfig& acuity) {
  Foveated f{FoveatedCloud(in.size()), {}, std::vector<uint32_t>(in.size()), {}, {}};
  FoveationConfig config;
  config.acuity = acuity;
  Foveator foveator = Foveator::create({in.size(), in.size()}, config).value();
  EXPECT_TRUE(foveator.foveate(in, gaze, f.out, f.stats, f.rep.data()).isOk());
  f.region.assign(foveator.lastRegions(), foveator.lastRegions() + in.size());
  ErrorModel error_model{&foveator.model(), {}};
  for (int r = 0; r < f.stats.region_count; ++r) error_model.voxel_size_m[r] = f.stats.regions[r].voxel_size_m;
  ErrorEvaluator evaluator = ErrorEvaluator::create(in.size()).value();
  EXPECT_TRUE(evaluator.evaluate(in, f.region.data(), f.rep.data(), f.out.points, gaze, error_model, f.metrics).isOk());
  return f;
}

// A small margin alone leaves points visibly displaced; refined to convergence, none
// is above its MAR (measured by the error metrics, in double), with far fewer points
// than the margin that guarantees it (sqrt(3)) keeps.
TEST(AcuityRefinement, ConvergedRefinementLeavesNoPointAboveItsMar) {
  const PointCloud in = noisyWall(7);
  for (double growth : {0.0, 3.0}) {
    Gaze gaze;
    gaze.origin_m = in.origin_m + Eigen::Vector3d(0.0, -1.0, 0.2);
    gaze.direction = Eigen::Vector3d(0.1, 1.0, -0.05).normalized();
    gaze.fovea_growth_deg = growth;
    AcuityConfig coarse = acuityConfig(0.15);
    const Foveated plain = foveateAndMeasure(in, gaze, coarse);
    EXPECT_GT(plain.metrics.all.above_mar, plain.metrics.all.seen / 20) << "growth " << growth;
    EXPECT_EQ(plain.stats.refined, 0u);
    AcuityConfig refined = coarse;
    refined.refine_passes = kMaxRefinePasses;
    const Foveated f = foveateAndMeasure(in, gaze, refined);
    EXPECT_EQ(f.metrics.all.above_mar, 0u) << "growth " << growth;
    EXPECT_LE(f.metrics.all.ratio_max, 1.0 + 1e-5);
    EXPECT_GT(f.stats.refined, 0u);
    EXPECT_GE(f.stats.refine_passes, 2);
    EXPECT_LE(f.stats.refine_passes, kMaxRefinePasses);
    // The stats count the levels after refinement.
    std::array<uint32_t, kMaxRegions> per_level{};
    for (uint8_t r : f.region) {
      if (r < kMaxRegions) ++per_level[r];
    }
    for (int r = 0; r < kMaxRegions; ++r) EXPECT_EQ(f.stats.regions[r].points_in, per_level[r]) << r;
    const Foveated guaranteed = foveateAndMeasure(in, gaze, acuityConfig());
    EXPECT_EQ(guaranteed.metrics.all.above_mar, 0u);
    EXPECT_LT(f.out.size(), guaranteed.out.size() * 3 / 4) << "growth " << growth;
    EXPECT_GT(f.out.size(), plain.out.size());
  }
}

// ---- one refinement pass against a brute force ----

// One trial's configuration: the margin, the floors, the slope and the view cull vary with it.
AcuityConfig refineTrialConfig(int trial) {
  // A constant floor of 32 mm (level 5) holds many points that would move.
  AcuityConfig a = acuityConfig(trial % 2 ? 0.12 : 0.4, trial % 4 == 1 ? 0.032 : 0.0, trial % 5 == 3 ? 0.1 : kDefaultSlope);
  a.floor_per_m2 = trial % 3 == 1 ? 0.002 : 0.0;
  a.view_cull = trial % 4 == 3 ? ViewCull::kCoarsest : ViewCull::kOff;
  a.view_cull_deg = 40.0;
  return a;
}

// One trial's gaze at the cloud, with a known head; some trials grow the fovea.
Gaze refineTrialGaze(const PointCloud& cloud, int trial, std::mt19937_64& rng) {
  Gaze raw;
  raw.origin_m = cloud.origin_m + Eigen::Vector3d(0.5, 0.2, -3.0);
  raw.direction = Eigen::Vector3d(0.05, -0.1, 1.0) + 0.2 * test::randomUnit(rng);
  raw.fovea_growth_deg = trial % 3 == 0 ? 4.0 : 0.0;
  raw.view_known = true;
  raw.view_forward = raw.direction + 0.5 * test::randomUnit(rng);
  return normalizeGaze(raw).value();
}

// The brute force's view of point P drawn at R (its representative): the angle
// between P - H and R - H, its MAR, whether the view cull holds it, the lowest
// level its floors allow, and whether the decision is too close to call.
struct PointReference {
  LD alpha = 0, mar = 0;
  bool outside = false;
  int lowest = 0;
  bool too_close = false;
};

PointReference pointReference(const PointCloud& cloud, std::size_t i, const Eigen::Vector3d& drawn, const Gaze& gaze,
                              const AcuityConfig& a, const std::array<double, kMaxRegions>& voxel) {
  PointReference ref;
  const Eigen::Vector3d p = cloud.world(i);
  const Eigen::Vector3d a3 = p - gaze.origin_m, b3 = drawn - gaze.origin_m;
  const LD ax = a3.x(), ay = a3.y(), az = a3.z(), bx = b3.x(), by = b3.y(), bz = b3.z();
  const LD cx = ay * bz - az * by, cy = az * bx - ax * bz, cz = ax * by - ay * bx;
  ref.alpha = std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz) * 180 /
              std::numbers::pi_v<LD>;
  const LD r = std::sqrt(ax * ax + ay * ay + az * az);
  const LD cosine = (ax * gaze.direction.x() + ay * gaze.direction.y() + az * gaze.direction.z()) / r;
  LD ecc = std::acos(std::max<LD>(-1, std::min<LD>(1, cosine))) * 180 / std::numbers::pi_v<LD>;
  ecc = std::max<LD>(0, ecc - static_cast<LD>(gaze.fovea_growth_deg));
  ref.mar = static_cast<LD>(a.slope) * ecc + static_cast<LD>(1.0 / 60.0);
  const LD head = (ax * gaze.view_forward.x() + ay * gaze.view_forward.y() + az * gaze.view_forward.z()) / r;
  const LD head_deg = std::acos(std::max<LD>(-1, std::min<LD>(1, head))) * 180 / std::numbers::pi_v<LD>;
  ref.outside = a.view_cull != ViewCull::kOff && head_deg > static_cast<LD>(a.view_cull_deg);
  // The floors: the level of the first voxel that reaches each.
  const LD floor_b = a.floor_m + a.floor_per_m2 * static_cast<LD>(cloud.x()[i] * cloud.x()[i] + cloud.y()[i] * cloud.y()[i] + cloud.z()[i] * cloud.z()[i]);
  for (int k = 1; k < kMaxRegions; ++k) {
    if (a.floor_m > 0 && ref.lowest == 0 && voxel[k] >= a.floor_m) ref.lowest = k;
  }
  if (a.floor_m > 0 && ref.lowest == 0) ref.lowest = kMaxRegions - 1;
  if (a.floor_per_m2 > 0) {
    int lift = 1;
    for (int k = 1; k < kMaxRegions; ++k) lift += voxel[k] < floor_b ? 1 : 0;
    ref.lowest = std::max(ref.lowest, std::min(lift, kMaxRegions - 1));
  }
  // Decisions within float's reach of a tie, or of the cull's cone, are not judged.
  ref.too_close = std::fabs(ref.alpha / ref.mar - 1) < 1e-3 || std::fabs(head_deg - static_cast<LD>(a.view_cull_deg)) < 1e-3;
  return ref;
}

// What the trials add up, so that the test is not vacuous.
struct RefineTally {
  int moved_total = 0, held_by_floor = 0, held_by_cull = 0;
};

// A trial's cloud, its levels, its sampling and the refinement's judgement.
struct RefineTrial {
  const PointCloud& cloud;
  const Gaze& gaze;
  const AcuityConfig& a;
  const std::array<double, kMaxRegions>& voxel;
  const std::vector<uint8_t>& level;
  const FoveatedCloud& out;
  const std::vector<uint32_t>& rep;
  const std::vector<uint8_t>& state;
};

// Each point's state as the brute force has it (stay, within or beyond), and the
// count refineTestRef returned (`beyond`); returns how many points the pass judged beyond.
std::size_t expectStatesMatchTheReference(int trial, const RefineTrial& t, std::size_t beyond, RefineTally& tally) {
  std::size_t expected_beyond = 0, judged_beyond = 0;
  for (std::size_t i = 0; i < t.cloud.size(); ++i) {
    const int n = t.level[i];
    if (n == 0 || n >= kMaxRegions) {
      EXPECT_EQ(t.state[i], kRefineStay);
      continue;
    }
    const PointReference ref = pointReference(t.cloud, i, t.out.points.world(t.rep[i]), t.gaze, t.a, t.voxel);
    if (ref.too_close) continue;
    const LD alpha = ref.alpha, mar = ref.mar;
    const bool movable = n > ref.lowest && !ref.outside;
    if (alpha > mar && n <= ref.lowest) ++tally.held_by_floor;
    if (alpha > mar && n > ref.lowest && ref.outside) ++tally.held_by_cull;
    const uint8_t expected = !movable ? kRefineStay : alpha > mar ? kRefineBeyond : kRefineWithin;
    expected_beyond += expected == kRefineBeyond;
    judged_beyond += t.state[i] == kRefineBeyond;
    EXPECT_EQ(t.state[i], expected) << "trial " << trial << " point " << i << " alpha/MAR " << static_cast<double>(alpha / mar);
  }
  std::size_t counted = 0;
  for (uint8_t st : t.state) counted += st == kRefineBeyond;
  EXPECT_EQ(beyond, counted) << trial;
  EXPECT_GE(beyond, expected_beyond) << trial;
  return judged_beyond;
}

// The move: every point that can move goes one level down when any point of its
// voxel (its representative) is beyond; the others stay. The counts follow the moves.
void expectMovesFollowTheBeyondVoxels(int trial, const RefineTrial& t, const PartitionCounts& counts,
                                      std::size_t judged_beyond, RefineTally& tally) {
  std::vector<bool> voxel_beyond(t.out.size(), false);
  for (std::size_t i = 0; i < t.cloud.size(); ++i) {
    if (t.state[i] == kRefineBeyond) voxel_beyond[t.rep[i]] = true;
  }
  std::vector<uint8_t> refined = t.level;
  std::vector<uint8_t> scratch(t.out.size(), 0xCD);
  PartitionCounts after = counts;
  const std::size_t moved = moveRefinedVoxels(t.state.data(), t.rep.data(), t.cloud.size(), t.out.size(), scratch.data(),
                                              refined.data(), after);
  std::size_t expected_moves = 0, whole_voxel_moves = 0;
  for (std::size_t i = 0; i < t.cloud.size(); ++i) {
    const bool move = t.state[i] != kRefineStay && voxel_beyond[t.rep[i]];
    expected_moves += move;
    whole_voxel_moves += move && t.state[i] == kRefineWithin;
    EXPECT_EQ(refined[i], move ? t.level[i] - 1 : t.level[i]) << "trial " << trial << " point " << i;
  }
  EXPECT_EQ(moved, expected_moves) << trial;
  tally.moved_total += static_cast<int>(moved);
  if (judged_beyond > 100) {
    EXPECT_GT(whole_voxel_moves, 0u) << trial;  // points within their MAR moved with their voxel
  }
  // The counts follow the moves.
  std::array<uint32_t, kMaxRegions> per_level{};
  for (uint8_t r : refined) {
    if (r < kMaxRegions) ++per_level[r];
  }
  for (int r = 0; r < kMaxRegions; ++r) EXPECT_EQ(after.per_region[r], per_level[r]) << r;
}

// One trial: a random cloud's levels and sampling, one pass judged against the
// brute force, then the move.
void runRefineTrial(int trial, std::mt19937_64& rng, RefineTally& tally) {
  PointCloud cloud = test::randomCloud(20000, Eigen::Vector3d(trial % 3 == 2 ? 1e4 : 3.0, -2.0, 1.0), 4.0f, rng());
  const AcuityConfig a = refineTrialConfig(trial);
  const RegionModel model = RegionModel::create(a).value();
  const LevelBounds bounds = LevelBounds::fromModel(model);
  const Gaze gaze = refineTrialGaze(cloud, trial, rng);
  std::vector<uint8_t> level(cloud.size());
  PartitionCounts counts;
  assignLevelsRef(cloud, gaze, bounds, level.data(), counts);
  std::array<double, kMaxRegions> voxel{};
  for (int n = 1; n < kMaxRegions; ++n) voxel[n] = model.voxelSizeM(n, 0.0);
  VoxelSampler sampler(cloud.size(), cloud.size());
  FoveatedCloud out(cloud.size());
  SampleCounts sc;
  std::vector<uint32_t> rep(cloud.size());
  ASSERT_TRUE(sampler.sample(cloud, level.data(), kMaxRegions, voxel, out, sc, rep.data()).isOk());
  std::vector<uint8_t> state(cloud.size());
  const std::size_t beyond = refineTestRef(cloud, gaze, bounds, out.points, rep.data(), level.data(), state.data());
  const RefineTrial t{cloud, gaze, a, voxel, level, out, rep, state};
  const std::size_t judged_beyond = expectStatesMatchTheReference(trial, t, beyond, tally);
  expectMovesFollowTheBeyondVoxels(trial, t, counts, judged_beyond, tally);
}

// One pass against a brute force written here in long double: a point is beyond when
// the angle between P - H and R - H exceeds the MAR at its eccentricity (less the
// growth), and it stays when its floor or the view cull holds it; then every point that
// can move goes one level down with its voxel when any point of the voxel is beyond.
TEST(AcuityRefinement, OnePassMatchesAnIndependentReference) {
  std::mt19937_64 rng(11);
  RefineTally tally;
  for (int trial = 0; trial < 12; ++trial) ASSERT_NO_FATAL_FAILURE(runRefineTrial(trial, rng, tally));
  // Not vacuous: points moved, and the floor and the cull held some.
  EXPECT_GT(tally.moved_total, 300);
  EXPECT_GT(tally.held_by_floor, 0);
  EXPECT_GT(tally.held_by_cull, 0);
}

// Points at the eye, non-finite ones, ones without a representative and a far
// origin: refinement skips what has no level or no representative, never crashes.
TEST(AcuityRefinement, HardCases) {
  const LevelBounds b = LevelBounds::fromModel(RegionModel::create(acuityConfig(0.12, 0.004)).value());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  PointCloud cloud(8);
  cloud.origin_m = Eigen::Vector3d(1e4, -1e4, 1e4);
  ASSERT_TRUE(cloud.push(0, 0, 0, 0));  // at the eye, held by the floor (level 2)
  ASSERT_TRUE(cloud.push(0, 0, 5, 0));
  ASSERT_TRUE(cloud.push(1, 0, 5, 0));
  ASSERT_TRUE(cloud.push(nan, 0, 5, 0));
  ASSERT_TRUE(cloud.push(0, 0, -5, 0));  // behind the eye
  ASSERT_TRUE(cloud.push(0.01f, 0, 5, 0));
  Gaze gaze;
  gaze.origin_m = cloud.origin_m;
  std::vector<uint8_t> level(cloud.size());
  PartitionCounts counts;
  assignLevelsRef(cloud, gaze, b, level.data(), counts);
  EXPECT_EQ(level[0], 2);
  EXPECT_EQ(level[1], 3);  // 5 m on the axis: r sin(1 arcmin) = 1.45 mm, 0.12 x 8 mm fits
  EXPECT_EQ(level[3], kRegionInvalid);
  EXPECT_EQ(level[5], 3);
  // Representatives far off, one missing; points 1 and 5 share one, on point 5.
  PointCloud out(8);
  out.origin_m = cloud.origin_m;
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(out.push(0.5f, 0.5f, 0.0f, 0));
  ASSERT_TRUE(out.push(0.01f, 0.0f, 5.0f, 0));
  std::vector<uint32_t> rep = {0, 5, kNoRepresentative, kNoRepresentative, 4, 5};
  std::vector<uint8_t> state(cloud.size());
  EXPECT_EQ(refineTestRef(cloud, gaze, b, out, rep.data(), level.data(), state.data()), 2u);
  EXPECT_EQ(state[0], kRefineStay);  // held by the floor
  EXPECT_EQ(state[1], kRefineBeyond);  // 10 mm across at 5 m: 6.9 arcmin
  EXPECT_EQ(state[2], kRefineStay);  // no representative
  EXPECT_EQ(state[3], kRefineStay);  // invalid
  EXPECT_EQ(state[4], kRefineBeyond);  // its representative is ahead of the eye, it is behind
  EXPECT_EQ(state[5], kRefineWithin);  // exactly on its representative
  std::vector<uint8_t> scratch(out.size());
  std::vector<uint8_t> refined = level;
  EXPECT_EQ(moveRefinedVoxels(state.data(), rep.data(), cloud.size(), out.size(), scratch.data(), refined.data(), counts),
            3u);
  EXPECT_EQ(refined[1], level[1] - 1);
  EXPECT_EQ(refined[5], level[5] - 1);  // within, but its voxel has a point beyond
  EXPECT_EQ(refined[4], level[4] - 1);
  EXPECT_EQ(refined[0], level[0]);
  EXPECT_EQ(refined[2], level[2]);
}

TEST(AcuityLevels, ModelValidatesItsFields) {
  EXPECT_EQ(parsePreset("acuity").value(), Preset::kAcuity);
  EXPECT_EQ(presetName(Preset::kAcuity), "ACUITY");
  const RegionModel m = RegionModel::create(acuityConfig()).value();
  EXPECT_TRUE(m.levels());
  EXPECT_EQ(m.regionCount(), kMaxRegions);
  EXPECT_EQ(m.boundCount(), 0);
  EXPECT_EQ(m.voxelSizeM(0, 4.0), 0.0);
  EXPECT_EQ(m.voxelSizeM(1, 4.0), 0.002);
  EXPECT_EQ(m.voxelSizeM(7, 1.0), 0.128);
  AcuityConfig bad = acuityConfig();
  bad.level_voxel_m = 0.0;
  EXPECT_NE(RegionModel::create(bad).status().message().find("acuity.level_voxel_m"), std::string::npos);
  bad = acuityConfig(std::sqrt(3.0), -1.0);
  EXPECT_NE(RegionModel::create(bad).status().message().find("acuity.floor_m"), std::string::npos);
  bad = acuityConfig(std::nan(""));
  EXPECT_NE(RegionModel::create(bad).status().message().find("acuity.level_margin"), std::string::npos);
  for (int passes : {-1, kMaxRefinePasses + 1}) {
    AcuityConfig refine = acuityConfig();
    refine.refine_passes = passes;
    EXPECT_NE(RegionModel::create(refine).status().message().find("acuity.refine_passes"), std::string::npos) << passes;
  }
  AcuityConfig refine = acuityConfig();
  refine.refine_passes = kMaxRefinePasses;
  EXPECT_EQ(RegionModel::create(refine).value().refinePasses(), kMaxRefinePasses);
  bad = acuityConfig();
  bad.view_cull_deg = 0.0;
  EXPECT_NE(RegionModel::create(bad).status().message().find("acuity.view_cull_deg"), std::string::npos);
  EXPECT_EQ(parseViewCull("drop").value(), ViewCull::kDrop);
  EXPECT_EQ(viewCullName(ViewCull::kCoarsest), "coarsest");
  EXPECT_FALSE(parseViewCull("sometimes").isOk());
  // The paper's presets are no levels.
  AcuityConfig f1;
  EXPECT_FALSE(RegionModel::create(f1).value().levels());
}

}  // namespace
}  // namespace fovea::pipeline
