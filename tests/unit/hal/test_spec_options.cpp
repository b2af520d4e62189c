// The tokenizer and the value parsers every camera backend's spec uses
// (hal/spec_options.h).
#include <gtest/gtest.h>

#include <string>
#include <string_view>
#include <vector>

#include "hal/spec_options.h"

namespace fovea::hal {
namespace {

using namespace std::string_view_literals;
using Head = SpecTokenRules::Head;

// An item as text, "key=value" or "key" when bare: one string per item compares
// whole token lists in one EXPECT_EQ.
std::vector<std::string> itemsText(const SpecTokens& tokens) {
  std::vector<std::string> out;
  for (const SpecItem& item : tokens.items) {
    out.push_back(std::string(item.key) + (item.has_value ? "=" + std::string(item.value) : ""));
  }
  return out;
}

using Items = std::vector<std::string>;

TEST(SpecTokens, HeadThenKeyValueItemsInOrderWithDuplicatesKept) {
  const SpecTokens tokens = tokenizeSpec("living-room,seed=3,size=64x48,seed=4");
  ASSERT_TRUE(tokens.head.has_value());
  EXPECT_EQ(*tokens.head, "living-room");
  EXPECT_EQ(itemsText(tokens), (Items{"seed=3", "size=64x48", "seed=4"}));
  EXPECT_TRUE(tokens.items[0].has_value);
  EXPECT_EQ(tokens.items[0].key, "seed");
  EXPECT_EQ(tokens.items[0].value, "3");
}

TEST(SpecTokens, SplitsAtTheFirstEqualsOnly) {
  const SpecTokens tokens = tokenizeSpec("serial=12,colour=serial=34,=x,k=,a==b");
  EXPECT_EQ(*tokens.head, "serial=12");  // kFirstItem: the head may hold '='
  ASSERT_EQ(tokens.items.size(), 4u);
  EXPECT_EQ(tokens.items[0].key, "colour");
  EXPECT_EQ(tokens.items[0].value, "serial=34");
  EXPECT_EQ(tokens.items[1].key, "");  // '=' without a key is still key=value, the key empty
  EXPECT_EQ(tokens.items[1].value, "x");
  EXPECT_TRUE(tokens.items[1].has_value);
  EXPECT_EQ(tokens.items[2].key, "k");
  EXPECT_EQ(tokens.items[2].value, "");
  EXPECT_TRUE(tokens.items[2].has_value);  // "k=" is not bare "k"
  EXPECT_EQ(tokens.items[3].value, "=b");
}

TEST(SpecTokens, BareAndEmptyItemsAreKeptForTheBackendToJudge) {
  const SpecTokens tokens = tokenizeSpec("p,loop,,x=1,");
  EXPECT_EQ(*tokens.head, "p");
  ASSERT_EQ(tokens.items.size(), 4u);
  EXPECT_EQ(tokens.items[0].key, "loop");
  EXPECT_FALSE(tokens.items[0].has_value);
  EXPECT_EQ(tokens.items[1].key, "");  // between two commas
  EXPECT_FALSE(tokens.items[1].has_value);
  EXPECT_EQ(itemsText(tokens), (Items{"loop", "", "x=1", ""}));  // the trailing comma's empty item last
}

TEST(SpecTokens, EmptyAndOnlyCommas) {
  for (const Head head : {Head::kFirstItem, Head::kFirstItemIfBare}) {
    const SpecTokens empty = tokenizeSpec("", {.head = head, .rest_key = {}, .bare_continues_value = false});
    ASSERT_TRUE(empty.head.has_value());  // "" is one empty item, bare
    EXPECT_EQ(*empty.head, "");
    EXPECT_TRUE(empty.items.empty());

    const SpecTokens commas = tokenizeSpec(",,,", {.head = head, .rest_key = {}, .bare_continues_value = false});
    EXPECT_EQ(*commas.head, "");
    EXPECT_EQ(itemsText(commas), (Items{"", "", ""}));

    const SpecTokens defaulted = tokenizeSpec(std::string_view(), {.head = head, .rest_key = {}, .bare_continues_value = false});
    EXPECT_EQ(*defaulted.head, "");
    EXPECT_TRUE(defaulted.items.empty());
  }
}

TEST(SpecTokens, AnOptionalHeadIsAbsentWhenTheFirstItemIsKeyValue) {
  const SpecTokens with_uri = tokenizeSpec("dev/1,fps=30", {.head = Head::kFirstItemIfBare, .rest_key = {}, .bare_continues_value = false});
  EXPECT_EQ(with_uri.head, std::optional<std::string_view>("dev/1"));
  EXPECT_EQ(itemsText(with_uri), (Items{"fps=30"}));

  const SpecTokens without = tokenizeSpec("fps=30,sync=off", {.head = Head::kFirstItemIfBare, .rest_key = {}, .bare_continues_value = false});
  EXPECT_FALSE(without.head.has_value());
  EXPECT_EQ(itemsText(without), (Items{"fps=30", "sync=off"}));

  const SpecTokens empty_head = tokenizeSpec(",fps=30", {.head = Head::kFirstItemIfBare, .rest_key = {}, .bare_continues_value = false});
  EXPECT_EQ(empty_head.head, std::optional<std::string_view>(""));
  EXPECT_EQ(itemsText(empty_head), (Items{"fps=30"}));

  const SpecTokens equals_only = tokenizeSpec("=", {.head = Head::kFirstItemIfBare, .rest_key = {}, .bare_continues_value = false});
  EXPECT_FALSE(equals_only.head.has_value());
  EXPECT_EQ(itemsText(equals_only), (Items{"="}));
}

TEST(SpecTokens, TheRestKeyTakesTheRestOfTheSpecCommasIncluded) {
  const SpecTokenRules rules{.head = Head::kFirstItem, .rest_key = "depth", .bare_continues_value = false};
  const SpecTokens tokens = tokenizeSpec("0,size=8x8,depth=v4l2:serial=1,colour=none,depth=x,", rules);
  EXPECT_EQ(*tokens.head, "0");
  EXPECT_EQ(itemsText(tokens), (Items{"size=8x8", "depth=v4l2:serial=1,colour=none,depth=x,"}));

  EXPECT_EQ(itemsText(tokenizeSpec("0,depth=", rules)), (Items{"depth="}));
  EXPECT_EQ(itemsText(tokenizeSpec("0,depth=,", rules)), (Items{"depth=,"}));
  // Bare "depth" and "depthx=" are ordinary items; the head is never the rest.
  EXPECT_EQ(itemsText(tokenizeSpec("0,depth,depthx=1", rules)), (Items{"depth", "depthx=1"}));
  const SpecTokens head_only = tokenizeSpec("depth=a,b", rules);
  EXPECT_EQ(*head_only.head, "depth=a");
  EXPECT_EQ(itemsText(head_only), (Items{"b"}));
  // No rest key: "=x" stays an item with an empty key.
  EXPECT_EQ(itemsText(tokenizeSpec("0,=x,y", {})), (Items{"=x", "y"}));
}

TEST(SpecTokens, BarePiecesContinueThePreviousValueWhenAsked) {
  const SpecTokenRules rules{.head = Head::kFirstItem, .rest_key = {}, .bare_continues_value = true};
  const SpecTokens tokens = tokenizeSpec("s,path=keyframes:0,1,2,3;1,4,5,6,seed=2,,x", rules);
  EXPECT_EQ(*tokens.head, "s");
  EXPECT_EQ(itemsText(tokens), (Items{"path=keyframes:0,1,2,3;1,4,5,6", "seed=2,,x"}));
  // Nothing to continue: the first bare items stay bare, and so do bare items after them.
  EXPECT_EQ(itemsText(tokenizeSpec("s,a,b,k=1,c", rules)), (Items{"a", "b", "k=1,c"}));
  EXPECT_EQ(itemsText(tokenizeSpec("s,,k=", rules)), (Items{"", "k="}));
  EXPECT_EQ(itemsText(tokenizeSpec("s,k=,", rules)), (Items{"k=,"}));
  // The joined value is a view of the spec itself.
  const std::string_view spec = "s,k=a,b";
  const SpecTokens joined = tokenizeSpec(spec, rules);
  ASSERT_EQ(joined.items.size(), 1u);
  EXPECT_EQ(joined.items[0].value.data(), spec.data() + 4);
}

TEST(SpecTokens, EmbeddedNulIsOrdinaryText) {
  const std::string_view spec = "a\0b,k\0=v\0w,\0"sv;
  const SpecTokens tokens = tokenizeSpec(spec);
  EXPECT_EQ(*tokens.head, "a\0b"sv);
  ASSERT_EQ(tokens.items.size(), 2u);
  EXPECT_EQ(tokens.items[0].key, "k\0"sv);
  EXPECT_EQ(tokens.items[0].value, "v\0w"sv);
  EXPECT_EQ(tokens.items[1].key, "\0"sv);
  EXPECT_FALSE(tokens.items[1].has_value);
}

TEST(SpecTokens, VeryLongSpecsSplitWhole) {
  constexpr std::size_t kItems = 100'000;
  std::string spec = "head";
  for (std::size_t i = 0; i < kItems; ++i) spec += ",k" + std::to_string(i) + "=" + std::string(i % 7, 'v');
  const std::string long_value(1'000'000, 'x');
  spec += ",last=" + long_value;
  const SpecTokens tokens = tokenizeSpec(spec);
  EXPECT_EQ(*tokens.head, "head");
  ASSERT_EQ(tokens.items.size(), kItems + 1);
  EXPECT_EQ(tokens.items[12345].key, "k12345");
  EXPECT_EQ(tokens.items[12345].value, std::string(12345 % 7, 'v'));
  EXPECT_EQ(tokens.items.back().value, long_value);

  const std::string commas(100'000, ',');
  EXPECT_EQ(tokenizeSpec(commas, {.head = Head::kFirstItem, .rest_key = {}, .bare_continues_value = true}).items.size(), commas.size());
  const std::string depth_of_commas = "0,depth=" + commas;  // outlives the views into it
  const SpecTokens rest = tokenizeSpec(depth_of_commas, {.head = Head::kFirstItem, .rest_key = "depth", .bare_continues_value = false});
  ASSERT_EQ(rest.items.size(), 1u);
  EXPECT_EQ(rest.items[0].value.size(), commas.size());
}

// Every character of the spec is in exactly one place: the head, a key, a
// value, or one of the separating ',' and '=' (a joined or rest value keeps its
// own commas).
TEST(SpecTokens, ViewsCoverTheSpecExactly) {
  const std::vector<std::string_view> specs = {
      "", ",", "a", "a,", ",a", "=", "==,=", "a,b=c,d", "x,k=1,2,,3,j=4", "0,depth=a,b=c", "k=v,w", ",,k,=,"};
  for (const std::string_view spec : specs) {
    for (const Head head : {Head::kFirstItem, Head::kFirstItemIfBare}) {
      for (const bool join : {false, true}) {
        const SpecTokens tokens =
            tokenizeSpec(spec, {.head = head, .rest_key = "depth", .bare_continues_value = join});
        std::string rebuilt = tokens.head.has_value() ? std::string(*tokens.head) : "";
        for (std::size_t i = 0; i < tokens.items.size(); ++i) {
          if (tokens.head.has_value() || i > 0) rebuilt += ',';
          rebuilt += tokens.items[i].key;
          if (tokens.items[i].has_value) rebuilt += "=" + std::string(tokens.items[i].value);
        }
        EXPECT_EQ(rebuilt, spec) << "head " << static_cast<int>(head) << " join " << join;
      }
    }
  }
}

TEST(SpecOptions, NumbersAreTheWholeTextOrNothing) {
  int i = 7;
  EXPECT_TRUE(parseSpecInt("42", i));
  EXPECT_EQ(i, 42);
  for (const char* bad : {"", "4x", " 4", "4 ", "0x10", "99999999999"}) EXPECT_FALSE(parseSpecInt(bad, i)) << bad;
  uint64_t u = 0;
  EXPECT_TRUE(parseSpecUint("18446744073709551615", u));
  EXPECT_FALSE(parseSpecUint("-1", u));
  double d = 0;
  EXPECT_TRUE(parseSpecDouble("0.25", d));
  EXPECT_DOUBLE_EQ(d, 0.25);
  for (const char* bad : {"", "nan", "inf", "1e999", "0.5m"}) EXPECT_FALSE(parseSpecDouble(bad, d)) << bad;
}

TEST(SpecOptions, OnOffAndItsMessage) {
  bool b = false;
  EXPECT_TRUE(parseSpecOnOff("tum", "loop", "on", b).isOk());
  EXPECT_TRUE(b);
  EXPECT_TRUE(parseSpecOnOff("tum", "loop", "off", b).isOk());
  EXPECT_FALSE(b);
  const Status s = parseSpecOnOff("tum", "loop", "yes", b);
  EXPECT_EQ(s.code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "tum: loop: expected on|off, got 'yes'");
  EXPECT_FALSE(b);  // unchanged on error
}

TEST(SpecOptions, SizeWithinItsBoundsAndItsMessage) {
  int w = 1, h = 1;
  EXPECT_TRUE(parseSpecSize("v4l2", "size", "640x480", 1, 16384, w, h).isOk());
  EXPECT_EQ(w, 640);
  EXPECT_EQ(h, 480);
  EXPECT_TRUE(parseSpecSize("mock", "size", "16x4096", 16, 4096, w, h).isOk());
  for (const char* bad : {"640", "640x", "x480", "0x480", "15x480", "640x4097", "640X480", "-640x480", "640x480x3"}) {
    const Status s = parseSpecSize("mock", "size", bad, 16, 4096, w, h);
    EXPECT_EQ(s.message(), std::string("mock: size: expected WxH with W and H in 16..4096 (e.g. 640x480), got '") +
                               bad + "'");
  }
  EXPECT_EQ(w, 16);  // unchanged on error
  EXPECT_EQ(h, 4096);
}

}  // namespace
}  // namespace fovea::hal
