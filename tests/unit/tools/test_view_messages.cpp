// The viewer's messages: what a tab may send is parsed strictly (anything else
// is an error the server counts), and what the operator sends is valid JSON.
#include <array>
#include <cmath>
#include <numbers>
#include <random>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tools/operator/view_messages.h"

namespace fovea::tools {
namespace {

TEST(ViewMessages, GazeIsParsedAndItsDirectionNormalised) {
  Result<ViewerMessage> m =
      parseViewerMessage(R"({"type":"gaze","origin":[3,0.35,1.55],"direction":[0,3,4],"orientation":[2,0,0,0]})");
  ASSERT_TRUE(m.isOk()) << m.status().message();
  EXPECT_EQ(m->kind, ViewerMessage::Kind::kGaze);
  EXPECT_DOUBLE_EQ(m->gaze.origin_m[1], 0.35);
  EXPECT_DOUBLE_EQ(m->gaze.direction[1], 0.6);
  EXPECT_DOUBLE_EQ(m->gaze.direction[2], 0.8);
  EXPECT_DOUBLE_EQ(m->gaze.orientation[0], 1.0);
  // The orientation is optional.
  m = parseViewerMessage(R"({"type":"gaze","origin":[0,0,0],"direction":[1,0,0]})");
  ASSERT_TRUE(m.isOk());
  EXPECT_DOUBLE_EQ(m->gaze.orientation[0], 1.0);
}

// Caught by fuzz_view_messages' reference oracle: the header promises that any
// non-zero finite length is accepted, but the sum of squares overflowed for
// long vectors and a 1e-12 floor refused short ones ("'direction' has no
// length").
TEST(ViewMessages, DirectionsAndOrientationsOfAnyNonZeroFiniteLengthAreNormalised) {
  constexpr double kH = std::numbers::sqrt2 / 2;
  const struct {
    const char* text;
    std::array<double, 3> direction;
    std::array<double, 4> orientation;
  } cases[] = {
      {R"({"type":"gaze","origin":[0,0,0],"direction":[1e200,1e200,0]})", {kH, kH, 0}, {1, 0, 0, 0}},
      {R"({"type":"gaze","origin":[0,0,0],"direction":[1.7976931348623157e308,0,-1.7976931348623157e308]})",
       {kH, 0, -kH},
       {1, 0, 0, 0}},
      {R"({"type":"gaze","origin":[0,0,0],"direction":[0,1e-13,0]})", {0, 1, 0}, {1, 0, 0, 0}},
      {R"({"type":"gaze","origin":[0,0,0],"direction":[0,0,-5e-324]})", {0, 0, -1}, {1, 0, 0, 0}},
      {R"({"type":"gaze","origin":[0,0,0],"direction":[1,0,0],"orientation":[1e-300,0,0,0]})", {1, 0, 0}, {1, 0, 0, 0}},
      {R"({"type":"gaze","origin":[0,0,0],"direction":[1,0,0],"orientation":[0,1e300,0,1e300]})",
       {1, 0, 0},
       {0, kH, 0, kH}},
  };
  for (const auto& c : cases) {
    Result<ViewerMessage> m = parseViewerMessage(c.text);
    ASSERT_TRUE(m.isOk()) << c.text << ": " << m.status().message();
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(m->gaze.direction[i], c.direction[i], 1e-15) << c.text;
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(m->gaze.orientation[i], c.orientation[i], 1e-15) << c.text;
  }
}

TEST(ViewMessages, ModeIsParsed) {
  Result<ViewerMessage> m = parseViewerMessage(R"({"type":"mode","gaze":"script"})");
  ASSERT_TRUE(m.isOk());
  EXPECT_EQ(m->kind, ViewerMessage::Kind::kMode);
  EXPECT_EQ(m->mode, GazeMode::kScript);
  EXPECT_EQ(parseViewerMessage(R"({"type":"mode","gaze":"cursor"})")->mode, GazeMode::kCursor);
}

TEST(ViewMessages, EveryMalformedMessageIsAnErrorThatSaysWhy) {
  const struct {
    const char* text;
    const char* why;
  } cases[] = {
      {"", "not JSON"},
      {"{", "not JSON"},
      {"[1,2,3]", "not a JSON object"},
      {R"({"origin":[0,0,0]})", "no 'type'"},
      {R"({"type":7})", "no 'type'"},
      {R"({"type":"teleport"})", "unknown type"},
      {R"({"type":"gaze","direction":[1,0,0]})", "'origin' is missing"},
      {R"({"type":"gaze","origin":[0,0],"direction":[1,0,0]})", "'origin' is not an array of 3"},
      {R"({"type":"gaze","origin":"here","direction":[1,0,0]})", "'origin' is not an array of 3"},
      {R"({"type":"gaze","origin":[0,0,"x"],"direction":[1,0,0]})", "non-number"},
      {R"({"type":"gaze","origin":[0,0,1e400],"direction":[1,0,0]})", ""},
      {R"({"type":"gaze","origin":[0,0,2e6],"direction":[1,0,0]})", "1e6 m"},
      {R"({"type":"gaze","origin":[0,0,0],"direction":[0,0,0]})", "'direction' has no length"},
      {R"({"type":"gaze","origin":[0,0,0],"direction":[1,0,0],"orientation":[0,0,0,0]})", "'orientation' has no length"},
      {R"({"type":"gaze","origin":[0,0,0],"direction":[1,0,0],"orientation":[1,0,0]})", "'orientation' is not an array of 4"},
      {R"({"type":"mode"})", "'gaze' is missing"},
      {R"({"type":"mode","gaze":"telepathy"})", "neither cursor nor script"},
  };
  for (const auto& c : cases) {
    Result<ViewerMessage> m = parseViewerMessage(c.text);
    ASSERT_FALSE(m.isOk()) << c.text;
    EXPECT_NE(m.status().message().find(c.why), std::string::npos) << c.text << ": " << m.status().message();
  }
  // Oversized: refused before parsing.
  const std::string big = R"({"type":"mode","gaze":"cursor","pad":")" + std::string(kMaxViewerMessageBytes, 'x') + "\"}";
  EXPECT_FALSE(parseViewerMessage(big).isOk());
}

// Random bytes, and random mutations of a valid message, never crash and
// never yield a gaze that is not finite and unit.
TEST(ViewMessages, RandomInputNeverYieldsAnInvalidGaze) {
  std::mt19937 rng(12);
  const std::string valid = R"({"type":"gaze","origin":[3,0.35,1.55],"direction":[0,1,0],"orientation":[1,0,0,0]})";
  int accepted = 0;
  for (int i = 0; i < 20000; ++i) {
    std::string text;
    if (i % 2 == 0) {
      text.resize(rng() % 200);
      for (char& c : text) c = static_cast<char>(rng());
    } else {
      text = valid;
      for (int k = 0, n = 1 + static_cast<int>(rng() % 4); k < n; ++k) text[rng() % text.size()] = static_cast<char>(rng());
    }
    Result<ViewerMessage> m = parseViewerMessage(text);
    if (!m.isOk() || m->kind != ViewerMessage::Kind::kGaze) continue;
    ++accepted;
    double n2 = 0;
    for (double d : m->gaze.direction) {
      ASSERT_TRUE(std::isfinite(d)) << text;
      n2 += d * d;
    }
    EXPECT_NEAR(std::sqrt(n2), 1.0, 1e-12) << text;
    for (double o : m->gaze.origin_m) ASSERT_TRUE(std::isfinite(o) && std::fabs(o) <= 1e6) << text;
  }
  EXPECT_GT(accepted, 0);  // some mutations (a digit for a digit) stay valid
}

TEST(ViewMessages, WhatTheOperatorSendsIsJson) {
  using nlohmann::json;
  const json hello = json::parse(helloJson(3, 120.0, GazeMode::kCursor, "fixed:0,0,1>0,1,1",
                                           std::array<double, 6>{0, 0, 1, 0, 2, 1}));
  EXPECT_EQ(hello["type"], "hello");
  EXPECT_EQ(hello["tab"], 3);
  EXPECT_EQ(hello["initial_eye"]["target"][1], 2.0);
  EXPECT_TRUE(json::parse(helloJson(1, 60.0, GazeMode::kScript, "", std::nullopt))["script"].is_null());

  // A refusal's text may hold bytes that are not UTF-8: still valid JSON.
  const json state = json::parse(stateJson(LinkState::kRefused, std::string("busy \xff\xfe"), "127.0.0.1:7000"));
  EXPECT_EQ(state["state"], "refused");

  ViewerFigures f;
  f.fps = 30.0;
  f.latency_p50_ms = NAN;  // not measured yet
  f.points_per_region = {10, 20};
  f.robot_gaze_direction = std::array<double, 3>{0, 1, 0};
  const json stats = json::parse(statsJson(f, 5));
  EXPECT_EQ(stats["fps"], 30.0);
  EXPECT_TRUE(stats["latency_ms"]["p50"].is_null());
  EXPECT_EQ(stats["points_per_region"][1], 20);
  EXPECT_TRUE(stats["robot"]["gaze_age_ms"].is_null());
  EXPECT_EQ(stats["robot"]["gaze_direction"][1], 1.0);
  EXPECT_EQ(stats["view"]["frames_dropped_for_tab"], 5);
}

}  // namespace
}  // namespace fovea::tools
