// Internal to firmware/config*: the rules between fields (max_voxels <=
// max_points, distinct GPIO lines, a key file or insecure when listening...)
// and what one setting implies for another, checked once everything is read.
#pragma once

#include "core/result.h"
#include "firmware/config_fields.h"
#include "firmware/service_config.h"

namespace fovea::firmware::config_detail {

// What one setting implies for another nobody set: tracking the camera
// (camera.pose.source = track...) needs the map, so the map is the source then
// unless foveation.source was set (to something else: validation says so).
void applyImpliedSettings(ServiceConfig& config, Origins& origins);

// Every field's range and the rules between fields; the message starts with
// where the offending value came from (its own origin, else a related field's).
Status validateWithOrigins(const ServiceConfig& config, const Origins& origins);

}  // namespace fovea::firmware::config_detail
