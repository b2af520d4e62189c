#include "pipeline/map/live_points.h"

namespace fovea::pipeline::map {

bool LivePointTally::take(int u, int v, const Eigen::Vector3f& p, uint32_t) {
  const bool whole = selection_.whole(p);
  for (int s = 1; s <= LiveSelection::kMaxStride; ++s) {
    kept_[static_cast<std::size_t>(s)] += whole || LiveSelection::onGrid(u, v, s) ? 1 : 0;
  }
  return true;
}

int LivePointTally::finestStrideWithin(std::size_t capacity) const {
  for (int s = 1; s <= LiveSelection::kMaxStride; ++s) {
    if (kept(s) <= capacity) return s;
  }
  return 0;
}

}  // namespace fovea::pipeline::map
