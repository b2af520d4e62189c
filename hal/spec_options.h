// The "backend:args,key=value" camera specs, split and parsed the same way by
// every backend: one tokenizer (tokenizeSpec) and the value parsers (whole text
// or nothing, finite numbers, on|off, WxH). Errors are kInvalidArgument
// "BACKEND: KEY: expected ..., got 'VALUE'".
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "core/result.h"

namespace fovea::hal {

// One comma-separated item of a spec: "key=value" split at its first '=' (the
// value may hold more: "colour=serial=12"), or a bare word without '=' (the word
// in key, has_value false; an empty item is a bare empty word).
struct SpecItem {
  std::string_view key;
  std::string_view value;
  bool has_value = false;
};

struct SpecTokenRules {
  enum class Head : uint8_t {
    kFirstItem,        // the first item is the head, '=' or not ("serial=12" names a V4L2 node)
    kFirstItemIfBare,  // the first item is the head unless it is key=value (an optional URI)
  };
  Head head = Head::kFirstItem;
  // The first item after the head with this key and a '=' takes the rest of the
  // spec, commas included, as its value, and ends the items (libcamera's
  // depth=SPEC names another camera's whole spec). Empty: no such key.
  std::string_view rest_key;
  // A bare item after a key=value continues that value, comma included (the
  // mock's keyframe lists hold commas). A bare item with no value before it
  // stays bare.
  bool bare_continues_value = false;
};

struct SpecTokens {
  std::optional<std::string_view> head;  // the whole first item, when the rules make it the head
  std::vector<SpecItem> items;           // in spec order, duplicates kept, nothing dropped
};

// Splits `spec` (the text after "backend:") by the rules. Never fails: which
// items are errors (bare, empty, repeated, unknown) is each backend's choice,
// made in item order so that the first error in the spec is the one reported.
// The views point into `spec`. "" is one empty item, "a," two items.
SpecTokens tokenizeSpec(std::string_view spec, const SpecTokenRules& rules = {});

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
