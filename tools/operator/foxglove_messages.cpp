#include "tools/operator/foxglove_messages.h"

#include <nlohmann/json.hpp>

namespace fovea::tools {

namespace {

using nlohmann::json;

bool isU32(const json& v) { return v.is_number_unsigned() && v.get<uint64_t>() <= 0xffffffffull; }

}  // namespace

Result<FoxgloveRequest> parseFoxgloveRequest(std::string_view text) {
  using R = Result<FoxgloveRequest>;
  if (text.size() > kMaxClientMessageBytes) {
    return R(ErrorCode::kParseError, "message of " + std::to_string(text.size()) + " bytes refused (at most " +
                                         std::to_string(kMaxClientMessageBytes) + ")");
  }
  const json m = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (m.is_discarded()) return R(ErrorCode::kParseError, "not JSON");
  if (!m.is_object()) return R(ErrorCode::kInvalidArgument, "not a foxglove.websocket.v1 message (a JSON object with an \"op\")");
  const auto op = m.find("op");
  if (op == m.end() || !op->is_string()) {
    return R(ErrorCode::kInvalidArgument, "not a foxglove.websocket.v1 message (a JSON object with an \"op\")");
  }
  FoxgloveRequest r;
  const std::string& name = op->get_ref<const std::string&>();
  if (name == "subscribe") {
    r.kind = FoxgloveRequest::Kind::kSubscribe;
    const auto list = m.find("subscriptions");
    if (list == m.end() || !list->is_array()) return R(ErrorCode::kInvalidArgument, "subscribe: no \"subscriptions\" array");
    for (const json& s : *list) {
      const bool ok = s.is_object() && s.contains("id") && s.contains("channelId") && isU32(s["id"]) && isU32(s["channelId"]);
      if (!ok) {
        r.refused.push_back("subscribe: a subscription is not {\"id\": u32, \"channelId\": u32}");
        continue;
      }
      r.subscriptions.push_back({static_cast<uint32_t>(s["id"].get<uint64_t>()), static_cast<uint32_t>(s["channelId"].get<uint64_t>())});
    }
  } else if (name == "unsubscribe") {
    r.kind = FoxgloveRequest::Kind::kUnsubscribe;
    const auto list = m.find("subscriptionIds");
    if (list == m.end() || !list->is_array()) return R(ErrorCode::kInvalidArgument, "unsubscribe: no \"subscriptionIds\" array");
    for (const json& id : *list) {
      if (!isU32(id)) {
        r.refused.push_back("unsubscribe: a subscription id is not a u32");
        continue;
      }
      r.subscription_ids.push_back(static_cast<uint32_t>(id.get<uint64_t>()));
    }
  } else {
    return R(ErrorCode::kInvalidArgument,
             json(name.substr(0, 64)).dump(-1, ' ', false, json::error_handler_t::replace) +
                 ": not supported by this server (it only streams; capabilities: none)");
  }
  return r;
}

std::string foxgloveStatusJson(int level, std::string_view message) {
  return json{{"op", "status"}, {"level", level}, {"message", std::string(message)}}.dump(-1, ' ', false,
                                                                                         json::error_handler_t::replace);
}

}  // namespace fovea::tools
