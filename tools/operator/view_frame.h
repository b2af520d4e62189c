// A decoded frame as the viewer page receives it: one binary WebSocket message
// laid out so the page hands its parts to WebGL without touching each point
// (docs/viewer.md, "Frames"). Little-endian:
//
//   0    "FVF1"                 magic
//   4    u32 frame_id
//   8    u32 point count N
//   12   u32 reserved (0)
//   16   f64[3] origin_m        positions are relative to this world point
//   40   f32[8] splat_m         a point's splat size per region (world metres)
//   72   u32[8] points per region
//   104  f32[3N] positions, u8[3N] RGB colours, u8[N] regions
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "net/codec.h"

namespace fovea::tools {

inline constexpr std::size_t kViewFrameHeaderBytes = 104;
inline constexpr std::size_t kViewFrameBytesPerPoint = 16;

inline constexpr std::size_t viewFrameBytes(std::size_t points) {
  return kViewFrameHeaderBytes + kViewFrameBytesPerPoint * points;
}

// Splat sizes per region, what covers the surface without holes: the median spacing
// of the region's points in the frame (tools/common/splat_spacing.h), or, for a
// voxel-sampled region, its voxel (its lattice step over periphery_step_ratio) when
// that is larger. The spacing matters where voxels are finer than the camera samples
// the surface (ACUITY's 2 to 8 mm levels a few metres away hold one pixel each): drawn
// at their voxel they would leave holes between them. Measured on up to max_pairs
// pairs per region; regions without points get 0, a lone point its voxel.
class SplatSizer {
 public:
  explicit SplatSizer(double periphery_step_ratio, std::size_t max_pairs = 4096)
      : ratio_(periphery_step_ratio), scratch_(max_pairs * pipeline::kMaxRegions) {}
  std::array<float, pipeline::kMaxRegions> sizes(const net::AssembledFrame& frame);

 private:
  double ratio_;
  std::vector<float> scratch_;
};

// Writes the frame into out (at least viewFrameBytes(points) bytes); returns
// the bytes written, 0 when out is too small or the frame has no cloud.
std::size_t packViewFrame(const net::AssembledFrame& frame, const std::array<float, pipeline::kMaxRegions>& splat_m,
                          std::span<uint8_t> out);

}  // namespace fovea::tools
