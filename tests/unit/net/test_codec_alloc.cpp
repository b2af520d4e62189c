// ChunkEncoder::encode allocates nothing after create(): the allocator of this
// binary is replaced by a counting one (tests/support/alloc_counter.h).
#include <gtest/gtest.h>

#include "net/codec.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/test_time.h"
#include "tests/unit/net/mock_frame.h"

namespace fovea::net {
namespace {

TEST(CodecZeroAllocation, EncodeBrickEncodeAndSummaryAfterCreate) {
  // Two different frames (orbit path) and F1/F3, so chunk counts vary.
  const test::MockFoveatedFrame a = test::mockFoveatedFrame("mock:living-room,path=orbit", pipeline::Preset::kF1, 1);
  const test::MockFoveatedFrame b = test::mockFoveatedFrame("mock:living-room,path=orbit", pipeline::Preset::kF3, 3);
  for (bool entropy : {false, true}) {
    CodecConfig config;
    config.entropy_coding = entropy;
    config.halve_peripheral_chroma = entropy;
    ChunkEncoder enc = ChunkEncoder::create(config, 640 * 480).value();
    const uint16_t sent[] = {1, 2, 3, 4};
    test::AllocationScope scope;
    // Both frames twice where an encode costs 10 to 40 times as much (sanitizers, qemu).
    const uint32_t frames = static_cast<uint32_t>(test::repetitions(20, 4));
    for (uint32_t frame = 0; frame < frames; ++frame) {
      const test::MockFoveatedFrame& f = frame % 2 ? a : b;
      ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, frame, 0).isOk());
      ASSERT_GT(enc.chunkCount(), 10u);
      // The same points as parts of a map brick: tagged chunks, sized for the tag.
      const BrickTag brick{-2, 0, 5, frame, static_cast<uint8_t>(frame % 3)};
      ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, frame, 0, &brick).isOk());
      ASSERT_GT(enc.chunkCount(), 10u);
      (void)enc.encodeSummary(frame, sent, sent);
    }
    EXPECT_EQ(scope.allocations(), 0u) << (entropy ? "zstd" : "raw");
  }
}

}  // namespace
}  // namespace fovea::net
