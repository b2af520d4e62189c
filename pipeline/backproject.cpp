#include "pipeline/backproject.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Dense>

namespace fovea::pipeline {

Status DepthRange::validate() const {
  if (!(std::isfinite(min_m) && min_m >= 0.0)) {
    return {ErrorCode::kInvalidArgument, "depth.min_m: must be a finite distance >= 0"};
  }
  if (!(std::isfinite(max_m) && max_m > min_m)) {
    return {ErrorCode::kInvalidArgument, "depth.max_m: must be finite and greater than depth.min_m"};
  }
  return Status::ok();
}

RawDepthRange rawDepthRange(const DepthRange& range, double depth_scale_m) {
  // The division's rounding is corrected by stepping until raw * scale brackets the range.
  auto depthOf = [depth_scale_m](int64_t raw) { return static_cast<double>(raw) * depth_scale_m; };
  RawDepthRange raw;
  raw.min = static_cast<int64_t>(std::clamp(std::ceil(range.min_m / depth_scale_m), 1.0, 65536.0));
  while (raw.min > 1 && depthOf(raw.min - 1) >= range.min_m) --raw.min;
  while (raw.min <= 65535 && depthOf(raw.min) < range.min_m) ++raw.min;
  raw.max = static_cast<int64_t>(std::clamp(std::floor(range.max_m / depth_scale_m), 0.0, 65535.0));
  while (raw.max < 65535 && depthOf(raw.max + 1) <= range.max_m) ++raw.max;
  while (raw.max >= 1 && depthOf(raw.max) > range.max_m) --raw.max;
  return raw;
}

PixelBackprojection::PixelBackprojection(const hal::RgbdFrame& frame, const DepthRange& range)
    : scale(static_cast<float>(frame.depth_scale_m)),
      cx(static_cast<float>(frame.intrinsics.cx)),
      cy(static_cast<float>(frame.intrinsics.cy)),
      inv_fx(static_cast<float>(1.0 / frame.intrinsics.fx)),
      inv_fy(static_cast<float>(1.0 / frame.intrinsics.fy)),
      r(frame.T_world_cam.R_world_cam.cast<float>()),
      raw(rawDepthRange(range, frame.depth_scale_m)) {}

Status validateFrame(const hal::RgbdFrame& frame) {
  const hal::CameraIntrinsics& k = frame.intrinsics;
  if (k.width != frame.width() || k.height != frame.height()) {
    return {ErrorCode::kInvalidInput, "frame: intrinsics are for " + std::to_string(k.width) + "x" +
                                          std::to_string(k.height) + " but the image is " +
                                          std::to_string(frame.width()) + "x" + std::to_string(frame.height())};
  }
  if (!(std::isfinite(k.fx) && std::isfinite(k.fy) && k.fx > 0.0 && k.fy > 0.0)) {
    return {ErrorCode::kInvalidInput, "frame: focal lengths must be finite and positive"};
  }
  if (!(std::isfinite(k.cx) && std::isfinite(k.cy))) {
    return {ErrorCode::kInvalidInput, "frame: principal point is not finite"};
  }
  if (!(std::isfinite(frame.depth_scale_m) && frame.depth_scale_m > 0.0)) {
    return {ErrorCode::kInvalidInput, "frame: depth scale must be finite and positive"};
  }
  const hal::Pose& pose = frame.T_world_cam;
  if (!pose.R_world_cam.allFinite() || !pose.t_world_cam.allFinite()) {
    return {ErrorCode::kInvalidInput, "frame: pose is not finite"};
  }
  const Eigen::Matrix3d should_be_identity = pose.R_world_cam.transpose() * pose.R_world_cam;
  if (!should_be_identity.isApprox(Eigen::Matrix3d::Identity(), 1e-6) || pose.R_world_cam.determinant() < 0.0) {
    return {ErrorCode::kInvalidInput, "frame: pose rotation is not a rotation matrix"};
  }
  return Status::ok();
}

Status backprojectRef(const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out,
                      BackprojectCounts& counts) {
  counts = {};
  out.clear();
  if (Status s = validateFrame(frame); !s) return s;
  if (Status s = range.validate(); !s) return s;

  const PixelBackprojection rule(frame, range);
  out.origin_m = frame.T_world_cam.t_world_cam;
  out.has_color = frame.has_rgb;

  const int w = frame.width();
  const int h = frame.height();
  counts.pixels = static_cast<std::size_t>(w) * h;
  const uint16_t* depth = frame.depth();
  std::size_t n = 0;
  const std::size_t capacity = out.capacity();
  float* ox = out.x();
  float* oy = out.y();
  float* oz = out.z();
  uint32_t* orgb = out.rgb();
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t p = static_cast<std::size_t>(v) * w + u;
      const uint32_t raw = depth[p];
      if (raw == 0) {
        ++counts.no_depth;
        continue;
      }
      if (!rule.valid(raw)) {
        ++counts.out_of_range;
        continue;
      }
      if (n == capacity) {
        out.clear();
        return {ErrorCode::kCapacityExceeded, "backproject: frame has more valid pixels than the cloud capacity " +
                                                  std::to_string(capacity) + ": raise pipeline.max_points"};
      }
      const Eigen::Vector3f q = rule.point(u, v, raw);
      ox[n] = q.x(), oy[n] = q.y(), oz[n] = q.z();
      orgb[n] = pixelRgb(frame, p);
      ++n;
    }
  }
  counts.valid = n;
  (void)out.resize(n);
  return Status::ok();
}

}  // namespace fovea::pipeline
