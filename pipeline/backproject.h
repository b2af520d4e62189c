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

// Scalar reference. kCapacityExceeded when out is too small for the frame's
// valid pixels (nothing is half-written: out is left empty).
Status backprojectRef(const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out,
                      BackprojectCounts& counts);

}  // namespace fovea::pipeline
