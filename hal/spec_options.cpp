#include "hal/spec_options.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <string>

namespace fovea::hal {

namespace {

template <typename T>
bool parseWhole(std::string_view text, T& out) {
  if (text.empty()) return false;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
  return ec == std::errc() && end == text.data() + text.size();
}

Status invalid(std::string_view backend, std::string_view key, std::string_view expected, std::string_view value) {
  return {ErrorCode::kInvalidArgument, std::string(backend) + ": " + std::string(key) + ": expected " +
                                           std::string(expected) + ", got '" + std::string(value) + "'"};
}

}  // namespace

SpecTokens tokenizeSpec(std::string_view spec, const SpecTokenRules& rules) {
  SpecTokens tokens;
  // Where the last item's value starts while bare pieces may still continue it
  // (npos: none open). Not std::optional: GCC 12 warns maybe-uninitialized on it here.
  constexpr std::size_t kNone = std::string_view::npos;
  std::size_t open_value_at = kNone;
  for (std::size_t start = 0; start <= spec.size();) {
    const std::size_t end = std::min(spec.find(',', start), spec.size());
    const std::string_view piece = spec.substr(start, end - start);
    const std::size_t piece_at = start;
    start = end + 1;
    const std::size_t eq = piece.find('=');
    const bool bare = eq == std::string_view::npos;
    if (piece_at == 0 && (rules.head == SpecTokenRules::Head::kFirstItem || bare)) {
      tokens.head = piece;
      continue;
    }
    if (bare) {
      if (rules.bare_continues_value && open_value_at != kNone) {
        tokens.items.back().value = spec.substr(open_value_at, end - open_value_at);
      } else {
        tokens.items.push_back({piece, {}, false});
        open_value_at = kNone;
      }
      continue;
    }
    const std::string_view key = piece.substr(0, eq);
    const std::size_t value_at = piece_at + eq + 1;
    if (!rules.rest_key.empty() && key == rules.rest_key) {
      tokens.items.push_back({key, spec.substr(value_at), true});
      break;
    }
    tokens.items.push_back({key, spec.substr(value_at, end - value_at), true});
    open_value_at = value_at;
  }
  return tokens;
}

bool parseSpecInt(std::string_view text, int& out) { return parseWhole(text, out); }

bool parseSpecUint(std::string_view text, uint64_t& out) { return parseWhole(text, out); }

bool parseSpecDouble(std::string_view text, double& out) { return parseWhole(text, out) && std::isfinite(out); }

Status parseSpecOnOff(std::string_view backend, std::string_view key, std::string_view value, bool& out) {
  if (value == "on") {
    out = true;
  } else if (value == "off") {
    out = false;
  } else {
    return invalid(backend, key, "on|off", value);
  }
  return Status::ok();
}

Status parseSpecSize(std::string_view backend, std::string_view key, std::string_view value, int min_side,
                     int max_side, int& width, int& height) {
  const std::size_t x = value.find('x');
  int w = 0;
  int h = 0;
  if (x == std::string_view::npos || !parseSpecInt(value.substr(0, x), w) || !parseSpecInt(value.substr(x + 1), h) ||
      w < min_side || h < min_side || w > max_side || h > max_side) {
    return invalid(backend, key,
                   "WxH with W and H in " + std::to_string(min_side) + ".." + std::to_string(max_side) +
                       " (e.g. 640x480)",
                   value);
  }
  width = w;
  height = h;
  return Status::ok();
}

}  // namespace fovea::hal
