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
  if (frame.cloud == nullptr) return 0;
  const pipeline::FoveatedCloud& c = *frame.cloud;
  const std::size_t n = c.points.size();
  const std::size_t bytes = viewFrameBytes(n);
  if (out.size() < bytes) return 0;
  uint8_t* d = out.data();
  const auto put = [&d](const void* src, std::size_t len) {
    std::memcpy(d, src, len);
    d += len;
  };
  put("FVF1", 4);
  const uint32_t head[3] = {frame.frame_id, static_cast<uint32_t>(n), 0};
  put(head, sizeof head);
  const double origin[3] = {c.points.origin_m.x(), c.points.origin_m.y(), c.points.origin_m.z()};
  put(origin, sizeof origin);
  put(splat_m.data(), sizeof(float) * splat_m.size());
  put(frame.points.data(), sizeof(uint32_t) * frame.points.size());
  // Positions interleaved (x, y, z) for one vertex attribute; then colours and regions.
  for (std::size_t i = 0; i < n; ++i) {
    const float v[3] = {c.points.x()[i], c.points.y()[i], c.points.z()[i]};
    std::memcpy(d + 12 * i, v, sizeof v);
  }
  d += 12 * n;
  const uint32_t* rgb = c.points.rgb();
  for (std::size_t i = 0; i < n; ++i) {
    d[3 * i] = pipeline::rgbRed(rgb[i]);
    d[3 * i + 1] = pipeline::rgbGreen(rgb[i]);
    d[3 * i + 2] = pipeline::rgbBlue(rgb[i]);
  }
  d += 3 * n;
  put(c.region.data(), n);
  return bytes;
}

}  // namespace fovea::tools
