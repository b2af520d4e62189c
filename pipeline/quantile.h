// The one quantile definition fovea reports with (fovead, the error report, the
// error metrics, fovea-operator): nearest rank, the smallest value with at least
// a share q of the values at or below it. Never interpolates, so every figure
// reported is a value that was measured.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>

namespace fovea::pipeline {

// Nearest-rank quantile of values (reordered in place, O(n)); q in [0, 1].
// values must not be empty (callers say what "no data" reports).
inline double nearestRankQuantile(std::span<double> values, double q) {
  const std::size_t n = values.size();
  const auto rank = static_cast<std::size_t>(std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(n)));
  const std::size_t k = std::clamp<std::size_t>(rank, 1, n) - 1;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

}  // namespace fovea::pipeline
