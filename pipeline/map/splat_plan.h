// The index map's first pass, planned a batch of slots at a time (issue 41,
// part 1): each surfel's fate this frame (skipped, removed as unstable, carved
// as seen through, or splatted) and, when it splats, the centre it offers
// (IndexMap::Centre). A surfel's plan reads that surfel, the frame's depth and
// weight at its centre's pixel and its brick's culling, nothing another plan
// changes, so a batch is planned lane by lane; SurfelMap then applies the plans
// in slot order (removals, carvings, offers).
//
// planSplatsRef() is the specification, a surfel at a time; planSplatsSimd()
// its Highway kernel (splat_plan_simd.cpp), which reads the pool as structure
// of arrays through gathers and gives the same plans bit for bit: the
// reference's additions, multiplications and divisions in its order, never a
// fused multiply-add.
#pragma once

#include <cstddef>
#include <cstdint>

#include "pipeline/map/surfel.h"

namespace fovea::pipeline::map {

// What a plan needs of the frame and of the map's bricks.
struct SplatFrame {
  float r[9] = {};                     // world to camera rotation, row-major
  const float* brick_cam = nullptr;    // per brick: its origin in camera coordinates (x, y, z)
  const uint32_t* brick_visible = nullptr;  // per brick: 1 when its bounding sphere reaches the view
  const float* measured_z = nullptr;   // per pixel, row-major: the frame's depth (0: none)
  const float* weight = nullptr;       // per pixel: that measurement's weight
  int w = 0, h = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0, f = 0, inv_fx = 0, inv_fy = 0;
  float min_z = 0;   // nearer than this a surfel is not splatted
  float sigmas = 0;  // the depth tolerance in the sensor's sigmas
  float carve = 0;   // the confidence a see-through costs per unit of the pixel's weight
  float u_lo = 0, u_hi = 0, v_lo = 0, v_hi = 0;  // the centres whose footprint may reach the image
  uint32_t frame = 0;         // the map's frame number
  uint32_t unstable_max = 0;  // frames an unstable surfel may live
};

// A batch's plans, structure of arrays. Lanes whose action is not kSplat (or
// kCarve, for `kept`) hold no meaning in the other arrays.
struct SplatPlan {
  enum Action : uint32_t { kSkip, kRemoveUnstable, kCarve, kSplat };
  static constexpr std::size_t kSize = 128;  // a multiple of every Highway target's lanes
  uint32_t action[kSize];
  int32_t centre_u[kSize], centre_v[kSize];  // the centre's pixel (up to kMaxReach outside the frame)
  uint32_t reach[kSize], rank[kSize];        // IndexMap::Centre's
  float depth[kSize], same[kSize], inv_depth[kSize], grad_u[kSize], grad_v[kSize];
  float kept[kSize];  // kCarve: the confidence the surfel keeps
};

// Plans surfels[0, count), count at most SplatPlan::kSize, into plan[0, count).
void planSplatsRef(const SplatFrame& frame, const Surfel* surfels, std::size_t count, SplatPlan& plan);
void planSplatsSimd(const SplatFrame& frame, const Surfel* surfels, std::size_t count, SplatPlan& plan);

}  // namespace fovea::pipeline::map
