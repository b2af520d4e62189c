// Per-target Highway form of depthSigma(float) (core/depth_noise.h) for the
// map's kernels (index_map_simd-inl.h, splat_plan_simd-inl.h): the scalar's
// operations in its order, so each kernel keeps its reference's bits.

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_MAP_DEPTH_SIGMA_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_MAP_DEPTH_SIGMA_SIMD_INL_H_
#undef FOVEA_PIPELINE_MAP_DEPTH_SIGMA_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_MAP_DEPTH_SIGMA_SIMD_INL_H_
#endif

#include "core/depth_noise.h"
#include "hwy/highway.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::map {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// base + (quadratic d) d with d = z - offset.
template <class DF, class V>
HWY_INLINE V DepthSigma(DF df, V z) {
  const auto d = hn::Sub(z, hn::Set(df, kDepthNoiseOffsetF));
  return hn::Add(hn::Set(df, kDepthNoiseBaseF), hn::Mul(hn::Mul(hn::Set(df, kDepthNoiseQuadraticF), d), d));
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::map
HWY_AFTER_NAMESPACE();

#endif  // include guard
