// The streaming flags `fovead run` and `fovead serve` share (--listen,
// --key-file, --insecure, --budget, ...), parsed into a StreamConfig.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/result.h"
#include "firmware/options.h"
#include "firmware/streamer.h"

namespace fovea::firmware {

// Value flags (--insecure is a switch).
extern const std::vector<std::string> kStreamFlags;

// The streaming options over `base` (serve's: the configuration's stream
// section, from the board profile, --config and --set), or nullopt without
// --listen; errors name the flag.
Result<std::optional<StreamConfig>> streamConfigFromArgs(const Args& args, const StreamConfig& base = {});

}  // namespace fovea::firmware
