#include "tools/operator/view_frame.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "tools/common/splat_spacing.h"

namespace fovea::tools {

// The page reads the frame with typed arrays in the machine's order, which is
// little-endian on every browser platform; the writer copies memory as it is.
static_assert(std::endian::native == std::endian::little, "the viewer's frame layout is little-endian");

std::array<float, pipeline::kMaxRegions> SplatSizer::sizes(const net::AssembledFrame& frame) {
  std::array<float, pipeline::kMaxRegions> out{};
  if (frame.cloud != nullptr) out = medianNeighbourSpacing(*frame.cloud, frame.points, scratch_);
  for (std::size_t r = 0; r < out.size(); ++r) {
    if (frame.points[r] == 0) {
      out[r] = 0.0f;
    } else if (r > 0 && frame.step_m[r] > 0.0) {
      out[r] = std::max(out[r], static_cast<float>(frame.step_m[r] / ratio_));
    }
  }
  return out;
}

std::size_t packViewFrame(const net::AssembledFrame& frame, const std::array<float, pipeline::kMaxRegions>& splat_m,
                          std::span<uint8_t> out) {
  return packViewFrame(frame, splat_m, ViewMap{}, out).bytes;
}

namespace {

// The held bricks that fit `room` points, whole, in slot order; f(slot) for each.
template <typename F>
void forEachBrickThatFits(const net::BrickCache& cache, std::size_t room, ViewPack& pack, F&& f) {
  for (std::size_t slot = 0; slot < cache.slotCount(); ++slot) {
    if (!cache.held(slot)) continue;
    const std::size_t n = cache.pointCount(slot);
    if (n > room) {
      ++pack.map_bricks_left_out;
      pack.map_points_left_out += n;
      continue;
    }
    room -= n;
    f(slot);
  }
}

}  // namespace

ViewPack packViewFrame(const net::AssembledFrame& frame, const std::array<float, pipeline::kMaxRegions>& splat_m,
                       const ViewMap& map, std::span<uint8_t> out) {
  ViewPack pack;
  if (frame.cloud == nullptr) return pack;
  const pipeline::FoveatedCloud& c = *frame.cloud;
  const std::size_t live = c.points.size();
  if (out.size() < viewFrameBytes(live)) return pack;
  // Count first: the layout's blocks (positions, colours, regions) follow from N.
  std::array<float, pipeline::kMaxRegions> map_splat_m{};
  if (map.cache != nullptr) {
    const std::size_t room = (out.size() - kViewFrameHeaderBytes) / kViewFrameBytesPerPoint - live;
    forEachBrickThatFits(*map.cache, room, pack, [&](std::size_t slot) {
      pack.map_points += map.cache->pointCount(slot);
      const uint8_t level = map.cache->level(slot);
      const double step = map.cache->stepM(slot);
      const double splat = level == 0 ? std::max<double>(splat_m[0], step) : step / map.periphery_step_ratio;
      map_splat_m[level] = std::max(map_splat_m[level], static_cast<float>(splat));
    });
    // The second walk below meets the same bricks: count what it leaves out once.
    pack.map_bricks_left_out = 0;
    pack.map_points_left_out = 0;
  }
  const std::size_t n = live + pack.map_points;
  const std::size_t bytes = viewFrameBytes(n);
  uint8_t* d = out.data();
  const auto put = [&d](const void* src, std::size_t len) {
    std::memcpy(d, src, len);
    d += len;
  };
  put("FVF2", 4);
  const uint32_t head[3] = {frame.frame_id, static_cast<uint32_t>(n), static_cast<uint32_t>(pack.map_points)};
  put(head, sizeof head);
  const double origin[3] = {c.points.origin_m.x(), c.points.origin_m.y(), c.points.origin_m.z()};
  put(origin, sizeof origin);
  put(splat_m.data(), sizeof(float) * splat_m.size());
  put(frame.points.data(), sizeof(uint32_t) * frame.points.size());
  put(map_splat_m.data(), sizeof(float) * map_splat_m.size());
  // Positions interleaved (x, y, z) for one vertex attribute; then colours and regions.
  uint8_t* positions = d;
  uint8_t* colours = d + 12 * n;
  uint8_t* regions = d + 15 * n;
  const auto putPoint = [&](std::size_t i, const float (&v)[3], uint32_t rgb, uint8_t region) {
    std::memcpy(positions + 12 * i, v, sizeof v);
    colours[3 * i] = pipeline::rgbRed(rgb);
    colours[3 * i + 1] = pipeline::rgbGreen(rgb);
    colours[3 * i + 2] = pipeline::rgbBlue(rgb);
    regions[i] = region;
  };
  const uint32_t* rgb = c.points.rgb();
  for (std::size_t i = 0; i < live; ++i) {
    const float v[3] = {c.points.x()[i], c.points.y()[i], c.points.z()[i]};
    putPoint(i, v, rgb[i], c.region[i]);
  }
  if (map.cache != nullptr) {
    net::BrickCache& cache = *map.cache;
    std::size_t i = live;
    forEachBrickThatFits(cache, pack.map_points, pack, [&](std::size_t slot) {
      const auto region = static_cast<uint8_t>(kViewMapRegion + cache.level(slot));
      cache.forEachPoint(slot, [&](const Eigen::Vector3d& world, uint32_t colour) {
        const Eigen::Vector3d p = world - c.points.origin_m;
        const float v[3] = {static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())};
        putPoint(i++, v, colour, region);
      });
      cache.touch(cache.key(slot), map.now_ns);
    });
  }
  return {bytes, pack.map_points, pack.map_bricks_left_out, pack.map_points_left_out};
}

}  // namespace fovea::tools
