// The value parsers every camera backend's spec uses (hal/spec_options.h).
#include <gtest/gtest.h>

#include "hal/spec_options.h"

namespace fovea::hal {
namespace {

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
