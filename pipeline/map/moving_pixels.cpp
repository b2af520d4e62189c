#include "pipeline/map/moving_pixels.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/depth_noise.h"
#include "pipeline/map/depth_region.h"
#include "pipeline/map/intensity_level.h"

namespace fovea::pipeline::map {

namespace {
constexpr float kNoSurface = std::numeric_limits<float>::infinity();
}  // namespace

Status MovingPixelsConfig::validate() const {
  if (!(std::isfinite(min_gap_m) && min_gap_m > 0.0)) return invalidArgument("moving.min_gap_m: must be positive");
  if (!(std::isfinite(gap_sigmas) && gap_sigmas >= 0.0)) return invalidArgument("moving.gap_sigmas: must be at least 0");
  if (!(region_step_share >= 0.0 && region_step_share <= 1.0)) {
    return invalidArgument("moving.region_step_share: must be in [0, 1]");
  }
  if (!(min_region_share >= 0.0 && min_region_share <= 1.0)) {
    return invalidArgument("moving.min_region_share: must be in [0, 1]");
  }
  if (settle_frames < 1 || settle_frames > 255) return invalidArgument("moving.settle_frames: must be in [1, 255]");
  if (!(steady_depth_share >= 0.0 && steady_depth_share <= 1.0)) {
    return invalidArgument("moving.steady_depth_share: must be in [0, 1]");
  }
  if (!(steady_intensity >= 0.0 && steady_intensity <= 1.0)) {
    return invalidArgument("moving.steady_intensity: must be in [0, 1]");
  }
  return Status::ok();
}

Result<MovingPixels> MovingPixels::create(int max_width, int max_height, const MovingPixelsConfig& config) {
  if (Status s = config.validate(); !s) return s;
  if (max_width < 2 || max_height < 2 || max_width > 8192 || max_height > 8192) {
    return Result<MovingPixels>(ErrorCode::kInvalidArgument, "moving pixels: size must be in [2, 8192] a side");
  }
  MovingPixels m;
  m.config_ = config;
  const auto half_width = static_cast<std::size_t>(max_width / 2), half_height = static_cast<std::size_t>(max_height / 2);
  m.max_half_pixels_ = half_width * half_height;
  m.mask_.assign(4 * m.max_half_pixels_, 0);
  m.class_.assign(m.max_half_pixels_, 0);
  m.queue_.assign(m.max_half_pixels_, 0);
  m.near_.assign(m.max_half_pixels_, 0.0f);
  m.column_near_.assign(half_width * static_cast<std::size_t>(max_height), 0.0f);
  m.age_.assign(m.max_half_pixels_, 0);
  m.depth_.assign(m.max_half_pixels_, 0.0f);
  m.intensity_.assign(m.max_half_pixels_, 0);
  return m;
}

std::size_t MovingPixels::memoryBytes() const {
  return mask_.capacity() + class_.capacity() + queue_.capacity() * sizeof(uint32_t) +
         (near_.capacity() + column_near_.capacity() + depth_.capacity()) * sizeof(float) + age_.capacity() +
         intensity_.capacity();
}

void MovingPixels::clear() {
  std::fill(mask_.begin(), mask_.end(), uint8_t{0});
  std::fill(age_.begin(), age_.end(), uint8_t{0});
}

uint32_t MovingPixels::update(const FrameIn& half, const ModelIn& model, const Eigen::Matrix3f& R,
                              const Eigen::Vector3f& t, const uint8_t* carried) {
  const bool fits = half.width > 0 && half.height > 0 &&
                    static_cast<std::size_t>(half.width) * static_cast<std::size_t>(half.height) <= max_half_pixels_ &&
                    model.width / 2 == half.width && model.height / 2 == half.height;
  if (!config_.enabled || !fits) {
    clear();
    half_width_ = half_height_ = 0;
    return 0;
  }
  if (half.width != half_width_ || half.height != half_height_) {
    clear();  // a new size: the ages belong to other pixels
    half_width_ = half.width;
    half_height_ = half.height;
  }
  nearestModelDepth(model);
  const std::size_t pixels = static_cast<std::size_t>(half.width) * static_cast<std::size_t>(half.height);
  for (std::size_t i = 0; i < pixels; ++i) class_[i] = classify(half, model, R, t, i);
  growMovers(half);
  return age(half, carried);
}

// Two passes of minima over 4 x 4 finest pixels, written for the compiler to
// vectorise (as plain loops of selects and minima; the minimum of positive
// depths and infinity does not depend on the order, so the result is the
// window's as before, when each half-level pixel's window was searched with
// clamped bounds: more than half of the moving pixels' time, perf on fovea-track).
void MovingPixels::nearestModelDepth(const ModelIn& model) {
  const int w = model.width, h = model.height, hw = w / 2, hh = h / 2;
  for (int v = 0; v < h; ++v) nearestAlongRow(model, v, column_near_.data() + static_cast<std::size_t>(v) * hw);
  for (int V = 0; V < hh; ++V) {  // ... then down the finest rows 2V - 1 .. 2V + 2
    float* out = near_.data() + static_cast<std::size_t>(V) * hw;
    std::fill_n(out, hw, kNoSurface);
    for (int v = std::max(2 * V - 1, 0); v <= std::min(2 * V + 2, h - 1); ++v) {
      const float* in = column_near_.data() + static_cast<std::size_t>(v) * hw;
      for (int U = 0; U < hw; ++U) out[U] = std::min(out[U], in[U]);
    }
    for (int U = 0; U < hw; ++U) out[U] = out[U] < kNoSurface ? out[U] : 0.0f;
  }
}

// Along finest row v: for each half-level column U, the nearest surfel depth over
// the finest columns 2U - 1 .. 2U + 2 (kNoSurface: none), into out[0, w / 2).
void MovingPixels::nearestAlongRow(const ModelIn& model, int v, float* out) {
  const int w = model.width, hw = w / 2;
  const std::size_t row = static_cast<std::size_t>(v) * static_cast<std::size_t>(w);
  const uint8_t* from_surfel = model.from_surfel + row;
  const float* z = model.z + row;
  const auto surfel = [&](int u) { return ((from_surfel[u] != 0) & (z[u] > 0.0f)) ? z[u] : kNoSurface; };
  const auto clamped = [&](int U) {
    float m = kNoSurface;
    for (int u = std::max(2 * U - 1, 0); u <= std::min(2 * U + 2, w - 1); ++u) m = std::min(m, surfel(u));
    return m;
  };
  // The columns whose window lies inside the row: 2U - 1 >= 0 and 2U + 2 <= w - 1.
  const int inner_end = std::max(1, std::min(hw, (w - 3) / 2 + 1));
  if (hw > 0) out[0] = clamped(0);
  for (int U = 1; U < inner_end; ++U) {
    out[U] = std::min(std::min(surfel(2 * U - 1), surfel(2 * U)), std::min(surfel(2 * U + 1), surfel(2 * U + 2)));
  }
  for (int U = inner_end; U < hw; ++U) out[U] = clamped(U);
}

uint8_t MovingPixels::classify(const FrameIn& half, const ModelIn& model, const Eigen::Matrix3f& R,
                               const Eigen::Vector3f& t, std::size_t i) const {
  const float pz = half.z[i];
  if (!(pz > 0.0f)) return kExplained;  // no depth: nothing to say
  const float px = half.x[i], py = half.y[i];
  const float qx = R(0, 0) * px + R(0, 1) * py + R(0, 2) * pz + t.x();
  const float qy = R(1, 0) * px + R(1, 1) * py + R(1, 2) * pz + t.y();
  const float qz = R(2, 0) * px + R(2, 1) * py + R(2, 2) * pz + t.z();
  if (!(qz > 0.0f)) return kUnknown;
  const float fu = model.fx * qx / qz + model.cx;
  const float fv = model.fy * qy / qz + model.cy;
  // Inside [-0.5, 2 x half - 0.5): also false for NaN, and before the cast.
  if (!(fu >= -0.5f && fu < static_cast<float>(2 * half_width_) - 0.5f && fv >= -0.5f &&
        fv < static_cast<float>(2 * half_height_) - 0.5f)) {
    return kUnknown;
  }
  const std::size_t j = static_cast<std::size_t>(static_cast<int>(fv + 0.5f) / 2) * static_cast<std::size_t>(half_width_) +
                        static_cast<std::size_t>(static_cast<int>(fu + 0.5f) / 2);
  const float mz = near_[j];
  if (!(mz > 0.0f)) return kUnknown;  // no surface known there: nothing says it is free
  const float gap = std::max(static_cast<float>(config_.min_gap_m), static_cast<float>(config_.gap_sigmas) * depthSigma(mz));
  return qz < mz - gap ? kInFront : kExplained;
}

void MovingPixels::growMovers(const FrameIn& half) {
  const std::size_t pixels = static_cast<std::size_t>(half.width) * static_cast<std::size_t>(half.height);
  const auto min_pixels = static_cast<std::size_t>(std::ceil(config_.min_region_share * static_cast<double>(pixels)));
  for (std::size_t seed = 0; seed < pixels; ++seed) {
    if (class_[seed] != kInFront) continue;  // not in front, or already in a region
    const std::size_t size = growRegion(half, seed);
    std::size_t in_front = 0;
    for (std::size_t k = 0; k < size; ++k) in_front += (class_[queue_[k]] & ~kVisited) == kInFront ? 1 : 0;
    const bool mover = size >= min_pixels && 2 * in_front >= size;
    if (!mover) continue;
    for (std::size_t k = 0; k < size; ++k) class_[queue_[k]] |= kInMover;
  }
}

std::size_t MovingPixels::growRegion(const FrameIn& half, std::size_t seed) {
  class_[seed] |= kVisited;
  // In front or unknown, and not visited yet: an explained pixel stops it.
  return growDepthRegion(
      half.width, half.height, half.z, static_cast<float>(config_.region_step_share), seed, queue_.data(),
      [this](std::size_t n) { return class_[n] == kInFront || class_[n] == kUnknown; },
      [this](std::size_t n) { class_[n] |= kVisited; });
}

uint32_t MovingPixels::age(const FrameIn& half, const uint8_t* carried) {
  const auto settle = static_cast<uint8_t>(config_.settle_frames);
  const auto depth_share = static_cast<float>(config_.steady_depth_share);
  const auto steady_i = static_cast<int>(std::lround(config_.steady_intensity * 255.0));
  const auto hw = static_cast<std::size_t>(half.width), fw = 2 * hw;
  uint32_t moving = 0;
  for (std::size_t V = 0; V < static_cast<std::size_t>(half.height); ++V) {
    for (std::size_t U = 0; U < hw; ++U) {
      const std::size_t i = V * hw + U;
      uint8_t is_moving = 0;
      if (carried != nullptr && carried[i] != 0) {
        age_[i] = 0;  // carried: moving as long as it is carried, never settling
        is_moving = 1;
      } else if (class_[i] & kInMover) {
        const float z = half.z[i];
        const int intensity = intensityLevel(half.intensity[i]);
        const bool steady = age_[i] > 0 && std::abs(z - depth_[i]) <= depth_share * z &&
                            std::abs(intensity - static_cast<int>(intensity_[i])) <= steady_i;
        age_[i] = steady ? static_cast<uint8_t>(std::min(age_[i] + 1, 255)) : uint8_t{1};
        depth_[i] = z;
        intensity_[i] = static_cast<uint8_t>(intensity);
        is_moving = age_[i] < settle ? 1 : 0;
      } else {
        age_[i] = 0;
      }
      const std::size_t top = 2 * V * fw + 2 * U;  // the finest 2 x 2 block
      mask_[top] = mask_[top + 1] = mask_[top + fw] = mask_[top + fw + 1] = is_moving;
      moving += 4u * is_moving;
    }
  }
  return moving;
}

}  // namespace fovea::pipeline::map
