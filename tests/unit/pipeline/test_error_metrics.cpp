// Error metrics of a foveated cloud: hand-computed values on tiny clouds, a
// brute-force recomputation on a random cloud, FREF and the edge cases.
#include <cmath>
#include <map>
#include <numbers>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "pipeline/error_metrics.h"
#include "pipeline/foveator.h"
#include "tests/support/clouds.h"

namespace fovea::pipeline {
namespace {

constexpr double kPi = std::numbers::pi;
double rad(double deg) { return deg * kPi / 180.0; }

RegionModel customModel(std::vector<double> bounds_deg, double slope = 0.022) {
  AcuityConfig config;
  config.preset = Preset::kCustom;
  config.custom_bounds_deg = std::move(bounds_deg);
  config.slope = slope;
  return RegionModel::create(config).value();
}

// The eye at the world origin looking along +x; points in the x-y plane.
Gaze eyeAlongX() {
  Gaze gaze;
  gaze.origin_m = Eigen::Vector3d::Zero();
  gaze.direction = Eigen::Vector3d::UnitX();
  return gaze;
}

// A point at eccentricity ecc_deg (in the x-y plane) and distance dist_m from the origin.
Eigen::Vector3d atEcc(double ecc_deg, double dist_m) {
  return {dist_m * std::cos(rad(ecc_deg)), dist_m * std::sin(rad(ecc_deg)), 0.0};
}

// A hand-made foveation: input points, their representatives and regions.
struct Tiny {
  PointCloud in{16};
  PointCloud out{16};
  std::vector<uint8_t> region;
  std::vector<uint32_t> rep;

  // Adds an input point p in region r represented by a new output point q.
  void add(const Eigen::Vector3d& p, const Eigen::Vector3d& q, uint8_t r) {
    ASSERT_TRUE(in.push(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()), 0));
    ASSERT_TRUE(out.push(static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()), 0));
    region.push_back(r);
    rep.push_back(static_cast<uint32_t>(out.size() - 1));
  }
};

ErrorMetrics evaluateTiny(const Tiny& t, const RegionModel& model, const Gaze& gaze,
                          std::array<double, kMaxRegions> voxel_m = {}) {
  ErrorEvaluator evaluator = ErrorEvaluator::create(16).value();
  ErrorMetrics metrics;
  const Status s = evaluator.evaluate(t.in, t.region.data(), t.rep.data(), t.out, gaze, {&model, voxel_m}, metrics);
  EXPECT_TRUE(s.isOk()) << s.toString();
  return metrics;
}

TEST(ErrorMetricsHelpers, AngleAndEccentricity) {
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  EXPECT_NEAR(eccentricityDeg(atEcc(30.0, 2.0), x), 30.0, 1e-12);
  EXPECT_NEAR(eccentricityDeg(-x, x), 180.0, 1e-12);
  EXPECT_NEAR(eccentricityDeg(Eigen::Vector3d(0, 0, 5), x), 90.0, 1e-12);
  EXPECT_NEAR(angleBetweenDeg(atEcc(10.0, 2.0), atEcc(10.3, 5.0)), 0.3, 1e-12);
  // A micro-degree at 10 km: acos(dot) would round to 0, atan2 of the cross keeps it.
  const Eigen::Vector3d far(10000.0, 0.0, 0.0);
  const Eigen::Vector3d moved(10000.0, 10000.0 * std::tan(rad(1e-6)), 0.0);
  EXPECT_NEAR(angleBetweenDeg(far, moved), 1e-6, 1e-15);
  EXPECT_EQ(angleBetweenDeg(Eigen::Vector3d::Zero(), x), 0.0);
}

// A point displaced by a known angle at a known eccentricity, by hand:
//  P0 at 10 deg, 2 m, moved 0.3 deg around the eye: MAR(10) = 0.22 + 1/60 = 0.236667 -> above (1.26761)
//  P1 at 30 deg, 3 m, moved 0.6 deg: MAR(30) = 0.66 + 1/60 = 0.676667 -> below (0.886700)
//  P2 at 45 deg, 1 m, moved 0.5 m along its own ray: no angle at all, 0.5 m of geometric error.
TEST(ErrorMetrics, KnownAngleAtKnownEccentricity) {
  const RegionModel model = customModel({20.0});
  Tiny t;
  t.add(atEcc(10.0, 2.0), atEcc(10.3, 2.0), 0);
  t.add(atEcc(30.0, 3.0), atEcc(29.4, 3.0), 1);
  t.add(atEcc(45.0, 1.0), atEcc(45.0, 1.5), 1);
  const ErrorMetrics m = evaluateTiny(t, model, eyeAlongX(), {0.0, 0.1});

  const double ratio0 = 0.3 / (0.022 * 10.0 + 1.0 / 60.0);
  const double ratio1 = 0.6 / (0.022 * 30.0 + 1.0 / 60.0);
  EXPECT_NEAR(ratio0, 1.267606, 1e-6);
  EXPECT_NEAR(ratio1, 0.886700, 1e-6);
  // Float coordinates at 2-3 m: angles to about 1e-5 deg.
  const RegionError& fovea = m.regions[0];
  EXPECT_EQ(fovea.points, 1u);
  EXPECT_EQ(fovea.seen, 1u);
  EXPECT_EQ(fovea.above_mar, 1u);
  EXPECT_EQ(fovea.above_reference_mar, 1u);  // the reference is the same m here
  EXPECT_NEAR(fovea.ratio_max, ratio0, 1e-4);
  EXPECT_NEAR(fovea.ratio_median, ratio0, 1e-4);
  EXPECT_DOUBLE_EQ(fovea.shareAboveMar(), 1.0);
  EXPECT_TRUE(std::isnan(fovea.rmsOverVoxel()));  // the fovea has no voxel

  const RegionError& rest = m.regions[1];
  EXPECT_EQ(rest.points, 2u);
  EXPECT_EQ(rest.seen, 2u);
  EXPECT_EQ(rest.above_mar, 0u);
  EXPECT_NEAR(rest.ratio_max, ratio1, 1e-4);
  // Nearest rank: the median of {0, 0.8867} is the smaller one.
  EXPECT_NEAR(rest.ratio_median, 0.0, 1e-6);
  EXPECT_NEAR(rest.ratio_p95, ratio1, 1e-4);
  const double chord1 = 2.0 * 3.0 * std::sin(rad(0.3));
  EXPECT_NEAR(rest.max_m, 0.5, 1e-6);
  EXPECT_NEAR(rest.rmsM(), std::sqrt((chord1 * chord1 + 0.25) / 2.0), 1e-6);
  EXPECT_NEAR(rest.maxOverVoxel(), 5.0, 1e-5);

  EXPECT_EQ(m.all.points, 3u);
  EXPECT_EQ(m.all.seen, 3u);
  EXPECT_EQ(m.all.above_mar, 1u);
  EXPECT_NEAR(m.all.shareAboveMar(), 1.0 / 3.0, 1e-12);
  EXPECT_NEAR(m.all.ratio_max, ratio0, 1e-4);
  EXPECT_NEAR(m.all.ratio_median, ratio1, 1e-4);
  EXPECT_EQ(m.at_eye, 0u);
  EXPECT_EQ(m.no_representative, 0u);
}

// The slope matters: with m = 0.034, MAR(10) = 0.356667 and the same 0.3 deg is below.
TEST(ErrorMetrics, SlopeMovesTheThreshold) {
  const RegionModel model = customModel({20.0}, 0.034);
  Tiny t;
  t.add(atEcc(10.0, 2.0), atEcc(10.3, 2.0), 0);
  const ErrorMetrics m = evaluateTiny(t, model, eyeAlongX());
  EXPECT_EQ(m.all.above_mar, 0u);
  EXPECT_NEAR(m.all.ratio_max, 0.3 / (0.034 * 10.0 + 1.0 / 60.0), 1e-4);
  // The fixed observer (m = 0.022 by default) still sees it.
  EXPECT_EQ(m.all.above_reference_mar, 1u);
  EXPECT_DOUBLE_EQ(m.all.shareAboveReferenceMar(), 1.0);
}

TEST(ErrorMetrics, ReferenceObserver) {
  const RegionModel model = customModel({20.0}, 0.022);
  Tiny t;
  t.add(atEcc(10.0, 2.0), atEcc(10.3, 2.0), 0);  // 0.3 deg at 10 deg
  ErrorEvaluator evaluator = ErrorEvaluator::create(16).value();
  ErrorMetrics m;
  // MAR(10) for m = 0.034 is 0.356667 > 0.3; for m = 0.022 it is 0.236667 < 0.3.
  ASSERT_TRUE(evaluator.evaluate(t.in, t.region.data(), t.rep.data(), t.out, eyeAlongX(), {&model, {}, 0.034}, m)
                  .isOk());
  EXPECT_EQ(m.all.above_mar, 1u);
  EXPECT_EQ(m.all.above_reference_mar, 0u);
  EXPECT_EQ(evaluator.evaluate(t.in, t.region.data(), t.rep.data(), t.out, eyeAlongX(), {&model, {}, -1.0}, m).code(),
            ErrorCode::kInvalidArgument);
}

// RMS of known displacements: 3 cm, 4 cm and 0 -> sqrt(25e-4 / 3) = 2.8868 cm, max 4 cm.
TEST(ErrorMetrics, RmsOfKnownDisplacements) {
  const RegionModel model = customModel({5.0});
  Tiny t;
  const Eigen::Vector3d base(2.0, 1.0, 0.5);
  t.add(base, base + Eigen::Vector3d(0.03, 0.0, 0.0), 1);
  t.add(base, base + Eigen::Vector3d(0.0, 0.04, 0.0), 1);
  t.add(base, base, 1);
  const ErrorMetrics m = evaluateTiny(t, model, eyeAlongX(), {0.0, 0.1});
  EXPECT_NEAR(m.regions[1].rmsM(), std::sqrt(25e-4 / 3.0), 1e-7);
  EXPECT_NEAR(m.regions[1].max_m, 0.04, 1e-7);
  EXPECT_NEAR(m.regions[1].rmsOverVoxel(), std::sqrt(25e-4 / 3.0) / 0.1, 1e-6);
  EXPECT_NEAR(m.regions[1].maxOverVoxel(), 0.4, 1e-6);
  EXPECT_EQ(m.regions[0].points, 0u);
  EXPECT_EQ(m.regions[0].rmsM(), 0.0);
  EXPECT_NEAR(m.all.rmsM(), std::sqrt(25e-4 / 3.0), 1e-7);
}

// Clouds far from the world origin: the origins cancel before the float coordinates.
TEST(ErrorMetrics, FarFromTheOriginKeepsPrecision) {
  const RegionModel model = customModel({5.0});
  Tiny t;
  const Eigen::Vector3d origin(10000.0, -20000.0, 300.0);
  t.in.origin_m = origin;
  t.out.origin_m = origin + Eigen::Vector3d(1.0, 0.0, 0.0);  // a different origin for the output
  t.add(atEcc(20.0, 2.0), atEcc(20.0, 2.0) + Eigen::Vector3d(-1.0 + 0.001, 0.0, 0.0), 1);
  Gaze gaze = eyeAlongX();
  gaze.origin_m = origin;
  const ErrorMetrics m = evaluateTiny(t, model, gaze, {0.0, 0.01});
  EXPECT_NEAR(m.all.max_m, 0.001, 1e-6);
  EXPECT_NEAR(m.all.rmsM(), 0.001, 1e-6);
}

TEST(ErrorMetrics, BorderBandsShowTheStep) {
  const RegionModel model = customModel({5.0, 10.0});
  Tiny t;
  // Region 1 (5..10 deg): one point in its first degree, one in its last, one in between.
  t.add(atEcc(5.5, 2.0), atEcc(5.6, 2.0), 1);   // 0.1 / MAR(5.5)
  t.add(atEcc(7.5, 2.0), atEcc(7.5, 2.0), 1);
  t.add(atEcc(9.5, 2.0), atEcc(9.7, 2.0), 1);   // 0.2 / MAR(9.5)
  // Region 2 (> 10 deg): its first degree.
  t.add(atEcc(10.5, 2.0), atEcc(11.5, 2.0), 2); // 1.0 / MAR(10.5)
  const ErrorMetrics m = evaluateTiny(t, model, eyeAlongX(), {0.0, 0.01, 0.05});
  const auto mar = [](double e) { return 0.022 * e + 1.0 / 60.0; };
  EXPECT_TRUE(std::isnan(m.regions[0].ratio_median_first_deg));
  EXPECT_EQ(m.regions[1].first_deg_points, 1u);
  EXPECT_EQ(m.regions[1].last_deg_points, 1u);
  EXPECT_NEAR(m.regions[1].ratio_median_first_deg, 0.1 / mar(5.5), 1e-4);
  EXPECT_NEAR(m.regions[1].ratio_median_last_deg, 0.2 / mar(9.5), 1e-4);
  EXPECT_NEAR(m.regions[2].ratio_median_first_deg, 1.0 / mar(10.5), 1e-4);
  EXPECT_TRUE(std::isnan(m.regions[2].ratio_median_last_deg));
  EXPECT_EQ(m.regions[2].last_deg_points, 0u);
}

TEST(ErrorMetricsEdgeCases, EmptyCloud) {
  const RegionModel model = customModel({5.0, 10.0});
  Tiny t;
  const ErrorMetrics m = evaluateTiny(t, model, eyeAlongX(), {0.0, 0.01, 0.05});
  EXPECT_EQ(m.region_count, 3);
  EXPECT_EQ(m.all.points, 0u);
  EXPECT_EQ(m.all.rmsM(), 0.0);
  EXPECT_EQ(m.all.max_m, 0.0);
  EXPECT_EQ(m.all.shareAboveMar(), 0.0);
  EXPECT_EQ(m.all.ratio_median, 0.0);
  for (int r = 0; r < 3; ++r) EXPECT_EQ(m.regions[r].seen, 0u);
}

// P at the eye has no direction: counted in at_eye, out of the perceptual counts,
// still in the geometric ones. The same when only R is at the eye.
TEST(ErrorMetricsEdgeCases, PointAtTheEye) {
  const RegionModel model = customModel({5.0});
  Tiny t;
  t.add(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 0);             // P = R = H
  t.add(Eigen::Vector3d::Zero(), Eigen::Vector3d(0.0, 0.01, 0.0), 1);     // P = H
  t.add(Eigen::Vector3d(0.0, 0.02, 0.0), Eigen::Vector3d::Zero(), 1);     // R = H
  t.add(atEcc(30.0, 2.0), atEcc(30.0, 2.0), 1);                          // an ordinary point
  const ErrorMetrics m = evaluateTiny(t, model, eyeAlongX(), {0.0, 0.1});
  EXPECT_EQ(m.at_eye, 3u);
  EXPECT_EQ(m.all.points, 4u);
  EXPECT_EQ(m.all.seen, 1u);
  EXPECT_EQ(m.all.above_mar, 0u);
  EXPECT_FALSE(std::isnan(m.all.ratio_max));
  EXPECT_NEAR(m.all.max_m, 0.02, 1e-8);
  EXPECT_EQ(m.regions[0].seen, 0u);
  EXPECT_EQ(m.regions[0].ratio_median, 0.0);
}

// Behind the eye Eq. 1 is extrapolated: MAR(180) = 3.96 + 1/60.
TEST(ErrorMetricsEdgeCases, PointBehindTheEye) {
  const RegionModel model = customModel({5.0});
  Tiny t;
  t.add(atEcc(180.0, 2.0), atEcc(179.0, 2.0), 1);
  const ErrorMetrics m = evaluateTiny(t, model, eyeAlongX(), {0.0, 0.1});
  EXPECT_NEAR(m.all.ratio_max, 1.0 / (0.022 * 180.0 + 1.0 / 60.0), 1e-4);
  EXPECT_EQ(m.all.above_mar, 0u);
}

TEST(ErrorMetricsEdgeCases, SkippedPointsAndBadInput) {
  const RegionModel model = customModel({5.0});
  Tiny t;
  t.add(atEcc(30.0, 2.0), atEcc(30.0, 2.0), 1);
  t.add(atEcc(30.0, 2.0), atEcc(31.0, 2.0), 1);
  t.region[1] = kRegionInvalid;
  t.rep[1] = kNoRepresentative;
  ErrorMetrics m = evaluateTiny(t, model, eyeAlongX(), {0.0, 0.1});
  EXPECT_EQ(m.no_representative, 1u);
  EXPECT_EQ(m.all.points, 1u);
  EXPECT_EQ(m.all.max_m, 0.0);

  ErrorEvaluator evaluator = ErrorEvaluator::create(16).value();
  t.region[1] = 1;
  t.rep[1] = 7;  // beyond the output
  EXPECT_EQ(evaluator.evaluate(t.in, t.region.data(), t.rep.data(), t.out, eyeAlongX(), {&model, {}}, m).code(),
            ErrorCode::kInvalidInput);
  t.rep[1] = 1;
  t.region[1] = 2;  // the model has two regions
  EXPECT_EQ(evaluator.evaluate(t.in, t.region.data(), t.rep.data(), t.out, eyeAlongX(), {&model, {}}, m).code(),
            ErrorCode::kInvalidInput);
  t.region[1] = 1;
  Gaze bad = eyeAlongX();
  bad.direction = Eigen::Vector3d::Zero();
  EXPECT_EQ(evaluator.evaluate(t.in, t.region.data(), t.rep.data(), t.out, bad, {&model, {}}, m).code(),
            ErrorCode::kInvalidInput);
  ErrorEvaluator small = ErrorEvaluator::create(1).value();
  EXPECT_EQ(small.evaluate(t.in, t.region.data(), t.rep.data(), t.out, eyeAlongX(), {&model, {}}, m).code(),
            ErrorCode::kCapacityExceeded);
  EXPECT_EQ(ErrorEvaluator::create(0).status().code(), ErrorCode::kInvalidArgument);
}

FoveationConfig configFor(Preset preset, double slope) {
  FoveationConfig config;
  config.acuity.preset = preset;
  config.acuity.slope = slope;
  return config;
}

// FREF keeps every point: zero error of every kind.
TEST(ErrorMetricsFoveation, FrefGivesZeroError) {
  PointCloud in = test::randomCloud(5000, Eigen::Vector3d(3.0, -2.0, 1.0), 2.0f, 11);
  Gaze gaze;
  gaze.origin_m = Eigen::Vector3d(3.0, -2.0, 1.0);
  gaze.direction = Eigen::Vector3d(0.3, 1.0, -0.2);
  Foveator foveator = Foveator::create({in.size(), in.size()}, configFor(Preset::kFRef, 0.022)).value();
  FoveatedCloud out(in.size());
  FoveationStats stats;
  std::vector<uint32_t> rep(in.size());
  ASSERT_TRUE(foveator.foveate(in, gaze, out, stats, rep.data()).isOk());
  ErrorEvaluator evaluator = ErrorEvaluator::create(in.size()).value();
  ErrorMetrics m;
  ASSERT_TRUE(evaluator.evaluate(in, foveator.lastRegions(), rep.data(), out.points, gaze, {&foveator.model(), {}}, m)
                  .isOk());
  EXPECT_EQ(m.region_count, 1);
  EXPECT_EQ(m.all.points, in.size());
  EXPECT_EQ(m.all.max_m, 0.0);
  EXPECT_EQ(m.all.sum_sq_m2, 0.0);
  EXPECT_EQ(m.all.above_mar, 0u);
  EXPECT_EQ(m.all.ratio_max, 0.0);
  EXPECT_EQ(m.all.seen + m.at_eye, in.size());
}

// Property: on a random cloud foveated with each preset, the geometric error per
// region equals a brute-force recomputation (long double, the centroid of each
// representative's input points computed here), the perceptual counts equal a
// recomputation with acos in long double, and no point is farther than
// sqrt(3) voxels from its representative.
class ErrorMetricsBruteForce : public ::testing::TestWithParam<Preset> {};

TEST_P(ErrorMetricsBruteForce, RandomCloud) {
  const Eigen::Vector3d origin(120.0, -40.0, 2.0);
  PointCloud in = test::randomCloud(30000, origin, 3.0f, 5);
  Gaze gaze;
  gaze.origin_m = origin + Eigen::Vector3d(0.2, 0.1, -0.3);
  gaze.direction = Eigen::Vector3d(1.0, 0.4, 0.1).normalized();
  const double slope = 0.028;
  Foveator foveator = Foveator::create({in.size(), in.size()}, configFor(GetParam(), slope)).value();
  FoveatedCloud out(in.size());
  FoveationStats stats;
  std::vector<uint32_t> rep(in.size());
  ASSERT_TRUE(foveator.foveate(in, gaze, out, stats, rep.data()).isOk());
  ErrorModel error_model{&foveator.model(), {}};
  for (int r = 0; r < stats.region_count; ++r) error_model.voxel_size_m[r] = stats.regions[r].voxel_size_m;
  ErrorEvaluator evaluator = ErrorEvaluator::create(in.size()).value();
  ErrorMetrics m;
  ASSERT_TRUE(evaluator.evaluate(in, foveator.lastRegions(), rep.data(), out.points, gaze, error_model, m).isOk());

  using LD = long double;
  struct Acc { LD x = 0, y = 0, z = 0; std::size_t n = 0; };
  std::map<uint32_t, Acc> centroid;  // by representative
  for (std::size_t i = 0; i < in.size(); ++i) {
    Acc& a = centroid[rep[i]];
    a.x += static_cast<LD>(origin.x()) + in.x()[i];
    a.y += static_cast<LD>(origin.y()) + in.y()[i];
    a.z += static_cast<LD>(origin.z()) + in.z()[i];
    ++a.n;
  }
  std::array<LD, kMaxRegions> sum_sq{};
  std::array<LD, kMaxRegions> max_d{};
  std::array<std::size_t, kMaxRegions> count{}, above{};
  const Eigen::Vector3d l = gaze.direction;
  for (std::size_t i = 0; i < in.size(); ++i) {
    const int r = foveator.lastRegions()[i];
    const Acc& a = centroid[rep[i]];
    const LD px = static_cast<LD>(origin.x()) + in.x()[i], py = static_cast<LD>(origin.y()) + in.y()[i],
             pz = static_cast<LD>(origin.z()) + in.z()[i];
    const LD dx = a.x / a.n - px, dy = a.y / a.n - py, dz = a.z / a.n - pz;
    const LD d2 = dx * dx + dy * dy + dz * dz;
    sum_sq[r] += d2;
    max_d[r] = std::max(max_d[r], std::sqrt(d2));
    ++count[r];
    // Perceptual, with acos of normalised vectors in long double, against the output point.
    const Eigen::Vector3d q = out.points.world(rep[i]);
    const LD ax = px - gaze.origin_m.x(), ay = py - gaze.origin_m.y(), az = pz - gaze.origin_m.z();
    const LD bx = static_cast<LD>(q.x()) - gaze.origin_m.x(), by = static_cast<LD>(q.y()) - gaze.origin_m.y(),
             bz = static_cast<LD>(q.z()) - gaze.origin_m.z();
    const LD na = std::sqrt(ax * ax + ay * ay + az * az), nb = std::sqrt(bx * bx + by * by + bz * bz);
    const LD cos_alpha = std::clamp((ax * bx + ay * by + az * bz) / (na * nb), -1.0L, 1.0L);
    const LD alpha_deg = std::acos(cos_alpha) * 180.0L / std::numbers::pi_v<long double>;
    const LD cos_ecc = std::clamp((ax * l.x() + ay * l.y() + az * l.z()) / na, -1.0L, 1.0L);
    const LD ecc_deg = std::acos(cos_ecc) * 180.0L / std::numbers::pi_v<long double>;
    above[r] += alpha_deg > slope * ecc_deg + 1.0L / 60.0L;
  }
  std::size_t total_above = 0;
  for (int r = 0; r < m.region_count; ++r) {
    const RegionError& e = m.regions[r];
    SCOPED_TRACE(r);
    ASSERT_EQ(e.points, count[r]);
    EXPECT_EQ(e.seen, count[r]);
    // The output points are float centroids clamped to their voxel: a few 1e-7 m off.
    const double rms = count[r] ? static_cast<double>(std::sqrt(sum_sq[r] / count[r])) : 0.0;
    EXPECT_NEAR(e.rmsM(), rms, 2e-6);
    EXPECT_NEAR(e.max_m, static_cast<double>(max_d[r]), 2e-6);
    // acos and atan2 may disagree on points within rounding of their MAR.
    EXPECT_NEAR(static_cast<double>(e.above_mar), static_cast<double>(above[r]), 2.0);
    if (r == 0) {
      EXPECT_EQ(e.max_m, 0.0);
    } else {
      EXPECT_LE(e.maxOverVoxel(), std::sqrt(3.0) + 1e-5);
    }
    total_above += e.above_mar;
  }
  EXPECT_EQ(m.all.above_mar, total_above);
  EXPECT_GT(total_above, 0u);  // the property is not vacuous: some points are above their MAR
  EXPECT_LT(total_above, m.all.seen - m.regions[0].seen);  // and some peripheral ones below
  EXPECT_EQ(m.all.points, in.size());
}

INSTANTIATE_TEST_SUITE_P(Presets, ErrorMetricsBruteForce,
                         ::testing::Values(Preset::kF1, Preset::kF2, Preset::kF3),
                         [](const auto& info) { return std::string(presetName(info.param)); });

}  // namespace
}  // namespace fovea::pipeline
