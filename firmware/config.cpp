// The configuration's entry points (config.h): a file, --set, validation and
// printing over the table of fields (config_fields.h), and the effective
// configuration of a command: board profile, config file, then --set.
#include "firmware/config.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <system_error>

#include "core/kernel_set.h"
#include "firmware/config_fields.h"
#include "firmware/config_load.h"
#include "firmware/config_validation.h"
#include "firmware/config_values.h"
#include "hal/camera.h"
#include "hal/gpio.h"

namespace fovea::firmware {

Result<ServiceConfig> loadServiceConfig(const std::string& path, const ServiceConfig& base) {
  Result<std::string> text = config_detail::readFile(path);
  if (!text) return text.status();
  return parseServiceConfig(text.value(), path, base);
}

Result<ServiceConfig> parseServiceConfig(std::string_view text, const std::string& name, const ServiceConfig& base) {
  ServiceConfig config = base;
  config_detail::Origins origins;
  if (Status s = config_detail::loadTextInto(std::string(text), name, config, origins); !s) return s;
  config_detail::applyImpliedSettings(config, origins);
  if (Status s = config_detail::validateWithOrigins(config, origins); !s) return s;
  return config;
}

Status applyOverride(ServiceConfig& config, std::string_view assignment) {
  config_detail::Origins origins;
  return config_detail::applyOverrideTracked(config, assignment, origins);
}

Status validate(const ServiceConfig& config) { return config_detail::validateWithOrigins(config, {}); }

std::string formatServiceConfig(const ServiceConfig& config) {
  std::string out = "# fovead configuration (fovead --print-config); the keys: board/README.md\n";
  std::string section;
  for (const config_detail::Field& field : config_detail::fields()) {
    const std::string field_section = config_detail::sectionOf(field.path);
    if (field_section != section) {
      section = field_section;
      out += "\n[" + section + "]\n";
    }
    const std::string key = section.empty() ? field.path : std::string(field.path).substr(section.size() + 1);
    out += key + " = " + config_detail::formatValue(field.get(config)) + "\n";
  }
  return out;
}

std::vector<std::string> missingBackends(const ServiceConfig& config) {
  std::vector<std::string> missing;
  auto check = [&missing](const char* field, const std::string& spec, const std::vector<std::string_view>& built) {
    const std::string name = spec.substr(0, spec.find(':'));
    if (std::find(built.begin(), built.end(), name) != built.end()) return;
    std::string list;
    for (std::string_view b : built) list += (list.empty() ? "" : ", ") + std::string(b);
    missing.push_back(std::string(field) + ": backend '" + name + "' is not in this build (built: " + list + ")");
  };
  check("camera.spec", config.camera.spec, hal::cameraBackendNames());
  check("gpio.spec", config.gpio.spec, hal::gpioBackendNames());
  return missing;
}

Result<ServiceConfig> resolveServiceConfig(std::optional<std::string> board, std::optional<std::string> config_file,
                                           std::span<const std::string> overrides) {
  config_detail::Origins origins;
  // The config file may name its board: read it once to see.
  std::string board_name = board.value_or(std::string(kDefaultBoard));
  if (config_file) {
    ServiceConfig peek;
    config_detail::Origins peek_origins;
    if (Status s = config_detail::loadInto(*config_file, peek, peek_origins); !s) return s;
    if (auto it = peek_origins.find("board"); it != peek_origins.end()) {
      if (board && *board != peek.board) {
        return invalidArgument(it->second + ": board: the file is for '" + peek.board + "', --board says '" + *board +
                               "'");
      }
      board_name = peek.board;
    }
  }
  if (board_name.empty() || board_name.find('/') != std::string::npos) {
    return invalidArgument("board: '" + board_name + "' is not a board name (use --config FILE for a file elsewhere)");
  }
  const std::string dir = boardDirectory();
  const std::string board_path = dir + "/" + board_name + ".toml";
  std::error_code ec;
  if (!std::filesystem::exists(board_path, ec)) {
    std::vector<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
      if (entry.path().extension() == ".toml") names.push_back(entry.path().stem().string());
    }
    std::sort(names.begin(), names.end());
    std::string list;
    for (const std::string& name : names) list += (list.empty() ? "" : ", ") + name;
    return Result<ServiceConfig>(ErrorCode::kNotFound, "unknown board '" + board_name + "': no " + board_name +
                                                           ".toml in " + dir + " (boards: " +
                                                           (list.empty() ? "none: set FOVEA_BOARD_DIR to the profiles' directory"
                                                                         : list) +
                                                           ")");
  }
  ServiceConfig config;
  config.board = board_name;
  if (Status s = config_detail::loadInto(board_path, config, origins); !s) return s;
  if (config.board != board_name) {
    return invalidArgument(origins["board"] + ": board: '" + config.board + "' in " + board_name +
                           ".toml (they must match)");
  }
  if (config_file) {
    if (Status s = config_detail::loadInto(*config_file, config, origins); !s) return s;
  }
  for (const std::string& assignment : overrides) {
    // A profile is picked before anything else; renaming it afterwards would only mislabel the result.
    if (assignment.rfind("board=", 0) == 0) return invalidArgument("--set: board: pick a profile with --board NAME");
    if (Status s = config_detail::applyOverrideTracked(config, assignment, origins); !s) return s;
  }
  // FOVEA_FORCE_KERNEL beats any file, as everywhere (core/kernel_set.h).
  if (const char* force = std::getenv("FOVEA_FORCE_KERNEL"); force && *force) {
    config.pipeline.kernels = fovea::defaultKernelSet();
  }
  config_detail::applyImpliedSettings(config, origins);
  if (Status s = config_detail::validateWithOrigins(config, origins); !s) return s;
  return config;
}

Result<ConfigSources> takeConfigSources(std::vector<std::string>& tokens) {
  ConfigSources sources;
  std::vector<std::string> rest;
  for (std::size_t i = 0; i < tokens.size(); ++i) {
    std::string flag = tokens[i];
    std::optional<std::string> value;
    if (const std::size_t eq = flag.find('='); flag.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = flag.substr(eq + 1);
      flag.resize(eq);
    }
    if (flag != "--board" && flag != "--config" && flag != "--set") {
      rest.push_back(tokens[i]);
      continue;
    }
    if (!value) {
      if (i + 1 >= tokens.size()) return invalidArgument(flag + " needs a value");
      value = tokens[++i];
    }
    if (flag == "--set") {
      sources.overrides.push_back(*value);
    } else if (std::optional<std::string>& slot = flag == "--board" ? sources.board : sources.config_file; slot) {
      return invalidArgument(flag + " given twice");
    } else {
      slot = *value;
    }
  }
  tokens = std::move(rest);
  return sources;
}

}  // namespace fovea::firmware
