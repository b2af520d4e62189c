// The index map: per pixel of a frame, the surfel the map shows there as seen
// from the frame's pose, and at what depth (issue 41, part 6: a class of its
// own; SurfelMap renders it, association and the tracker read it).
//
// Built for a CPU (issue 41, part 1) in two passes instead of a z-tested
// scatter of every surfel's footprint:
//  1. offerCentre(): each surfel, in slot order, to the one pixel of its centre:
//     the nearer wins, and of surfels within the sensor's noise of each other
//     (one surface) the one of lower `rank` (the map gives the more confident
//     surfel the lower rank), the first offered of equal ranks.
//     A cell keeps the winner's slot, its footprint's reach (0 to kMaxReach
//     pixels) and its plane as inverse depth and its change per pixel (1/z is
//     affine in the pixel on a plane, so a neighbour's depth needs no ray).
//  2. gather(): each pixel looks at the centres within kMaxReach of it, in the
//     order of kGatherOffsets (nearest first), and takes the nearest surface's
//     nearest centre: a candidate whose footprint reaches the pixel replaces
//     the held one when nearer by more than the sensor's noise at its depth,
//     or, within that noise and as far from the pixel as the held one's
//     centre, when it is the older surfel (the lower slot: the scatter's ties
//     went to the earlier slot too; by the offsets' order instead, TUM teddy's
//     ATE was 2.51 mm against 2.36, fovea-track).
//     Pixel by pixel independent, so the Highway kernel (index_map_simd.cpp)
//     runs it a vector of pixels at a time with plain loads: gatherIndexRef()
//     is its reference, the same bits.
// What a cell loses against a scatter: of two surfels whose centres fall into
// one pixel only the winner's footprint is drawn (docs/map.md, "The index map").
//
// Memory: the centre grid, 17 bytes a cell over the largest frame and a border
// (kMaxReach each side, a vector's lanes more on the right), and the result,
// 8 bytes a pixel; allocated by the constructor. Nothing else allocates. The
// grid's planes (12 of its bytes a cell) are read last by the gather, so their
// floats are the caller's scratch until the next reset() (scratch(): fusion
// keeps a frame's normals there, SurfelMap::fuse()).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/kernel_set.h"

namespace fovea::pipeline::map {

// A pixel (x, y) sees the centre at (x - du, y - dv) when that surfel's reach is
// at least `reach`. Nearest first (du^2 + dv^2 = 0, 1, 2, 4), then rows, then
// columns: the order in which equally near surfaces are offered.
struct GatherOffset {
  int8_t du, dv;
  uint8_t reach;
};
inline constexpr int kMaxReach = 2;
inline constexpr GatherOffset kGatherOffsets[] = {
    {0, 0, 0},  {0, -1, 1}, {-1, 0, 1}, {1, 0, 1}, {0, 1, 1}, {-1, -1, 2}, {1, -1, 2},
    {-1, 1, 2}, {1, 1, 2},  {0, -2, 2}, {-2, 0, 2}, {2, 0, 2}, {0, 2, 2}};

// The centre grid as the gather reads it: (width + 2 pad) x (height + 2 pad)
// cells at `stride`, pixel (x, y) at cell (y + pad) * stride + x + pad. A cell
// is reach << 24 | slot (kEmptyCell: none) and the plane's inverse depth at the
// cell's pixel, with its change per pixel to the right and down.
struct CentreGrid {
  static constexpr uint32_t kSlotBits = 0x00ffffffu;    // a cell's slot; all set: none
  static constexpr uint32_t kEmptyCell = kSlotBits;      // reach 0, no slot: inverse depth 0 there
  static constexpr int kPad = kMaxReach;
  // Cells right of the border that a vector of the widest Highway target (64
  // floats) may load past the frame's last pixel: empty.
  static constexpr int kVectorSlack = 64;
  const uint32_t* cell = nullptr;
  const float* inv_depth = nullptr;
  const float* grad_u = nullptr;
  const float* grad_v = nullptr;
  int width = 0, height = 0;
  std::size_t stride = 0;
  std::size_t at(int x, int y) const {
    return static_cast<std::size_t>(y + kPad) * stride + static_cast<std::size_t>(x + kPad);
  }
};

// Rows [y0, y1) of the gather: per pixel (row-major over width) the slot
// (kNoSurfel: none) and its depth (infinity: none). `sigmas`: the depth
// tolerance in the sensor's sigmas, sigmas * depthSigma(z) (core/depth_noise.h).
// The arithmetic, so that SIMD can reproduce it: iz = (inv_depth + grad_u * du)
// + grad_v * dv with du, dv as floats; a candidate needs iz > 0 and its reach;
// z = 1 / iz and same = sigmas * depthSigma(z); it is taken when z < held - same,
// or when z <= held + same, its du^2 + dv^2 is the held one's and its slot is
// lower (held starts at infinity, with no slot).
struct IndexOut {
  uint32_t* slot = nullptr;
  float* depth = nullptr;
};
void gatherIndexRef(const CentreGrid& grid, float sigmas, int y0, int y1, const IndexOut& out);
void gatherIndexSimd(const CentreGrid& grid, float sigmas, int y0, int y1, const IndexOut& out);

class IndexMap {
 public:
  static constexpr uint32_t kNoSurfel = 0xffffffffu;

  // A surfel's centre, offered to the cell of its pixel.
  struct Centre {
    float depth = 0;      // on its plane at the pixel's centre (the surfel's own depth when flat)
    float same = 0;       // the depth within which two surfels are one surface here
    uint8_t rank = 0;     // of one surface's centres in a cell, the lowest wins
    uint8_t reach = 0;    // its footprint: pixels around the centre, 0 to kMaxReach
    float inv_depth = 0;  // 1 / depth
    float grad_u = 0, grad_v = 0;  // the change of inv_depth per pixel right and down
  };

  IndexMap() = default;
  // scratch_floats: the planes' storage is at least that long (scratch()).
  IndexMap(int max_width, int max_height, std::size_t scratch_floats = 0);

  // Empties the centres for a new frame of that size (at most the largest).
  void reset(int width, int height);
  // Pass 1: surfel `slot` (below 2^24) centred at pixel (u, v), which may lie up
  // to kMaxReach outside the frame.
  void offerCentre(int u, int v, const Centre& c, uint32_t slot) {
    const std::size_t k = grid().at(u, v);
    float* const inv_depth = planes_.data();
    const float held = 1.0f / inv_depth[k];  // infinity for an empty cell
    const bool take = (c.depth < held - c.same) | ((c.depth <= held + c.same) & (c.rank < rank_[k]));
    if (!take) return;
    cell_[k] = static_cast<uint32_t>(c.reach) << 24 | slot;
    inv_depth[k] = c.inv_depth;
    inv_depth[cells_ + k] = c.grad_u;
    inv_depth[2 * cells_ + k] = c.grad_v;
    rank_[k] = c.rank;
  }
  // Pass 2, rows [y0, y1) (callers yield between bands).
  void gather(KernelSet kernels, float sigmas, int y0, int y1) {
    const IndexOut out{slot_.data(), depth_.data()};
    if (kernels == KernelSet::kSimd) {
      gatherIndexSimd(grid(), sigmas, y0, y1, out);
    } else {
      gatherIndexRef(grid(), sigmas, y0, y1, out);
    }
  }

  // The last rendered frame's size (0 x 0 before the first).
  int width() const { return width_; }
  int height() const { return height_; }
  // Per pixel, row-major: the surfel's slot (kNoSurfel: none) and its depth.
  uint32_t slot(std::size_t i) const { return slot_[i]; }
  float depth(std::size_t i) const { return depth_[i]; }
  const uint32_t* slots() const { return slot_.data(); }
  const float* depths() const { return depth_.data(); }
  CentreGrid grid() const {
    const float* inv_depth = planes_.data();
    return {cell_.data(), inv_depth, inv_depth + cells_, inv_depth + 2 * cells_, width_, height_, stride_};
  }
  // The planes' floats, free from a gather to the next reset() (whose pass 1
  // writes them again): at least the constructor's scratch_floats.
  float* scratch() { return planes_.data(); }
  const float* scratch() const { return planes_.data(); }
  std::size_t memoryBytes() const;

 private:
  int width_ = 0, height_ = 0;
  std::size_t stride_ = 0;
  std::vector<uint32_t> cell_;
  std::size_t cells_ = 0;
  std::vector<float> planes_;  // by cell: inverse depth, then grad_u, then grad_v; the scratch's rest
  std::vector<uint8_t> rank_;
  std::vector<uint32_t> slot_;
  std::vector<float> depth_;
};

}  // namespace fovea::pipeline::map
