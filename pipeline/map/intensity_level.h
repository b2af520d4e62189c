// A pixel's intensity in 1/255 steps, as the movers' and the carried things'
// references keep it (moving_pixels.h, carried_pixels.h): one rounding for both.
#pragma once

#include <algorithm>

namespace fovea::pipeline::map {

// 0 .. 255 for an intensity clamped to [0, 1] (NaN: 0), rounded as
// std::lround(c * 255.0f) rounds: for x >= 0, x + 0.5 in double is exact and
// truncates to the same integer (libm's lround took about a third of the
// carried pixels' find() on the still room).
inline int intensityLevel(float intensity) {
  const float c = intensity >= 0.0f ? std::min(intensity, 1.0f) : 0.0f;
  return static_cast<int>(static_cast<double>(c * 255.0f) + 0.5);
}

}  // namespace fovea::pipeline::map
