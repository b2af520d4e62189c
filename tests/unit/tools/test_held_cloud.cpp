// MAP-DELTA's quality pieces: what fovea-operator --save-held writes
// (tools/operator/held_cloud.h: a frame's live points and every held brick, and
// the text beside them) read back as written, and fovea-eval's nearest-point
// above-MAR share for such a cloud (tools/eval/quality/held_error.h).
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>

#include "net/codec.h"
#include "tools/eval/quality/held_error.h"
#include "tools/operator/held_cloud.h"
#include "tools/operator/map_holder.h"

namespace fovea::tools {
namespace {

// One brick version's encoded parts: `points` points on a slab at the brick
// (as test_map_holder.cpp makes them), the brick's level in its tag.
std::vector<std::vector<uint8_t>> brickParts(net::BrickTag tag, int points) {
  pipeline::FoveatedCloud cloud(static_cast<std::size_t>(points));
  cloud.points.origin_m = Eigen::Vector3d(0.5 * tag.x, 0.5 * tag.y, 0.5 * tag.z);
  for (int i = 0; i < points; ++i) {
    EXPECT_TRUE(cloud.points.push(0.002f * static_cast<float>(i % 100), 0.002f * static_cast<float>(i / 100), 0.0f,
                                  0x102030u + static_cast<uint32_t>(i)));
  }
  std::fill_n(cloud.region.begin(), cloud.size(), uint8_t{0});
  std::fill_n(cloud.weight.begin(), cloud.size(), 1u);
  net::ChunkEncoder encoder = net::ChunkEncoder::create(net::CodecConfig{}, static_cast<std::size_t>(points)).value();
  const double fovea[1] = {0.0};
  EXPECT_TRUE(encoder.encode(cloud, fovea, 1, 0, &tag));
  std::vector<std::vector<uint8_t>> out;
  for (std::size_t i = 0; i < encoder.chunkCount(); ++i) {
    const std::span<const uint8_t> c = encoder.chunk(i);
    out.emplace_back(c.begin(), c.end());
  }
  return out;
}

class HeldCloudTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("fovea_test_held_cloud_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  void addBrick(MapHolder& map, net::BrickTag tag, int points) {
    for (const auto& p : brickParts(tag, points)) {
      ASSERT_LE(p.size(), sizeof aligned_);
      std::memcpy(aligned_, p.data(), p.size());
      (void)map.add(std::span<const uint8_t>(aligned_, p.size()), 1);
    }
  }
  // Two bricks held: 300 points at level 0 and 120 at level 3.
  void addTwoBricks(MapHolder& map) {
    net::BrickTag a{};
    a.x = 2;
    a.y = -1;
    a.z = 3;
    a.version = 1;
    a.level = 0;
    net::BrickTag b = a;
    b.x = -4;
    b.level = 3;
    addBrick(map, a, 300);
    addBrick(map, b, 120);
    ASSERT_EQ(map.cache().bricksHeld(), 2u);
  }
  std::filesystem::path dir_;
  alignas(8) uint8_t aligned_[net::kMaxMtu];
};

// The live frame's regions: 0 and 2.
constexpr uint8_t kLiveRegions[5] = {0, 0, 2, 2, 2};

// A frame of 5 live points in regions 0 and 2, whole.
void makeWholeLiveFrame(pipeline::FoveatedCloud& live, net::AssembledFrame& f) {
  live.points.origin_m = Eigen::Vector3d(10.0, 20.0, 30.0);
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(live.points.push(0.1f * static_cast<float>(i), 0.0f, 1.0f, 0xff0000u + static_cast<uint32_t>(i)));
  std::copy(kLiveRegions, kLiveRegions + 5, live.region.begin());
  f.frame_id = 93;
  f.summary_received = true;
  f.points = {2, 0, 3};
  f.chunks_received = {1, 0, 1};
  f.chunks_expected = {1, 0, 1};
  f.step_m[2] = 0.0005;
  f.cloud = &live;
}

// The held cloud of that frame and the two bricks: the live points first, in
// world coordinates and with their regions, then the cache's points of each brick.
void expectLivePointsThenTheBricks(const HeldCloud& held, const MapHolder& map) {
  EXPECT_EQ(held.info.frame_id, 93u);
  EXPECT_EQ(held.info.live_points, 5u);
  EXPECT_EQ(held.info.map_points, 420u);
  EXPECT_EQ(held.info.map_bricks, 2u);
  EXPECT_EQ(held.info.live_step_m[2], 0.0005);
  ASSERT_EQ(held.points.size(), 425u);
  ASSERT_EQ(held.region.size(), 425u);
  // The live points first, in world coordinates and with their regions.
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(held.region[i], kLiveRegions[i]);
    EXPECT_NEAR((held.points.world(i) - Eigen::Vector3d(10.0 + 0.1 * i, 20.0, 31.0)).norm(), 0.0, 1e-5);
  }
  // Then each brick's points: 8 + its level, where the cache has them.
  std::size_t level0 = 0, level3 = 0;
  for (std::size_t i = 5; i < 425; ++i) {
    if (held.region[i] == kHeldMapRegion + 0) ++level0;
    if (held.region[i] == kHeldMapRegion + 3) ++level3;
  }
  EXPECT_EQ(level0, 300u);
  EXPECT_EQ(level3, 120u);
  std::vector<Eigen::Vector3d> cached;
  for (std::size_t slot = 0; slot < map.cache().slotCount(); ++slot) {
    if (map.cache().held(slot)) map.cache().forEachPoint(slot, [&](const Eigen::Vector3d& w, uint32_t) { cached.push_back(w); });
  }
  ASSERT_EQ(cached.size(), 420u);
  for (std::size_t i = 0; i < cached.size(); ++i) EXPECT_NEAR((held.points.world(5 + i) - cached[i]).norm(), 0.0, 2e-5) << i;
  EXPECT_GT(held.info.map_step_m[3], 0.0);
  EXPECT_EQ(held.info.map_step_m[1], 0.0);  // no brick at level 1
}

// Saved and read back: the same points (double coordinates), colours, regions and text.
void expectSavedAndReadBackTheSame(const std::string& path, const HeldCloud& held) {
  ASSERT_TRUE(saveHeldCloud(path, held));
  Result<HeldCloud> back = loadHeldCloud(path);
  ASSERT_TRUE(back) << back.status().message();
  EXPECT_EQ(back->info.frame_id, 93u);
  EXPECT_EQ(back->info.live_points, 5u);
  EXPECT_EQ(back->info.map_points, 420u);
  EXPECT_EQ(back->info.map_bricks, 2u);
  EXPECT_EQ(back->info.live_step_m, held.info.live_step_m);
  EXPECT_EQ(back->info.map_step_m, held.info.map_step_m);
  EXPECT_EQ(back->info.periphery_step_ratio, held.info.periphery_step_ratio);
  ASSERT_EQ(back->points.size(), 425u);
  EXPECT_EQ(back->region, held.region);
  for (std::size_t i = 0; i < 425; ++i) {
    EXPECT_NEAR((back->points.world(i) - held.points.world(i)).norm(), 0.0, 1e-5) << i;
    EXPECT_EQ(back->points.rgb()[i], held.points.rgb()[i]) << i;
  }
}

TEST_F(HeldCloudTest, TheFramesPointsThenEveryHeldBrickReadBackAsWritten) {
  net::BrickCacheConfig config;
  config.max_bricks = 16;
  config.max_points = 1 << 14;
  MapHolder map = MapHolder::create(config).value();
  ASSERT_NO_FATAL_FAILURE(addTwoBricks(map));

  pipeline::FoveatedCloud live(5);
  net::AssembledFrame f;
  ASSERT_NO_FATAL_FAILURE(makeWholeLiveFrame(live, f));
  EXPECT_TRUE(frameComplete(f));

  const HeldCloud held = heldCloud(f, map.cache());
  ASSERT_NO_FATAL_FAILURE(expectLivePointsThenTheBricks(held, map));
  ASSERT_NO_FATAL_FAILURE(expectSavedAndReadBackTheSame((dir_ / "held.ply").string(), held));
}

TEST_F(HeldCloudTest, AFrameIsWholeWithItsSummaryAndEveryChunk) {
  pipeline::FoveatedCloud live(1);
  net::AssembledFrame f;
  f.cloud = &live;
  f.chunks_expected = {2, 1};
  f.chunks_received = {2, 1};
  EXPECT_FALSE(frameComplete(f));  // no summary: completed by a newer frame
  f.summary_received = true;
  EXPECT_TRUE(frameComplete(f));
  f.chunks_received = {2, 0};
  EXPECT_FALSE(frameComplete(f));  // a chunk lost
  f.chunks_received = {2, 1};
  f.cloud = nullptr;
  EXPECT_FALSE(frameComplete(f));
}

TEST_F(HeldCloudTest, ReadingSaysWhatIsWrong) {
  const std::string path = (dir_ / "held.ply").string();
  Result<HeldCloud> none = loadHeldCloud(path);
  ASSERT_FALSE(none);
  EXPECT_NE(none.status().message().find("held.ply.txt"), std::string::npos);

  HeldCloud held;
  held.info.frame_id = 7;
  held.info.live_points = 2;
  held.points = pipeline::PointCloud(2);
  ASSERT_TRUE(held.points.push(0, 0, 1, 0));
  ASSERT_TRUE(held.points.push(0, 1, 1, 0));
  held.region = {0, 1};
  ASSERT_TRUE(saveHeldCloud(path, held));
  ASSERT_TRUE(loadHeldCloud(path));
  // The text says three points, the PLY has two.
  {
    std::ofstream txt(path + ".txt");
    txt << heldInfoText([&] {
      HeldCloudInfo i = held.info;
      i.map_points = 1;
      return i;
    }());
  }
  Result<HeldCloud> mismatch = loadHeldCloud(path);
  ASSERT_FALSE(mismatch);
  EXPECT_EQ(mismatch.status().code(), ErrorCode::kParseError);
  // A line it does not know, or one cut short.
  std::ofstream(path + ".txt") << "frame_id 7\nlive_points\n";
  Result<HeldCloud> cut = loadHeldCloud(path);
  ASSERT_FALSE(cut);
  EXPECT_NE(cut.status().message().find("live_points"), std::string::npos);
}

// The nearest-point share: an eye at the origin looking down +z at a wall 2 m
// away; the input on the wall, the drawn cloud the same points moved sideways.
TEST(HeldShareAboveMar, CountsTheNearestPointsDisplacementAgainstTheMar) {
  eval::EyeCamera eye;
  eye.width = 200;
  eye.height = 200;
  eye.horizontal_fov_deg = 90.0;
  pipeline::PointCloud input(400), drawn(400), far_off(1);
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 20; ++j) {
      const float x = -0.2f + 0.02f * static_cast<float>(i), y = -0.2f + 0.02f * static_cast<float>(j);
      ASSERT_TRUE(input.push(x, y, 2.0f, 0));
      ASSERT_TRUE(drawn.push(x + 0.0001f, y, 2.0f, 0));  // 0.1 mm at 2 m: 0.003 degrees, below 1 arcmin
    }
  }
  std::size_t seen = 0;
  EXPECT_EQ(eval::heldShareAboveMar(input, drawn, eye, Eigen::Vector3d::UnitZ(), 0.022, &seen), 0.0);
  EXPECT_EQ(seen, 400u);
  // Moved 8 mm (0.23 degrees): above the MAR near the gaze (1 arcmin + 0.022 x ecc,
  // ecc up to 8 degrees here: at most 0.19 degrees).
  for (std::size_t i = 0; i < drawn.size(); ++i) drawn.x()[i] = input.x()[i] + 0.008f;
  EXPECT_EQ(eval::heldShareAboveMar(input, drawn, eye, Eigen::Vector3d::UnitZ(), 0.022), 1.0);
  // A coarse observer (m = 0.2) does not see it beyond about 1 degree.
  const double coarse = eval::heldShareAboveMar(input, drawn, eye, Eigen::Vector3d::UnitZ(), 0.2);
  EXPECT_GT(coarse, 0.0);
  EXPECT_LT(coarse, 0.1);
  // Nothing within 10 cm: above.
  ASSERT_TRUE(far_off.push(5.0f, 5.0f, 2.0f, 0));
  EXPECT_EQ(eval::heldShareAboveMar(input, far_off, eye, Eigen::Vector3d::UnitZ(), 0.022), 1.0);
  // Points behind the eye or off its image are not judged: NaN when none is left.
  for (std::size_t i = 0; i < input.size(); ++i) input.z()[i] = -2.0f;
  EXPECT_TRUE(std::isnan(eval::heldShareAboveMar(input, drawn, eye, Eigen::Vector3d::UnitZ(), 0.022, &seen)));
  EXPECT_EQ(seen, 0u);
}

}  // namespace
}  // namespace fovea::tools
