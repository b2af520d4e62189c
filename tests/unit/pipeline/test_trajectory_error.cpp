// The absolute trajectory error (pipeline/map/trajectory_error.h): exact on a
// rigidly moved copy, the least-squares alignment (no small rotation or
// translation of the returned one does better, written out here), and what a
// bad input gets.
#include "pipeline/map/trajectory_error.h"

#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace fovea::pipeline::map {
namespace {

double rmseUnder(const std::vector<Eigen::Vector3d>& est, const std::vector<Eigen::Vector3d>& truth,
                 const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  double sq = 0.0;
  for (std::size_t i = 0; i < est.size(); ++i) sq += (R * est[i] + t - truth[i]).squaredNorm();
  return std::sqrt(sq / static_cast<double>(est.size()));
}

TEST(TrajectoryError, ARigidlyMovedCopyHasNone) {
  std::mt19937 rng(1);
  std::normal_distribution<double> n(0.0, 1.0);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(1.1, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(4.0, -2.0, 0.5);
  std::vector<Eigen::Vector3d> truth, est;
  for (int i = 0; i < 200; ++i) {
    est.emplace_back(n(rng), n(rng), n(rng));
    truth.push_back(R * est.back() + t);
  }
  Result<TrajectoryError> e = absoluteTrajectoryError(est, truth);
  ASSERT_TRUE(e.isOk()) << e.status().message();
  EXPECT_LT(e->rmse_m, 1e-9);
  EXPECT_LT(e->max_m, 1e-9);
  EXPECT_LT((e->R - R).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((e->t - t).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_EQ(e->pairs, 200u);
}

TEST(TrajectoryError, TheAlignmentIsTheLeastSquaresOne) {
  std::mt19937 rng(2);
  std::normal_distribution<double> n(0.0, 1.0);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(-0.4, Eigen::Vector3d(0, 1, 0)).toRotationMatrix();
  const Eigen::Vector3d t(0.3, 0.0, -1.0);
  std::vector<Eigen::Vector3d> truth, est;
  for (int i = 0; i < 60; ++i) {  // a path, as a camera's: a curve plus noise of a centimetre
    const double s = 0.05 * i;
    truth.emplace_back(std::cos(s), 0.2 * s, std::sin(2 * s));
    est.push_back(R.transpose() * (truth.back() - t) + 0.01 * Eigen::Vector3d(n(rng), n(rng), n(rng)));
  }
  Result<TrajectoryError> e = absoluteTrajectoryError(est, truth);
  ASSERT_TRUE(e.isOk());
  EXPECT_NEAR(e->rmse_m, rmseUnder(est, truth, e->R, e->t), 1e-12);
  EXPECT_LE(e->rmse_m, rmseUnder(est, truth, R, t) + 1e-12);  // no worse than the true transform
  EXPECT_GT(e->rmse_m, 0.005);
  EXPECT_LT(e->rmse_m, 0.03);
  EXPECT_LE(e->median_m, e->max_m);
  EXPECT_LE(e->mean_m, e->rmse_m + 1e-15);
  // Every small rotation (about each axis, both signs) or shift of the alignment does worse.
  for (int axis = 0; axis < 3; ++axis) {
    for (double step : {-1e-3, 1e-3}) {
      const Eigen::Matrix3d dR = Eigen::AngleAxisd(step, Eigen::Vector3d::Unit(axis)).toRotationMatrix();
      EXPECT_GT(rmseUnder(est, truth, dR * e->R, dR * e->t), e->rmse_m);
      EXPECT_GT(rmseUnder(est, truth, e->R, e->t + step * Eigen::Vector3d::Unit(axis)), e->rmse_m);
    }
  }
}

TEST(TrajectoryError, BadInputIsAnError) {
  std::vector<Eigen::Vector3d> a(5, Eigen::Vector3d::Zero()), b(4, Eigen::Vector3d::Zero());
  EXPECT_EQ(absoluteTrajectoryError(a, b).status().code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(absoluteTrajectoryError(std::vector<Eigen::Vector3d>(2), std::vector<Eigen::Vector3d>(2)).status().code(),
            ErrorCode::kInvalidArgument);
  std::vector<Eigen::Vector3d> c(5, Eigen::Vector3d::Ones());
  c[3].y() = std::nan("");
  Result<TrajectoryError> e = absoluteTrajectoryError(c, a);
  ASSERT_FALSE(e.isOk());
  EXPECT_NE(e.status().message().find("pair 3"), std::string::npos) << e.status().message();
}

}  // namespace
}  // namespace fovea::pipeline::map
