// The operator's copy of the map (net/brick_cache.h): versions assembled from
// parts and drawn only whole, never a stale version over a newer one (also
// with versions that wrap, and against a brute-force model of random arrival
// orders with loss and duplicates), eviction of the least recently needed
// brick in fixed memory, and bad parts counted.
#include <algorithm>
#include <map>
#include <random>
#include <cstring>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "net/brick_cache.h"

namespace fovea::net {
namespace {

// One part as decodeChunk would give it: `count` points of version `version`,
// their x the part's index and y the version, so that what is drawn tells where
// it came from.
struct Part {
  DecodedChunk chunk;
  pipeline::FoveatedCloud cloud{512};
};

Part makePart(BrickKey key, uint32_t version, uint16_t part, uint16_t parts, std::size_t points = 10) {
  Part p;
  p.chunk.has_brick = true;
  p.chunk.brick = BrickTag{key.x, key.y, key.z, version, 2};
  p.chunk.chunk_index = part;
  p.chunk.chunk_count = parts;
  p.chunk.points = points;
  p.chunk.step_m = 0.0005;
  p.cloud.points.origin_m = Eigen::Vector3d(key.x, key.y, key.z) * 0.5;
  for (std::size_t i = 0; i < points; ++i) {
    EXPECT_TRUE(p.cloud.points.push(static_cast<float>(part) * 0.01f, static_cast<float>(version % 1000) * 0.001f,
                                    static_cast<float>(i) * 0.001f, 0x102030u));
  }
  return p;
}

// Small enough that a sanitizer tree allocates it quickly.
BrickCacheConfig small() {
  BrickCacheConfig config;
  config.max_bricks = 256;
  config.max_points = 1 << 14;
  return config;
}

BrickCache::Outcome add(BrickCache& cache, const Part& p, int64_t now = 0) {
  return cache.add(p.chunk, p.cloud, 0, now);
}

// The versions whose parts the drawn points carry (y encodes the version).
std::set<uint32_t> drawnVersions(const BrickCache& cache, int slot) {
  std::set<uint32_t> versions;
  const Eigen::Vector3d origin = Eigen::Vector3d(cache.key(slot).x, cache.key(slot).y, cache.key(slot).z) * 0.5;
  cache.forEachPoint(static_cast<std::size_t>(slot), [&](const Eigen::Vector3d& p, uint32_t) {
    versions.insert(static_cast<uint32_t>(std::lround((p.y() - origin.y()) * 1000.0)));
  });
  return versions;
}

TEST(BrickCache, AVersionIsDrawnOnlyWhenAllItsPartsArrived) {
  BrickCache cache = BrickCache::create(small()).value();
  const BrickKey key{1, -2, 3};
  EXPECT_EQ(add(cache, makePart(key, 7, 0, 3)), BrickCache::Outcome::kStored);
  EXPECT_EQ(add(cache, makePart(key, 7, 2, 3)), BrickCache::Outcome::kStored);
  int slot = cache.find(key);
  ASSERT_GE(slot, 0);
  EXPECT_FALSE(cache.held(static_cast<std::size_t>(slot)));
  EXPECT_EQ(add(cache, makePart(key, 7, 2, 3)), BrickCache::Outcome::kDuplicate);
  EXPECT_EQ(add(cache, makePart(key, 7, 1, 3, 300)), BrickCache::Outcome::kCompleted);
  ASSERT_TRUE(cache.held(static_cast<std::size_t>(slot)));
  EXPECT_EQ(cache.version(static_cast<std::size_t>(slot)), 7u);
  EXPECT_EQ(cache.pointCount(static_cast<std::size_t>(slot)), 320u);
  EXPECT_EQ(cache.level(static_cast<std::size_t>(slot)), 2);
  // Every point where its part put it, in world coordinates.
  std::multiset<int> parts;
  cache.forEachPoint(static_cast<std::size_t>(slot), [&](const Eigen::Vector3d& p, uint32_t rgb) {
    EXPECT_EQ(rgb, 0x102030u);
    parts.insert(static_cast<int>(std::lround((p.x() - 0.5) * 100.0)));
    EXPECT_NEAR(p.y(), -1.0 + 0.007, 1e-6);
  });
  EXPECT_EQ(parts.count(0), 10u);
  EXPECT_EQ(parts.count(1), 300u);
  EXPECT_EQ(parts.count(2), 10u);
  // Every part taken is listed for the acknowledgement, duplicates too (their ack may have been lost).
  EXPECT_EQ(cache.received().size(), 4u);
  EXPECT_EQ(cache.counters().versions, 1u);
  EXPECT_EQ(cache.bricksHeld(), 1u);
  EXPECT_EQ(cache.pointsHeld(), 320u);
}

// A brick whose surfels all went is sent as a version of no point (one empty
// chunk, net/codec.h): through the real encoder and decoder, it replaces what
// the operator draws of the brick with nothing, and an older version arriving
// late does not bring the points back.
TEST(BrickCache, AnEmptyVersionThroughTheCodecEmptiesTheBrick) {
  BrickCache cache = BrickCache::create(small()).value();
  const BrickKey key{3, 1, -2};
  ASSERT_EQ(add(cache, makePart(key, 4, 0, 1)), BrickCache::Outcome::kCompleted);
  const int slot = cache.find(key);
  ASSERT_GE(slot, 0);
  EXPECT_EQ(cache.pointCount(static_cast<std::size_t>(slot)), 10u);

  ChunkEncoder encoder = ChunkEncoder::create(CodecConfig{}, 64).value();
  pipeline::FoveatedCloud none(64);
  const double steps[3] = {0.0, 0.01, 0.02};
  const BrickTag tag{key.x, key.y, key.z, 5, 2};
  ASSERT_TRUE(encoder.encode(none, steps, 7, 0, &tag));
  ASSERT_EQ(encoder.chunkCount(), 1u);
  alignas(16) uint8_t aligned[kMaxMtu];
  const std::span<const uint8_t> c = encoder.chunk(0);
  std::memcpy(aligned, c.data(), c.size());
  pipeline::FoveatedCloud decoded(64);
  Result<DecodedChunk> d = decodeChunk(std::span<const uint8_t>(aligned, c.size()), decoded);
  ASSERT_TRUE(d) << d.status().message();
  EXPECT_TRUE(d->has_brick);
  EXPECT_EQ(d->points, 0u);
  EXPECT_EQ(d->brick.version, 5u);
  EXPECT_EQ(decoded.size(), 0u);
  EXPECT_EQ(cache.add(d.value(), decoded, 0, 0), BrickCache::Outcome::kCompleted);
  EXPECT_TRUE(cache.held(static_cast<std::size_t>(slot)));
  EXPECT_EQ(cache.version(static_cast<std::size_t>(slot)), 5u);
  EXPECT_EQ(cache.pointCount(static_cast<std::size_t>(slot)), 0u);
  EXPECT_EQ(add(cache, makePart(key, 4, 0, 1)), BrickCache::Outcome::kStale);
  EXPECT_EQ(cache.pointCount(static_cast<std::size_t>(slot)), 0u);
  // A frame (no tag) of no point is no chunk at all, as before.
  ASSERT_TRUE(encoder.encode(none, steps, 8, 0));
  EXPECT_EQ(encoder.chunkCount(), 0u);
}

TEST(BrickCache, AStaleVersionIsNeverDrawnOverANewerOneAndVersionsWrap) {
  BrickCache cache = BrickCache::create(small()).value();
  const BrickKey key{0, 0, 0};
  EXPECT_EQ(add(cache, makePart(key, 5, 0, 1)), BrickCache::Outcome::kCompleted);
  EXPECT_EQ(add(cache, makePart(key, 4, 0, 1)), BrickCache::Outcome::kStale);
  // v7 in assembly: a part of v6 is stale too, and v5 stays drawn meanwhile.
  EXPECT_EQ(add(cache, makePart(key, 7, 0, 2)), BrickCache::Outcome::kStored);
  EXPECT_EQ(add(cache, makePart(key, 6, 0, 1)), BrickCache::Outcome::kStale);
  const auto slot = static_cast<std::size_t>(cache.find(key));
  EXPECT_EQ(cache.version(slot), 5u);
  // v8 supersedes v7 in assembly.
  EXPECT_EQ(add(cache, makePart(key, 8, 0, 1)), BrickCache::Outcome::kCompleted);
  EXPECT_EQ(cache.version(slot), 8u);
  EXPECT_EQ(cache.counters().superseded_versions, 1u);
  EXPECT_EQ(drawnVersions(cache, static_cast<int>(slot)), std::set<uint32_t>{8});
  // Wrapping: 0xfffffff0 then 3 is newer (serial-number order).
  const BrickKey other{9, 9, 9};
  EXPECT_EQ(add(cache, makePart(other, 0xfffffff0u, 0, 1)), BrickCache::Outcome::kCompleted);
  EXPECT_EQ(add(cache, makePart(other, 3, 0, 1)), BrickCache::Outcome::kCompleted);
  EXPECT_EQ(add(cache, makePart(other, 0xfffffff5u, 0, 1)), BrickCache::Outcome::kStale);
  EXPECT_EQ(cache.version(static_cast<std::size_t>(cache.find(other))), 3u);
  // A version cut into another number of parts than its first part said is not the robot's.
  EXPECT_EQ(add(cache, makePart(key, 9, 0, 3)), BrickCache::Outcome::kStored);
  EXPECT_EQ(add(cache, makePart(key, 9, 1, 4)), BrickCache::Outcome::kBad);
}

// Property: random arrival orders of the parts of six successive versions, with
// loss, duplicates and reordering, checked after every part against what
// arrived so far: the drawn version never goes back, every part of it arrived,
// and it holds exactly that version's points; without loss the last version is
// drawn in the end.
TEST(BrickCache, RandomArrivalsNeverDrawAStaleOrPartialVersion) {
  std::mt19937 rng(26);
  for (int trial = 0; trial < 200; ++trial) {
    BrickCacheConfig config = small();
    config.max_points = 4096;
    config.block_points = 16;
    BrickCache cache = BrickCache::create(config).value();
    const BrickKey key{trial, 1, 2};
    const bool lossy = trial % 2 == 1;
    struct Sent {
      uint32_t version;
      uint16_t part, parts;
    };
    std::vector<Sent> sent;
    std::map<uint32_t, uint16_t> parts_of;
    const uint32_t first = trial % 4 == 0 ? 0xfffffffau : 1u;
    for (uint32_t v = 0; v < 6; ++v) {
      const uint16_t parts = static_cast<uint16_t>(1 + rng() % 5);
      parts_of[first + v] = parts;
      for (uint16_t p = 0; p < parts; ++p) {
        if (lossy && rng() % 10 == 0) continue;
        sent.push_back({first + v, p, parts});
        if (rng() % 5 == 0) sent.push_back({first + v, p, parts});  // duplicated
      }
    }
    // Reordered within a window of 6.
    for (std::size_t i = 0; i + 1 < sent.size(); ++i) std::swap(sent[i], sent[std::min(sent.size() - 1, i + rng() % 6)]);
    std::map<uint32_t, std::set<uint16_t>> arrived;
    int64_t drawn_rank = -1;  // versions as v - first, so that order is plain
    for (const Sent& s : sent) {
      add(cache, makePart(key, s.version, s.part, s.parts, 3));
      arrived[s.version].insert(s.part);
      const int slot = cache.find(key);
      ASSERT_GE(slot, 0);
      if (!cache.held(static_cast<std::size_t>(slot))) continue;
      const uint32_t v = cache.version(static_cast<std::size_t>(slot));
      const int64_t rank = static_cast<int64_t>(v - first);
      ASSERT_GE(rank, drawn_rank) << "trial " << trial << ": a stale version was drawn over a newer one";
      drawn_rank = rank;
      ASSERT_EQ(arrived[v].size(), parts_of[v]) << "trial " << trial << ": version " << v << " drawn unfinished";
      ASSERT_EQ(cache.pointCount(static_cast<std::size_t>(slot)), 3u * parts_of[v]);
      ASSERT_EQ(drawnVersions(cache, slot), std::set<uint32_t>{v % 1000});
    }
    if (!lossy) {
      EXPECT_EQ(drawn_rank, 5) << "trial " << trial << ": without loss the last version is drawn";
    }
  }
}

TEST(BrickCache, AFullCacheEvictsTheLeastRecentlyNeededBrickAndListsIt) {
  BrickCacheConfig config = small();
  config.max_bricks = 4;
  BrickCache cache = BrickCache::create(config).value();
  for (int b = 0; b < 4; ++b) ASSERT_EQ(add(cache, makePart({b, 0, 0}, 1, 0, 1), 10 + b), BrickCache::Outcome::kCompleted);
  cache.touch({0, 0, 0}, 100);  // the viewer drew brick 0: brick 1 is now the least recently needed
  ASSERT_EQ(add(cache, makePart({4, 0, 0}, 1, 0, 1), 101), BrickCache::Outcome::kCompleted);
  EXPECT_EQ(cache.find({1, 0, 0}), -1);
  ASSERT_EQ(cache.evicted().size(), 1u);
  EXPECT_EQ(cache.evicted()[0], (BrickKey{1, 0, 0}));
  for (int b : {0, 2, 3, 4}) EXPECT_GE(cache.find({b, 0, 0}), 0) << b;
  EXPECT_EQ(cache.bricksHeld(), 4u);
  cache.clearEvicted();
  EXPECT_TRUE(cache.evicted().empty());
  // Many more: the table keeps finding every brick it holds (the deletions shift its cells).
  for (int b = 5; b < 200; ++b) {
    ASSERT_EQ(add(cache, makePart({b * 7, -b, b % 3}, 1, 0, 1), 200 + b), BrickCache::Outcome::kCompleted);
    for (int k = std::max(5, b - 3); k <= b; ++k) ASSERT_GE(cache.find({k * 7, -k, k % 3}), 0) << b << " " << k;
  }
  EXPECT_EQ(cache.counters().evicted, 196u);
}

TEST(BrickCache, APoolTooSmallEvictsOthersButNeverTheBrickItFills) {
  BrickCacheConfig config;
  config.max_points = 64;
  config.block_points = 8;
  BrickCache cache = BrickCache::create(config).value();
  ASSERT_EQ(add(cache, makePart({0, 0, 0}, 1, 0, 1, 40), 1), BrickCache::Outcome::kCompleted);
  ASSERT_EQ(add(cache, makePart({1, 0, 0}, 1, 0, 2, 20), 2), BrickCache::Outcome::kStored);
  // 20 more for brick 1 do not fit beside brick 0's 40: brick 0 goes, brick 1 stays.
  ASSERT_EQ(add(cache, makePart({1, 0, 0}, 1, 1, 2, 20), 3), BrickCache::Outcome::kCompleted);
  EXPECT_EQ(cache.find({0, 0, 0}), -1);
  EXPECT_EQ(cache.pointsHeld(), 40u);
  // More points than the whole pool: dropped, counted, nothing else lost.
  Part huge = makePart({2, 0, 0}, 1, 0, 1, 65);
  EXPECT_EQ(add(cache, huge), BrickCache::Outcome::kNoRoom);
  EXPECT_EQ(cache.counters().no_room_parts, 1u);
  EXPECT_EQ(cache.pointsHeld(), 40u);
}

TEST(BrickCache, BadPartsAreCountedAndChangeNothing) {
  BrickCacheConfig config = small();
  config.max_parts = 8;
  BrickCache cache = BrickCache::create(config).value();
  Part untagged = makePart({0, 0, 0}, 1, 0, 1);
  untagged.chunk.has_brick = false;
  EXPECT_EQ(add(cache, untagged), BrickCache::Outcome::kBad);
  EXPECT_EQ(add(cache, makePart({0, 0, 0}, 1, 3, 3)), BrickCache::Outcome::kBad);
  EXPECT_EQ(add(cache, makePart({0, 0, 0}, 1, 0, 0)), BrickCache::Outcome::kBad);
  EXPECT_EQ(add(cache, makePart({0, 0, 0}, 1, 0, 9)), BrickCache::Outcome::kNoRoom);
  EXPECT_EQ(cache.counters().bad_parts, 3u);
  EXPECT_EQ(cache.bricksHeld(), 0u);
  EXPECT_TRUE(cache.received().empty());
  BrickCacheConfig bad;
  bad.max_bricks = 0;
  EXPECT_FALSE(BrickCache::create(bad));
  bad = {};
  bad.max_points = 10;
  EXPECT_FALSE(BrickCache::create(bad));
}

}  // namespace
}  // namespace fovea::net
