// The mock camera's image: the clean render ray-cast from the scene (with
// screen-space culling, and for a dynamic scene only the moving shapes'
// rectangle re-rendered each frame), then the sensor model's noise and
// dropouts on top of it (writeFrame). Apart from the camera's options,
// lifecycle and faults (mock_camera.cpp) because it is the per-pixel work.
#include "hal/camera/mock/mock_camera.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>

#include "hal/camera/mock/hash.h"
#include "core/depth_noise.h"
#include "hal/camera/mock/sensor_model.h"

namespace fovea::hal::mock {

namespace {

using Eigen::Vector3d;

uint8_t toByte(float channel) {
  return static_cast<uint8_t>(std::clamp(channel, 0.0f, 1.0f) * 255.0f + 0.5f);
}

// acos on [0, 1] within 7e-5 rad (Abramowitz and Stegun 4.4.45); libm's acos
// was a tenth of the render time.
double acosUnit(double x) {
  return std::sqrt(1.0 - x) * (1.5707288 + x * (-0.2121144 + x * (0.0742610 - 0.0187293 * x)));
}

bool inRange(double z_m) { return z_m >= kMinRangeM && z_m <= kMaxRangeM; }

// Nearest depth unit (halves round up), at least 1 (0 means "no measurement").
uint16_t toDepthUnits(double z_m) {
  const double units = std::clamp(z_m / kDepthScaleM + 0.5, 1.0, 65535.0);
  return static_cast<uint16_t>(units);
}

uint8_t addRgbNoise(uint8_t clean, uint64_t bits) {
  const int byte = static_cast<int>(bits & 0xFFu);
  const int delta = ((byte * (2 * kRgbNoiseLevels + 1)) >> 8) - kRgbNoiseLevels;
  return static_cast<uint8_t>(std::clamp(clean + delta, 0, 255));
}

}  // namespace

void MockCamera::renderClean(const Pose& pose, double time_s) {
  const bool same_pose = have_render_ && pose.R_world_cam == rendered_pose_.R_world_cam &&
                         pose.t_world_cam == rendered_pose_.t_world_cam;
  if (!scene_.isDynamic()) {
    if (same_pose) return;
    renderRect(pose, time_s, SceneLayer::kAll, fullRect(), work_);
    updateDropouts(fullRect());
  } else {
    // Whatever updateDropouts() rewrites starts again from the background: it
    // turns the clean dropout probabilities into the final ones in place.
    const PixelRect rect = dynamicRect(pose, time_s);
    PixelRect redo = fullRect();
    if (!same_pose) {
      renderRect(pose, time_s, SceneLayer::kStatic, fullRect(), background_);
    } else {
      redo = grow(unite(dynamic_rect_, rect), kEdgeReachPx);
    }
    copyRect(background_, redo, work_);
    renderRect(pose, time_s, SceneLayer::kDynamic, rect, work_);
    dynamic_rect_ = rect;
    updateDropouts(redo);
  }
  rendered_pose_ = pose;
  have_render_ = true;
}

void MockCamera::renderRect(const Pose& pose, double time_s, SceneLayer layer,
                            const PixelRect& rect, CleanImage& out) {
  if (rect.empty()) return;
  const bool static_layer = layer != SceneLayer::kDynamic;
  const bool dynamic_layer = layer != SceneLayer::kStatic && scene_.isDynamic();
  if (static_layer) sortShapeRects(pose);
  for (int y = rect.y0; y < rect.y1; ++y) {
    const std::size_t hit_count = castRow(pose, time_s, y, rect, static_layer, dynamic_layer, out);
    modelRowNoise(y, hit_count, out);
  }
}

// Screen-space culling of the static shapes: each shape's projected bounds,
// the shapes sorted by their first column; castRow() then sweeps each row,
// keeping the shapes covering the current pixel.
void MockCamera::sortShapeRects(const Pose& pose) {
  const std::size_t shape_count = scene_.staticShapeCount();
  for (std::size_t s = 0; s < shape_count; ++s) {
    Vector3d lo, hi;
    shape_rects_[s] = scene_.staticShapeBounds(s, lo, hi) ? projectBox(pose, lo, hi) : fullRect();
    shape_order_[s] = static_cast<uint16_t>(s);
  }
  std::sort(shape_order_.begin(), shape_order_.end(), [&](uint16_t a, uint16_t b) {
    return shape_rects_[a].x0 < shape_rects_[b].x0 ||
           (shape_rects_[a].x0 == shape_rects_[b].x0 && a < b);
  });
}

// Ray-casts row y of rect: depth and shaded colour into `out`, and each hit's
// incidence and material dropout into row_hits_ for modelRowNoise(); returns
// how many hits. Without the static layer, the static render already in `out`
// bounds the rays (and a miss leaves its pixel alone).
std::size_t MockCamera::castRow(const Pose& pose, double time_s, int y, const PixelRect& rect,
                                bool static_layer, bool dynamic_layer, CleanImage& out) {
  const Vector3d origin = pose.t_world_cam;
  const Vector3d r0 = pose.R_world_cam.col(0);
  const Vector3d r1 = pose.R_world_cam.col(1);
  const Vector3d r2 = pose.R_world_cam.col(2);
  const Vector3d row = r1 * ray_y_[static_cast<std::size_t>(y)] + r2;
  const std::size_t row_start = out.at(0, y);
  std::size_t row_count = 0;
  std::size_t next_in_row = 0;
  std::size_t active_count = 0;
  std::size_t hit_count = 0;
  if (static_layer) {
    for (const uint16_t s : shape_order_) {
      const PixelRect& r = shape_rects_[s];
      if (!r.empty() && y >= r.y0 && y < r.y1) row_shapes_[row_count++] = s;
    }
  }
  for (int x = rect.x0; x < rect.x1; ++x) {
    const std::size_t i = row_start + static_cast<std::size_t>(x);
    // d_cam = (x', y', 1), so the ray parameter t of a hit is its depth z.
    const Vector3d dir = r0 * ray_x_[static_cast<std::size_t>(x)] + row;
    Hit hit;
    bool found = false;
    double t_max = kInf;
    if (static_layer) {
      while (next_in_row < row_count && shape_rects_[row_shapes_[next_in_row]].x0 <= x) {
        active_shapes_[active_count++] = row_shapes_[next_in_row++];
      }
      std::size_t kept = 0;
      for (std::size_t j = 0; j < active_count; ++j) {
        if (shape_rects_[active_shapes_[j]].x1 > x) active_shapes_[kept++] = active_shapes_[j];
      }
      active_count = kept;
      found = scene_.intersectShapes(origin, dir, active_shapes_.data(), active_count, kInf, hit);
      if (found) t_max = hit.t;
    } else if (out.depth_m[i] > 0.0) {
      t_max = out.depth_m[i];  // the static layer already rendered there
    }
    if (dynamic_layer) {
      found |= scene_.intersect(origin, dir, time_s, SceneLayer::kDynamic, t_max, hit);
      found |= scene_.intersectCarried(pose, dir, found ? hit.t : t_max, hit);
    }
    if (!found) {
      if (static_layer) {
        out.depth_m[i] = 0.0;
        out.sigma_m[i] = 0.0f;
        out.drop_prob[i] = 1.0f;
        std::memset(&out.rgb[3 * i], 0, 3);
      }
      continue;
    }
    out.depth_m[i] = hit.t;
    const Eigen::Vector3f color = scene_.shade(origin, dir, hit);
    out.rgb[3 * i + 0] = toByte(color.x());
    out.rgb[3 * i + 1] = toByte(color.y());
    out.rgb[3 * i + 2] = toByte(color.z());
    row_hits_[hit_count++] = {x, static_cast<float>(std::abs(hit.normal.dot(dir))),
                              static_cast<float>(dir.squaredNorm()), scene_.irDropout(hit)};
  }
  return hit_count;
}

// Second pass over the row's hits: the noise model's square roots and
// divisions, in a tight loop whose iterations overlap (inline with the
// ray cast, their latency was a third of the render time).
void MockCamera::modelRowNoise(int y, std::size_t hit_count, CleanImage& out) {
  const std::size_t row_start = out.at(0, y);
  for (std::size_t k = 0; k < hit_count; ++k) {
    const RowHit& h = row_hits_[k];
    const std::size_t i = row_start + static_cast<std::size_t>(h.x);
    const double z_m = out.depth_m[i];
    const double cos_incidence = std::min(
        1.0, static_cast<double>(h.n_dot_d) / std::sqrt(static_cast<double>(h.d_squared)));
    const double theta_rad = acosUnit(cos_incidence);
    const double theta_capped = std::min(theta_rad, kSigmaAngleCapRad);
    const double angle_ratio = theta_capped / (std::numbers::pi / 2.0 - theta_capped);
    const double sigma_m = depthSigma(z_m) +
                           kSigmaAngleM / std::sqrt(z_m) * angle_ratio * angle_ratio;
    const double theta_deg = theta_rad * (180.0 / std::numbers::pi);
    const double p_grazing = std::clamp(
        (theta_deg - kGrazingStartDeg) / (kGrazingFullDeg - kGrazingStartDeg), 0.0, 1.0);
    const double p_keep = (1.0 - p_grazing) * (1.0 - h.ir_dropout) * (1.0 - kRandomDropout);
    out.sigma_m[i] = static_cast<float>(sigma_m);
    out.drop_prob[i] = static_cast<float>(1.0 - p_keep);
  }
}

void MockCamera::copyRect(const CleanImage& from, const PixelRect& rect, CleanImage& to) const {
  if (rect.empty()) return;
  const auto n = static_cast<std::size_t>(rect.x1 - rect.x0);
  for (int y = rect.y0; y < rect.y1; ++y) {
    const std::size_t i = to.at(rect.x0, y);  // whole images both (a dynamic scene's)
    std::memcpy(&to.depth_m[i], &from.depth_m[i], n * sizeof(double));
    std::memcpy(&to.sigma_m[i], &from.sigma_m[i], n * sizeof(float));
    std::memcpy(&to.drop_prob[i], &from.drop_prob[i], n * sizeof(float));
    std::memcpy(&to.rgb[3 * i], &from.rgb[3 * i], 3 * n);
  }
}

// The pixels whose rays can meet the box. Rays reach only z > kMinT in the
// camera frame, so the box is clipped there first: its projection is bounded by
// the projections of the corners in front and of the points where its edges
// cross the clipping plane. Then a margin of a pixel; empty when the box is
// wholly behind.
MockCamera::PixelRect MockCamera::projectBox(const Pose& pose, const Vector3d& lo,
                                             const Vector3d& hi) const {
  constexpr double kNearM = Scene::kMinT;
  const CameraIntrinsics& k = info_.intrinsics;
  Vector3d corners[8];
  for (int c = 0; c < 8; ++c) {
    const Vector3d p_world((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(),
                           (c & 4) ? hi.z() : lo.z());
    corners[c] = pose.R_world_cam.transpose() * (p_world - pose.t_world_cam);
  }
  double u_min = kInf, u_max = -kInf, v_min = kInf, v_max = -kInf;
  const auto include = [&](const Vector3d& p) {
    const double u = k.fx * p.x() / p.z() + k.cx;
    const double v = k.fy * p.y() / p.z() + k.cy;
    u_min = std::min(u_min, u);
    u_max = std::max(u_max, u);
    v_min = std::min(v_min, v);
    v_max = std::max(v_max, v);
  };
  for (int c = 0; c < 8; ++c) {
    if (corners[c].z() >= kNearM) include(corners[c]);
    for (const int bit : {1, 2, 4}) {  // the three edges from c to a corner with one more bit
      if ((c & bit) != 0) continue;
      const Vector3d& a = corners[c];
      const Vector3d& b = corners[c | bit];
      if ((a.z() < kNearM) == (b.z() < kNearM)) continue;
      Vector3d crossing = a + (b - a) * ((kNearM - a.z()) / (b.z() - a.z()));
      crossing.z() = kNearM;
      include(crossing);
    }
  }
  if (u_min > u_max) return {};  // wholly behind the clipping plane
  const auto clampTo = [](double value, int limit) {
    return static_cast<int>(std::clamp(value, 0.0, static_cast<double>(limit)));
  };
  PixelRect r;
  r.x0 = clampTo(std::floor(u_min) - 1.0, options_.width);
  r.x1 = clampTo(std::ceil(u_max) + 2.0, options_.width);
  r.y0 = clampTo(std::floor(v_min) - 1.0, options_.height);
  r.y1 = clampTo(std::ceil(v_max) + 2.0, options_.height);
  return r;
}

// Every pixel whose ray can hit a dynamic shape at time_s or a carried one.
MockCamera::PixelRect MockCamera::dynamicRect(const Pose& pose, double time_s) const {
  Vector3d lo, hi;
  PixelRect rect;
  if (scene_.dynamicBounds(time_s, lo, hi)) rect = projectBox(pose, lo, hi);
  if (scene_.carriedBounds(lo, hi)) rect = unite(rect, projectBox(Pose{}, lo, hi));  // camera frame
  return rect;
}

MockCamera::PixelRect MockCamera::unite(const PixelRect& a, const PixelRect& b) const {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)};
}

MockCamera::PixelRect MockCamera::grow(const PixelRect& r, int pixels) const {
  if (r.empty()) return r;
  return {std::max(0, r.x0 - pixels), std::max(0, r.y0 - pixels),
          std::min(options_.width, r.x1 + pixels), std::min(options_.height, r.y1 + pixels)};
}

// Discontinuity bands: a pixel next to (8-neighbourhood) a surface nearer by
// more than the jump threshold is always lost; the pixel two to the left of
// such an occluder (the projector's shadow side) is lost half of the time.
// The 3 x 3 minimum is separable: a horizontal pass into near_row_min_m_
// (fillNearRow), then a vertical one (finishDropoutRow). The horizontal pass
// keeps three rows (row r at r % 3), each filled just before the first output
// row that needs it. In place: work_'s probabilities in rect must be the clean
// ones (rendered or copied since).
void MockCamera::updateDropouts(const PixelRect& rect) {
  if (rect.empty()) return;
  const int h = options_.height;
  int filled = std::max(0, rect.y0 - 1) - 1;  // the last row filled
  for (int y = rect.y0; y < rect.y1; ++y) {
    const int y_below = std::min(h - 1, y + 1);
    while (filled < y_below) fillNearRow(++filled, rect.x0, rect.x1);
    finishDropoutRow(y, rect.x0, rect.x1);
  }
}

float* MockCamera::nearRow(int y) {
  return near_row_min_m_.data() + static_cast<std::size_t>(y % 3) * static_cast<std::size_t>(options_.width);
}

// Row y's nearest depth over each pixel and its left and right neighbours.
void MockCamera::fillNearRow(int y, int x0, int x1) {
  const int w = options_.width;
  const double* depth = work_.depth_m.data() + work_.at(0, y);
  const auto surface = [](double z) { return z > 0.0 ? z : kInf; };  // 0: nothing there
  float* out = nearRow(y);
  for (int x = x0; x < x1; ++x) {
    double nearest = surface(depth[x]);
    if (x > 0) nearest = std::min(nearest, surface(depth[x - 1]));
    if (x + 1 < w) nearest = std::min(nearest, surface(depth[x + 1]));
    out[x] = static_cast<float>(nearest);
  }
}

// Row y's final dropout probabilities; the near rows y - 1 .. y + 1 (clamped
// to the image) are filled.
void MockCamera::finishDropoutRow(int y, int x0, int x1) {
  const int w = options_.width;
  const float* above = nearRow(std::max(0, y - 1));
  const float* here = nearRow(y);
  const float* below = nearRow(std::min(options_.height - 1, y + 1));
  const std::size_t row = work_.at(0, y);
  const double* depth = work_.depth_m.data() + row;
  float* drop_prob = work_.drop_prob.data() + row;
  for (int x = x0; x < x1; ++x) {
    float p = drop_prob[x];
    const double z = depth[x];
    if (z > 0.0 && p < 1.0f) {
      // z - zq > kEdgeJumpM + kEdgeJumpPerM * zq, solved for zq. The pixel
      // itself is never nearer than that.
      const double occluder_below_m = (z - kEdgeJumpM) / (1.0 + kEdgeJumpPerM);
      const float nearest = std::min({above[x], here[x], below[x]});
      if (nearest < occluder_below_m) {
        p = 1.0f;
      } else if (x + kEdgeReachPx < w) {
        const double zq = depth[x + kEdgeReachPx];
        if (zq > 0.0 && zq < occluder_below_m) p = 1.0f - (1.0f - p) * (1.0f - kShadowDropout);
      }
    }
    drop_prob[x] = p;
  }
}

// The sensor model's random part. Pixels go in pairs that share one Box-Muller
// draw (its cosine and sine branches), which halves the transcendental work.
// Per pair: hash a = (u1: 24 bits, u2: 24 bits, dropout of the first: 16 bits),
// hash b = mix64(a) = (dropout of the second: 16 bits, RGB noise: 2 x 24 bits).
void MockCamera::writeFrame(RgbdFrame& slot, uint64_t sequence) const {
  writeRows(slot, sequence, 0, options_.height);
}

// Rows [y0, y1) of the frame from work_, which holds them (a ring of rows:
// one row a call). A pair may straddle two rows (an odd width): each call
// draws it and writes its own pixel.
void MockCamera::writeRows(RgbdFrame& slot, uint64_t sequence, int y0, int y1) const {
  const auto width = static_cast<std::size_t>(options_.width);
  const std::size_t begin = static_cast<std::size_t>(y0) * width;
  const std::size_t end = static_cast<std::size_t>(y1) * width;
  const std::size_t clean_begin = work_.at(0, y0);  // pixel i's clean values at clean_begin + (i - begin)
  uint16_t* depth = slot.depth();
  uint8_t* rgb = slot.rgb();
  if (!options_.noise) {
    for (int y = y0; y < y1; ++y) {
      const std::size_t row = static_cast<std::size_t>(y) * width;
      const std::size_t clean = work_.at(0, y);
      for (std::size_t x = 0; x < width; ++x) {
        const double z = work_.depth_m[clean + x];
        depth[row + x] = inRange(z) ? toDepthUnits(z) : 0;
      }
      std::memcpy(rgb + 3 * row, &work_.rgb[3 * clean], 3 * width);
    }
    return;
  }
  const uint64_t frame_key = hash2(options_.seed, options_.temporal_noise ? sequence : 0);
  for (std::size_t first = begin & ~std::size_t{1}; first < end; first += 2) {
    const uint64_t a = hash2(frame_key, first / 2);
    const uint64_t b = mix64(a);
    const double u1 = static_cast<double>((a >> 40) + 1) * 0x1.0p-24;  // (0, 1]
    const double u2 = static_cast<double>((a >> 16) & 0xFFFFFFu) * 0x1.0p-24;
    const double radius = std::sqrt(-2.0 * std::log(u1));
    const double angle = 2.0 * std::numbers::pi * u2;
    const double gaussian[2] = {radius * std::cos(angle), radius * std::sin(angle)};
    const uint64_t drop_bits[2] = {a & 0xFFFFu, b & 0xFFFFu};
    for (std::size_t k = 0; k < 2; ++k) {
      const std::size_t i = first + k;
      if (i < begin || i >= end) continue;
      const std::size_t c = clean_begin + (i - begin);
      const double z = work_.depth_m[c];
      uint16_t units = 0;
      if (inRange(z)) {
        const float u_drop = static_cast<float>(drop_bits[k]) * 0x1.0p-16f;
        if (u_drop >= work_.drop_prob[c]) units = toDepthUnits(z + work_.sigma_m[c] * gaussian[k]);
      }
      depth[i] = units;
      const uint64_t rgb_bits = b >> (16 + 24 * k);
      for (std::size_t ch = 0; ch < 3; ++ch) {
        rgb[3 * i + ch] = addRgbNoise(work_.rgb[3 * c + ch], rgb_bits >> (8 * ch));
      }
    }
  }
}

void MockCamera::renderAndWriteRows(const Pose& pose, double time_s, RgbdFrame& slot, uint64_t sequence) {
  const int w = options_.width;
  const int h = options_.height;
  sortShapeRects(pose);
  for (int y = 0; y <= h; ++y) {
    if (y < h) {
      const std::size_t hits = castRow(pose, time_s, y, fullRect(), /*static_layer=*/true, /*dynamic_layer=*/false, work_);
      modelRowNoise(y, hits, work_);
      fillNearRow(y, 0, w);
    }
    if (y > 0) {
      finishDropoutRow(y - 1, 0, w);
      writeRows(slot, sequence, y - 1, y);
    }
  }
}

}  // namespace fovea::hal::mock
