#include "tools/common/splat_spacing.h"

#include <algorithm>
#include <cmath>

namespace fovea::tools {

std::array<float, pipeline::kMaxRegions> medianNeighbourSpacing(
    const pipeline::FoveatedCloud& cloud, const std::array<uint32_t, pipeline::kMaxRegions>& region_points,
    std::span<float> scratch) {
  constexpr std::size_t kRegions = pipeline::kMaxRegions;
  std::array<float, kRegions> spacing{};
  const std::size_t per_region = scratch.size() / kRegions;
  if (per_region == 0) return spacing;
  std::array<std::size_t, kRegions> stride{}, seen{}, pairs{};
  for (std::size_t r = 0; r < kRegions; ++r) stride[r] = std::max<std::size_t>(1, region_points[r] / per_region);
  const pipeline::PointCloud& p = cloud.points;
  const uint8_t* region = cloud.region.data();
  for (std::size_t i = 1; i < p.size(); ++i) {
    const uint8_t r = region[i];
    if (r >= kRegions || region[i - 1] != r || pairs[r] == per_region) continue;
    if (seen[r]++ % stride[r] != 0) continue;
    const float dx = p.x()[i] - p.x()[i - 1], dy = p.y()[i] - p.y()[i - 1], dz = p.z()[i] - p.z()[i - 1];
    scratch[r * per_region + pairs[r]++] = std::sqrt(dx * dx + dy * dy + dz * dz);
  }
  for (std::size_t r = 0; r < kRegions; ++r) {
    if (pairs[r] == 0) continue;
    const auto first = scratch.begin() + static_cast<std::ptrdiff_t>(r * per_region);
    const auto mid = first + static_cast<std::ptrdiff_t>(pairs[r] / 2);
    std::nth_element(first, mid, first + static_cast<std::ptrdiff_t>(pairs[r]));
    spacing[r] = *mid;
  }
  return spacing;
}

}  // namespace fovea::tools
