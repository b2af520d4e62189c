// V4L2 pixel formats into depth and RGB8: fixed vectors for Z16/Y16 and the
// 4:2:2 formats, an independent floating-point BT.601 computation for every
// Y/U/V on a grid, strides with padding, short frames, and MJPEG through
// libturbojpeg: a JPEG made in the test from a known image decodes back to
// it, truncated and garbage JPEGs fail without a crash.
#include <gtest/gtest.h>

#include <turbojpeg.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "hal/camera/v4l2/pixel_formats.h"
#include "tests/support/alloc_counter.h"

namespace fovea::hal::v4l2 {
namespace {

TEST(V4l2PixelFormats, Depth16IsLittleEndianWithStride) {
  // 2x2 image, stride 6 (2 bytes of padding per row).
  const uint8_t src[] = {0x34, 0x12, 0xff, 0x00, 0xee, 0xee,  //
                         0x00, 0x00, 0x01, 0x80, 0xee, 0xee};
  uint16_t depth[4] = {};
  ASSERT_TRUE(depth16ToDepth(src, sizeof(src), 6, 2, 2, depth));
  EXPECT_EQ(depth[0], 0x1234);
  EXPECT_EQ(depth[1], 0x00ff);
  EXPECT_EQ(depth[2], 0x0000);
  EXPECT_EQ(depth[3], 0x8001);
  // The last row needs no padding: 6 + 4 bytes are enough, 9 are not.
  EXPECT_TRUE(depth16ToDepth(src, 10, 6, 2, 2, depth));
  uint16_t untouched[4] = {7, 7, 7, 7};
  EXPECT_FALSE(depth16ToDepth(src, 9, 6, 2, 2, untouched));
  EXPECT_EQ(untouched[0], 7);
  EXPECT_FALSE(depth16ToDepth(src, sizeof(src), 3, 2, 2, untouched));  // stride below a row
  EXPECT_FALSE(depth16ToDepth(src, sizeof(src), 6, 0, 2, untouched));
}

TEST(V4l2PixelFormats, Bt601LimitedRangeFixedVectors) {
  struct Case {
    int y, u, v;
    uint8_t r, g, b;
  };
  // Black, white, and the BT.601 75%/100% primaries (studio-swing values).
  const Case cases[] = {
      {16, 128, 128, 0, 0, 0},       {235, 128, 128, 255, 255, 255}, {126, 128, 128, 128, 128, 128},
      {81, 90, 240, 255, 0, 0},      {145, 54, 34, 0, 255, 1},       {41, 240, 110, 0, 0, 255},
      {0, 0, 0, 0, 135, 0},          {255, 255, 255, 255, 125, 255},
  };
  for (const Case& c : cases) {
    uint8_t rgb[3];
    yuvToRgbPixel(c.y, c.u, c.v, rgb);
    EXPECT_EQ(rgb[0], c.r) << c.y << " " << c.u << " " << c.v;
    EXPECT_EQ(rgb[1], c.g) << c.y << " " << c.u << " " << c.v;
    EXPECT_EQ(rgb[2], c.b) << c.y << " " << c.u << " " << c.v;
  }
}

TEST(V4l2PixelFormats, Bt601MatchesFloatingPointWithinOneLevel) {
  for (int y = 0; y < 256; y += 5) {
    for (int u = 0; u < 256; u += 15) {
      for (int v = 0; v < 256; v += 15) {
        const double c = 255.0 / 219.0 * (y - 16);
        const double d = 255.0 / 224.0 * (u - 128);
        const double e = 255.0 / 224.0 * (v - 128);
        const double ref[3] = {c + 1.402 * e, c - 0.344136 * d - 0.714136 * e, c + 1.772 * d};
        uint8_t rgb[3];
        yuvToRgbPixel(y, u, v, rgb);
        for (int k = 0; k < 3; ++k) {
          const double want = std::clamp(ref[k], 0.0, 255.0);
          EXPECT_LE(std::abs(rgb[k] - want), 1.5) << "y " << y << " u " << u << " v " << v << " channel " << k;
        }
      }
    }
  }
}

TEST(V4l2PixelFormats, YuyvAndUyvySharedChroma) {
  // Two pixels: Y0 white, Y1 black, neutral chroma; then a red pair.
  const uint8_t yuyv[] = {235, 128, 16, 128, 81, 90, 81, 240};
  const uint8_t uyvy[] = {128, 235, 128, 16, 90, 81, 240, 81};
  const uint8_t want[] = {255, 255, 255, 0, 0, 0, 255, 0, 0, 255, 0, 0};
  uint8_t rgb[12] = {};
  ASSERT_TRUE(yuyvToRgb(yuyv, sizeof(yuyv), 8, 4, 1, rgb));
  EXPECT_TRUE(std::equal(rgb, rgb + 12, want));
  std::fill(rgb, rgb + 12, 0);
  ASSERT_TRUE(uyvyToRgb(uyvy, sizeof(uyvy), 8, 4, 1, rgb));
  EXPECT_TRUE(std::equal(rgb, rgb + 12, want));
  EXPECT_FALSE(yuyvToRgb(yuyv, 7, 8, 4, 1, rgb));    // short
  EXPECT_FALSE(yuyvToRgb(yuyv, 8, 8, 3, 1, rgb));    // odd width
  EXPECT_FALSE(uyvyToRgb(uyvy, 8, 4, 4, 1, rgb));    // stride below a row
}

TEST(V4l2PixelFormats, Rgb24CopiesBgr24Swaps) {
  const uint8_t src[] = {1, 2, 3, 4, 5, 6, 0, 0,  //
                         7, 8, 9, 10, 11, 12, 0, 0};
  uint8_t rgb[12] = {};
  ASSERT_TRUE(rgb24ToRgb(src, sizeof(src), 8, 2, 2, rgb));
  const uint8_t copied[] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  EXPECT_TRUE(std::equal(rgb, rgb + 12, copied));
  ASSERT_TRUE(bgr24ToRgb(src, sizeof(src), 8, 2, 2, rgb));
  const uint8_t swapped[] = {3, 2, 1, 6, 5, 4, 9, 8, 7, 12, 11, 10};
  EXPECT_TRUE(std::equal(rgb, rgb + 12, swapped));
  EXPECT_FALSE(rgb24ToRgb(src, 13, 8, 2, 2, rgb));
  EXPECT_FALSE(bgr24ToRgb(src, 13, 8, 2, 2, rgb));
}

// A smooth known image (gradients), JPEG-compressed at quality 95, 4:4:4.
class V4l2Mjpeg : public ::testing::Test {
 protected:
  static constexpr int kW = 64;
  static constexpr int kH = 48;
  void SetUp() override {
    image_.resize(static_cast<std::size_t>(kW) * kH * 3);
    for (int y = 0; y < kH; ++y) {
      for (int x = 0; x < kW; ++x) {
        uint8_t* p = &image_[(static_cast<std::size_t>(y) * kW + x) * 3];
        p[0] = static_cast<uint8_t>(x * 4);
        p[1] = static_cast<uint8_t>(y * 5);
        p[2] = static_cast<uint8_t>(128 + (x - y));
      }
    }
    tjhandle c = tjInitCompress();
    ASSERT_NE(c, nullptr);
    unsigned char* out = nullptr;
    unsigned long size = 0;
    ASSERT_EQ(tjCompress2(c, image_.data(), kW, kW * 3, kH, TJPF_RGB, &out, &size, TJSAMP_444, 95, 0), 0)
        << tjGetErrorStr2(c);
    jpeg_.assign(out, out + size);
    tjFree(out);
    tjDestroy(c);
    ASSERT_TRUE(decoder_.create().isOk());
  }
  std::vector<uint8_t> image_;
  std::vector<uint8_t> jpeg_;
  MjpegDecoder decoder_;
};

TEST_F(V4l2Mjpeg, DecodesAKnownImage) {
  std::vector<uint8_t> rgb(image_.size(), 0);
  ASSERT_TRUE(decoder_.decode(jpeg_.data(), jpeg_.size(), kW, kH, rgb.data()));
  int worst = 0;
  for (std::size_t i = 0; i < rgb.size(); ++i) worst = std::max(worst, std::abs(rgb[i] - image_[i]));
  EXPECT_LE(worst, 8);  // JPEG is lossy; quality 95 on gradients stays within a few levels
  // The same decoder again (one handle for the whole run).
  ASSERT_TRUE(decoder_.decode(jpeg_.data(), jpeg_.size(), kW, kH, rgb.data()));
}

// fovea's part allocates nothing; libjpeg-turbo takes and frees its per-image
// working memory in every decode (pixel_formats.h says so): the same count
// each frame, so it does not grow with the run. The other conversions allocate nothing.
TEST_F(V4l2Mjpeg, AllocationsPerFrameAreLibjpegsAndSteady) {
  std::vector<uint8_t> rgb(image_.size(), 0);
  ASSERT_TRUE(decoder_.decode(jpeg_.data(), jpeg_.size(), kW, kH, rgb.data()));
  uint64_t per_frame[3] = {};
  for (uint64_t& n : per_frame) {
    test::AllocationScope scope;
    ASSERT_TRUE(decoder_.decode(jpeg_.data(), jpeg_.size(), kW, kH, rgb.data()));
    n = scope.allocations();
  }
  std::printf("libjpeg-turbo allocations per MJPEG frame: %llu\n", static_cast<unsigned long long>(per_frame[0]));
  EXPECT_EQ(per_frame[0], per_frame[1]);
  EXPECT_EQ(per_frame[1], per_frame[2]);
  std::vector<uint8_t> yuyv(static_cast<std::size_t>(kW) * kH * 2, 128);
  std::vector<uint16_t> depth(static_cast<std::size_t>(kW) * kH);
  test::AllocationScope scope;
  ASSERT_TRUE(yuyvToRgb(yuyv.data(), yuyv.size(), kW * 2, kW, kH, rgb.data()));
  ASSERT_TRUE(uyvyToRgb(yuyv.data(), yuyv.size(), kW * 2, kW, kH, rgb.data()));
  ASSERT_TRUE(depth16ToDepth(yuyv.data(), yuyv.size(), kW * 2, kW, kH, depth.data()));
  EXPECT_EQ(scope.allocations(), 0u);
}

TEST_F(V4l2Mjpeg, WrongSizeIsRefused) {
  std::vector<uint8_t> rgb(static_cast<std::size_t>(kW) * 2 * kH * 3, 0);
  EXPECT_FALSE(decoder_.decode(jpeg_.data(), jpeg_.size(), kW * 2, kH, rgb.data()));
  EXPECT_FALSE(decoder_.decode(jpeg_.data(), jpeg_.size(), kW, kH - 1, rgb.data()));
}

TEST_F(V4l2Mjpeg, TruncatedJpegsFailWithoutACrash) {
  std::vector<uint8_t> rgb(image_.size(), 0);
  for (std::size_t keep : {std::size_t{0}, std::size_t{2}, std::size_t{20}, jpeg_.size() / 3, jpeg_.size() / 2,
                           jpeg_.size() - 10}) {
    EXPECT_FALSE(decoder_.decode(jpeg_.data(), keep, kW, kH, rgb.data())) << "kept " << keep << " bytes";
  }
  // The decoder still works after the failures.
  EXPECT_TRUE(decoder_.decode(jpeg_.data(), jpeg_.size(), kW, kH, rgb.data()));
}

TEST_F(V4l2Mjpeg, GarbageFailsWithoutACrash) {
  std::vector<uint8_t> rgb(image_.size(), 0);
  std::vector<uint8_t> garbage(4096);
  uint32_t state = 12345;
  for (int round = 0; round < 50; ++round) {
    for (uint8_t& b : garbage) {
      state = state * 1664525u + 1013904223u;
      b = static_cast<uint8_t>(state >> 24);
    }
    if (round % 2 == 1) {  // a valid header followed by noise
      std::copy(jpeg_.begin(), jpeg_.begin() + static_cast<std::ptrdiff_t>(std::min<std::size_t>(jpeg_.size(), 600)),
                garbage.begin());
    }
    EXPECT_FALSE(decoder_.decode(garbage.data(), garbage.size(), kW, kH, rgb.data())) << "round " << round;
  }
  EXPECT_FALSE(decoder_.decode(nullptr, 100, kW, kH, rgb.data()));
  MjpegDecoder never_created;
  EXPECT_FALSE(never_created.decode(jpeg_.data(), jpeg_.size(), kW, kH, rgb.data()));
}

}  // namespace
}  // namespace fovea::hal::v4l2
