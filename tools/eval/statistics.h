// The statistics of fovea-eval's tables: means, spreads and Welch's t-test
// across HMD positions (the paper's significance test was a t-test; Welch's
// does not assume equal variances).
#pragma once

#include <span>

namespace fovea::tools::eval {

double mean(std::span<const double> v);               // NaN when empty
double sampleStdDev(std::span<const double> v);       // n - 1 in the denominator; NaN below 2 values

// I_x(a, b), the regularised incomplete beta function, for a, b > 0 and x in [0, 1]
// (NaN outside). Evaluated by its continued fraction (DLMF 8.17.22), with modified
// Lentz's method, on the side of (a + 1) / (a + b + 2) where it converges fast
// (Press et al., Numerical Recipes, 3rd ed., section 6.4).
double regularizedIncompleteBeta(double x, double a, double b);

// P(|T| >= |t|) for Student's t with `df` degrees of freedom (df > 0, not
// necessarily whole): I_{df / (df + t^2)}(df / 2, 1 / 2).
double studentTTwoSidedP(double t, double df);

struct WelchTest {
  double t = 0.0;   // (mean a - mean b) / sqrt(var a / n_a + var b / n_b)
  double df = 0.0;  // Welch-Satterthwaite degrees of freedom
  double p = 1.0;   // two-sided
};
// Needs two values on each side (NaN t, df and p otherwise). When both sides have
// no spread, t is +-inf and p 0 if the means differ, and t 0 and p 1 if not.
WelchTest welchTTest(std::span<const double> a, std::span<const double> b);

}  // namespace fovea::tools::eval
