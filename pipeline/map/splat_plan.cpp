// planSplatsRef (splat_plan.h): the index map's first pass, a surfel at a time.
// Every product and sum is written out in the order the Highway kernel
// repeats: a 3-vector's dot product (and a rotation's rows) as
// a0 b0 + (a1 b1 + a2 b2), Eigen's order for the fixed-size products this
// pass used before, so that the maps are those it made, bit for bit.
#include <algorithm>

#include "core/depth_noise.h"
#include "pipeline/map/float3.h"
#include "pipeline/map/index_map.h"
#include "pipeline/map/map_kernels.h"
#include "pipeline/map/splat_plan.h"

namespace fovea::pipeline::map {

namespace {

// A splatting surfel's centre at pixel (iu, iv): its footprint's reach from its
// radius, and its plane (through p, with the camera-frame normal direction n,
// not normalised: the depth on a plane along a ray is a ratio) as inverse depth
// at the pixel's ray and its change per pixel, so that a slanted surface is not
// seen in front of itself at the footprint's edge. Near grazing (the ray along
// the plane within about 11 degrees: (n . ray)^2 <= 0.04 |ray|^2 |n|^2, no
// root) the plane's depth is ill-conditioned, and a plane nearer than the
// depth range's start is a surfel seen edge on: both take the centre's own
// depth at every pixel of the footprint.
void planCentre(const SplatFrame& f, const Surfel& s, Float3 p, int iu, int iv, std::size_t j, SplatPlan& plan) {
  const float footprint = f.f * surfelRadius(s) / p.z;
  plan.reach[j] = static_cast<uint32_t>(std::clamp(static_cast<int>(footprint), 0, kMaxReach));
  const Eigen::Vector3f d = surfelDirection(s);
  const Float3 n = rotate(f.r, {d.x(), d.y(), d.z()});
  const float inv_plane = 1.0f / dot(n, p);
  const float rx = (static_cast<float>(iu) - f.cx) * f.inv_fx, ry = (static_cast<float>(iv) - f.cy) * f.inv_fy;
  const float along = n.x * rx + (n.y * ry + n.z);
  const bool steep = along * along > 0.04f * (rx * rx + ry * ry + 1.0f) * dot(n, n);
  const float on_plane = along * inv_plane;
  if (steep && on_plane * f.min_z <= 1.0f && on_plane > 0.0f) {
    plan.inv_depth[j] = on_plane;
    plan.depth[j] = 1.0f / on_plane;
    plan.grad_u[j] = n.x * f.inv_fx * inv_plane;
    plan.grad_v[j] = n.y * f.inv_fy * inv_plane;
  } else {
    plan.inv_depth[j] = 1.0f / p.z;
    plan.depth[j] = p.z;
    plan.grad_u[j] = 0.0f;
    plan.grad_v[j] = 0.0f;
  }
  plan.same[j] = f.sigmas * depthSigma(plan.depth[j]);
  // Of one surface's centres in a cell the most confident: the measurements
  // keep averaging into the surfel that holds the most (docs/map.md, "The index
  // map", has the centre nearest the pixel's measured against it). 8.8 fixed
  // point in steps of an eighth; the cap is 20 (SurfelMapConfig::confidence_cap).
  plan.rank[j] = static_cast<uint32_t>(255 - std::min<int>(s.confidence >> 5, 255));
}

SplatPlan::Action planSurfel(const SplatFrame& f, const Surfel& s, std::size_t j, SplatPlan& plan) {
  if (!(s.flags & kSurfelLive)) return SplatPlan::kSkip;
  if (!(s.flags & kSurfelStable) && f.frame - s.first_seen > f.unstable_max) return SplatPlan::kRemoveUnstable;
  if (!f.brick_visible[s.brick]) return SplatPlan::kSkip;
  const float* o = f.brick_cam + 3 * static_cast<std::size_t>(s.brick);
  const Float3 q = rotate(f.r, {s.x, s.y, s.z});
  const Float3 p{o[0] + q.x, o[1] + q.y, o[2] + q.z};
  if (!(p.z >= f.min_z)) return SplatPlan::kSkip;
  const float pu = f.fx * p.x / p.z + f.cx, pv = f.fy * p.y / p.z + f.cy;
  if (!(pu > f.u_lo && pu < f.u_hi && pv > f.v_lo && pv < f.v_hi)) return SplatPlan::kSkip;
  const int iu = roundHalfAwayFromZero(pu), iv = roundHalfAwayFromZero(pv);
  // Free space: the camera measures a surface clearly behind the surfel at
  // its centre's pixel, so it sees through it. Every such surfel is carved,
  // not only the nearest along the ray: an object that moved towards the
  // camera and away again leaves layers behind each other, and carving only
  // the front one took a frame or more per layer (on the mock balloon scene,
  // 4 % of the surfels in view were such ghosts).
  if (iu >= 0 && iv >= 0 && iu < f.w && iv < f.h) {
    const std::size_t centre = static_cast<std::size_t>(iv) * static_cast<std::size_t>(f.w) + static_cast<std::size_t>(iu);
    const float measured = f.measured_z[centre];
    if (measured > 0.0f && p.z < measured - f.sigmas * depthSigma(measured)) {
      plan.kept[j] = 0.5f * decodeConfidence(s.confidence) - f.carve * f.weight[centre];
      return SplatPlan::kCarve;
    }
  }
  plan.centre_u[j] = iu;
  plan.centre_v[j] = iv;
  planCentre(f, s, p, iu, iv, j, plan);
  return SplatPlan::kSplat;
}

}  // namespace

void planSplatsRef(const SplatFrame& frame, const Surfel* surfels, std::size_t count, SplatPlan& plan) {
  for (std::size_t j = 0; j < count; ++j) plan.action[j] = planSurfel(frame, surfels[j], j, plan);
}

}  // namespace fovea::pipeline::map
