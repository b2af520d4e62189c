#include "tools/eval/quality/splat_renderer.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "pipeline/point_cloud.h"

namespace fovea::tools::eval {

double EyeCamera::focalPx() const {
  return 0.5 * width / std::tan(0.5 * horizontal_fov_deg * std::numbers::pi / 180.0);
}

Eigen::Vector3d EyeCamera::toEye(const Eigen::Vector3d& world) const {
  return world_from_eye.transpose() * (world - position_m);
}

Eigen::Vector2d EyeCamera::pixelOfEye(const Eigen::Vector3d& eye) const {
  const double f = focalPx();
  return {0.5 * width + f * eye.x() / eye.z(), 0.5 * height + f * eye.y() / eye.z()};
}

bool EyeCamera::project(const Eigen::Vector3d& world, Eigen::Vector2d& pixel) const {
  const Eigen::Vector3d eye = toEye(world);
  if (!(eye.z() > kNearPlaneM)) {
    return false;
  }
  pixel = pixelOfEye(eye);
  return true;
}

Eigen::Vector3d EyeCamera::rayThroughPixel(int x, int y) const {
  const double f = focalPx();
  const Eigen::Vector3d eye((x + 0.5 - 0.5 * width) / f, (y + 0.5 - 0.5 * height) / f, 1.0);
  return world_from_eye * eye.normalized();
}

namespace {

// The pixels [first, last) a splat of n pixels centred on coordinate c covers
// along an axis of `size` pixels: those whose centres are in (c - n/2, c + n/2].
// Empty when off the image. In double until clipped: c can be far outside int's
// range for a point near the eye plane (and NaN from a degenerate camera).
struct Span {
  int first = 0, last = 0;
};
Span coveredSpan(double c, int n, int size) {
  const double first = std::floor(c - 0.5 * n + 0.5);
  if (!(first < size && first + n > 0)) {
    return {};
  }
  return {static_cast<int>(std::max(first, 0.0)), static_cast<int>(std::min(first + n, static_cast<double>(size)))};
}

}  // namespace

RenderCounts renderSplats(const SplatCloud& cloud, const EyeCamera& camera, const std::array<uint8_t, 3>& background,
                          Image& out) {
  const int w = camera.width, h = camera.height;
  const std::size_t pixels = static_cast<std::size_t>(std::max(w, 0)) * static_cast<std::size_t>(std::max(h, 0));
  out.width = w;
  out.height = h;
  out.depth.assign(pixels, std::numeric_limits<float>::infinity());
  out.rgb.resize(pixels * 3);
  for (std::size_t p = 0; p < pixels; ++p) {
    std::copy(background.begin(), background.end(), out.rgb.begin() + static_cast<std::ptrdiff_t>(p * 3));
  }

  RenderCounts counts;
  const double f = camera.focalPx();
  // Clamping the side to the image bounds the work of one splat (and keeps the
  // side in int) whatever its size and depth.
  const double max_side = std::max({w, h, 1});
  for (std::size_t i = 0; i < cloud.count; ++i) {
    const Eigen::Vector3d world = cloud.origin_m + Eigen::Vector3d(cloud.x[i], cloud.y[i], cloud.z[i]);
    const float size = cloud.size_m[i];
    if (!world.allFinite() || !std::isfinite(size) || !(size > 0.0f)) {
      ++counts.skipped_invalid;
      continue;
    }
    const Eigen::Vector3d eye = camera.toEye(world);
    if (!(eye.z() > kNearPlaneM)) {
      ++counts.behind;
      continue;
    }
    const Eigen::Vector2d uv = camera.pixelOfEye(eye);
    const int side = static_cast<int>(std::lround(std::clamp(f * size / eye.z(), 1.0, max_side)));
    const Span xs = coveredSpan(uv.x(), side, w);
    const Span ys = coveredSpan(uv.y(), side, h);
    if (xs.first == xs.last || ys.first == ys.last) {
      ++counts.outside;
      continue;
    }
    ++counts.drawn;
    const float depth = static_cast<float>(eye.z());
    const uint32_t c = cloud.rgb[i];
    const uint8_t r = pipeline::rgbRed(c), g = pipeline::rgbGreen(c), b = pipeline::rgbBlue(c);
    for (int y = ys.first; y < ys.last; ++y) {
      const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
      for (int x = xs.first; x < xs.last; ++x) {
        const std::size_t p = row + static_cast<std::size_t>(x);
        // Strictly nearer: on a tie the earlier (lower-index) point stays.
        if (depth < out.depth[p]) {
          out.depth[p] = depth;
          out.rgb[p * 3] = r;
          out.rgb[p * 3 + 1] = g;
          out.rgb[p * 3 + 2] = b;
        }
      }
    }
  }
  return counts;
}

}  // namespace fovea::tools::eval
