// gatherIndexSimd (index_map.h), dynamically dispatched as vertices_simd.cpp is:
// foreach_target.h re-includes this file once per Highway target, compiling
// index_map_simd-inl.h for each, and HWY_DYNAMIC_DISPATCH calls the best one.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/map/index_map_simd.cpp"
#include "hwy/foreach_target.h"  // IWYU pragma: keep

#include "hwy/highway.h"
#include "pipeline/map/index_map_simd-inl.h"

#if HWY_ONCE

namespace fovea::pipeline::map {

HWY_EXPORT(GatherIndexT);

void gatherIndexSimd(const CentreGrid& grid, float sigmas, int y0, int y1, const IndexOut& out) {
  HWY_DYNAMIC_DISPATCH(GatherIndexT)(grid, sigmas, y0, y1, out);
}

}  // namespace fovea::pipeline::map

#endif  // HWY_ONCE
