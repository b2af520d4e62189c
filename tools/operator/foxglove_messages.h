// The text messages of fovea-operator --foxglove (foxglove.websocket.v1): what a
// client may send (subscribe, unsubscribe), parsed strictly, and the status
// message the server answers bad input with. Fuzzed (tests/fuzz/fuzz_foxglove_messages.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"

namespace fovea::tools {

// The largest text message a client may send (a subscribe of every channel is far smaller).
inline constexpr std::size_t kMaxClientMessageBytes = 64 * 1024;

struct FoxgloveSubscription {
  uint32_t id = 0;
  uint32_t channel_id = 0;
  bool operator==(const FoxgloveSubscription&) const = default;
};

struct FoxgloveRequest {
  enum class Kind { kSubscribe, kUnsubscribe };
  Kind kind = Kind::kSubscribe;
  std::vector<FoxgloveSubscription> subscriptions;  // kSubscribe: the well-formed entries, in order
  std::vector<uint32_t> subscription_ids;           // kUnsubscribe: the well-formed ids, in order
  std::vector<std::string> refused;                 // why each malformed entry was left out
};

// kParseError: not JSON (or over kMaxClientMessageBytes); kInvalidArgument: not a
// JSON object with a string "op", an op other than subscribe and unsubscribe
// (this server advertises no capabilities), or no "subscriptions" /
// "subscriptionIds" array. Entries that are not {"id": u32, "channelId": u32}
// (subscribe) or u32 (unsubscribe) are left out, each with a reason in refused.
Result<FoxgloveRequest> parseFoxgloveRequest(std::string_view text);

// {"op":"status","level":L,"message":M}: L 0 info, 1 warning, 2 error. Text that is
// not UTF-8 is replaced (U+FFFD), so the result is always JSON.
std::string foxgloveStatusJson(int level, std::string_view message);

}  // namespace fovea::tools
