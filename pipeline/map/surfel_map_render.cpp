// SurfelMap's index map, rendered for a frame (renderIndexMap): the bricks the
// view can see (cullBricks), then every surfel of them offered to the cell of
// its centre's pixel, with the removals and carvings the pass makes, and the
// footprints filled by the index map's gather (index_map.h); the reference
// (splatReference) or its fast path (splatFast and the gather's Highway
// kernel, the same index map bit for bit). Fusion's association and the
// tracker read the result.
#include <cmath>
#include <cstdint>

#include <Eigen/Geometry>

#include "pipeline/map/surfel_map.h"

namespace fovea::pipeline::map {

// What the index map's first pass needs of the frame for every surfel.
struct SurfelMap::SplatView {
  int w = 0, h = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0, f = 0, inv_fx = 0, inv_fy = 0;
  float min_z = 0, sigmas = 0, carve = 0;
  float u_lo = 0, u_hi = 0, v_lo = 0, v_hi = 0;  // the centres that may reach the image
  Eigen::Matrix3f R_cw_f;
};

// A batch of slots' fates and centres: splatFast()'s first pass, read by its second.
struct SurfelMap::SplatBatch {
  enum : uint8_t { kSkip, kRemoveUnstable, kCarve, kSplat };
  static constexpr std::size_t kSize = 128;
  uint8_t action[kSize];
  int32_t centre_u[kSize], centre_v[kSize];
  IndexMap::Centre centre[kSize];  // for kSplat
  float kept[kSize];               // for kCarve: the confidence it keeps
};

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
  const double a_left = (-0.5 - kMaxReach - k.cx) / k.fx, a_right = (w - 0.5 + kMaxReach - k.cx) / k.fx;
  const double b_top = (-0.5 - kMaxReach - k.cy) / k.fy, b_bottom = (h - 0.5 + kMaxReach - k.cy) / k.fy;
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

// renderIndexMap()'s reference: every surfel in slot order to its centre's
// cell, then the gather's reference.
void SurfelMap::splatReference(const hal::RgbdFrame& frame, const Eigen::Matrix3f& R_cw_f, FuseStats& stats) {
  const SplatView view = splatView(frame, R_cw_f);
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
    if (!(p.z() >= view.min_z)) continue;
    const float pu = view.fx * p.x() / p.z() + view.cx, pv = view.fy * p.y() / p.z() + view.cy;
    if (!(pu > view.u_lo && pu < view.u_hi && pv > view.v_lo && pv < view.v_hi)) continue;
    const int iu = static_cast<int>(std::lround(pu)), iv = static_cast<int>(std::lround(pv));
    // Free space: the camera measures a surface clearly behind the surfel at
    // its centre's pixel, so it sees through it. Every such surfel is carved,
    // not only the nearest along the ray: an object that moved towards the
    // camera and away again leaves layers behind each other, and carving only
    // the front one took a frame or more per layer (on the mock balloon scene,
    // 4 % of the surfels in view were such ghosts).
    if (iu >= 0 && iv >= 0 && iu < view.w && iv < view.h) {
      const std::size_t centre = static_cast<std::size_t>(iv) * view.w + iu;
      const float measured = vertex_z_[centre];
      if (measured > 0.0f && p.z() < measured - view.sigmas * depthSigma(measured)) {
        const float left = 0.5f * decodeConfidence(s.confidence) - view.carve * weight_[centre];
        if (carveTo(static_cast<uint32_t>(slot), left, stats)) removeSurfel(static_cast<uint32_t>(slot));
        continue;
      }
    }
    index_map_.offerCentre(iu, iv, centreOf(view, s, p, iu, iv), static_cast<uint32_t>(slot));
  }
  gatherIndexMap(view, KernelSet::kRef);
}

// A splatting surfel's centre for the index map (both paths): its footprint's
// reach from its radius, and its plane (through p, with the camera-frame normal
// direction n, not normalised: the depth on a plane along a ray is a ratio) as
// inverse depth at the centre pixel's ray and its change per pixel, so that a
// slanted surface is not seen in front of itself at the footprint's edge. Near
// grazing (the ray along the plane within about 11 degrees: (n . ray)^2 <=
// 0.04 |ray|^2 |n|^2, no root) the plane's depth is ill-conditioned, and a
// plane nearer than the depth range's start is a surfel seen edge on: both take
// the centre's own depth at every pixel of the footprint.
IndexMap::Centre SurfelMap::centreOf(const SplatView& view, const Surfel& s, const Eigen::Vector3f& p, int iu,
                                     int iv) const {
  IndexMap::Centre c;
  const float footprint = view.f * surfelRadius(s) / p.z();
  c.reach = static_cast<uint8_t>(std::clamp(static_cast<int>(footprint), 0, kMaxReach));
  const Eigen::Vector3f n = view.R_cw_f * surfelDirection(s);
  const float inv_plane = 1.0f / n.dot(p);
  const float rx = (static_cast<float>(iu) - view.cx) * view.inv_fx, ry = (static_cast<float>(iv) - view.cy) * view.inv_fy;
  const float along = n.x() * rx + (n.y() * ry + n.z());
  const bool steep = along * along > 0.04f * (rx * rx + ry * ry + 1.0f) * n.squaredNorm();
  const float on_plane = along * inv_plane;
  if (steep && on_plane * view.min_z <= 1.0f && on_plane > 0.0f) {
    c.inv_depth = on_plane;
    c.depth = 1.0f / on_plane;
    c.grad_u = n.x() * view.inv_fx * inv_plane;
    c.grad_v = n.y() * view.inv_fy * inv_plane;
  } else {
    c.inv_depth = 1.0f / p.z();
    c.depth = p.z();
  }
  c.same = view.sigmas * depthSigma(c.depth);
  // Of one surface's centres in a cell the most confident: the measurements
  // keep averaging into the surfel that holds the most (docs/map.md, "The index
  // map", has the centre nearest the pixel's measured against it). 8.8 fixed
  // point in steps of an eighth; the cap is 20 (SurfelMapConfig::confidence_cap).
  c.rank = static_cast<uint8_t>(255 - std::min<int>(s.confidence >> 5, 255));
  return c;
}

// The gather over the frame, in bands of rows between safe points.
void SurfelMap::gatherIndexMap(const SplatView& view, KernelSet kernels) {
  constexpr int kBandRows = 16;
  for (int y0 = 0; y0 < view.h; y0 += kBandRows) {
    index_map_.gather(kernels, view.sigmas, y0, std::min(view.h, y0 + kBandRows));
    yieldGate();
  }
}

// The fast path of renderIndexMap(): the reference's arithmetic and order of
// side effects (surfels in slot order, the same removals, carvings and centre
// offers), so the same index map bit for bit (test_map_equivalence's
// MapsFusedWithEitherKernelSetAreTheSame), then the gather's Highway kernel.
// Two passes over a batch of slots: the first decides each surfel's fate and
// computes its centre from the surfel alone (nothing another surfel's fate
// changes: a removal or carving touches only that surfel), surfel after
// independent surfel, so the divisions and square roots of several overlap;
// the second applies the removals, carvings and offers in slot order, as the
// reference does.
void SurfelMap::splatFast(const hal::RgbdFrame& frame, const Eigen::Matrix3f& R_cw_f, FuseStats& stats) {
  const SplatView view = splatView(frame, R_cw_f);
  SplatBatch batch;
  for (std::size_t b0 = 0; b0 < high_water_; b0 += SplatBatch::kSize) {
    const std::size_t count = std::min(SplatBatch::kSize, high_water_ - b0);
    planSplats(view, b0, count, batch);
    applySplats(b0, count, batch, stats);
    yieldGate();
  }
  gatherIndexMap(view, KernelSet::kSimd);
}

SurfelMap::SplatView SurfelMap::splatView(const hal::RgbdFrame& frame, const Eigen::Matrix3f& R_cw_f) const {
  SplatView v;
  v.w = frame.width();
  v.h = frame.height();
  const hal::CameraIntrinsics& k = frame.intrinsics;
  v.fx = static_cast<float>(k.fx), v.fy = static_cast<float>(k.fy);
  v.cx = static_cast<float>(k.cx), v.cy = static_cast<float>(k.cy);
  v.inv_fx = 1.0f / v.fx, v.inv_fy = 1.0f / v.fy;
  v.f = 0.5f * (v.fx + v.fy);
  v.min_z = static_cast<float>(std::max(config_.depth.min_m, 1e-3));
  v.sigmas = static_cast<float>(config_.depth_tolerance_sigmas);
  v.carve = static_cast<float>(config_.carve_weight);
  v.u_lo = -0.5f - kMaxReach, v.u_hi = static_cast<float>(v.w) - 0.5f + kMaxReach;
  v.v_lo = -0.5f - kMaxReach, v.v_hi = static_cast<float>(v.h) - 0.5f + kMaxReach;
  v.R_cw_f = R_cw_f;
  return v;
}

// splatFast()'s first pass: the fate of slots [b0, b0 + count) and, for those
// that splat, their centres.
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
        batch.kept[j] = 0.5f * decodeConfidence(s.confidence) - view.carve * weight_[centre];
        continue;
      }
    }
    batch.action[j] = SplatBatch::kSplat;
    batch.centre_u[j] = iu;
    batch.centre_v[j] = iv;
    batch.centre[j] = centreOf(view, s, p, iu, iv);
  }
}

// splatFast()'s second pass: the batch's removals, carvings and offers in slot order.
void SurfelMap::applySplats(std::size_t b0, std::size_t count, const SplatBatch& batch, FuseStats& stats) {
  for (std::size_t j = 0; j < count; ++j) {
    const auto slot = static_cast<uint32_t>(b0 + j);
    switch (batch.action[j]) {
      case SplatBatch::kSkip: continue;
      case SplatBatch::kRemoveUnstable:
        removeSurfel(slot);
        ++stats.removed_unstable;
        continue;
      case SplatBatch::kCarve:
        if (carveTo(slot, batch.kept[j], stats)) removeSurfel(slot);
        continue;
      default: index_map_.offerCentre(batch.centre_u[j], batch.centre_v[j], batch.centre[j], slot);
    }
  }
}

}  // namespace fovea::pipeline::map
