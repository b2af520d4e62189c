#include "pipeline/map/explained_view.h"

#include <cmath>

#include "core/depth_noise.h"

namespace fovea::pipeline::map {

Result<ExplainedView> ExplainedView::create(int max_width, int max_height, double depth_tolerance_sigmas) {
  if (max_width <= 0 || max_height <= 0) {
    return Result<ExplainedView>(ErrorCode::kInvalidArgument, "explained view: the frame size must be positive");
  }
  if (!(depth_tolerance_sigmas > 0.0 && depth_tolerance_sigmas < 100.0)) {
    return Result<ExplainedView>(ErrorCode::kInvalidArgument, "explained view: the depth tolerance must be in (0, 100) sigmas");
  }
  ExplainedView view;
  view.max_pixels_ = static_cast<std::size_t>(max_width) * static_cast<std::size_t>(max_height);
  view.sigmas_ = static_cast<float>(depth_tolerance_sigmas * std::sqrt(2.0));
  view.raw_.assign(view.max_pixels_, 0);
  return view;
}

void ExplainedView::capture(const hal::RgbdFrame& frame, const uint8_t* explained) {
  const std::size_t pixels = frame.pixelCount();
  if (pixels == 0 || pixels > max_pixels_) {
    width_ = height_ = 0;
    return;
  }
  width_ = frame.width();
  height_ = frame.height();
  const hal::CameraIntrinsics& k = frame.intrinsics;
  fx_ = static_cast<float>(k.fx), fy_ = static_cast<float>(k.fy);
  cx_ = static_cast<float>(k.cx), cy_ = static_cast<float>(k.cy);
  pose_ = frame.T_world_cam;
  scale_ = static_cast<float>(frame.depth_scale_m);
  const uint16_t* raw = frame.depth();
  for (std::size_t i = 0; i < pixels; ++i) raw_[i] = explained[i] ? raw[i] : uint16_t{0};
}

std::size_t ExplainedView::removeExplained(PointCloud& cloud) const {
  if (empty()) return 0;
  const Eigen::Matrix3f R = intoView();
  const Eigen::Vector3f t = intoViewOffset(cloud.origin_m);
  float *x = cloud.x(), *y = cloud.y(), *z = cloud.z();
  uint32_t* rgb = cloud.rgb();
  const std::size_t n = cloud.size();
  std::size_t kept = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f q = R * Eigen::Vector3f(x[i], y[i], z[i]) + t;
    if (explains(q.x(), q.y(), q.z())) continue;
    x[kept] = x[i], y[kept] = y[i], z[kept] = z[i], rgb[kept] = rgb[i];
    ++kept;
  }
  (void)cloud.resize(kept);
  return n - kept;
}

void ExplainedView::visitUnexplained(const hal::RgbdFrame& frame, const PixelBackprojection& rule,
                                     LivePointSink& sink, VisitCounts& counts) const {
  counts = {};
  const Eigen::Matrix3f R = intoView();
  const Eigen::Vector3f t = intoViewOffset(frame.T_world_cam.t_world_cam);
  const uint8_t* rgb = frame.rgb();
  rule.forEachPoint(frame, [&](int u, int v, std::size_t i, const Eigen::Vector3f& p) {
    if (sink.skips(u, v)) return true;
    ++counts.valid;
    if (!empty()) {
      const Eigen::Vector3f q = R * p + t;
      if (explains(q.x(), q.y(), q.z())) {
        ++counts.explained;
        return true;
      }
    }
    return sink.take(u, v, p, frame.has_rgb ? packRgb(rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]) : 0u);
  });
}

}  // namespace fovea::pipeline::map
