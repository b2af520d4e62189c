// planAssociationRef and planMergeRef (association_plan.h): the association's
// arithmetic, a pixel at a time. Every product and sum is written out in the
// order the Highway kernel repeats and the association used before it was
// planned (Eigen's, for its fixed-size products, dot products and norms:
// a0 b0 + (a1 b1 + a2 b2)), so that the maps are those it made, bit for bit.
#include <algorithm>
#include <cmath>

#include "core/depth_noise.h"
#include "pipeline/map/association_plan.h"
#include "pipeline/map/float3.h"
#include "pipeline/map/index_map.h"

namespace fovea::pipeline::map {

namespace {

// The normal test's cosine at depth z (SurfelMap::updateNormalTolerance's table).
float normalCosTolerance(const AssociationFrame& f, float z) {
  const auto b = static_cast<std::size_t>(std::max(0.0f, (z - f.normal_cos_z_min) * f.normal_cos_per_m));
  return f.normal_cos[std::min<std::size_t>(b, f.normal_cos_size - 1)];
}

void planPixel(const AssociationFrame& f, const Surfel* surfels, std::size_t j, AssociationPlan& plan) {
  plan.bits[j] = 0;
  const float weight = f.weight[j];
  if (weight == 0.0f) {
    plan.kind[j] = AssociationPlan::kNothing;
    return;
  }
  const Float3 normal{f.nx[j], f.ny[j], f.nz[j]};
  if (dot(normal, normal) > 0.0f) plan.bits[j] = AssociationPlan::kHasNormal;
  const uint32_t slot = f.slot[j];
  plan.slot[j] = slot;
  if (slot == IndexMap::kNoSurfel) {
    plan.kind[j] = AssociationPlan::kEmpty;
    return;
  }
  const float z = f.z[j];
  const float tolerance = f.sigmas * depthSigma(z);
  const float seen = f.seen[j];
  if (seen < z - tolerance) {
    plan.kind[j] = AssociationPlan::kCarve;
  } else if (seen <= z + tolerance) {
    plan.kind[j] = AssociationPlan::kAtDepth;
    if (plan.bits[j] & AssociationPlan::kHasNormal) planMergeRef(f, surfels[slot], j, plan);
  } else {
    plan.kind[j] = AssociationPlan::kInFront;
  }
}

// The surfel's colour and the pixel's, weighted a and b: red | green << 8 | blue << 16.
uint32_t mergedColour(const Surfel& s, const uint8_t* rgb, float a, float b) {
  const auto red = static_cast<uint8_t>(a * s.red + b * rgb[0] + 0.5f);
  const auto green = static_cast<uint8_t>(a * s.green + b * rgb[1] + 0.5f);
  const auto blue = static_cast<uint8_t>(a * s.blue + b * rgb[2] + 0.5f);
  return static_cast<uint32_t>(red) | static_cast<uint32_t>(green) << 8 | static_cast<uint32_t>(blue) << 16;
}

}  // namespace

// The surfel's normal comes as its decoded direction and that direction's
// length, not as a unit vector: the weighted sum of unit normals scaled by the
// length and the confidences' sum points the same way, and the encoding keeps
// only the way (it divides by the L1 norm), so the merge needs no division for
// it. The test (d / |d|) . n < cos is d . n < cos |d|: a square root, no division.
void planMergeRef(const AssociationFrame& f, const Surfel& s, std::size_t j, AssociationPlan& plan) {
  const float weight = f.weight[j], z = f.z[j];
  const Float3 n_world = rotate(f.r, {f.nx[j], f.ny[j], f.nz[j]});
  const Eigen::Vector3f decoded = surfelDirection(s);
  const Float3 d{decoded.x(), decoded.y(), decoded.z()};
  const float d_norm = std::sqrt(dot(d, d));
  plan.bits[j] &= ~(AssociationPlan::kMerges | AssociationPlan::kStable);
  if (dot(d, n_world) < normalCosTolerance(f, z) * d_norm) return;  // another orientation
  plan.bits[j] |= AssociationPlan::kMerges;
  // Relative to the surfel's brick: its origin is in camera coordinates
  // already, a few metres from the vertex.
  const float* o = f.brick_cam + 3 * static_cast<std::size_t>(s.brick);
  const Float3 rel = rotate(f.r, {f.ray_u[j] * z - o[0], f.ray_v * z - o[1], z - o[2]});
  const float c = decodeConfidence(s.confidence);
  const float sum = c + weight;
  const float inv_sum = 1.0f / sum;
  const float a = c * inv_sum, b = weight * inv_sum;
  plan.rgb[j] = mergedColour(s, f.rgb == nullptr ? kGreyRgb : f.rgb + 3 * j, a, b);
  plan.x[j] = a * s.x + b * rel.x;
  plan.y[j] = a * s.y + b * rel.y;
  plan.z[j] = a * s.z + b * rel.z;
  const float wd = weight * d_norm;
  const Float3 n{c * d.x + wd * n_world.x, c * d.y + wd * n_world.y, c * d.z + wd * n_world.z};
  const Float3 normal = dot(n, n) > 0.0f ? n : n_world;
  const float radius = a * surfelRadius(s) + b * f.radius[j];
  plan.normal_radius[j] = (encodeNormal({normal.x, normal.y, normal.z}) << 8) | encodeRadius(radius);
  const float capped = std::min(sum, f.confidence_cap);
  plan.confidence[j] = encodeConfidence(capped);
  if (capped >= f.stable_confidence) plan.bits[j] |= AssociationPlan::kStable;
}

void planAssociationRef(const AssociationFrame& frame, const Surfel* surfels, std::size_t count, AssociationPlan& plan,
                        std::size_t begin) {
  for (std::size_t j = begin; j < count; ++j) planPixel(frame, surfels, j, plan);
}

}  // namespace fovea::pipeline::map
