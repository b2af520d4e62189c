// SurfelMap's index map, rendered for a frame (renderIndexMap): the bricks the
// view can see (cullBricks), then every surfel of them offered to the cell of
// its centre's pixel, with the removals and carvings the pass makes, and the
// footprints filled by the index map's gather (index_map.h); the plans and the
// gather by the reference or by their Highway kernels (splat_plan.h,
// index_map.h: the same index map bit for bit). Fusion's association and the
// tracker read the result.
#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Geometry>

#include "pipeline/map/surfel_map.h"

namespace fovea::pipeline::map {

void SurfelMap::renderIndexMap(const hal::RgbdFrame& frame, FuseStats& stats) {
  index_map_.reset(frame.width(), frame.height());
  cullBricks(frame);
  splatSurfels(frame, stats);
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

// Every surfel to its centre's cell, a batch of slots at a time: the batch
// planned (splat_plan.h: the reference or its Highway kernel, the same plans),
// then its removals, carvings and offers applied in slot order; then the
// gather fills the footprints, in bands of rows between safe points.
void SurfelMap::splatSurfels(const hal::RgbdFrame& frame, FuseStats& stats) {
  const SplatFrame view = splatFrame(frame);
  SplatPlan plan;
  for (std::size_t b0 = 0; b0 < high_water_; b0 += SplatPlan::kSize) {
    const std::size_t count = std::min(SplatPlan::kSize, high_water_ - b0);
    if (config_.kernels == KernelSet::kRef) {
      planSplatsRef(view, surfels_.data() + b0, count, plan);
    } else {
      planSplatsSimd(view, surfels_.data() + b0, count, plan);
    }
    applySplats(b0, count, plan, stats);
    yieldGate();
  }
  constexpr int kBandRows = 16;
  for (int y0 = 0; y0 < view.h; y0 += kBandRows) {
    index_map_.gather(config_.kernels, view.sigmas, y0, std::min(view.h, y0 + kBandRows));
    yieldGate();
  }
}

// The plan's view of the frame and of the bricks' culling (brick_cam_ as three floats a brick).
SplatFrame SurfelMap::splatFrame(const hal::RgbdFrame& frame) const {
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float));
  SplatFrame v;
  const Eigen::Matrix3d R_cw = frame.T_world_cam.R_world_cam.transpose();
  for (int i = 0; i < 9; ++i) v.r[i] = static_cast<float>(R_cw(i / 3, i % 3));
  v.brick_cam = brick_cam_.data()->data();
  v.brick_visible = brick_visible_.data();
  v.measured_z = vertex_z_.data();
  v.weight = weight_.data();
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
  v.frame = frame_;
  v.unstable_max = config_.unstable_max_frames;
  return v;
}

// A batch's plans applied in slot order: its removals, carvings and offers.
void SurfelMap::applySplats(std::size_t b0, std::size_t count, const SplatPlan& plan, FuseStats& stats) {
  for (std::size_t j = 0; j < count; ++j) {
    const auto slot = static_cast<uint32_t>(b0 + j);
    switch (plan.action[j]) {
      case SplatPlan::kSkip: continue;
      case SplatPlan::kRemoveUnstable:
        removeSurfel(slot);
        ++stats.removed_unstable;
        continue;
      case SplatPlan::kCarve:
        if (carveTo(slot, plan.kept[j], stats)) removeSurfel(slot);
        continue;
      default: {
        IndexMap::Centre c;
        c.depth = plan.depth[j];
        c.same = plan.same[j];
        c.rank = static_cast<uint8_t>(plan.rank[j]);
        c.reach = static_cast<uint8_t>(plan.reach[j]);
        c.inv_depth = plan.inv_depth[j];
        c.grad_u = plan.grad_u[j];
        c.grad_v = plan.grad_v[j];
        index_map_.offerCentre(plan.centre_u[j], plan.centre_v[j], c, slot);
      }
    }
  }
}

}  // namespace fovea::pipeline::map
