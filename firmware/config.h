// The configuration file of fovead (TOML, read with toml11) and the board
// profiles (board/*.toml, the same format): every field of ServiceConfig by a
// "section.key" name, one table of fields (config_fields.cpp) that loading,
// --set, validation and printing all use. board/README.md lists the keys.
//
// Errors name the place, the field and the fix, e.g.
//   board/rpi5.toml:12: stream.budget_mbps: must be within 0.01 .. 10000 (got -3)
//   fovea.toml:4: unknown key 'camera.sepc' (did you mean 'camera.spec'?)
//   fovea.toml:7: pipeline.max_points: expected an integer, got a string
//   --set: stream.insecure: expected a boolean, got an integer
// Unknown keys and sections are errors, never ignored. Nothing throws.
#pragma once

#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"
#include "firmware/service_config.h"

namespace fovea::firmware {

// Reads a TOML file over `base`: every key the file holds replaces base's value,
// the rest stays. Then validates the whole configuration.
Result<ServiceConfig> loadServiceConfig(const std::string& path, const ServiceConfig& base);
// The same from the file's text (tests, fuzzing); name stands for the path in messages.
Result<ServiceConfig> parseServiceConfig(std::string_view text, const std::string& name, const ServiceConfig& base);

// One "section.key=value" (the command line's --set). The value is TOML
// ("125", "true", "[5, 8, 18]", "\"text\""); a string or choice may also be
// written bare (camera.spec=mock:balloon). Checks the field's type and range,
// not the rules between fields (validate() does).
Status applyOverride(ServiceConfig& config, std::string_view assignment);

// Every field's range or choices, and the rules between fields (max_voxels <=
// max_points, distinct GPIO lines, a key file or insecure when listening...).
// The message starts with the field: "pipeline.max_voxels: ...".
Status validate(const ServiceConfig& config);

// The configuration as TOML, every key, that loads back to the same config.
std::string formatServiceConfig(const ServiceConfig& config);

// The camera and GPIO backends the configuration names that this build lacks,
// e.g. "camera.spec: backend 'v4l2' is not in this build (built: mock, tum)";
// empty when all are present. A profile is data: it validates either way, and
// the service reports these when it opens the devices.
std::vector<std::string> missingBackends(const ServiceConfig& config);

// Where board profiles are: $FOVEA_BOARD_DIR; else, for an installed fovead,
// PREFIX/share/fovea/board beside its PREFIX/bin; else (a build tree) the source
// tree's board/ (the compile definition FOVEA_BOARD_DIR).
std::string boardDirectory();
inline constexpr std::string_view kDefaultBoard = "host-mock";

// The effective configuration of `fovead serve` and `fovead print-config`: the
// board profile (board, else the config file's `board` key, else host-mock;
// <boardDirectory()>/NAME.toml), then the config file, then each --set in
// order, then validate(). FOVEA_FORCE_KERNEL, when set, still picks the kernels.
// An error names where the offending value came from.
Result<ServiceConfig> resolveServiceConfig(std::optional<std::string> board, std::optional<std::string> config_file,
                                           std::span<const std::string> overrides);

// Where a command's configuration comes from: --board NAME, --config FILE and
// any number of --set SECTION.KEY=VALUE (also written --flag=value).
struct ConfigSources {
  std::optional<std::string> board;
  std::optional<std::string> config_file;
  std::vector<std::string> overrides;
};
// Takes those flags out of `tokens` (a command's arguments), leaving the rest
// in order. kInvalidArgument for a missing value or --board/--config given twice.
Result<ConfigSources> takeConfigSources(std::vector<std::string>& tokens);
inline Result<ServiceConfig> resolveServiceConfig(const ConfigSources& sources) {
  return resolveServiceConfig(sources.board, sources.config_file, sources.overrides);
}

}  // namespace fovea::firmware
