// "No figure": what the tools' tables and statistics hold where a value does not
// exist (a median of nothing, a ratio without a denominator), one constant for all.
#pragma once

#include <limits>

namespace fovea::tools {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace fovea::tools
