// The operator's receive path for the map allocates nothing after start-up:
// MapHolder::add (decode, cache, evictions), sendAcks, and packing the map into
// a viewer frame. The allocator of this binary is replaced by a counting one
// (tests/support/alloc_counter.h).
#include <algorithm>
#include <cstring>
#include <vector>

#include <gtest/gtest.h>

#include "net/codec.h"
#include "tests/support/alloc_counter.h"
#include "tools/operator/map_holder.h"
#include "tools/operator/view_frame.h"

namespace fovea::tools {
namespace {

TEST(MapHolderZeroAllocation, AddAcknowledgeAndDrawAfterCreate) {
  // 40 bricks of 2 versions each, several parts apiece, into a cache that holds
  // about half of them: every path of add() runs, evictions included.
  net::ChunkEncoder encoder = net::ChunkEncoder::create(net::CodecConfig{}, 2000).value();
  pipeline::FoveatedCloud cloud(2000);
  std::vector<std::vector<uint8_t>> payloads;
  for (uint32_t version = 1; version <= 2; ++version) {
    for (int b = 0; b < 40; ++b) {
      cloud.clear();
      cloud.points.origin_m = Eigen::Vector3d(0.5 * b, 0.0, 1.0);
      for (int i = 0; i < 600 + 10 * b; ++i) {
        ASSERT_TRUE(cloud.points.push(0.003f * static_cast<float>(i % 50), 0.003f * static_cast<float>(i / 50),
                                      0.001f * static_cast<float>(version), 0x336699u));
      }
      std::fill_n(cloud.region.begin(), cloud.size(), uint8_t{0});
      std::fill_n(cloud.weight.begin(), cloud.size(), 1u);
      const double fovea[1] = {0.0};
      const net::BrickTag tag{b, 0, 2, version, 0};
      ASSERT_TRUE(encoder.encode(cloud, fovea, version, 0, &tag));
      for (std::size_t i = 0; i < encoder.chunkCount(); ++i) {
        payloads.emplace_back(encoder.chunk(i).begin(), encoder.chunk(i).end());
      }
    }
  }
  net::BrickCacheConfig config;
  config.max_bricks = 64;
  config.max_points = 16384;
  MapHolder map = MapHolder::create(config).value();
  // The live frame the map is drawn with, and a viewer buffer for both.
  pipeline::FoveatedCloud live(100);
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(live.points.push(0.01f * static_cast<float>(i), 0.f, 1.f, 0));
  net::AssembledFrame frame;
  frame.cloud = &live;
  frame.points[0] = 100;
  std::vector<uint8_t> view(viewFrameBytes(100 + config.max_points));
  alignas(8) static uint8_t aligned[net::kMaxMtu];
  // Warm-up: the decoder's per-thread context is made on first use (FrameAssembler::create does it in the operator).
  std::memcpy(aligned, payloads[0].data(), payloads[0].size());
  (void)map.add(std::span<const uint8_t>(aligned, payloads[0].size()), 0);
  // A bad payload is counted, outside the scope: net::decodeChunk's error carries
  // a message string (as for a bad frame chunk in the FrameAssembler).
  std::memset(aligned, 0x5a, 100);
  EXPECT_EQ(map.add(std::span<const uint8_t>(aligned, 100), 0), net::BrickCache::Outcome::kBad);

  std::size_t messages = 0, packed = 0;
  test::AllocationScope scope;
  int64_t now = 1;
  for (const std::vector<uint8_t>& p : payloads) {
    std::memcpy(aligned, p.data(), p.size());
    (void)map.add(std::span<const uint8_t>(aligned, p.size()), ++now);
    if (map.ackDue(now, net::kMinMtu - net::kDatagramOverhead) || now % 16 == 0) {
      map.sendAcks(net::kMinMtu - net::kDatagramOverhead, now, [&](const net::BrickAckMsg& m) {
        messages += m.part_count > 0 ? 1 : 0;
        return true;
      });
    }
    if (now % 32 == 0) packed += packViewFrame(frame, {}, ViewMap{&map.cache(), 0.125, now}, view).map_points;
  }
  const MapTotals t = map.totals();
  EXPECT_EQ(scope.allocations(), 0u);
  EXPECT_GT(t.evicted, 0u);
  EXPECT_GT(t.versions, 40u);
  EXPECT_EQ(t.bad_parts, 1u);
  EXPECT_GT(messages, 0u);
  EXPECT_GT(packed, 0u);
}

}  // namespace
}  // namespace fovea::tools
