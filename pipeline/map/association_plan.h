// Fusion's association (step 4 of SurfelMap::fuse, docs/map.md), planned a
// batch of pixels of one row at a time (issue 41, part 1): for each pixel, what
// the index map shows there (nothing, a surfel the camera sees through, one at
// the measured depth, one behind the measurement) and, for a surfel at its
// depth, the normal test and the whole merge (position, normal, radius,
// confidence and colour) computed from the surfel as it is
// when the batch is planned. SurfelMap then applies the plans in pixel order.
// A pixel whose surfel an earlier pixel of the same batch merged or carved
// (about 7 % of the merges: a surfel's footprint covers up to 13 pixels) is
// planned again at its turn, from the surfel as it is then (planMergeRef), so
// the map is the one a pixel-by-pixel pass makes, bit for bit.
//
// planAssociationRef() is the specification, a pixel at a time;
// planAssociationSimd() its Highway kernel (association_plan_simd.cpp), which
// gathers the surfels' fields as structure of arrays and gives the same plans
// bit for bit: the reference's additions, multiplications, divisions and square
// roots in its order (a 3-vector's dot product as a0 b0 + (a1 b1 + a2 b2),
// Eigen's order for the fixed-size products the association used before),
// never a fused multiply-add.
#pragma once

#include <cstddef>
#include <cstdint>

#include "pipeline/map/surfel.h"

namespace fovea::pipeline::map {

// What a batch's plans read: the frame's per-pixel maps from the batch's first
// pixel on, its row's rays, and the map's bricks.
struct AssociationFrame {
  float r[9] = {};                   // camera to world rotation, row-major
  const float* brick_cam = nullptr;  // per brick: its origin in camera coordinates (x, y, z)
  // Per pixel of the batch (index 0: its first pixel).
  const uint32_t* slot = nullptr;  // the index map's surfel (IndexMap::kNoSurfel: none)
  const float* seen = nullptr;     // the depth the index map shows there
  const float* weight = nullptr;   // the measurement's weight (0: none)
  const float* z = nullptr;        // its depth
  const float* nx = nullptr;       // its camera-frame normal (0, 0, 0: none)
  const float* ny = nullptr;
  const float* nz = nullptr;
  const float* radius = nullptr;   // its footprint's radius
  const uint8_t* rgb = nullptr;    // its colour, 3 bytes a pixel (null: grey, a frame without colour)
  const float* ray_u = nullptr;    // per pixel: the vertex's x over its depth (the column's ray)
  float ray_v = 0.0f;              // the row's: the vertex's y over its depth
  // The normal test's cosine by depth: bucket (z - z_min) * per_m of `size`.
  const float* normal_cos = nullptr;
  uint32_t normal_cos_size = 1;
  float normal_cos_z_min = 0.0f, normal_cos_per_m = 0.0f;
  float sigmas = 0.0f;             // the depth tolerance in the sensor's sigmas
  float confidence_cap = 0.0f;
  float stable_confidence = 0.0f;
};

// A batch's plans, structure of arrays. The merge's arrays mean something only
// for a kAtDepth pixel with kHasNormal | kMerges.
struct AssociationPlan {
  enum Kind : uint32_t {
    kNothing,  // no measurement (weight 0)
    kEmpty,    // the index map shows no surfel: a new surfel, with a normal
    kCarve,    // the measurement lies clearly behind the surfel: seen through
    kAtDepth,  // within the tolerance: explains, settles, and with a normal merges
    kInFront,  // the measurement lies in front of it: a new surfel, with a normal
  };
  enum Bits : uint32_t {
    kHasNormal = 1,  // the pixel has a normal
    kMerges = 2,     // ... within the normal test's tolerance of the surfel's
    kStable = 4,     // the merged confidence reaches SurfelMapConfig::stable_confidence
  };
  static constexpr std::size_t kSize = 128;  // a multiple of every Highway target's lanes
  uint32_t kind[kSize], bits[kSize], slot[kSize];
  float x[kSize], y[kSize], z[kSize];  // the merged position, from the surfel's brick
  uint32_t normal_radius[kSize];       // the merged normal's and radius's codes
  uint32_t confidence[kSize];          // the merged confidence's code (capped)
  uint32_t rgb[kSize];                 // the merged colour: red | green << 8 | blue << 16
};

// Plans pixels [begin, count) of `frame`, count at most AssociationPlan::kSize,
// against `surfels` (the pool), into plan[begin, count).
void planAssociationRef(const AssociationFrame& frame, const Surfel* surfels, std::size_t count, AssociationPlan& plan,
                        std::size_t begin = 0);
void planAssociationSimd(const AssociationFrame& frame, const Surfel* surfels, std::size_t count, AssociationPlan& plan);

// The normal test and the merge of pixel j against `s` as it is now, into lane
// j of `plan` (its kMerges and kStable bits, and the merge's arrays): the
// reference's own lane, for the pixel whose surfel changed since its batch was
// planned.
void planMergeRef(const AssociationFrame& frame, const Surfel& s, std::size_t j, AssociationPlan& plan);

}  // namespace fovea::pipeline::map
