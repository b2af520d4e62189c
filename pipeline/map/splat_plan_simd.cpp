// planSplatsSimd (splat_plan.h), dynamically dispatched as index_map_simd.cpp is:
// foreach_target.h re-includes this file once per Highway target, compiling
// splat_plan_simd-inl.h for each, and HWY_DYNAMIC_DISPATCH calls the best one.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/map/splat_plan_simd.cpp"
#include "hwy/foreach_target.h"  // IWYU pragma: keep

#include "hwy/highway.h"
#include "pipeline/map/splat_plan_simd-inl.h"

#if HWY_ONCE

#include <bit>

namespace fovea::pipeline::map {

// The kernel reads a surfel's words as the layout below and little-endian
// (flags the top byte of the word after the normal, the brick the top half of
// the next).
static_assert(std::endian::native == std::endian::little);
static_assert(offsetof(Surfel, normal_radius) == 12 && offsetof(Surfel, red) == 16 && offsetof(Surfel, flags) == 19 &&
              offsetof(Surfel, confidence) == 20 && offsetof(Surfel, brick) == 22 && offsetof(Surfel, first_seen) == 24);

HWY_EXPORT(PlanSplatsT);

void planSplatsSimd(const SplatFrame& frame, const Surfel* surfels, std::size_t count, SplatPlan& plan) {
  if (count == 0) return;
  HWY_DYNAMIC_DISPATCH(PlanSplatsT)(frame, surfels, count, plan);
}

}  // namespace fovea::pipeline::map

#endif  // HWY_ONCE
