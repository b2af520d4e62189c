// `fovead serve`'s flags as a ServiceConfig: the seam where the configuration
// file and board profiles (resolveServiceConfig) plug in. serviceConfigFromArgs
// applies the flags present in `args` over `base` (the defaults, or what a
// board profile and a configuration file resolved) and leaves the rest.
#pragma once

#include <string>
#include <vector>

#include "core/result.h"
#include "firmware/options.h"
#include "firmware/service_config.h"

namespace fovea::firmware {

// Value flags and switches `fovead serve` accepts (foveation and stream flags included).
const std::vector<std::string>& serveFlags();
extern const std::vector<std::string> kServeSwitches;

Result<ServiceConfig> serviceConfigFromArgs(const Args& args, ServiceConfig base);

}  // namespace fovea::firmware
