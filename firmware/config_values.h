// Internal to firmware/config*: one field's value checked against its row of the
// table (range, choices, UTF-8 text) and written as TOML text, the two things
// loading, validation and printing share.
#pragma once

#include <string>
#include <string_view>

#include "firmware/config_fields.h"

namespace fovea::firmware::config_detail {

// Shortest text that reads back as the same double.
std::string formatNumber(double v);
// "\"text\"", escaped as a TOML basic string.
std::string quote(std::string_view text);
// The value as TOML: a float always with a point or exponent, a string quoted.
std::string formatValue(const Value& value);

// What is wrong with a value of the right type ("" when nothing).
std::string checkValue(const Field& field, const Value& value);

}  // namespace fovea::firmware::config_detail
