// Back-projection of an RGB-D frame into a world-space point cloud.
//
// The cloud's origin is the camera position (t_world_cam, double); each point is
// stored as float R_world_cam * p_cam relative to it. Pixels whose depth is 0 or
// outside [min_depth_m, max_depth_m] are skipped (the range test is done on the
// raw integer depth, so it is exact). The float arithmetic below is the
// specification that SIMD kernels must reproduce:
//   z  = float(raw) * scale;  x = ((float(u) - cx) * inv_fx) * z;  y = ((float(v) - cy) * inv_fy) * z
//   p  = (r00 x + r01 y) + r02 z, etc., with float constants and no FMA.
#pragma once

#include <cstddef>
#include <cstdint>

#include <Eigen/Core>

#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline {

struct DepthRange {
  double min_m = 0.1;
  double max_m = 10.0;
  Status validate() const;
};

// The depth range in raw units: raw in [min, max] <=> min_m <= raw * scale_m <= max_m
// (in double). Every back-projection kernel tests raw values against it, exactly.
struct RawDepthRange {
  int64_t min = 1;
  int64_t max = 0;  // below min: nothing is valid
};
RawDepthRange rawDepthRange(const DepthRange& range, double depth_scale_m);

struct BackprojectCounts {
  std::size_t pixels = 0;
  std::size_t valid = 0;
  std::size_t no_depth = 0;      // raw depth 0
  std::size_t out_of_range = 0;  // outside [min_m, max_m]
};

// Rejects frames that cannot be back-projected: non-finite or non-positive
// intrinsics or depth scale, a non-finite or non-rigid pose, a size that does not
// match the intrinsics. The message says which.
Status validateFrame(const hal::RgbdFrame& frame);

// Pixel i's colour as a cloud keeps it (0 for a frame without colour).
inline uint32_t pixelRgb(const hal::RgbdFrame& frame, std::size_t i) {
  if (!frame.has_rgb) return 0u;
  const uint8_t* c = frame.rgb() + 3 * i;
  return packRgb(c[0], c[1], c[2]);
}

// One pixel's back-projection as the arithmetic above makes it, for the
// kernels that take a frame's points one at a time (backprojectRef, the map's
// live points: pipeline/map/live_points.h). For a frame validateFrame() passed.
struct PixelBackprojection {
  float scale = 0, cx = 0, cy = 0, inv_fx = 0, inv_fy = 0;
  Eigen::Matrix3f r = Eigen::Matrix3f::Identity();
  RawDepthRange raw;

  PixelBackprojection() = default;
  PixelBackprojection(const hal::RgbdFrame& frame, const DepthRange& range);
  bool valid(uint32_t raw_depth) const { return raw_depth >= raw.min && raw_depth <= raw.max; }
  // Relative to the camera's position, in the world's axes.
  Eigen::Vector3f point(int u, int v, uint32_t raw_depth) const {
    const float z = static_cast<float>(raw_depth) * scale;
    const float x = ((static_cast<float>(u) - cx) * inv_fx) * z;
    const float y = ((static_cast<float>(v) - cy) * inv_fy) * z;
    return {(r(0, 0) * x + r(0, 1) * y) + r(0, 2) * z, (r(1, 0) * x + r(1, 1) * y) + r(1, 2) * z,
            (r(2, 0) * x + r(2, 1) * y) + r(2, 2) * z};
  }
  // fn(u, v, pixel index, point) for each valid pixel in row-major order,
  // while it returns true.
  template <typename Fn>
  void forEachPoint(const hal::RgbdFrame& frame, Fn&& fn) const {
    const uint16_t* depth = frame.depth();
    const int w = frame.width(), h = frame.height();
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const std::size_t i = static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
        if (!valid(depth[i])) continue;
        if (!fn(u, v, i, point(u, v, depth[i]))) return;
      }
    }
  }
};

// Scalar reference. kCapacityExceeded when out is too small for the frame's
// valid pixels (nothing is half-written: out is left empty).
Status backprojectRef(const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out,
                      BackprojectCounts& counts);

}  // namespace fovea::pipeline
