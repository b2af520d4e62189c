// The viewer's binary frame, read back by an independent reader written here
// from the layout in docs/viewer.md, and the splat sizes.
#include <cstring>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "tools/operator/view_frame.h"

namespace fovea::tools {
namespace {

template <typename T>
T readAt(const std::vector<uint8_t>& b, std::size_t offset) {
  T v;
  std::memcpy(&v, b.data() + offset, sizeof v);
  return v;
}

struct Frame {
  pipeline::FoveatedCloud cloud{1000};
  net::AssembledFrame frame;
};

Frame randomFrame(std::size_t n, uint32_t seed) {
  Frame f;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coord(-5.f, 5.f);
  f.cloud.points.origin_m = {1e4, -2.5, 0.125};
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_TRUE(f.cloud.points.push(coord(rng), coord(rng), coord(rng), static_cast<uint32_t>(rng()) & 0xffffff));
    f.cloud.region[i] = static_cast<uint8_t>(rng() % 4);
    f.frame.points[f.cloud.region[i]] += 1;
  }
  f.frame.frame_id = 77;
  f.frame.cloud = &f.cloud;
  return f;
}

TEST(ViewFrame, LayoutReadsBackExactly) {
  Frame f = randomFrame(321, 1);
  std::array<float, pipeline::kMaxRegions> splat{0.004f, 0.02f, 0.05f, 0.1f};
  std::vector<uint8_t> buf(viewFrameBytes(1000));
  const std::size_t bytes = packViewFrame(f.frame, splat, buf);
  const std::size_t n = 321;
  ASSERT_EQ(bytes, 104 + 16 * n);
  EXPECT_EQ(std::memcmp(buf.data(), "FVF1", 4), 0);
  EXPECT_EQ(readAt<uint32_t>(buf, 4), 77u);
  EXPECT_EQ(readAt<uint32_t>(buf, 8), n);
  EXPECT_EQ(readAt<uint32_t>(buf, 12), 0u);
  EXPECT_EQ(readAt<double>(buf, 16), 1e4);
  EXPECT_EQ(readAt<double>(buf, 24), -2.5);
  EXPECT_EQ(readAt<double>(buf, 32), 0.125);
  for (std::size_t r = 0; r < 8; ++r) {
    EXPECT_EQ(readAt<float>(buf, 40 + 4 * r), splat[r]);
    EXPECT_EQ(readAt<uint32_t>(buf, 72 + 4 * r), f.frame.points[r]);
  }
  const std::size_t colours = 104 + 12 * n, regions = colours + 3 * n;
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(readAt<float>(buf, 104 + 12 * i), f.cloud.points.x()[i]);
    EXPECT_EQ(readAt<float>(buf, 104 + 12 * i + 4), f.cloud.points.y()[i]);
    EXPECT_EQ(readAt<float>(buf, 104 + 12 * i + 8), f.cloud.points.z()[i]);
    const uint32_t rgb = f.cloud.points.rgb()[i];
    EXPECT_EQ(buf[colours + 3 * i], rgb >> 16);
    EXPECT_EQ(buf[colours + 3 * i + 1], (rgb >> 8) & 0xff);
    EXPECT_EQ(buf[colours + 3 * i + 2], rgb & 0xff);
    EXPECT_EQ(buf[regions + i], f.cloud.region[i]);
  }
}

TEST(ViewFrame, ABufferTooSmallOrNoCloudWritesNothing) {
  Frame f = randomFrame(10, 2);
  std::vector<uint8_t> buf(viewFrameBytes(10) - 1, 0xab);
  EXPECT_EQ(packViewFrame(f.frame, {}, buf), 0u);
  EXPECT_EQ(buf[0], 0xab);
  net::AssembledFrame empty;
  std::vector<uint8_t> big(viewFrameBytes(10));
  EXPECT_EQ(packViewFrame(empty, {}, big), 0u);
  // An empty cloud is a valid frame of no points.
  Frame none = randomFrame(0, 3);
  EXPECT_EQ(packViewFrame(none.frame, {}, big), viewFrameBytes(0));
}

TEST(SplatSizer, PeripheryFromItsStepAndTheFoveaFromItsSpacing) {
  Frame f;
  // A fovea sampled every 4 mm along a line (Morton neighbours), then region 2.
  for (int i = 0; i < 500; ++i) {
    ASSERT_TRUE(f.cloud.points.push(0.004f * static_cast<float>(i), 0.f, 1.f, 0));
    f.cloud.region[static_cast<std::size_t>(i)] = 0;
  }
  for (int i = 0; i < 50; ++i) {
    ASSERT_TRUE(f.cloud.points.push(0.1f * static_cast<float>(i), 1.f, 1.f, 0));
    f.cloud.region[static_cast<std::size_t>(500 + i)] = 2;
  }
  f.frame.cloud = &f.cloud;
  f.frame.points[0] = 500;
  f.frame.points[2] = 50;
  f.frame.step_m[0] = 0.001;
  f.frame.step_m[2] = 0.0125;
  SplatSizer sizer(0.125, 64);  // fewer pairs than the fovea has: thinned evenly
  const auto s = sizer.sizes(f.frame);
  EXPECT_NEAR(s[0], 0.004f, 1e-6f);
  EXPECT_EQ(s[1], 0.0f);  // no points
  EXPECT_NEAR(s[2], 0.1f, 1e-6f);
  EXPECT_EQ(s[3], 0.0f);
}

TEST(SplatSizer, VoxelsFinerThanTheSamplingAreDrawnAtTheSpacing) {
  Frame f;
  // Region 1: 2 mm voxels (ACUITY's finest level) holding one camera sample each,
  // 6 mm apart: drawn at 2 mm they would leave 4 mm holes.
  for (int i = 0; i < 100; ++i) {
    ASSERT_TRUE(f.cloud.points.push(0.006f * static_cast<float>(i), 0.f, 3.f, 0));
    f.cloud.region[static_cast<std::size_t>(i)] = 1;
  }
  // Region 3: 64 mm voxels, dense: each a neighbour of the next. Its splat stays its voxel.
  for (int i = 0; i < 40; ++i) {
    ASSERT_TRUE(f.cloud.points.push(0.064f * static_cast<float>(i), 1.f, 3.f, 0));
    f.cloud.region[static_cast<std::size_t>(100 + i)] = 3;
  }
  // Region 4: one lone voxel, no pair to measure: its voxel.
  ASSERT_TRUE(f.cloud.points.push(5.f, 5.f, 5.f, 0));
  f.cloud.region[140] = 4;
  // A region-1 point after it does not pair with region 1's run across region 4.
  ASSERT_TRUE(f.cloud.points.push(9.f, 9.f, 9.f, 0));
  f.cloud.region[141] = 1;
  f.frame.cloud = &f.cloud;
  f.frame.points[1] = 101;
  f.frame.points[3] = 40;
  f.frame.points[4] = 1;
  f.frame.step_m[1] = 0.002 * 0.125;
  f.frame.step_m[3] = 0.064 * 0.125;
  f.frame.step_m[4] = 0.128 * 0.125;
  SplatSizer sizer(0.125);
  const auto s = sizer.sizes(f.frame);
  EXPECT_NEAR(s[1], 0.006f, 1e-6f);
  EXPECT_NEAR(s[3], 0.064f, 1e-6f);
  EXPECT_NEAR(s[4], 0.128f, 1e-6f);
  EXPECT_EQ(s[0], 0.0f);
}

}  // namespace
}  // namespace fovea::tools
