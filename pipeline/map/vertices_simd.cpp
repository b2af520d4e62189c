// computeDepthsSimd and computeNormalsSimd (map_kernels.h), dynamically dispatched: foreach_target.h
// re-includes this file once per Highway target, compiling vertices_simd-inl.h
// for each; HWY_EXPORT builds the table and HWY_DYNAMIC_DISPATCH calls the best
// supported target (pipeline::forceSimdTarget() restricts it, as for the other kernels).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/map/vertices_simd.cpp"
#include "hwy/foreach_target.h"  // IWYU pragma: keep

#include "hwy/highway.h"
#include "pipeline/map/vertices_simd-inl.h"

#if HWY_ONCE

namespace fovea::pipeline::map {

HWY_EXPORT(ComputeDepthsT);
HWY_EXPORT(ComputeNormalsT);

uint32_t computeNormalsSimd(const VertexParams& params, const PixelMaps& out) {
  return HWY_DYNAMIC_DISPATCH(ComputeNormalsT)(params, out);
}

uint32_t computeDepthsSimd(const VertexParams& params, float* z, float* weight) {
  return HWY_DYNAMIC_DISPATCH(ComputeDepthsT)(params, z, weight);
}

}  // namespace fovea::pipeline::map

#endif  // HWY_ONCE
