// trackLevelSimd, computeNormalsSimd and downsampleSimd (tracker_kernels.h),
// dynamically dispatched: foreach_target.h re-includes this file once per
// Highway target, compiling tracker_simd-inl.h for each; HWY_EXPORT builds the
// table and HWY_DYNAMIC_DISPATCH calls the best supported target
// (pipeline::forceSimdTarget() restricts it, as for the other kernels).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/map/tracker_simd.cpp"
#include "hwy/foreach_target.h"  // IWYU pragma: keep

#include "hwy/highway.h"
#include "pipeline/map/tracker_simd-inl.h"

#if HWY_ONCE

namespace fovea::pipeline::map {

HWY_EXPORT(TrackLevelT);
HWY_EXPORT(ComputeNormalsT);
HWY_EXPORT(DownsampleT);

void downsampleSimd(const PyramidLevelIn& from, const PyramidLevelOut& to, float step_share, bool normals) {
  HWY_DYNAMIC_DISPATCH(DownsampleT)(from, to, step_share, normals);
}

void computeNormalsSimd(const NormalMapIn& in, float* nx, float* ny, float* nz) {
  HWY_DYNAMIC_DISPATCH(ComputeNormalsT)(in, nx, ny, nz);
}

void trackLevelSimd(const TrackFrameLevel& frame, const TrackModelLevel& model, const TrackParams& params,
                    TrackSums& sums) {
  HWY_DYNAMIC_DISPATCH(TrackLevelT)(frame, model, params, sums);
}

}  // namespace fovea::pipeline::map

#endif  // HWY_ONCE
