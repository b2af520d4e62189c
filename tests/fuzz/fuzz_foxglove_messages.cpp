// Fuzz target for the text messages a Foxglove client sends fovea-operator
// --foxglove (tools/operator/foxglove_messages.h): the bytes are one text
// message, given to parseFoxgloveRequest as FoxgloveServer's data handler gives
// it. Oracles besides "no crash, no exception":
// - an error is kParseError or kInvalidArgument, with a message; text over
//   kMaxClientMessageBytes is always an error, text that is not JSON a kParseError;
// - a reference reading of the rules from the same JSON value agrees on what
//   is accepted and on every subscription, id and refused entry;
// - what parses, written back as @foxglove/ws-protocol's client writes it,
//   parses to the same request;
// - foxgloveStatusJson of the bytes (the server quotes what it refuses) is a
//   JSON status object, its message the bytes whenever they are UTF-8.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "tests/fuzz/fuzz_target.h"
#include "tools/operator/foxglove_messages.h"

namespace {

using namespace fovea;
using namespace fovea::tools;
using nlohmann::json;

std::string_view current_input;

[[noreturn]] void fail(const std::string& what) {
  std::fprintf(stderr, "fuzz_foxglove_messages: %s\ninput: %.*s\n", what.c_str(), static_cast<int>(current_input.size()),
               current_input.data());
  std::abort();
}

bool u32(const json& v) { return v.is_number_unsigned() && v.get<uint64_t>() <= 0xffffffffull; }

struct Expected {
  bool accepted = false;
  FoxgloveRequest request;
};

Expected reference(const json& m) {
  Expected e;
  if (!m.is_object() || !m.contains("op") || !m["op"].is_string()) return e;
  if (m["op"] == "subscribe") {
    if (!m.contains("subscriptions") || !m["subscriptions"].is_array()) return e;
    e.request.kind = FoxgloveRequest::Kind::kSubscribe;
    for (const json& s : m["subscriptions"]) {
      if (s.is_object() && s.contains("id") && s.contains("channelId") && u32(s["id"]) && u32(s["channelId"])) {
        e.request.subscriptions.push_back({s["id"].get<uint32_t>(), s["channelId"].get<uint32_t>()});
      } else {
        e.request.refused.emplace_back();
      }
    }
  } else if (m["op"] == "unsubscribe") {
    if (!m.contains("subscriptionIds") || !m["subscriptionIds"].is_array()) return e;
    e.request.kind = FoxgloveRequest::Kind::kUnsubscribe;
    for (const json& id : m["subscriptionIds"]) {
      if (u32(id)) {
        e.request.subscription_ids.push_back(id.get<uint32_t>());
      } else {
        e.request.refused.emplace_back();
      }
    }
  } else {
    return e;
  }
  e.accepted = true;
  return e;
}

void checkSame(const FoxgloveRequest& got, const FoxgloveRequest& want, bool refused_too, const char* when) {
  const std::string where = std::string(" (") + when + ")";
  if (got.kind != want.kind) fail("the kind differs" + where);
  if (got.subscriptions != want.subscriptions) fail("the subscriptions differ" + where);
  if (got.subscription_ids != want.subscription_ids) fail("the subscription ids differ" + where);
  if (refused_too && got.refused.size() != want.refused.size()) fail("the refused entries differ" + where);
  for (const std::string& why : got.refused) {
    if (why.empty()) fail("a refused entry without a reason" + where);
  }
}

// Written as FoxgloveClient writes it (JSON.stringify of {op, subscriptions} / {op, subscriptionIds}).
void checkRoundTrip(const FoxgloveRequest& r) {
  json written;
  if (r.kind == FoxgloveRequest::Kind::kSubscribe) {
    json list = json::array();
    for (const FoxgloveSubscription& s : r.subscriptions) list.push_back({{"id", s.id}, {"channelId", s.channel_id}});
    written = {{"op", "subscribe"}, {"subscriptions", list}};
  } else {
    written = {{"op", "unsubscribe"}, {"subscriptionIds", r.subscription_ids}};
  }
  const std::string text = written.dump();
  if (text.size() > kMaxClientMessageBytes) return;
  Result<FoxgloveRequest> again = parseFoxgloveRequest(text);
  if (!again) fail("what parsed, written again, does not parse: " + again.status().message());
  if (!again->refused.empty()) fail("what parsed, written again, has refused entries");
  checkSame(*again, r, false, "written and parsed again");
}

void checkStatus(std::string_view text) {
  const std::string bytes(text);
  json j = json::parse(foxgloveStatusJson(2, bytes), nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) fail("foxgloveStatusJson is not a JSON object");
  if (j["op"] != "status" || j["level"] != 2 || !j["message"].is_string()) fail("foxgloveStatusJson: " + j.dump());
  bool utf8 = true;
  try {
    (void)json(bytes).dump();
  } catch (const json::type_error&) {
    utf8 = false;
  }
  if (utf8 && j["message"] != bytes) fail("foxgloveStatusJson changed UTF-8 text");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  // Exactly the message's bytes on the heap, as civetweb hands them over.
  const std::vector<char> bytes(data, data + size);
  const std::string_view text(bytes.data(), bytes.size());
  current_input = text;

  Result<FoxgloveRequest> got = parseFoxgloveRequest(text);
  if (!got) {
    const ErrorCode code = got.status().code();
    if (code != ErrorCode::kParseError && code != ErrorCode::kInvalidArgument) fail("an error of another code");
    if (got.status().message().empty()) fail("an error without a message");
  }
  checkStatus(text);
  if (size > kMaxClientMessageBytes) {
    if (got) fail("a message over kMaxClientMessageBytes was accepted");
    return 0;
  }
  const json message = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (message.is_discarded()) {
    if (got || got.status().code() != ErrorCode::kParseError) fail("text that is not JSON is not a parse error");
    return 0;
  }
  const Expected want = reference(message);
  if (got.isOk() != want.accepted) fail(got ? "accepted a message the rules refuse" : "refused a message the rules accept");
  if (got) {
    checkSame(*got, want.request, true, "against the rules");
    checkRoundTrip(*got);
  }
  return 0;
}

// The corpus (tests/fuzz/corpus/fuzz_foxglove_messages/) holds what a client sends.
std::vector<fovea::fuzz::Input> fovea::fuzz::seeds() { return {}; }
