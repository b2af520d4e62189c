// IndexMap's grid and the gather's scalar reference (index_map.h).
#include "pipeline/map/index_map.h"

#include <algorithm>
#include <limits>

#include "core/depth_noise.h"

namespace fovea::pipeline::map {

namespace {

std::size_t strideFor(int width) {
  return static_cast<std::size_t>(width + 2 * CentreGrid::kPad + CentreGrid::kVectorSlack);
}

}  // namespace

IndexMap::IndexMap(int max_width, int max_height, std::size_t scratch_floats) {
  cells_ = strideFor(max_width) * static_cast<std::size_t>(max_height + 2 * CentreGrid::kPad);
  const std::size_t pixels = static_cast<std::size_t>(max_width) * static_cast<std::size_t>(max_height);
  cell_.resize(cells_);
  planes_.resize(std::max(3 * cells_, scratch_floats));
  rank_.resize(cells_);
  slot_.resize(pixels);
  depth_.resize(pixels);
}

// An empty cell is kEmptyCell with inverse depth 0: the gather's iz > 0 and its
// reach test refuse it at every offset, whatever its gradients hold (earlier
// frames' or the scratch's floats, even a NaN: iz > 0 is false for it), and
// offerCentre() sees it at infinity.
void IndexMap::reset(int width, int height) {
  width_ = width;
  height_ = height;
  stride_ = strideFor(width);
  const auto n = static_cast<std::ptrdiff_t>(stride_ * static_cast<std::size_t>(height + 2 * CentreGrid::kPad));
  std::fill(cell_.begin(), cell_.begin() + n, CentreGrid::kEmptyCell);
  std::fill(planes_.begin(), planes_.begin() + n, 0.0f);  // the inverse depths
}

std::size_t IndexMap::memoryBytes() const {
  return (cell_.capacity() + slot_.capacity()) * sizeof(uint32_t) +
         (planes_.capacity() + depth_.capacity()) * sizeof(float) +
         rank_.capacity();
}

void gatherIndexRef(const CentreGrid& grid, float sigmas, int y0, int y1, const IndexOut& out) {
  for (int y = y0; y < y1; ++y) {
    for (int x = 0; x < grid.width; ++x) {
      float held = std::numeric_limits<float>::infinity();
      uint32_t cell = CentreGrid::kEmptyCell;
      int held_rsq = -1;
      for (const GatherOffset& o : kGatherOffsets) {
        const std::size_t k = grid.at(x - o.du, y - o.dv);
        const float iz =
            (grid.inv_depth[k] + grid.grad_u[k] * static_cast<float>(o.du)) + grid.grad_v[k] * static_cast<float>(o.dv);
        if (!(iz > 0.0f) || (grid.cell[k] >> 24) < o.reach) continue;
        const float z = 1.0f / iz;
        const float same = sigmas * depthSigma(z);
        const int rsq = o.du * o.du + o.dv * o.dv;
        const bool older = rsq == held_rsq && (grid.cell[k] & CentreGrid::kSlotBits) < (cell & CentreGrid::kSlotBits);
        if (z < held - same || (z <= held + same && older)) {
          held = z;
          cell = grid.cell[k];
          held_rsq = rsq;
        }
      }
      const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(grid.width) + static_cast<std::size_t>(x);
      const uint32_t slot = cell & CentreGrid::kSlotBits;
      out.slot[i] = slot == CentreGrid::kSlotBits ? IndexMap::kNoSurfel : slot;
      out.depth[i] = held;
    }
  }
}

}  // namespace fovea::pipeline::map
