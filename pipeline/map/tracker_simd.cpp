// PLACEHOLDER (not committed as is): replaced by the Highway kernel.
#include "pipeline/map/tracker_kernels.h"
namespace fovea::pipeline::map {
void trackLevelSimd(const TrackFrameLevel& frame, const TrackModelLevel& model, const TrackParams& params,
                    TrackSums& sums) {
  trackLevelRef(frame, model, params, sums);
}
}  // namespace fovea::pipeline::map
