// trackLevelSimd (tracker_kernels.h). NOT YET VECTORISED: it calls the scalar
// reference, so KernelSet::kSimd tracks exactly as kRef (docs/tracking.md). The
// Highway kernel (foreach_target.h + HWY_DYNAMIC_DISPATCH, as vertices_simd.cpp)
// is still to write.
#include "pipeline/map/tracker_kernels.h"
namespace fovea::pipeline::map {
void trackLevelSimd(const TrackFrameLevel& frame, const TrackModelLevel& model, const TrackParams& params,
                    TrackSums& sums) {
  trackLevelRef(frame, model, params, sums);
}
}  // namespace fovea::pipeline::map
