// SurfelMap's index map, rendered for a frame (renderIndexMap): the bricks the
// view can see (cullBricks), then every surfel of them splatted over its
// footprint into the z-buffer, with the removals and carvings the pass makes;
// the reference (splatReference) or its fast path (splatFast, the same index
// map bit for bit). Fusion's association and the tracker read the result.
#include <cmath>
#include <cstdint>

#include <Eigen/Geometry>

#include "pipeline/map/surfel_map.h"

namespace fovea::pipeline::map {

namespace {

constexpr int kMaxSplatPixels = 2;  // a surfel covers at most 2 pixels around its centre in the index map

}  // namespace

void SurfelMap::renderIndexMap(const hal::RgbdFrame& frame, FuseStats& stats) {
  index_map_.reset(frame.width(), frame.height());
  cullBricks(frame);
  const Eigen::Matrix3f R_cw_f = frame.T_world_cam.R_world_cam.transpose().cast<float>();
  if (config_.kernels != KernelSet::kRef) {
    splatFast(frame, R_cw_f, stats);
  } else {
    splatReference(frame, R_cw_f, stats);
  }
}

// Each brick's origin in camera coordinates, once (in double: the brick and
// the camera may both be kilometres from the world origin), and whether it is
// visible: its bounding sphere reaches into the view, in the depth range and
// inside each of the frustum's four side planes (widened by the splat's
// reach), so that a map larger than the view costs little more than the view.
void SurfelMap::cullBricks(const hal::RgbdFrame& frame) {
  const int w = frame.width(), h = frame.height();
  const Eigen::Matrix3d R_cw = frame.T_world_cam.R_world_cam.transpose();
  const Eigen::Vector3d& t = frame.T_world_cam.t_world_cam;
  const hal::CameraIntrinsics& k = frame.intrinsics;
  const double half = 0.5 * config_.brick_size_m;
  const double radius = std::sqrt(3.0) * half;
  // Side planes through the camera: x = a z (left, right) and y = b z (top, bottom).
  const double a_left = (-0.5 - kMaxSplatPixels - k.cx) / k.fx, a_right = (w - 0.5 + kMaxSplatPixels - k.cx) / k.fx;
  const double b_top = (-0.5 - kMaxSplatPixels - k.cy) / k.fy, b_bottom = (h - 0.5 + kMaxSplatPixels - k.cy) / k.fy;
  const double n_left = std::sqrt(1.0 + a_left * a_left), n_right = std::sqrt(1.0 + a_right * a_right);
  const double n_top = std::sqrt(1.0 + b_top * b_top), n_bottom = std::sqrt(1.0 + b_bottom * b_bottom);
  for (std::size_t b = 0; b < brick_count_; ++b) {
    const Eigen::Vector3d o = R_cw * (brickOrigin(static_cast<uint16_t>(b)) - t);
    brick_cam_[b] = o.cast<float>();
    const Eigen::Vector3d c = o + R_cw * Eigen::Vector3d::Constant(half);  // the brick's centre
    brick_visible_[b] = c.z() > -radius && c.z() < config_.depth.max_m + radius &&
                                (c.x() - a_left * c.z()) / n_left >= -radius &&
                                (a_right * c.z() - c.x()) / n_right >= -radius &&
                                (c.y() - b_top * c.z()) / n_top >= -radius &&
                                (b_bottom * c.z() - c.y()) / n_bottom >= -radius
                            ? 1
                            : 0;
  }
}

// renderIndexMap()'s reference: every surfel in slot order, its footprint's
// pixels in row order.
void SurfelMap::splatReference(const hal::RgbdFrame& frame, const Eigen::Matrix3f& R_cw_f, FuseStats& stats) {
  const int w = frame.width(), h = frame.height();
  const hal::CameraIntrinsics& k = frame.intrinsics;
  const auto fx = static_cast<float>(k.fx), fy = static_cast<float>(k.fy);
  const auto cx = static_cast<float>(k.cx), cy = static_cast<float>(k.cy);
  const float inv_fx = 1.0f / fx, inv_fy = 1.0f / fy;
  const float f = 0.5f * (fx + fy);
  const auto min_z = static_cast<float>(std::max(config_.depth.min_m, 1e-3));
  const auto sigmas = static_cast<float>(config_.depth_tolerance_sigmas);
  const auto carve = static_cast<float>(config_.carve_weight);
  for (std::size_t slot = 0; slot < high_water_; ++slot) {
    if (slot % kYieldEvery == 0) yieldGate();
    const Surfel& s = surfels_[slot];
    if (!(s.flags & kSurfelLive)) continue;
    if (!(s.flags & kSurfelStable) && frame_ - s.first_seen > config_.unstable_max_frames) {
      removeSurfel(static_cast<uint32_t>(slot));
      ++stats.removed_unstable;
      continue;
    }
    if (!brick_visible_[s.brick]) continue;
    const Eigen::Vector3f p = brick_cam_[s.brick] + R_cw_f * Eigen::Vector3f(s.x, s.y, s.z);
    if (!(p.z() >= min_z)) continue;
    const float pu = fx * p.x() / p.z() + cx, pv = fy * p.y() / p.z() + cy;
    if (!(pu > -0.5f - kMaxSplatPixels && pu < static_cast<float>(w) - 0.5f + kMaxSplatPixels &&
          pv > -0.5f - kMaxSplatPixels && pv < static_cast<float>(h) - 0.5f + kMaxSplatPixels)) {
      continue;
    }
    const int iu = static_cast<int>(std::lround(pu)), iv = static_cast<int>(std::lround(pv));
    // Free space: the camera measures a surface clearly behind the surfel at
    // its centre's pixel, so it sees through it. Every such surfel is carved,
    // not only the nearest along the ray: an object that moved towards the
    // camera and away again leaves layers behind each other, and carving only
    // the front one took a frame or more per layer (on the mock balloon scene,
    // 4 % of the surfels in view were such ghosts).
    if (iu >= 0 && iv >= 0 && iu < w && iv < h) {
      const std::size_t centre = static_cast<std::size_t>(iv) * w + iu;
      const float measured = vertex_z_[centre];
      if (measured > 0.0f && p.z() < measured - sigmas * depthSigma(measured)) {
        const float left = 0.5f * decodeConfidence(s.confidence) - carve * weight_[centre];
        if (carveTo(static_cast<uint32_t>(slot), left, stats)) removeSurfel(static_cast<uint32_t>(slot));
        continue;
      }
    }
    // The footprint in pixels, and the surfel's plane: the depth it has at a
    // neighbouring pixel is where that pixel's ray meets the plane, so a slanted
    // surface is not seen in front of itself.
    const float footprint = f * surfelRadius(s) / p.z();
    const int reach = std::min(kMaxSplatPixels, static_cast<int>(footprint));
    const Eigen::Vector3f n = R_cw_f * surfelNormal(s);
    const float plane = n.dot(p);
    // Surfels within the sensor's noise at this depth are one surface (the
    // tolerance at the centre's depth: the splat spans a few millimetres of it).
    const float same = sigmas * depthSigma(p.z());
    for (int dv = -reach; dv <= reach; ++dv) {
      const int y = iv + dv;
      if (y < 0 || y >= h) continue;
      const float ry = (static_cast<float>(y) - cy) * inv_fy;
      const float along_y = n.y() * ry + n.z();
      for (int du = -reach; du <= reach; ++du) {
        const int x = iu + du;
        if (x < 0 || x >= w || du * du + dv * dv > reach * reach) continue;
        const float rx = (static_cast<float>(x) - cx) * inv_fx;
        const float along = n.x() * rx + along_y;
        // Near grazing the plane's depth is ill-conditioned: the centre depth then
        // (|along| > 0.2 |ray|, squared: no root).
        float z = along * along > 0.04f * (rx * rx + ry * ry + 1.0f) ? plane / along : p.z();
        if (!(z >= min_z)) z = p.z();
        const std::size_t i = static_cast<std::size_t>(y) * w + x;
        // Nearer wins; within the sensor's noise of each other (one surface),
        // the surfel whose centre is nearer the pixel.
        index_map_.offer(i, z, same, static_cast<uint8_t>(du * du + dv * dv), static_cast<uint32_t>(slot));
      }
    }
  }
}

namespace {

// A footprint's pixels (du, dv) with du^2 + dv^2 <= reach^2, in the reference's
// order (rows, then columns), by reach 0, 1, 2: the first 1, 5 and 13 entries of
// the lists below.
struct SplatOffset {
  int8_t du, dv;
  uint8_t reach_sq;
};
constexpr SplatOffset kSplat0[] = {{0, 0, 0}};
constexpr SplatOffset kSplat1[] = {{0, -1, 1}, {-1, 0, 1}, {0, 0, 0}, {1, 0, 1}, {0, 1, 1}};
constexpr SplatOffset kSplat2[] = {{0, -2, 4}, {-1, -1, 2}, {0, -1, 1}, {1, -1, 2}, {-2, 0, 4},
                                   {-1, 0, 1}, {0, 0, 0},   {1, 0, 1},  {2, 0, 4},  {-1, 1, 2},
                                   {0, 1, 1},  {1, 1, 2},   {0, 2, 4}};
static_assert(kMaxSplatPixels == 2, "the footprints above go to 2 pixels");

}  // namespace

// What splatFast() needs of the frame for every surfel and footprint pixel.
struct SurfelMap::SplatView {
  int w = 0, h = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0, f = 0;
  float min_z = 0, sigmas = 0, carve = 0;
  float u_lo = 0, u_hi = 0, v_lo = 0, v_hi = 0;  // the centres that may reach the image
  const float* ray_u = nullptr;  // (u - cx) / fx by column
  const float* ray_v = nullptr;  // (v - cy) / fy by row
  Eigen::Matrix3f R_cw_f;
};

// A batch of slots' fates and projections: splatFast()'s first pass, read by its second.
struct SurfelMap::SplatBatch {
  enum : uint8_t { kSkip, kRemoveUnstable, kCarve, kSplat };
  static constexpr std::size_t kSize = 128;
  uint8_t action[kSize];
  int32_t centre_u[kSize], centre_v[kSize];
  uint8_t reach_of[kSize];
  // plane_of: the plane's offset for kSplat, the confidence kept for kCarve.
  float depth_of[kSize], plane_of[kSize], same_of[kSize], nx_of[kSize], ny_of[kSize], nz_of[kSize];
};

// The fast path of renderIndexMap()'s splatting: the reference's arithmetic and
// order of side effects (surfels in slot order, the same removals, carvings and
// z-buffer updates), so the same index map bit for bit
// (test_map_equivalence's MapsFusedWithEitherKernelSetAreTheSame), without its
// per-surfel and per-pixel overheads: the rays through the columns and rows from
// tables made once a frame, lround() inline, the footprint's pixels from a list
// instead of a (2 reach + 1)^2 loop with a circle test, and no bounds tests for a
// footprint inside the image. Two passes over a batch of slots: the first
// decides each surfel's fate and computes its projection from the surfel alone
// (nothing another surfel's fate changes: a removal or carving touches only
// that surfel), surfel after independent surfel, so the divisions and square
// roots of several overlap; the second applies the removals, carvings and
// splats in slot order, as the reference does.
void SurfelMap::splatFast(const hal::RgbdFrame& frame, const Eigen::Matrix3f& R_cw_f, FuseStats& stats) {
  const SplatView view = splatView(frame, R_cw_f);
  SplatBatch batch;
  for (std::size_t b0 = 0; b0 < high_water_; b0 += SplatBatch::kSize) {
    const std::size_t count = std::min(SplatBatch::kSize, high_water_ - b0);
    planSplats(view, b0, count, batch);
    applySplats(view, b0, count, batch, stats);
    yieldGate();
  }
}

SurfelMap::SplatView SurfelMap::splatView(const hal::RgbdFrame& frame, const Eigen::Matrix3f& R_cw_f) {
  SplatView v;
  v.w = frame.width();
  v.h = frame.height();
  const hal::CameraIntrinsics& k = frame.intrinsics;
  v.fx = static_cast<float>(k.fx), v.fy = static_cast<float>(k.fy);
  v.cx = static_cast<float>(k.cx), v.cy = static_cast<float>(k.cy);
  const float inv_fx = 1.0f / v.fx, inv_fy = 1.0f / v.fy;
  v.f = 0.5f * (v.fx + v.fy);
  v.min_z = static_cast<float>(std::max(config_.depth.min_m, 1e-3));
  v.sigmas = static_cast<float>(config_.depth_tolerance_sigmas);
  v.carve = static_cast<float>(config_.carve_weight);
  for (int x = 0; x < v.w; ++x) ray_u_[static_cast<std::size_t>(x)] = (static_cast<float>(x) - v.cx) * inv_fx;
  for (int y = 0; y < v.h; ++y) ray_v_[static_cast<std::size_t>(y)] = (static_cast<float>(y) - v.cy) * inv_fy;
  v.ray_u = ray_u_.data();
  v.ray_v = ray_v_.data();
  v.u_lo = -0.5f - kMaxSplatPixels, v.u_hi = static_cast<float>(v.w) - 0.5f + kMaxSplatPixels;
  v.v_lo = -0.5f - kMaxSplatPixels, v.v_hi = static_cast<float>(v.h) - 0.5f + kMaxSplatPixels;
  v.R_cw_f = R_cw_f;
  return v;
}

// splatFast()'s first pass: the fate of slots [b0, b0 + count) and, for those
// that splat, their projections.
void SurfelMap::planSplats(const SplatView& view, std::size_t b0, std::size_t count, SplatBatch& batch) const {
  const float* const measured_z = vertex_z_.data();
  const uint8_t* const visible = brick_visible_.data();
  const uint32_t unstable_max = config_.unstable_max_frames;
  for (std::size_t j = 0; j < count; ++j) {
    const Surfel& s = surfels_[b0 + j];
    batch.action[j] = SplatBatch::kSkip;
    if (!(s.flags & kSurfelLive)) continue;
    if (!(s.flags & kSurfelStable) && frame_ - s.first_seen > unstable_max) {
      batch.action[j] = SplatBatch::kRemoveUnstable;
      continue;
    }
    if (!visible[s.brick]) continue;
    const Eigen::Vector3f p = brick_cam_[s.brick] + view.R_cw_f * Eigen::Vector3f(s.x, s.y, s.z);
    if (!(p.z() >= view.min_z)) continue;
    const float pu = view.fx * p.x() / p.z() + view.cx, pv = view.fy * p.y() / p.z() + view.cy;
    if (!(pu > view.u_lo && pu < view.u_hi && pv > view.v_lo && pv < view.v_hi)) continue;
    const int iu = roundHalfAwayFromZero(pu), iv = roundHalfAwayFromZero(pv);
    if (iu >= 0 && iv >= 0 && iu < view.w && iv < view.h) {
      const std::size_t centre = static_cast<std::size_t>(iv) * view.w + iu;
      const float measured = measured_z[centre];
      if (measured > 0.0f && p.z() < measured - view.sigmas * depthSigma(measured)) {
        batch.action[j] = SplatBatch::kCarve;
        batch.plane_of[j] = 0.5f * decodeConfidence(s.confidence) - view.carve * weight_[centre];  // what it keeps
        continue;
      }
    }
    batch.action[j] = SplatBatch::kSplat;
    batch.centre_u[j] = iu;
    batch.centre_v[j] = iv;
    const float footprint = view.f * surfelRadius(s) / p.z();
    batch.reach_of[j] = static_cast<uint8_t>(std::clamp(static_cast<int>(footprint), 0, kMaxSplatPixels));
    const Eigen::Vector3f n = view.R_cw_f * surfelNormal(s);
    batch.nx_of[j] = n.x();
    batch.ny_of[j] = n.y();
    batch.nz_of[j] = n.z();
    batch.plane_of[j] = n.dot(p);
    batch.depth_of[j] = p.z();
    batch.same_of[j] = view.sigmas * depthSigma(p.z());
  }
}

// splatFast()'s second pass: the batch's removals, carvings and splats in slot order.
void SurfelMap::applySplats(const SplatView& view, std::size_t b0, std::size_t count, const SplatBatch& batch,
                            FuseStats& stats) {
  for (std::size_t j = 0; j < count; ++j) {
    const auto slot = static_cast<uint32_t>(b0 + j);
    switch (batch.action[j]) {
      case SplatBatch::kSkip: continue;
      case SplatBatch::kRemoveUnstable:
        removeSurfel(slot);
        ++stats.removed_unstable;
        continue;
      case SplatBatch::kCarve:
        if (carveTo(slot, batch.plane_of[j], stats)) removeSurfel(slot);
        continue;
      default: splatFootprint(view, batch, j, slot);
    }
  }
}

// One surfel's footprint into the z-buffer (the reference's test, pixel by pixel).
void SurfelMap::splatFootprint(const SplatView& view, const SplatBatch& batch, std::size_t j, uint32_t slot) {
  const int w = view.w, h = view.h;
  const int iu = batch.centre_u[j], iv = batch.centre_v[j];
  const int reach = batch.reach_of[j];
  const float nx = batch.nx_of[j], ny = batch.ny_of[j], nz = batch.nz_of[j];
  const float plane = batch.plane_of[j], pz = batch.depth_of[j], same = batch.same_of[j];
  const SplatOffset* offsets = reach == 0 ? kSplat0 : reach == 1 ? kSplat1 : kSplat2;
  const int count = reach == 0 ? 1 : reach == 1 ? 5 : 13;
  const bool inside = iu >= reach && iv >= reach && iu + reach < w && iv + reach < h;
  for (int o = 0; o < count; ++o) {
    const int x = iu + offsets[o].du, y = iv + offsets[o].dv;
    if (!inside && (x < 0 || x >= w || y < 0 || y >= h)) continue;
    // Written as selects (as IndexMap::offer): GCC 12 makes a branch of the
    // steep test, which predicts well.
    const float rx = view.ray_u[x], ry = view.ray_v[y];
    const float along = nx * rx + (ny * ry + nz);
    const bool steep = along * along > 0.04f * (rx * rx + ry * ry + 1.0f);
    const float on_plane = plane / (steep ? along : 1.0f);
    float z = steep ? on_plane : pz;
    z = z >= view.min_z ? z : pz;
    index_map_.offer(static_cast<std::size_t>(y) * w + x, z, same, offsets[o].reach_sq, slot);
  }
}

}  // namespace fovea::pipeline::map
