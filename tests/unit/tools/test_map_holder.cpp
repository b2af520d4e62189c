// The operator's copy of the map (tools/operator/map_holder.h): brick chunks made
// by the robot's encoder go in as payloads; what it holds, and the
// acknowledgements it sends (their contents, their splitting at a small MTU, the
// evicted bricks in them, their pace) come out; bad payloads are counted.
#include <algorithm>
#include <cstring>
#include <set>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "net/codec.h"
#include "net/messages.h"
#include "net/wire.h"
#include "tools/operator/map_holder.h"

namespace fovea::tools {
namespace {

constexpr int64_t kMs = 1'000'000;

// The encoded parts of one brick version: `points` points on a slab at the brick.
struct Parts {
  std::vector<std::vector<uint8_t>> payloads;
};

Parts brickParts(net::BrickTag tag, int points, std::size_t max_payload = net::kDefaultMtu - net::kDatagramOverhead) {
  pipeline::FoveatedCloud cloud(static_cast<std::size_t>(points));
  cloud.points.origin_m = Eigen::Vector3d(0.5 * tag.x, 0.5 * tag.y, 0.5 * tag.z);
  for (int i = 0; i < points; ++i) {
    EXPECT_TRUE(cloud.points.push(0.002f * static_cast<float>(i % 100), 0.002f * static_cast<float>(i / 100),
                                  0.0001f * static_cast<float>(tag.version), 0x102030u + static_cast<uint32_t>(i)));
  }
  std::fill_n(cloud.region.begin(), cloud.size(), uint8_t{0});
  std::fill_n(cloud.weight.begin(), cloud.size(), 1u);
  net::CodecConfig config;
  config.max_payload = max_payload;
  net::ChunkEncoder encoder = net::ChunkEncoder::create(config, static_cast<std::size_t>(points)).value();
  const double fovea[1] = {0.0};
  EXPECT_TRUE(encoder.encode(cloud, fovea, 1, 0, &tag));
  Parts p;
  for (std::size_t i = 0; i < encoder.chunkCount(); ++i) {
    const std::span<const uint8_t> c = encoder.chunk(i);
    p.payloads.emplace_back(c.begin(), c.end());
  }
  return p;
}

// Payloads must start 8-byte aligned, as the link returns them.
class MapHolderTest : public ::testing::Test {
 protected:
  net::BrickCache::Outcome add(MapHolder& map, const std::vector<uint8_t>& payload, int64_t now) {
    EXPECT_LE(payload.size(), sizeof aligned_);
    if (!payload.empty()) std::memcpy(aligned_, payload.data(), payload.size());
    return map.add(std::span<const uint8_t>(aligned_, payload.size()), now);
  }
  void addAll(MapHolder& map, const Parts& parts, int64_t now) {
    for (const auto& p : parts.payloads) add(map, p, now);
  }
  static MapHolder make(std::size_t max_bricks = 64, std::size_t max_points = 1 << 16) {
    net::BrickCacheConfig c;
    c.max_bricks = max_bricks;
    c.max_points = max_points;
    return MapHolder::create(c).value();
  }
  // Sends the acknowledgements, keeping copies of the messages.
  std::vector<net::BrickAckMsg> acks(MapHolder& map, std::size_t max_payload, int64_t now) {
    std::vector<net::BrickAckMsg> out;
    const std::size_t n = map.sendAcks(max_payload, now, [&](const net::BrickAckMsg& m) {
      out.push_back(m);
      return true;
    });
    EXPECT_EQ(n, out.size());
    return out;
  }
  alignas(8) uint8_t aligned_[net::kMaxMtu];
};

TEST_F(MapHolderTest, HoldsWhatArrivedWholeAndAcknowledgesEveryPart) {
  MapHolder map = make();
  const Parts a = brickParts({1, 2, 3, 7, 0}, 900);
  const Parts b = brickParts({-1, 0, 4, 1, 0}, 300);
  ASSERT_GE(a.payloads.size(), 2u) << "a brick of several parts";
  // All of b, and a without its last part: only b is drawn.
  addAll(map, b, 1 * kMs);
  for (std::size_t i = 0; i + 1 < a.payloads.size(); ++i) add(map, a.payloads[i], 2 * kMs);
  EXPECT_EQ(map.totals().bricks_held, 1u);
  EXPECT_EQ(map.totals().points_held, 300u);
  EXPECT_EQ(add(map, a.payloads.back(), 3 * kMs), net::BrickCache::Outcome::kCompleted);
  const MapTotals t = map.totals();
  EXPECT_EQ(t.bricks_held, 2u);
  EXPECT_EQ(t.points_held, 1200u);
  EXPECT_EQ(t.versions, 2u);
  EXPECT_EQ(t.parts, a.payloads.size() + b.payloads.size());
  const int slot = map.cache().find({1, 2, 3});
  ASSERT_GE(slot, 0);
  EXPECT_EQ(map.cache().version(static_cast<std::size_t>(slot)), 7u);
  EXPECT_EQ(map.cache().pointCount(static_cast<std::size_t>(slot)), 900u);

  // One message at the default MTU holds every part, each by brick, version and index.
  const std::vector<net::BrickAckMsg> sent = acks(map, net::kDefaultMtu - net::kDatagramOverhead, 4 * kMs);
  ASSERT_EQ(sent.size(), 1u);
  EXPECT_EQ(sent[0].evicted_count, 0u);
  std::set<std::tuple<int, uint32_t, uint16_t>> got;
  for (std::size_t i = 0; i < sent[0].part_count; ++i) {
    got.insert({sent[0].parts[i].key.x, sent[0].parts[i].version, sent[0].parts[i].part});
  }
  std::set<std::tuple<int, uint32_t, uint16_t>> want;
  for (std::size_t i = 0; i < a.payloads.size(); ++i) want.insert({1, 7u, static_cast<uint16_t>(i)});
  for (std::size_t i = 0; i < b.payloads.size(); ++i) want.insert({-1, 1u, static_cast<uint16_t>(i)});
  EXPECT_EQ(got, want);
  EXPECT_EQ(map.totals().acks_sent, 1u);
  // Acknowledged once: the lists are empty and nothing more is due.
  EXPECT_TRUE(map.cache().received().empty());
  EXPECT_FALSE(map.ackDue(100 * kMs, net::kDefaultMtu));
  EXPECT_TRUE(acks(map, net::kDefaultMtu - net::kDatagramOverhead, 100 * kMs).empty());
  // A duplicate is acknowledged again (its first acknowledgement may have been lost) and counted.
  EXPECT_EQ(add(map, b.payloads[0], 101 * kMs), net::BrickCache::Outcome::kDuplicate);
  EXPECT_EQ(map.totals().duplicate_parts, 1u);
  EXPECT_EQ(map.cache().received().size(), 1u);
}

TEST_F(MapHolderTest, AcknowledgementsSplitOverMessagesThatFitASmallMtu) {
  MapHolder map = make();
  const std::size_t small = net::kMinMtu - net::kDatagramOverhead;
  // Many parts: a brick cut at the smallest MTU, and 20 one-part bricks.
  const Parts big = brickParts({0, 0, 0, 1, 0}, 3000, small);
  addAll(map, big, 1 * kMs);
  for (int i = 0; i < 20; ++i) addAll(map, brickParts({10 + i, 0, 0, 1, 0}, 50), 1 * kMs);
  const std::size_t parts = big.payloads.size() + 20;
  ASSERT_EQ(map.cache().received().size(), parts);
  const std::size_t per_message = net::BrickAckMsg::partsThatFit(small, 0);
  ASSERT_GT(parts, 2 * per_message) << "the test needs at least three messages";
  // More than one message holds: due at once, whatever the clock.
  EXPECT_TRUE(map.ackDue(1 * kMs + 1, small));
  const std::vector<net::BrickAckMsg> sent = acks(map, small, 2 * kMs);
  ASSERT_EQ(sent.size(), (parts + per_message - 1) / per_message);
  std::size_t total = 0;
  net::MessageEncoder encoder;
  for (const net::BrickAckMsg& m : sent) {
    EXPECT_GT(m.part_count, 0u);
    EXPECT_LE(m.part_count, per_message);
    EXPECT_LE(encoder.encode(m).size(), small) << "each message fits the MTU";
    total += m.part_count;
  }
  EXPECT_EQ(total, parts);
  EXPECT_EQ(map.totals().acks_sent, sent.size());
}

TEST_F(MapHolderTest, AnEvictedBrickIsReportedInTheNextAcknowledgement) {
  // Room for two bricks: the third evicts the one received least recently.
  MapHolder map = make(2, 4096);
  addAll(map, brickParts({1, 0, 0, 1, 0}, 100), 1 * kMs);
  addAll(map, brickParts({2, 0, 0, 1, 0}, 100), 2 * kMs);
  (void)acks(map, net::kDefaultMtu - net::kDatagramOverhead, 3 * kMs);
  addAll(map, brickParts({3, 0, 0, 1, 0}, 100), 4 * kMs);
  EXPECT_EQ(map.totals().evicted, 1u);
  EXPECT_EQ(map.totals().bricks_held, 2u);
  EXPECT_LT(map.cache().find({1, 0, 0}), 0);
  const std::vector<net::BrickAckMsg> sent = acks(map, net::kDefaultMtu - net::kDatagramOverhead, 5 * kMs);
  ASSERT_EQ(sent.size(), 1u);
  ASSERT_EQ(sent[0].evicted_count, 1u);
  EXPECT_EQ(sent[0].evicted[0], (net::BrickKey{1, 0, 0}));
  EXPECT_EQ(sent[0].part_count, 1u);  // brick 3's part
  EXPECT_TRUE(map.cache().evicted().empty());
}

TEST_F(MapHolderTest, EvictedKeysBeyondOneMessageGoInSeveral) {
  // One pool block of room: 40 bricks in turn evict 39, more than a message's 32 keys.
  MapHolder map = make(64, 256);
  for (int i = 0; i < 40; ++i) addAll(map, brickParts({i, 0, 0, 1, 0}, 20), (i + 1) * kMs);
  ASSERT_EQ(map.cache().evicted().size(), 39u);
  EXPECT_TRUE(map.ackDue(41 * kMs, net::kMinMtu - net::kDatagramOverhead));
  const std::vector<net::BrickAckMsg> sent = acks(map, net::kMinMtu - net::kDatagramOverhead, 41 * kMs);
  std::size_t keys = 0, parts = 0;
  for (const net::BrickAckMsg& m : sent) {
    keys += m.evicted_count;
    parts += m.part_count;
  }
  EXPECT_EQ(keys, 39u);
  EXPECT_EQ(parts, 40u);
  EXPECT_GE(sent.size(), 4u) << "at the smallest MTU a message holds 11 keys beside a part";
}

TEST_F(MapHolderTest, AcknowledgementsGoEvery25Ms) {
  MapHolder map = make();
  EXPECT_EQ(map.nextAckNs(), INT64_MAX) << "nothing to acknowledge";
  const std::size_t payload = net::kDefaultMtu - net::kDatagramOverhead;
  addAll(map, brickParts({1, 0, 0, 1, 0}, 10), 100 * kMs);
  ASSERT_TRUE(map.ackDue(100 * kMs, payload)) << "the first may go at once";
  (void)acks(map, payload, 100 * kMs);
  addAll(map, brickParts({1, 0, 0, 2, 0}, 10), 101 * kMs);
  EXPECT_FALSE(map.ackDue(124 * kMs, payload));
  EXPECT_EQ(map.nextAckNs(), 125 * kMs);
  EXPECT_TRUE(map.ackDue(125 * kMs, payload));
}

TEST_F(MapHolderTest, BadPayloadsAreCountedNotHeld) {
  MapHolder map = make();
  Parts good = brickParts({1, 0, 0, 1, 0}, 200);
  // Garbage, a chunk cut short, a flipped byte in the middle, and an empty payload.
  std::vector<uint8_t> garbage(300);
  for (std::size_t i = 0; i < garbage.size(); ++i) garbage[i] = static_cast<uint8_t>(i * 37 + 11);
  EXPECT_EQ(add(map, garbage, 1), net::BrickCache::Outcome::kBad);
  std::vector<uint8_t> cut(good.payloads[0].begin(), good.payloads[0].begin() + 40);
  EXPECT_EQ(add(map, cut, 1), net::BrickCache::Outcome::kBad);
  EXPECT_EQ(add(map, {}, 1), net::BrickCache::Outcome::kBad);
  // A frame's chunk (no brick tag) sent as a brick chunk.
  pipeline::FoveatedCloud cloud(10);
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(cloud.points.push(0.01f * static_cast<float>(i), 0.f, 1.f, 0));
  std::fill_n(cloud.region.begin(), 10, uint8_t{0});
  std::fill_n(cloud.weight.begin(), 10, 1u);
  net::ChunkEncoder encoder = net::ChunkEncoder::create(net::CodecConfig{}, 10).value();
  const double fovea[1] = {0.0};
  ASSERT_TRUE(encoder.encode(cloud, fovea, 1, 0));
  const std::span<const uint8_t> frame_chunk = encoder.chunk(0);
  EXPECT_EQ(add(map, {frame_chunk.begin(), frame_chunk.end()}, 1), net::BrickCache::Outcome::kBad);
  const MapTotals t = map.totals();
  EXPECT_EQ(t.bad_parts, 4u);
  EXPECT_EQ(t.payloads, 4u);
  EXPECT_EQ(t.bricks_held, 0u);
  EXPECT_TRUE(map.cache().received().empty()) << "nothing bad is acknowledged";
  // And the good ones still go in afterwards.
  addAll(map, good, 2);
  EXPECT_EQ(map.totals().points_held, 200u);
}

TEST_F(MapHolderTest, ResetEmptiesTheCopyAndKeepsTheCounts) {
  MapHolder map = make();
  addAll(map, brickParts({1, 0, 0, 5, 0}, 100), 1 * kMs);
  const uint64_t parts = map.totals().parts;
  map.reset();
  EXPECT_EQ(map.totals().bricks_held, 0u);
  EXPECT_TRUE(map.cache().received().empty());
  EXPECT_EQ(map.totals().parts, parts);
  // A restarted robot numbers versions afresh: version 1 is taken, not stale.
  addAll(map, brickParts({1, 0, 0, 1, 0}, 100), 2 * kMs);
  EXPECT_EQ(map.totals().bricks_held, 1u);
  EXPECT_EQ(map.totals().stale_parts, 0u);
}

TEST(MapHolderConfig, BadSizesAreRefusedByName) {
  net::BrickCacheConfig c;
  c.max_points = 10;  // under one block
  const Result<MapHolder> r = MapHolder::create(c);
  ASSERT_FALSE(r);
  EXPECT_NE(r.status().message().find("max_points"), std::string::npos) << r.status().message();
}

TEST(MapLiveText, SaysWhatChangedInTheWindow) {
  MapTotals before, now;
  before.parts = 10;
  now.parts = 25;
  now.versions = 3;
  now.bricks_held = 4;
  now.points_held = 1000;
  const std::string s = mapLiveText(now, before);
  EXPECT_NE(s.find("map 4 bricks 1000 pts, +15 parts +3 versions"), std::string::npos) << s;
  EXPECT_NE(mapSummaryJson(now).find("\"versions_completed\": 3"), std::string::npos);
}

}  // namespace
}  // namespace fovea::tools
