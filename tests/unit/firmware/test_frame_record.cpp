// A recorded camera frame (firmware/frame_record.h): written and read back bit
// for bit, the layout checked against offsets written out here, and every way a
// record can be wrong refused with its reason.
#include "firmware/frame_record.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace fovea::firmware {
namespace {

hal::RgbdFrame randomFrame(int width, int height, bool has_rgb, uint32_t seed) {
  hal::RgbdFrame frame(width, height);
  EXPECT_TRUE(frame.setSize(width, height));
  std::mt19937 rng(seed);
  for (std::size_t i = 0; i < frame.pixelCount(); ++i) frame.depth()[i] = static_cast<uint16_t>(rng());
  for (std::size_t i = 0; i < frame.pixelCount() * 3; ++i) frame.rgb()[i] = static_cast<uint8_t>(rng());
  frame.has_rgb = has_rgb;
  frame.intrinsics = {width, height, 525.0 + seed, 524.5, 319.5, 239.25};
  frame.depth_scale_m = 1.0 / 5000.0;
  frame.T_world_cam.R_world_cam = Eigen::AngleAxisd(0.3 + seed, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  frame.T_world_cam.t_world_cam = {1.25, -2.5, 1e6 + 0.125};
  frame.stamp_ns = 1'311'868'164'363'181'000 + seed;
  frame.sequence = 42 + seed;
  return frame;
}

void expectSameFrame(const hal::RgbdFrame& a, const hal::RgbdFrame& b) {
  ASSERT_EQ(a.width(), b.width());
  ASSERT_EQ(a.height(), b.height());
  EXPECT_EQ(a.has_rgb, b.has_rgb);
  EXPECT_EQ(0, std::memcmp(a.depth(), b.depth(), a.pixelCount() * 2));
  if (a.has_rgb) {
    EXPECT_EQ(0, std::memcmp(a.rgb(), b.rgb(), a.pixelCount() * 3));
  }
  EXPECT_EQ(a.intrinsics.width, b.intrinsics.width);
  EXPECT_EQ(a.intrinsics.height, b.intrinsics.height);
  EXPECT_EQ(a.intrinsics.fx, b.intrinsics.fx);
  EXPECT_EQ(a.intrinsics.fy, b.intrinsics.fy);
  EXPECT_EQ(a.intrinsics.cx, b.intrinsics.cx);
  EXPECT_EQ(a.intrinsics.cy, b.intrinsics.cy);
  EXPECT_EQ(a.depth_scale_m, b.depth_scale_m);
  EXPECT_EQ(a.T_world_cam.R_world_cam, b.T_world_cam.R_world_cam);
  EXPECT_EQ(a.T_world_cam.t_world_cam, b.T_world_cam.t_world_cam);
  EXPECT_EQ(a.stamp_ns, b.stamp_ns);
  EXPECT_EQ(a.sequence, b.sequence);
}

TEST(FrameRecord, RoundTripsBitForBitWithAndWithoutColour) {
  for (const bool rgb : {true, false}) {
    for (const auto& [w, h] : {std::pair{640, 480}, std::pair{1, 1}, std::pair{7, 3}}) {
      const hal::RgbdFrame frame = randomFrame(w, h, rgb, static_cast<uint32_t>(w + h));
      std::vector<uint8_t> bytes(frameRecordBytes(w, h, rgb));
      ASSERT_EQ(encodeFrameRecord(frame, bytes), bytes.size());
      hal::RgbdFrame back(640, 480);
      ASSERT_TRUE(decodeFrameRecord(bytes, back)) << decodeFrameRecord(bytes, back).message();
      expectSameFrame(frame, back);
    }
  }
}

// The layout of frame_record.h, read with offsets written out here.
TEST(FrameRecord, LayoutIsTheDocumentedOne) {
  const hal::RgbdFrame frame = randomFrame(4, 2, true, 1);
  std::vector<uint8_t> bytes(frameRecordBytes(4, 2, true));
  ASSERT_EQ(bytes.size(), 168u + 8 * 2 + 8 * 3);
  ASSERT_EQ(encodeFrameRecord(frame, bytes), bytes.size());
  auto u32 = [&](std::size_t o) { return static_cast<uint32_t>(bytes[o] | bytes[o + 1] << 8 | bytes[o + 2] << 16 | uint32_t{bytes[o + 3]} << 24); };
  auto f64 = [&](std::size_t o) {
    uint64_t bits = 0;
    for (int i = 7; i >= 0; --i) bits = bits << 8 | bytes[o + static_cast<std::size_t>(i)];
    double d;
    std::memcpy(&d, &bits, 8);
    return d;
  };
  EXPECT_EQ(std::string(bytes.begin(), bytes.begin() + 4), "FVFR");
  EXPECT_EQ(bytes[4] | bytes[5] << 8, 1);
  EXPECT_EQ(bytes[6] | bytes[7] << 8, 1);
  EXPECT_EQ(u32(8), 4u);
  EXPECT_EQ(u32(12), 2u);
  EXPECT_EQ(u32(16), 43u);  // the sequence's low word
  EXPECT_EQ(f64(32), frame.intrinsics.fx);
  EXPECT_EQ(f64(56), frame.intrinsics.cy);
  EXPECT_EQ(f64(64), 1.0 / 5000.0);
  EXPECT_EQ(f64(72 + 8 * 5), frame.T_world_cam.R_world_cam(1, 2));
  EXPECT_EQ(f64(144 + 16), 1e6 + 0.125);
  EXPECT_EQ(bytes[168] | bytes[169] << 8, frame.depth()[0]);
  EXPECT_EQ(bytes[168 + 16], frame.rgb()[0]);
  EXPECT_EQ(bytes.back(), frame.rgb()[8 * 3 - 1]);
}

TEST(FrameRecord, TooSmallABufferWritesNothing) {
  const hal::RgbdFrame frame = randomFrame(8, 8, true, 2);
  std::vector<uint8_t> bytes(frameRecordBytes(8, 8, true) - 1, 0xAB);
  EXPECT_EQ(encodeFrameRecord(frame, bytes), 0u);
  EXPECT_EQ(bytes.front(), 0xAB);
}

TEST(FrameRecord, EveryWrongRecordIsRefusedWithItsReason) {
  const hal::RgbdFrame frame = randomFrame(16, 8, true, 3);
  std::vector<uint8_t> good(frameRecordBytes(16, 8, true));
  ASSERT_EQ(encodeFrameRecord(frame, good), good.size());
  hal::RgbdFrame slot(16, 8);
  auto refused = [&](std::vector<uint8_t> bytes, const std::string& why) {
    const Status s = decodeFrameRecord(bytes, slot);
    EXPECT_FALSE(s) << why;
    EXPECT_NE(s.message().find(why), std::string::npos) << s.message();
  };
  auto patched = [&](std::size_t offset, const void* value, std::size_t size) {
    std::vector<uint8_t> bytes = good;
    std::memcpy(bytes.data() + offset, value, size);
    return bytes;
  };
  // Every cut, from nothing to one byte short.
  for (std::size_t n = 0; n < good.size(); ++n) {
    EXPECT_FALSE(decodeFrameRecord(std::span<const uint8_t>(good.data(), n), slot)) << n;
  }
  std::vector<uint8_t> longer = good;
  longer.push_back(0);
  refused(longer, "frame takes");
  refused(patched(0, "FVFX", 4), "magic");
  const uint16_t v2 = 2, flags = 6;
  refused(patched(4, &v2, 2), "version 2");
  refused(patched(6, &flags, 2), "unknown flags");
  const uint32_t zero = 0, huge = 1u << 20;
  refused(patched(8, &zero, 4), "no camera's");
  refused(patched(12, &huge, 4), "no camera's");
  // A record that says it has no colour is shorter: this one is too long for that.
  const uint16_t no_rgb = 0;
  refused(patched(6, &no_rgb, 2), "frame takes");
  // Bigger than the slot.
  hal::RgbdFrame small(8, 8);
  const Status s = decodeFrameRecord(good, small);
  EXPECT_FALSE(s);
  EXPECT_NE(s.message().find("larger than the frame slot"), std::string::npos) << s.message();
  // What the pipeline would refuse.
  const double nan = std::numeric_limits<double>::quiet_NaN(), negative = -1.0, two = 2.0;
  refused(patched(32, &nan, 8), "focal lengths");
  refused(patched(40, &negative, 8), "focal lengths");
  refused(patched(64, &negative, 8), "depth scale");
  refused(patched(72, &two, 8), "rotation");
  refused(patched(144, &nan, 8), "pose is not finite");
  // And the good one still reads.
  EXPECT_TRUE(decodeFrameRecord(good, slot));
}

}  // namespace
}  // namespace fovea::firmware
