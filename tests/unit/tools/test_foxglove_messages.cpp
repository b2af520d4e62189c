// tools/operator/foxglove_messages: what a Foxglove client may send, parsed
// strictly; the status message that answers bad input.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "tools/operator/foxglove_messages.h"

namespace fovea::tools {
namespace {

TEST(FoxgloveMessages, SubscribeAndUnsubscribeAsTheReferenceClientWritesThem) {
  Result<FoxgloveRequest> s = parseFoxgloveRequest(R"({"op":"subscribe","subscriptions":[{"id":0,"channelId":1},{"id":7,"channelId":4}]})");
  ASSERT_TRUE(s) << s.status().message();
  EXPECT_EQ(s->kind, FoxgloveRequest::Kind::kSubscribe);
  ASSERT_EQ(s->subscriptions.size(), 2u);
  EXPECT_EQ(s->subscriptions[1], (FoxgloveSubscription{7, 4}));
  EXPECT_TRUE(s->refused.empty());
  Result<FoxgloveRequest> u = parseFoxgloveRequest(R"({"op":"unsubscribe","subscriptionIds":[0,4294967295]})");
  ASSERT_TRUE(u);
  EXPECT_EQ(u->kind, FoxgloveRequest::Kind::kUnsubscribe);
  EXPECT_EQ(u->subscription_ids, (std::vector<uint32_t>{0, 4294967295u}));
}

TEST(FoxgloveMessages, MalformedEntriesAreLeftOutWithAReason) {
  Result<FoxgloveRequest> s = parseFoxgloveRequest(
      R"({"op":"subscribe","subscriptions":[{"id":-1,"channelId":1},{"id":1.5,"channelId":1},{"id":4294967296,"channelId":1},"x",{"id":2},{"id":3,"channelId":2}]})");
  ASSERT_TRUE(s);
  EXPECT_EQ(s->subscriptions, (std::vector<FoxgloveSubscription>{{3, 2}}));
  EXPECT_EQ(s->refused.size(), 5u);
  Result<FoxgloveRequest> u = parseFoxgloveRequest(R"({"op":"unsubscribe","subscriptionIds":["1",null,2]})");
  ASSERT_TRUE(u);
  EXPECT_EQ(u->subscription_ids, (std::vector<uint32_t>{2}));
  EXPECT_EQ(u->refused.size(), 2u);
}

TEST(FoxgloveMessages, BadMessagesAreErrorsThatSayWhy) {
  EXPECT_EQ(parseFoxgloveRequest("garbage").status().code(), ErrorCode::kParseError);
  EXPECT_EQ(parseFoxgloveRequest("").status().code(), ErrorCode::kParseError);
  EXPECT_EQ(parseFoxgloveRequest("[1,2]").status().code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(parseFoxgloveRequest(R"({"op":3})").status().code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(parseFoxgloveRequest(R"({"op":"subscribe"})").status().code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(parseFoxgloveRequest(R"({"op":"unsubscribe","subscriptionIds":{}})").status().code(), ErrorCode::kInvalidArgument);
  const Result<FoxgloveRequest> unsupported = parseFoxgloveRequest(R"({"op":"clientAdvertise","channels":[]})");
  ASSERT_FALSE(unsupported);
  EXPECT_NE(unsupported.status().message().find("\"clientAdvertise\": not supported"), std::string::npos)
      << unsupported.status().message();
  // Over the limit: refused before it is parsed, even when it is a good message.
  std::string big = R"({"op":"unsubscribe","subscriptionIds":[)";
  while (big.size() <= kMaxClientMessageBytes) big += "1,";
  big += "1]}";
  const Result<FoxgloveRequest> over = parseFoxgloveRequest(big);
  ASSERT_FALSE(over);
  EXPECT_NE(over.status().message().find("refused (at most 65536)"), std::string::npos);
}

TEST(FoxgloveMessages, StatusIsJsonEvenForBytesThatAreNotUtf8) {
  const nlohmann::json ok = nlohmann::json::parse(foxgloveStatusJson(2, "subscribe: no channel 99"));
  EXPECT_EQ(ok["op"], "status");
  EXPECT_EQ(ok["level"], 2);
  EXPECT_EQ(ok["message"], "subscribe: no channel 99");
  const nlohmann::json bad = nlohmann::json::parse(foxgloveStatusJson(1, std::string("a\xff\xfe" "b")), nullptr, false);
  ASSERT_FALSE(bad.is_discarded());
  EXPECT_EQ(bad["level"], 1);
  EXPECT_EQ(bad["message"], "a\xEF\xBF\xBD\xEF\xBF\xBD" "b");
}

}  // namespace
}  // namespace fovea::tools
