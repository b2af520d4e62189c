// One region of a depth image grown from a seed (moving_pixels.h's movers,
// carried_pixels.h's carried things): a breadth-first fill through the
// 4-neighbours that may join it and lie within `step` times the depth of the
// pixel that reaches them, so that a region stops at a depth edge.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>

namespace fovea::pipeline::map {

// The region of `seed` in a width x height image of depths z: its pixels into
// queue[0, returned), seed first. may_join(n): n is not in a region yet and
// its class lets it in; join(n) marks it taken (the caller has marked the seed).
template <typename MayJoin, typename Join>
std::size_t growDepthRegion(int width, int height, const float* z, float step, std::size_t seed, uint32_t* queue,
                            MayJoin&& may_join, Join&& join) {
  const auto w = static_cast<std::size_t>(width);
  const std::size_t pixels = w * static_cast<std::size_t>(height);
  std::size_t tail = 0;
  queue[tail++] = static_cast<uint32_t>(seed);
  for (std::size_t head = 0; head < tail; ++head) {
    const std::size_t i = queue[head];
    const std::size_t u = i % w;
    const float depth = z[i];
    const std::size_t neighbours[4] = {u > 0 ? i - 1 : pixels, u + 1 < w ? i + 1 : pixels, i >= w ? i - w : pixels,
                                       i + w < pixels ? i + w : pixels};
    for (std::size_t n : neighbours) {
      if (n >= pixels || !may_join(n)) continue;  // outside, or not to join
      if (!(std::abs(z[n] - depth) <= step * depth)) continue;
      join(n);
      queue[tail++] = static_cast<uint32_t>(n);
    }
  }
  return tail;
}

}  // namespace fovea::pipeline::map
