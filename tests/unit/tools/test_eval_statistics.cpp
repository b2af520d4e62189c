// fovea-eval's statistics against independent references: Student's t tail
// probabilities by numerical integration of the density, Cauchy's closed form
// (one degree of freedom), textbook table values, and Welch's t and degrees of
// freedom worked by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "tools/eval/statistics.h"

namespace fovea::tools::eval {
namespace {

// 2 P(T > |t|) = 1 - 2 * integral of the density from 0 to |t| (Simpson's rule).
double tailByIntegration(double t, double df) {
  const double norm = std::exp(std::lgamma((df + 1) / 2) - std::lgamma(df / 2)) / std::sqrt(df * std::numbers::pi);
  const auto density = [&](double x) { return norm * std::pow(1 + x * x / df, -(df + 1) / 2); };
  const int n = 200000;  // even
  const double h = std::fabs(t) / n;
  double sum = density(0) + density(std::fabs(t));
  for (int i = 1; i < n; ++i) sum += (i % 2 ? 4 : 2) * density(i * h);
  return 1 - 2 * sum * h / 3;
}

TEST(EvalStatistics, StudentTailMatchesIntegrationAndClosedForms) {
  for (double df : {1.0, 2.5, 4.0, 7.3, 10.0, 30.0, 200.0}) {
    for (double t : {0.0, 0.3, 1.0, 2.0, -2.5, 4.0, 8.0}) {
      EXPECT_NEAR(studentTTwoSidedP(t, df), tailByIntegration(t, df), 1e-7) << "t " << t << " df " << df;
    }
  }
  // One degree of freedom is Cauchy: P(|T| >= t) = 1 - 2 atan(t) / pi.
  for (double t : {0.5, 1.0, 3.0, 50.0}) EXPECT_NEAR(studentTTwoSidedP(t, 1.0), 1 - 2 * std::atan(t) / std::numbers::pi, 1e-12);
  // Table values (two-sided 5 % and 1 % points).
  EXPECT_NEAR(studentTTwoSidedP(2.228139, 10.0), 0.05, 1e-6);
  EXPECT_NEAR(studentTTwoSidedP(3.169273, 10.0), 0.01, 1e-6);
  EXPECT_NEAR(studentTTwoSidedP(2.776445, 4.0), 0.05, 1e-6);
  EXPECT_EQ(studentTTwoSidedP(0.0, 3.0), 1.0);
  EXPECT_EQ(studentTTwoSidedP(INFINITY, 3.0), 0.0);
  EXPECT_TRUE(std::isnan(studentTTwoSidedP(1.0, 0.0)));
  EXPECT_TRUE(std::isnan(studentTTwoSidedP(NAN, 3.0)));
}

TEST(EvalStatistics, IncompleteBetaEdgesAndSymmetry) {
  EXPECT_EQ(regularizedIncompleteBeta(0.0, 2.0, 3.0), 0.0);
  EXPECT_EQ(regularizedIncompleteBeta(1.0, 2.0, 3.0), 1.0);
  EXPECT_TRUE(std::isnan(regularizedIncompleteBeta(1.5, 2.0, 3.0)));
  EXPECT_TRUE(std::isnan(regularizedIncompleteBeta(0.5, -1.0, 3.0)));
  // I_x(1, 1) = x; I_x(a, b) = 1 - I_{1-x}(b, a); I_x(2, 1) = x^2.
  for (double x : {0.01, 0.3, 0.5, 0.77, 0.999}) {
    EXPECT_NEAR(regularizedIncompleteBeta(x, 1.0, 1.0), x, 1e-14);
    EXPECT_NEAR(regularizedIncompleteBeta(x, 2.0, 1.0), x * x, 1e-14);
    EXPECT_NEAR(regularizedIncompleteBeta(x, 3.5, 0.5) + regularizedIncompleteBeta(1 - x, 0.5, 3.5), 1.0, 1e-12);
  }
}

TEST(EvalStatistics, WelchByHand) {
  const std::vector<double> a = {1, 2, 3, 4, 5}, b = {2, 4, 6, 8, 10};
  EXPECT_DOUBLE_EQ(mean(a), 3.0);
  EXPECT_NEAR(sampleStdDev(b), std::sqrt(10.0), 1e-12);
  // var/n: 2.5 / 5 = 0.5 and 10 / 5 = 2; t = -3 / sqrt(2.5); df = 2.5^2 / (0.5^2 / 4 + 2^2 / 4).
  const WelchTest w = welchTTest(a, b);
  EXPECT_NEAR(w.t, -3.0 / std::sqrt(2.5), 1e-12);
  EXPECT_NEAR(w.df, 6.25 / 1.0625, 1e-12);
  EXPECT_NEAR(w.p, tailByIntegration(w.t, w.df), 1e-7);
  EXPECT_GT(w.p, 0.05);  // |t| = 1.90 on 5.9 df: not significant
  // A clear difference: five positions each, bandwidths near 2 and near 6 MB/s.
  const std::vector<double> low = {2.0, 2.1, 1.9, 2.05, 1.95}, high = {6.0, 6.3, 5.8, 6.1, 5.9};
  EXPECT_LT(welchTTest(low, high).p, 1e-6);
  // No spread on either side.
  const std::vector<double> c = {3, 3, 3}, d = {4, 4, 4};
  EXPECT_EQ(welchTTest(c, c).p, 1.0);
  EXPECT_EQ(welchTTest(c, d).p, 0.0);
  EXPECT_TRUE(std::isinf(welchTTest(c, d).t));
  // Too few values.
  const std::vector<double> one = {1.0};
  EXPECT_TRUE(std::isnan(welchTTest(one, a).p));
  EXPECT_TRUE(std::isnan(mean(std::vector<double>{})));
}

}  // namespace
}  // namespace fovea::tools::eval
