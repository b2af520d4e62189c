// planAssociationSimd (association_plan.h), dynamically dispatched as
// splat_plan_simd.cpp is: foreach_target.h re-includes this file once per
// Highway target, compiling association_plan_simd-inl.h for each, and
// HWY_DYNAMIC_DISPATCH calls the best one.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/map/association_plan_simd.cpp"
#include "hwy/foreach_target.h"  // IWYU pragma: keep

#include "hwy/highway.h"
#include "pipeline/map/association_plan_simd-inl.h"

#if HWY_ONCE

#include <bit>

namespace fovea::pipeline::map {

// The kernel reads a surfel's words as the layout below and little-endian
// (the colour the low three bytes of the word at red, the brick the top half of
// the word the confidence starts).
static_assert(std::endian::native == std::endian::little);
static_assert(offsetof(Surfel, normal_radius) == 12 && offsetof(Surfel, red) == 16 && offsetof(Surfel, green) == 17 &&
              offsetof(Surfel, blue) == 18 && offsetof(Surfel, confidence) == 20 && offsetof(Surfel, brick) == 22);

HWY_EXPORT(PlanAssociationT);

void planAssociationSimd(const AssociationFrame& frame, const Surfel* surfels, std::size_t count, AssociationPlan& plan) {
  const std::size_t done = count == 0 ? 0 : HWY_DYNAMIC_DISPATCH(PlanAssociationT)(frame, surfels, count, plan);
  planAssociationRef(frame, surfels, count, plan, done);
}

}  // namespace fovea::pipeline::map

#endif  // HWY_ONCE
