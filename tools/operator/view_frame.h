// A decoded frame as the viewer page receives it: one binary WebSocket message
// laid out so the page hands its parts to WebGL without touching each point
// (docs/viewer.md, "Frames"). Little-endian:
//
//   0    "FVF2"                 magic
//   4    u32 frame_id
//   8    u32 point count N      the frame's live points, then the map's
//   12   u32 map points M       the last M of the N: the operator's bricks
//   16   f64[3] origin_m        positions are relative to this world point
//   40   f32[8] splat_m         a live point's splat size per region (world metres)
//   72   u32[8] live points per region
//   104  f32[8] map splat_m     a map point's splat size per brick level
//   136  f32[3N] positions, u8[3N] RGB colours, u8[N] regions (a map point's: 8 + its level)
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "net/brick_cache.h"
#include "net/codec.h"

namespace fovea::tools {

inline constexpr std::size_t kViewFrameHeaderBytes = 136;
// A map point's region byte: kViewMapRegion + its brick's level.
inline constexpr uint8_t kViewMapRegion = pipeline::kMaxRegions;
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

// The operator's map drawn with each frame (tools/operator/map_holder.h).
struct ViewMap {
  net::BrickCache* cache = nullptr;  // null: no map
  double periphery_step_ratio = 0.125;  // a level's voxel is its brick's step over this (net::CodecConfig)
  int64_t now_ns = 0;                   // bricks drawn are touch()ed: the cache evicts the least recently drawn
};
struct ViewPack {
  std::size_t bytes = 0;             // written; 0 as above
  std::size_t map_points = 0;        // of the map's, drawn
  std::size_t map_bricks_left_out = 0;  // held but not drawn: the buffer was full
  std::size_t map_points_left_out = 0;
};
// As above, with the held bricks of map.cache after the frame's points: whole
// bricks while they fit `out` (the rest are counted). A map point's splat is its
// level's voxel (level 0, raw surfels: the frame's fovea splat, at least the brick's step).
ViewPack packViewFrame(const net::AssembledFrame& frame, const std::array<float, pipeline::kMaxRegions>& splat_m,
                       const ViewMap& map, std::span<uint8_t> out);

}  // namespace fovea::tools
