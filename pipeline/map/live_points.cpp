#include "pipeline/map/live_points.h"

#include <algorithm>
#include <string>

namespace fovea::pipeline::map {

bool LivePointTally::take(int u, int v, const Eigen::Vector3f& p, uint32_t) {
  const bool whole = selection_.whole(p);
  if (whole) {
    const std::size_t i = static_cast<std::size_t>(v) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(u);
    cone_bits_[i >> 6] |= uint64_t{1} << (i & 63u);
  }
  for (int s = 1; s <= LiveSelection::kMaxStride; ++s) {
    kept_[static_cast<std::size_t>(s)] += whole || LiveSelection::onGrid(u, v, s) ? 1 : 0;
  }
  on_coarsest_grid_ += LiveSelection::onGrid(u, v, LiveSelection::kMaxStride) ? 1 : 0;
  return true;
}

int LivePointTally::finestStrideWithin(std::size_t capacity) const {
  for (int s = 1; s <= LiveSelection::kMaxStride; ++s) {
    if (kept(s) <= capacity) return s;
  }
  return 0;
}

LiveCollector::LiveCollector(int max_width, int max_height)
    : cone_bits_((static_cast<std::size_t>(std::max(max_width, 0)) * static_cast<std::size_t>(std::max(max_height, 0)) + 63) / 64, 0) {}

bool LiveCollector::fits(int width, int height) const {
  return width > 0 && height > 0 &&
         static_cast<std::size_t>(width) * static_cast<std::size_t>(height) <= 64 * cone_bits_.size();
}

Status LiveCollector::overCapacity(std::size_t kept, std::size_t capacity) {
  return {ErrorCode::kCapacityExceeded, "live points: " + std::to_string(kept) + " even on every " +
                                            std::to_string(LiveSelection::kMaxStride) +
                                            "th pixel, the gaze's cone too, capacity " + std::to_string(capacity)};
}

}  // namespace fovea::pipeline::map
