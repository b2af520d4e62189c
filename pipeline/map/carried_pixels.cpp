#include "pipeline/map/carried_pixels.h"

#include <algorithm>
#include <cmath>

#include "core/depth_noise.h"
#include "pipeline/map/depth_region.h"
#include "pipeline/map/intensity_level.h"

namespace fovea::pipeline::map {

namespace {
bool shareOk(double v) { return v >= 0.0 && v <= 1.0; }  // false for NaN
}  // namespace

Status CarriedPixelsConfig::validate() const {
  if (!(std::isfinite(still_sigmas) && still_sigmas >= 0.0)) {
    return invalidArgument("carried.still_sigmas: must be at least 0");
  }
  if (!shareOk(still_intensity)) return invalidArgument("carried.still_intensity: must be in [0, 1]");
  if (still_frames < 1 || still_frames > 255) return invalidArgument("carried.still_frames: must be in [1, 255]");
  if (!(max_depth_m > 0.0)) return invalidArgument("carried.max_depth_m: must be positive");
  if (margin_pixels < 0 || margin_pixels > 64) return invalidArgument("carried.margin_pixels: must be in [0, 64]");
  if (!(min_changed_share > 0.0 && min_changed_share <= 1.0)) {
    return invalidArgument("carried.min_changed_share: must be in (0, 1]");
  }
  if (!shareOk(region_step_share)) return invalidArgument("carried.region_step_share: must be in [0, 1]");
  if (!(min_region_share > 0.0 && min_region_share <= 1.0)) {
    return invalidArgument("carried.min_region_share: must be in (0, 1]");
  }
  return Status::ok();
}

Result<CarriedPixels> CarriedPixels::create(int max_width, int max_height, const CarriedPixelsConfig& config) {
  if (Status s = config.validate(); !s) return s;
  if (max_width < 2 || max_height < 2 || max_width > 8192 || max_height > 8192) {
    return Result<CarriedPixels>(ErrorCode::kInvalidArgument, "carried pixels: size must be in [2, 8192] a side");
  }
  CarriedPixels c;
  c.config_ = config;
  c.max_pixels_ = static_cast<std::size_t>(max_width / 2) * static_cast<std::size_t>(max_height / 2);
  c.mask_.assign(c.max_pixels_, 0);
  c.class_.assign(c.max_pixels_, 0);
  c.queue_.assign(c.max_pixels_, 0);
  c.depth_.assign(c.max_pixels_, 0.0f);
  c.intensity_.assign(c.max_pixels_, 0);
  c.age_.assign(c.max_pixels_, 0);
  return c;
}

std::size_t CarriedPixels::memoryBytes() const {
  return mask_.capacity() + class_.capacity() + queue_.capacity() * sizeof(uint32_t) +
         depth_.capacity() * sizeof(float) + intensity_.capacity() + age_.capacity();
}

void CarriedPixels::clear() {
  std::fill(mask_.begin(), mask_.end(), uint8_t{0});
  have_references_ = false;
  compared_ = 0;
  changed_share_ = 0.0;
}

uint32_t CarriedPixels::find(const FrameIn& half) {
  const bool fits = half.width > 0 && half.height > 0 &&
                    static_cast<std::size_t>(half.width) * static_cast<std::size_t>(half.height) <= max_pixels_;
  if (!config_.enabled || !fits) {
    clear();
    width_ = height_ = 0;
    return 0;
  }
  if (half.width != width_ || half.height != height_) clear();  // the references belong to other pixels
  width_ = half.width;
  height_ = half.height;
  const std::size_t pixels = static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  std::fill_n(mask_.begin(), pixels, uint8_t{0});
  const bool had_references = have_references_;
  changed_share_ = age(half);
  if (!had_references) return 0;  // the first frame: references only
  return changed_share_ >= config_.min_changed_share ? markRegions(half) : 0;
}

double CarriedPixels::age(const FrameIn& half) {
  const std::size_t pixels = static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  const auto sigmas = static_cast<float>(config_.still_sigmas);
  const int still_levels = static_cast<int>(std::lround(config_.still_intensity * 255.0));
  if (have_references_) compared_ = std::min(compared_ + 1, config_.still_frames);
  const int long_frames = std::max(compared_, 1);
  std::size_t valid = 0, changed = 0;
  for (std::size_t i = 0; i < pixels; ++i) {
    const float z = half.z[i], reference = depth_[i];
    const int level = intensityLevel(half.intensity[i]);
    const bool has_depth = z > 0.0f;  // false for NaN
    const bool still = have_references_ && has_depth && reference > 0.0f &&
                       std::abs(z - reference) <= sigmas * depthSigma(z) &&
                       std::abs(level - static_cast<int>(intensity_[i])) <= still_levels;
    if (still) {
      age_[i] = static_cast<uint8_t>(std::min(age_[i] + 1, 255));
    } else {
      depth_[i] = has_depth ? z : 0.0f;
      intensity_[i] = static_cast<uint8_t>(level);
      age_[i] = 0;
    }
    const bool still_long = still && age_[i] >= long_frames;
    class_[i] = still_long ? kStill : uint8_t{0};
    valid += has_depth ? 1u : 0u;
    changed += has_depth && !still_long ? 1u : 0u;
  }
  have_references_ = true;
  return valid > 0 ? static_cast<double>(changed) / static_cast<double>(valid) : 0.0;
}

uint32_t CarriedPixels::markRegions(const FrameIn& half) {
  const std::size_t pixels = static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  const auto min_pixels = static_cast<std::size_t>(std::ceil(config_.min_region_share * static_cast<double>(pixels)));
  uint32_t carried = 0;
  for (std::size_t seed = 0; seed < pixels; ++seed) {
    if (class_[seed] != kStill) continue;  // not still, or already in a region
    const std::size_t size = growRegion(half, seed);
    if (size < min_pixels) continue;
    double depth_sum = 0.0;
    for (std::size_t k = 0; k < size; ++k) depth_sum += half.z[queue_[k]];
    if (depth_sum > config_.max_depth_m * static_cast<double>(size)) continue;  // beyond reach
    for (std::size_t k = 0; k < size; ++k) mask_[queue_[k]] = 1;
    carried += static_cast<uint32_t>(size);
  }
  if (carried == 0 || config_.margin_pixels == 0) return carried;
  return widen();
}

// A square of margin_pixels a side around each carried pixel: a pass along the
// rows into class_ (free by now), then one down the columns back into mask_,
// each an OR of shifted rows that the compiler vectorises (the loops that
// looked for the first carried neighbour pixel by pixel were a third of find()
// with a box in view).
uint32_t CarriedPixels::widen() {
  const int w = width_, h = height_, r = config_.margin_pixels;
  const auto row = [w](std::vector<uint8_t>& a, int v) {
    return a.data() + static_cast<std::size_t>(v) * static_cast<std::size_t>(w);
  };
  for (int v = 0; v < h; ++v) {
    const uint8_t* in = row(mask_, v);
    uint8_t* out = row(class_, v);
    std::fill_n(out, w, uint8_t{0});
    for (int k = -r; k <= r; ++k) {
      const int u1 = std::min(w, w - k);  // u + k within the row
      for (int u = std::max(0, -k); u < u1; ++u) out[u] |= in[u + k];
    }
  }
  uint32_t carried = 0;
  for (int v = 0; v < h; ++v) {
    uint8_t* out = row(mask_, v);
    std::fill_n(out, w, uint8_t{0});
    for (int y = std::max(v - r, 0); y <= std::min(v + r, h - 1); ++y) {
      const uint8_t* in = row(class_, y);
      for (int u = 0; u < w; ++u) out[u] |= in[u];
    }
    for (int u = 0; u < w; ++u) carried += out[u];
  }
  return carried;
}

std::size_t CarriedPixels::growRegion(const FrameIn& half, std::size_t seed) {
  class_[seed] |= kVisited;
  return growDepthRegion(
      width_, height_, half.z, static_cast<float>(config_.region_step_share), seed, queue_.data(),
      [this](std::size_t n) { return class_[n] == kStill; },  // still for long, not visited yet
      [this](std::size_t n) { class_[n] |= kVisited; });
}

}  // namespace fovea::pipeline::map
