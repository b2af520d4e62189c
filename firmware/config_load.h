// Internal to firmware/config*: a configuration's text read into ServiceConfig
// field by field (a TOML file, a board profile, one --set), each value checked
// alone and its origin noted; unknown keys are errors with a near name offered.
#pragma once

#include <string>
#include <string_view>

#include "core/result.h"
#include "firmware/config_fields.h"
#include "firmware/service_config.h"

namespace fovea::firmware::config_detail {

// The whole file; kNotFound or kIoError naming the path.
Result<std::string> readFile(const std::string& path);

// Applies a file's text over `config`: field by field in the file's order,
// each checked alone (validate() checks the rules between fields). path names
// the file in messages.
Status loadTextInto(const std::string& text, const std::string& path, ServiceConfig& config, Origins& origins);
// The same from the file at `path`.
Status loadInto(const std::string& path, ServiceConfig& config, Origins& origins);

// One "section.key=value" (config.h's applyOverride), its origin noted as "--set".
Status applyOverrideTracked(ServiceConfig& config, std::string_view assignment, Origins& origins);

}  // namespace fovea::firmware::config_detail
