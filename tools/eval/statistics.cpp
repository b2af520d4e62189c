#include "tools/eval/statistics.h"

#include <cmath>
#include <limits>

#include "tools/common/nan.h"

namespace fovea::tools::eval {

namespace {

// The continued fraction of I_x(a, b) / (x^a (1 - x)^b / (a B(a, b))), by modified
// Lentz's method: the even and odd terms d_2m, d_2m+1 of DLMF 8.17.22.
double betaContinuedFraction(double x, double a, double b) {
  constexpr double kTiny = 1e-300;
  constexpr double kEpsilon = 1e-15;
  constexpr int kMaxTerms = 10000;
  double c = 1.0;
  double d = 1.0 - (a + b) * x / (a + 1.0);
  if (std::fabs(d) < kTiny) d = kTiny;
  d = 1.0 / d;
  double f = d;
  for (int m = 1; m <= kMaxTerms; ++m) {
    const double m2 = 2.0 * m;
    const double even = m * (b - m) * x / ((a + m2 - 1.0) * (a + m2));
    const double odd = -(a + m) * (a + b + m) * x / ((a + m2) * (a + m2 + 1.0));
    for (const double term : {even, odd}) {
      d = 1.0 + term * d;
      if (std::fabs(d) < kTiny) d = kTiny;
      c = 1.0 + term / c;
      if (std::fabs(c) < kTiny) c = kTiny;
      d = 1.0 / d;
      f *= c * d;
    }
    if (std::fabs(c * d - 1.0) < kEpsilon) break;
  }
  return f;
}
}  // namespace

double mean(std::span<const double> v) {
  if (v.empty()) return kNaN;
  double sum = 0.0;
  for (double x : v) sum += x;
  return sum / static_cast<double>(v.size());
}

double sampleStdDev(std::span<const double> v) {
  if (v.size() < 2) return kNaN;
  const double m = mean(v);
  double ss = 0.0;
  for (double x : v) ss += (x - m) * (x - m);
  return std::sqrt(ss / static_cast<double>(v.size() - 1));
}

double regularizedIncompleteBeta(double x, double a, double b) {
  if (!(a > 0.0) || !(b > 0.0) || !(x >= 0.0) || !(x <= 1.0)) return kNaN;
  if (x == 0.0) return 0.0;
  if (x == 1.0) return 1.0;
  // x^a (1 - x)^b / B(a, b), in logarithms.
  const double front = std::exp(std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) +
                                b * std::log1p(-x));
  if (x < (a + 1.0) / (a + b + 2.0)) return front * betaContinuedFraction(x, a, b) / a;
  return 1.0 - front * betaContinuedFraction(1.0 - x, b, a) / b;
}

double studentTTwoSidedP(double t, double df) {
  if (!(df > 0.0) || std::isnan(t)) return kNaN;
  if (std::isinf(t)) return 0.0;
  return regularizedIncompleteBeta(df / (df + t * t), df / 2.0, 0.5);
}

WelchTest welchTTest(std::span<const double> a, std::span<const double> b) {
  if (a.size() < 2 || b.size() < 2) return {kNaN, kNaN, kNaN};
  const double na = static_cast<double>(a.size()), nb = static_cast<double>(b.size());
  const double sa = sampleStdDev(a), sb = sampleStdDev(b);
  const double va = sa * sa / na, vb = sb * sb / nb;
  const double diff = mean(a) - mean(b);
  WelchTest w;
  if (va + vb == 0.0) {
    w.df = na + nb - 2.0;
    w.t = diff == 0.0 ? 0.0 : std::copysign(std::numeric_limits<double>::infinity(), diff);
    w.p = diff == 0.0 ? 1.0 : 0.0;
    return w;
  }
  w.t = diff / std::sqrt(va + vb);
  w.df = (va + vb) * (va + vb) / (va * va / (na - 1.0) + vb * vb / (nb - 1.0));
  w.p = studentTTwoSidedP(w.t, w.df);
  return w;
}

}  // namespace fovea::tools::eval
