// The viewer's binary frame, read back by an independent reader written here
// from the layout in docs/viewer.md, and the splat sizes.
#include <cstring>
#include <set>
#include <tuple>
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
  ASSERT_EQ(bytes, 136 + 16 * n);
  EXPECT_EQ(std::memcmp(buf.data(), "FVF2", 4), 0);
  EXPECT_EQ(readAt<uint32_t>(buf, 4), 77u);
  EXPECT_EQ(readAt<uint32_t>(buf, 8), n);
  EXPECT_EQ(readAt<uint32_t>(buf, 12), 0u) << "no map points";
  EXPECT_EQ(readAt<double>(buf, 16), 1e4);
  EXPECT_EQ(readAt<double>(buf, 24), -2.5);
  EXPECT_EQ(readAt<double>(buf, 32), 0.125);
  for (std::size_t r = 0; r < 8; ++r) {
    EXPECT_EQ(readAt<float>(buf, 40 + 4 * r), splat[r]);
    EXPECT_EQ(readAt<uint32_t>(buf, 72 + 4 * r), f.frame.points[r]);
    EXPECT_EQ(readAt<float>(buf, 104 + 4 * r), 0.0f) << "no map";
  }
  const std::size_t colours = 136 + 12 * n, regions = colours + 3 * n;
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(readAt<float>(buf, 136 + 12 * i), f.cloud.points.x()[i]);
    EXPECT_EQ(readAt<float>(buf, 136 + 12 * i + 4), f.cloud.points.y()[i]);
    EXPECT_EQ(readAt<float>(buf, 136 + 12 * i + 8), f.cloud.points.z()[i]);
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

// A brick version made by the robot's encoder and taken into the cache.
void addBrick(net::BrickCache& cache, net::BrickTag tag, int points, int64_t now) {
  pipeline::FoveatedCloud cloud(static_cast<std::size_t>(points));
  cloud.points.origin_m = Eigen::Vector3d(0.5 * tag.x, 0.5 * tag.y, 0.5 * tag.z);
  for (int i = 0; i < points; ++i) {
    ASSERT_TRUE(cloud.points.push(0.01f * static_cast<float>(i % 40), 0.01f * static_cast<float>(i / 40), 0.25f,
                                  0x010203u * static_cast<uint32_t>(i % 80)));
  }
  std::fill_n(cloud.region.begin(), cloud.size(), tag.level);
  std::fill_n(cloud.weight.begin(), cloud.size(), 1u);
  net::ChunkEncoder encoder = net::ChunkEncoder::create(net::CodecConfig{}, static_cast<std::size_t>(points)).value();
  std::vector<double> voxel(tag.level + 1u);
  for (std::size_t l = 1; l < voxel.size(); ++l) voxel[l] = 0.01 * static_cast<double>(l);
  ASSERT_TRUE(encoder.encode(cloud, voxel, 1, 0, &tag));
  alignas(8) uint8_t aligned[net::kMaxMtu];
  pipeline::FoveatedCloud decoded(static_cast<std::size_t>(points));
  for (std::size_t i = 0; i < encoder.chunkCount(); ++i) {
    const std::span<const uint8_t> c = encoder.chunk(i);
    std::memcpy(aligned, c.data(), c.size());
    decoded.clear();
    Result<net::DecodedChunk> chunk = net::decodeChunk(std::span<const uint8_t>(aligned, c.size()), decoded);
    ASSERT_TRUE(chunk) << chunk.status().message();
    cache.add(chunk.value(), decoded, 0, now);
  }
  ASSERT_GE(cache.find({tag.x, tag.y, tag.z}), 0);
}

net::BrickCache smallCache(std::size_t bricks) {
  net::BrickCacheConfig c;
  c.max_bricks = bricks;
  c.max_points = 4096;
  return net::BrickCache::create(c).value();
}

TEST(ViewFrame, TheMapsHeldBricksFollowTheFramesPoints) {
  Frame f = randomFrame(100, 4);
  net::BrickCache cache = smallCache(8);
  addBrick(cache, {3, -1, 2, 1, 0}, 150, 10);
  addBrick(cache, {-2, 0, 5, 4, 2}, 90, 10);
  std::array<float, pipeline::kMaxRegions> splat{0.004f, 0.02f};
  std::vector<uint8_t> buf(viewFrameBytes(1000));
  const double ratio = net::CodecConfig{}.periphery_step_ratio;
  const ViewPack pack = packViewFrame(f.frame, splat, ViewMap{&cache, ratio, 20}, buf);
  const std::size_t live = 100, m = 240, n = live + m;
  ASSERT_EQ(pack.bytes, viewFrameBytes(n));
  EXPECT_EQ(pack.map_points, m);
  EXPECT_EQ(pack.map_points_left_out, 0u);
  EXPECT_EQ(readAt<uint32_t>(buf, 8), n);
  EXPECT_EQ(readAt<uint32_t>(buf, 12), m);
  for (std::size_t r = 0; r < 8; ++r) EXPECT_EQ(readAt<uint32_t>(buf, 72 + 4 * r), f.frame.points[r]) << "live points only";
  // Level 0: raw surfels, drawn like the frame's fovea; level 2: its voxel (2 cm).
  EXPECT_FLOAT_EQ(readAt<float>(buf, 104), 0.004f);
  EXPECT_FLOAT_EQ(readAt<float>(buf, 104 + 4 * 2), 0.02f);
  EXPECT_EQ(readAt<float>(buf, 104 + 4 * 1), 0.0f) << "no brick at level 1";
  // Every held point, at its world position less the frame's origin, with its colour, region 8 + level.
  std::multiset<std::tuple<float, float, float, uint32_t, uint8_t>> want, got;
  for (std::size_t slot = 0; slot < cache.slotCount(); ++slot) {
    if (!cache.held(slot)) continue;
    cache.forEachPoint(slot, [&](const Eigen::Vector3d& w, uint32_t rgb) {
      const Eigen::Vector3d p = w - f.cloud.points.origin_m;
      want.insert({static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()), rgb,
                   static_cast<uint8_t>(8 + cache.level(slot))});
    });
  }
  ASSERT_EQ(want.size(), m);
  const std::size_t colours = 136 + 12 * n, regions = colours + 3 * n;
  for (std::size_t i = live; i < n; ++i) {
    const uint32_t rgb = (uint32_t{buf[colours + 3 * i]} << 16) | (uint32_t{buf[colours + 3 * i + 1]} << 8) |
                         buf[colours + 3 * i + 2];
    got.insert({readAt<float>(buf, 136 + 12 * i), readAt<float>(buf, 136 + 12 * i + 4), readAt<float>(buf, 136 + 12 * i + 8),
                rgb, buf[regions + i]});
  }
  EXPECT_EQ(got, want);
  // The frame's own points come first, unchanged.
  for (std::size_t i = 0; i < live; ++i) {
    EXPECT_EQ(readAt<float>(buf, 136 + 12 * i), f.cloud.points.x()[i]);
    EXPECT_EQ(buf[regions + i], f.cloud.region[i]);
  }
}

TEST(ViewFrame, MapBricksThatDoNotFitAreLeftOutWholeAndCounted) {
  Frame f = randomFrame(100, 5);
  net::BrickCache cache = smallCache(8);
  addBrick(cache, {0, 0, 0, 1, 0}, 150, 10);
  addBrick(cache, {1, 0, 0, 1, 0}, 60, 10);
  // Room for the frame and 100 map points: the small brick fits, the large one not.
  std::vector<uint8_t> buf(viewFrameBytes(200));
  const ViewPack pack = packViewFrame(f.frame, {}, ViewMap{&cache, 0.125, 20}, buf);
  EXPECT_EQ(pack.map_points, 60u);
  EXPECT_EQ(pack.map_bricks_left_out, 1u);
  EXPECT_EQ(pack.map_points_left_out, 150u);
  EXPECT_EQ(pack.bytes, viewFrameBytes(160));
  EXPECT_EQ(readAt<uint32_t>(buf, 12), 60u);
}

TEST(ViewFrame, BricksDrawnAreTouchedSoTheCacheKeepsThem) {
  // Two bricks of room: A arrives first, B later; drawing A alone makes B the least recently needed.
  Frame f = randomFrame(10, 6);
  net::BrickCache cache = smallCache(2);
  addBrick(cache, {0, 0, 0, 1, 0}, 20, 10);
  addBrick(cache, {1, 0, 0, 1, 0}, 30, 20);
  // Room for the frame and 25 map points: A (20) is drawn at t = 30, B (30) is not.
  std::vector<uint8_t> buf(viewFrameBytes(35));
  ASSERT_EQ(packViewFrame(f.frame, {}, ViewMap{&cache, 0.125, 30}, buf).map_points, 20u);
  addBrick(cache, {2, 0, 0, 1, 0}, 20, 40);
  EXPECT_GE(cache.find({0, 0, 0}), 0) << "drawn, so kept";
  EXPECT_LT(cache.find({1, 0, 0}), 0) << "not drawn since t = 20: evicted";
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
