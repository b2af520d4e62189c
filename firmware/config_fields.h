// Internal to firmware/config*: the table of every configuration field (its
// "section.key" name, type, range and how it maps onto ServiceConfig), which
// loading, --set, validation and printing all read, so that a key is declared once.
#pragma once

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "firmware/service_config.h"

namespace fovea::firmware::config_detail {

using Value = std::variant<bool, int64_t, double, std::string, std::vector<double>>;
enum class Kind { kBool, kInt, kFloat, kString, kChoice, kFloatList };

// One setting: its "section.key" name, its TOML type and range (in the file's
// units: ms, MB/s), and how it maps onto ServiceConfig.
struct Field {
  const char* path;
  Kind kind;
  double min = 0.0;  // kInt, kFloat, each element of kFloatList: inclusive
  double max = 0.0;
  std::vector<std::string> choices;  // kChoice
  Value (*get)(const ServiceConfig&) = nullptr;
  void (*set)(ServiceConfig&, const Value&) = nullptr;
  // An extra check of a kString value: an error message, or "" when fine.
  std::string (*check)(const std::string&) = nullptr;
};

// The table: every field of ServiceConfig but stream.link.key (read from
// stream.key_file at start-up) and stream.codec.max_payload (follows each
// session's MTU). Within a section, plain keys come before sub-sections.
const std::vector<Field>& fields();
// The field named `path`, or nullptr.
const Field* findField(std::string_view path);
// "camera.pose" for "camera.pose.source"; "" for a top-level key.
std::string sectionOf(std::string_view path);
// Every section and sub-section ("camera", "foveation", "foveation.fixation").
const std::set<std::string>& sections();

// Where each field got its value ("board/rpi5.toml:12", "--set").
using Origins = std::map<std::string, std::string>;

}  // namespace fovea::firmware::config_detail
