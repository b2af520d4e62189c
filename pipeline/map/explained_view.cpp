#include "pipeline/map/explained_view.h"

#include <cmath>

namespace fovea::pipeline::map {

Result<ExplainedView> ExplainedView::create(int max_width, int max_height, double depth_tolerance_sigmas,
                                            KernelSet kernels) {
  if (max_width <= 0 || max_height <= 0) {
    return Result<ExplainedView>(ErrorCode::kInvalidArgument, "explained view: the frame size must be positive");
  }
  if (!(depth_tolerance_sigmas > 0.0 && depth_tolerance_sigmas < 100.0)) {
    return Result<ExplainedView>(ErrorCode::kInvalidArgument, "explained view: the depth tolerance must be in (0, 100) sigmas");
  }
  ExplainedView view;
  view.max_pixels_ = static_cast<std::size_t>(max_width) * static_cast<std::size_t>(max_height);
  view.sigmas_ = static_cast<float>(depth_tolerance_sigmas * std::sqrt(2.0));
  view.raw_.assign(view.max_pixels_ + 1, 0);
  view.kernels_ = kernels;
  view.codes_.assign(static_cast<std::size_t>(max_width), 0);
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
  const IntoView into = intoView(cloud.origin_m);
  const ViewLookup view = lookup();
  float *x = cloud.x(), *y = cloud.y(), *z = cloud.z();
  uint32_t* rgb = cloud.rgb();
  const std::size_t n = cloud.size();
  std::size_t kept = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f q = into.apply(Eigen::Vector3f(x[i], y[i], z[i]));
    if (view.explains(q.x(), q.y(), q.z())) continue;
    x[kept] = x[i], y[kept] = y[i], z[kept] = z[i], rgb[kept] = rgb[i];
    ++kept;
  }
  (void)cloud.resize(kept);
  return n - kept;
}

void ExplainedView::visitUnexplained(const hal::RgbdFrame& frame, const PixelBackprojection& rule,
                                     LivePointSink& sink, VisitCounts& counts) const {
  counts = {};
  const auto offer = [&](int u, int v, std::size_t i) {
    return sink.take(u, v, rule.point(u, v, frame.depth()[i]), pixelRgb(frame, i));
  };
  if (static_cast<std::size_t>(frame.width()) > codes_.size()) {  // wider than any view: judged by none
    rule.forEachPoint(frame, [&](int u, int v, std::size_t i, const Eigen::Vector3f&) {
      if (sink.skips(u, v)) return true;
      ++counts.valid;
      return offer(u, v, i);
    });
    return;
  }
  ViewJudgeParams params{lookup(), intoView(frame.T_world_cam.t_world_cam), rule, frame.depth(), frame.width()};
  uint8_t* codes = codes_.data();
  for (int v = 0; v < frame.height(); ++v) {
    (kernels_ == KernelSet::kSimd ? judgeRowSimd : judgeRowRef)(params, v, codes);
    const std::size_t row = static_cast<std::size_t>(v) * static_cast<std::size_t>(frame.width());
    for (int u = 0; u < frame.width(); ++u) {
      if (codes[u] == kJudgedInvalid || sink.skips(u, v)) continue;
      ++counts.valid;
      if (codes[u] == kJudgedExplained) {
        ++counts.explained;
        continue;
      }
      if (!offer(u, v, row + static_cast<std::size_t>(u))) return;
    }
  }
}

}  // namespace fovea::pipeline::map
