// The surfel map's per-pixel work (SurfelMap::fuse() step 2): each depth pixel's
// camera-frame depth, normal, radius and weight, written as structure-of-arrays
// maps, in two parts: computeDepths (z and weight, which the index map's render
// reads) and computeNormals (normals and radii, made after the render, in its
// scratch). Each has two kernels, one output, BIT FOR BIT (docs/kernels.md,
// docs/map.md): *Ref, the scalar reference, the specification (map_kernels.cpp),
// and *Simd, Highway, dynamic dispatch (vertices_simd.cpp); computeVertices* is
// both parts in turn.
//
// The arithmetic is defined so that SIMD can reproduce it (only Add, Sub, Mul, Div,
// Sqrt, comparisons and selects, in the order written below, never a fused
// multiply-add), and the one transcendental, the weight's exp(), is taken per
// column and per row by prepareVertices(), not per pixel:
//   vertex:  z = float(raw) * scale, zero (no measurement) when raw is outside
//            [raw_min, raw_max]; x = ray_u[u] * z and y = ray_v[v] * z, with
//            ray_u[u] = (float(u) - cx) / fx and ray_v[v] = (float(v) - cy) / fy (no
//            map of their own: made from z where needed, the same bits every time).
//   weight:  weight_u[u] * weight_v[v] for a pixel with a vertex, else 0, where
//            weight_u[u] = exp(-(du * du) / (half_diagonal * half_diagonal) / (2 * 0.6^2)),
//            du = float(u) - cx (weight_v likewise with dv = float(v) - cy) and
//            half_diagonal = sqrt(cx * cx + cy * cy): Keller et al.'s Gaussian fall-off
//            from the image centre, exp(-gamma^2 / (2 sigma^2)) with sigma 0.6, split
//            into its two factors (equal up to float rounding).
//   normal:  from central differences over kNormalReach pixels, a = r - l, b = down - up,
//            n = a x b; none (zero) at a pixel without a vertex, within kNormalReach of
//            the border, next to a neighbour without a vertex, across a step
//            |z' - z| > (0.05 * kNormalReach) * z, or when |n| is not > 0. Then
//            n = n / |n| with |n| = sqrt((nx nx + ny ny) + nz nz), the ray
//            p / |p| (same norm), facing = -((nx rx + ny ry) + nz rz), and n and facing
//            negated when facing < 0 (the normal looks towards the camera).
//   radius:  for a pixel with a normal, clamp(sqrt(2) * z / f / max(facing, 0.2),
//            kMinRadiusM, kMaxRadiusM) with f = 0.5 * (fx + fy) (left to right; max and
//            clamp as std::max and std::clamp); 0 without a normal.
// computeDepths* return the pixels with a vertex, computeNormals* and
// computeVertices* the pixels with a normal.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/kernel_set.h"
#include "hal/frame.h"
#include "pipeline/backproject.h"

namespace fovea::pipeline::map {

// Pixels each side of the central differences: over one, a Kinect-class sensor's
// noise turns most normals by more than the association's tolerance.
inline constexpr int kNormalReach = 2;

// std::lround(x) for |x| < 2^23, inline (the index map's fast path rounds two a
// surfel; the call was 1.3 % of fusion): x - trunc(x) is exact there.
// test_map_equivalence's RoundingIsLround checks it against std::lround.
inline int roundHalfAwayFromZero(float x) {
  const int t = static_cast<int>(x);
  const float frac = x - static_cast<float>(t);
  return frac >= 0.5f ? t + 1 : frac <= -0.5f ? t - 1 : t;
}

// Per-pixel maps, each of at least width x height floats.
struct PixelMaps {
  float* z = nullptr;   // camera-frame depth [m]; 0: no valid measurement
  float* nx = nullptr;  // unit normal towards the camera; zero: none (the pixel can carve, not merge or add)
  float* ny = nullptr;
  float* nz = nullptr;
  float* radius = nullptr;  // [m]; 0 without a normal
  float* weight = nullptr;  // Keller's weight in (0, 1]; 0 without a vertex
};

// A frame's per-column and per-row factors, for frames up to the largest size
// (allocated here, once): the weight's two factors and the rays' slopes. ray_u
// has kNormalReach columns before the frame's first and kRaySlack after its
// last, which the SIMD kernel loads and masks.
struct VertexTables {
  static constexpr std::size_t kRaySlack = 64 + 2;  // the widest vector's lanes and kNormalReach
  VertexTables() = default;
  VertexTables(int max_width, int max_height);
  std::vector<float> weight_u, weight_v, ray_u, ray_v;
  std::size_t memoryBytes() const;
};

struct VertexParams {
  const uint16_t* depth = nullptr;
  int width = 0;
  int height = 0;
  int32_t raw_min = 1;  // valid raw depth: raw_min <= raw <= raw_max (raw_min >= 1)
  int32_t raw_max = 0;
  float scale = 0.0f, fx = 0.0f, fy = 0.0f, cx = 0.0f, cy = 0.0f;
  float f = 0.0f;                     // 0.5 * (fx + fy)
  const float* weight_u = nullptr;    // width entries
  const float* weight_v = nullptr;    // height entries
  const float* ray_u = nullptr;       // width entries, readable from [-kNormalReach] to [width + kRaySlack)
  const float* ray_v = nullptr;       // height entries
};

// The parameters of a frame that SurfelMap::checkFrame() accepted (at least 3x3,
// finite positive fx, fy and depth scale, finite cx, cy, at most the tables'
// size), with the tables written for it.
VertexParams prepareVertices(const hal::RgbdFrame& frame, const RawDepthRange& raw, VertexTables& tables);

uint32_t computeDepthsRef(const VertexParams& params, float* z, float* weight);
uint32_t computeDepthsSimd(const VertexParams& params, float* z, float* weight);
inline uint32_t computeDepths(const VertexParams& params, float* z, float* weight, KernelSet kernels) {
  return kernels == KernelSet::kSimd ? computeDepthsSimd(params, z, weight) : computeDepthsRef(params, z, weight);
}

// From out.z (computeDepths'): out.nx, ny, nz and radius; out.weight is not touched.
uint32_t computeNormalsRef(const VertexParams& params, const PixelMaps& out);
uint32_t computeNormalsSimd(const VertexParams& params, const PixelMaps& out);
inline uint32_t computeNormals(const VertexParams& params, const PixelMaps& out, KernelSet kernels) {
  return kernels == KernelSet::kSimd ? computeNormalsSimd(params, out) : computeNormalsRef(params, out);
}

// Both parts in turn (the benches and the equivalence tests).
inline uint32_t computeVerticesRef(const VertexParams& params, const PixelMaps& out) {
  (void)computeDepthsRef(params, out.z, out.weight);
  return computeNormalsRef(params, out);
}
inline uint32_t computeVerticesSimd(const VertexParams& params, const PixelMaps& out) {
  (void)computeDepthsSimd(params, out.z, out.weight);
  return computeNormalsSimd(params, out);
}
inline uint32_t computeVertices(const VertexParams& params, const PixelMaps& out, KernelSet kernels) {
  return kernels == KernelSet::kSimd ? computeVerticesSimd(params, out) : computeVerticesRef(params, out);
}

}  // namespace fovea::pipeline::map
