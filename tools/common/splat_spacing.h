// How far apart a decoded cloud's points lie, per region: what a splat must cover so
// that a surface drawn from them has no holes. Shared by the browser viewer
// (tools/operator/view_frame.h) and fovea-eval's renderer (tools/eval/quality_eval.cpp).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "pipeline/acuity.h"
#include "pipeline/point_cloud.h"

namespace fovea::tools {

// Per region, the median distance between consecutive points of that region (the
// codec writes them in Morton order, so these are neighbours on the surface), over
// up to scratch.size() / kMaxRegions pairs per region, thinned evenly over its
// region_points[r] points. 0 for a region without such a pair. Does not allocate.
std::array<float, pipeline::kMaxRegions> medianNeighbourSpacing(
    const pipeline::FoveatedCloud& cloud, const std::array<uint32_t, pipeline::kMaxRegions>& region_points,
    std::span<float> scratch);

}  // namespace fovea::tools
