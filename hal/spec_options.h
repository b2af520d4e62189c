// Values of the "backend:args,key=value" camera specs, parsed the same way by
// every backend: whole text or nothing, finite numbers, on|off, WxH. Errors are
// kInvalidArgument "BACKEND: KEY: expected ..., got 'VALUE'".
#pragma once

#include <cstdint>
#include <string_view>

#include "core/result.h"

namespace fovea::hal {

// The whole text as a number; false for anything else (signs as from_chars).
bool parseSpecInt(std::string_view text, int& out);
bool parseSpecUint(std::string_view text, uint64_t& out);
bool parseSpecDouble(std::string_view text, double& out);  // finite only

// "on" or "off".
Status parseSpecOnOff(std::string_view backend, std::string_view key, std::string_view value, bool& out);

// "WxH" with both sides within min_side .. max_side.
Status parseSpecSize(std::string_view backend, std::string_view key, std::string_view value, int min_side,
                     int max_side, int& width, int& height);

}  // namespace fovea::hal
