// TimestampPairer against a brute-force model written here: the model keeps
// every colour frame the pairer should keep, in push order, and scans them all.
#include "hal/camera/pairing.h"

#include <cstdint>
#include <cstdio>
#include <deque>
#include <limits>
#include <optional>
#include <random>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/alloc_counter.h"

namespace fovea::hal {
namespace {

// Wide enough for any difference of two int64 stamps (the model's own way of
// not overflowing; __extension__ keeps -Wpedantic quiet about the GCC type).
__extension__ typedef __int128 Wide;

// The contract of pairing.h, written the obvious way.
class ModelPairer {
 public:
  ModelPairer(std::size_t capacity, int64_t tolerance_ns) : capacity_(capacity), tolerance_ns_(tolerance_ns) {}

  // Checks the slot the pairer offers (a free one, or the oldest's when full),
  // then records the push.
  ::testing::AssertionResult push(int64_t stamp_ns, int offered_slot) {
    if (!kept_.empty() && stamp_ns < kept_.back().stamp_ns) {
      ++counts.stamps_backwards;
      forgetAll();
    } else if (kept_.size() == capacity_) {
      if (offered_slot != kept_.front().slot) {
        return ::testing::AssertionFailure() << "full: offered slot " << offered_slot << ", the oldest is in "
                                             << kept_.front().slot;
      }
      if (!kept_.front().used) ++counts.colour_dropped;
      kept_.pop_front();
    }
    if (offered_slot < 0 || static_cast<std::size_t>(offered_slot) >= capacity_) {
      return ::testing::AssertionFailure() << "slot " << offered_slot << " out of range";
    }
    for (const Frame& f : kept_) {
      if (f.slot == offered_slot) return ::testing::AssertionFailure() << "slot " << offered_slot << " is in use";
    }
    kept_.push_back({stamp_ns, offered_slot, false});
    return ::testing::AssertionSuccess();
  }

  std::optional<int> pair(int64_t depth_ns) {
    Frame* best = nullptr;
    Wide best_d = 0;
    for (Frame& f : kept_) {
      Wide d = static_cast<Wide>(depth_ns) - f.stamp_ns;
      if (d < 0) d = -d;
      if (d > tolerance_ns_) continue;
      // Nearest; ties: the smaller stamp, then the earlier push (this order).
      if (best != nullptr && d == best_d) ++ties;
      if (best == nullptr || d < best_d || (d == best_d && f.stamp_ns < best->stamp_ns)) {
        best = &f;
        best_d = d;
      }
    }
    if (best == nullptr) {
      ++counts.depth_unmatched;
      return std::nullopt;
    }
    best->used = true;
    ++counts.paired;
    return best->slot;
  }

  void forgetAll() {
    for (const Frame& f : kept_) counts.colour_dropped += f.used ? 0 : 1;
    kept_.clear();
  }

  std::size_t size() const { return kept_.size(); }
  PairingCounts counts;
  uint64_t ties = 0;  // depth frames equally near two kept colour frames

 private:
  struct Frame {
    int64_t stamp_ns;
    int slot;
    bool used;
  };
  std::size_t capacity_;
  int64_t tolerance_ns_;
  std::deque<Frame> kept_;
};

void expectSameCounts(const PairingCounts& a, const PairingCounts& b, const char* where) {
  EXPECT_EQ(a.paired, b.paired) << where;
  EXPECT_EQ(a.depth_unmatched, b.depth_unmatched) << where;
  EXPECT_EQ(a.colour_dropped, b.colour_dropped) << where;
  EXPECT_EQ(a.stamps_backwards, b.stamps_backwards) << where;
}

// Two 30 Hz streams with jitter, drops, colour bursts, depth gaps and clock steps.
TEST(TimestampPairer, MatchesABruteForceScanOnRandomStreams) {
  std::mt19937_64 rng(20240610);
  uint64_t total_paired = 0, total_unmatched = 0, total_dropped = 0, total_steps = 0, total_ties = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const std::size_t capacity = 1 + rng() % 8;
    // Half the trials on a coarse grid (1 ms), so equal distances (ties) happen.
    const int64_t grid_ns = (trial % 2 == 0) ? 1 : 1'000'000;
    const int64_t period_ns = (trial % 2 == 0) ? 33'333'333 : 33'000'000;
    const int64_t tolerance_ns = static_cast<int64_t>(rng() % 25'000'000);
    TimestampPairer pairer(capacity, tolerance_ns);
    ModelPairer model(capacity, tolerance_ns);
    int64_t colour_ns = static_cast<int64_t>(rng() % 1'000'000) * grid_ns;
    int64_t depth_ns = colour_ns + (static_cast<int64_t>(rng() % 20'000'000) - 10'000'000) / grid_ns * grid_ns;
    std::uniform_int_distribution<int64_t> jitter(-3'000'000, 3'000'000);
    for (int step = 0; step < 300; ++step) {
      const uint64_t r = rng();
      // Colour: usually one frame, sometimes none (dropped at the source),
      // sometimes a burst; rarely the clock steps back.
      int colour_frames = (r % 10 == 0) ? 0 : (r % 17 == 0) ? 2 + static_cast<int>(r % 5) : 1;
      for (int c = 0; c < colour_frames; ++c) {
        int64_t stamp = colour_ns + jitter(rng) / grid_ns * grid_ns;
        if ((r >> 8) % 97 == 0 && c == 0) stamp -= static_cast<int64_t>(1 + (r >> 16) % 3'000'000'000);
        if ((r >> 24) % 53 == 0) stamp = colour_ns;  // an exact repeat now and then
        const int slot = pairer.nextColourSlot();
        ASSERT_TRUE(model.push(stamp, slot)) << "trial " << trial << " step " << step;
        pairer.pushColour(stamp);
        colour_ns = std::max(colour_ns, stamp) + (colour_frames > 1 ? 2'000'000 : period_ns);
      }
      // Depth: usually one frame, sometimes a gap.
      if ((r >> 32) % 11 != 0) {
        const int64_t stamp = depth_ns + jitter(rng) / grid_ns * grid_ns;
        ASSERT_EQ(pairer.pairDepth(stamp), model.pair(stamp)) << "trial " << trial << " step " << step;
      }
      depth_ns += period_ns;
      if ((r >> 40) % 5 == 0) depth_ns = colour_ns;  // realign now and then so pairs happen
      if ((r >> 48) % 251 == 0) {
        pairer.clear();
        model.forgetAll();
      }
      ASSERT_EQ(pairer.size(), model.size());
    }
    expectSameCounts(pairer.counts(), model.counts, "end of trial");
    total_paired += pairer.counts().paired;
    total_unmatched += pairer.counts().depth_unmatched;
    total_dropped += pairer.counts().colour_dropped;
    total_steps += pairer.counts().stamps_backwards;
    total_ties += model.ties;
  }
  // The streams reach every branch (a property test that never pairs proves nothing).
  EXPECT_GT(total_paired, 10'000u);
  EXPECT_GT(total_unmatched, 1'000u);
  EXPECT_GT(total_dropped, 1'000u);
  EXPECT_GT(total_steps, 100u);
  EXPECT_GT(total_ties, 100u);
  std::printf("paired %llu, unmatched %llu, dropped %llu, clock steps %llu, ties %llu\n",
              static_cast<unsigned long long>(total_paired), static_cast<unsigned long long>(total_unmatched),
              static_cast<unsigned long long>(total_dropped), static_cast<unsigned long long>(total_steps),
              static_cast<unsigned long long>(total_ties));
}

TEST(TimestampPairer, PicksTheNearestFrame) {
  TimestampPairer p(4, 10);
  p.pushColour(100);  // slot 0
  p.pushColour(110);  // slot 1
  p.pushColour(120);  // slot 2
  EXPECT_EQ(p.pairDepth(108), 1);
  EXPECT_EQ(p.pairDepth(117), 2);
  EXPECT_EQ(p.pairDepth(95), 0);
  EXPECT_EQ(p.counts().paired, 3u);
}

TEST(TimestampPairer, TiesGoToTheEarlierFrame) {
  TimestampPairer p(4, 100);
  p.pushColour(100);
  p.pushColour(120);
  EXPECT_EQ(p.pairDepth(110), 0);  // 10 ns from both
  // Equal stamps: the one pushed first.
  TimestampPairer q(4, 100);
  q.pushColour(100);
  q.pushColour(200);
  q.pushColour(200);
  EXPECT_EQ(q.pairDepth(210), 1);
  EXPECT_EQ(q.counts().stamps_backwards, 0u);  // an equal stamp is not a clock step
}

TEST(TimestampPairer, ToleranceIsInclusive) {
  TimestampPairer p(2, 5'000'000);
  p.pushColour(1'000'000'000);
  EXPECT_EQ(p.pairDepth(1'005'000'000), 0);   // exactly at the tolerance: paired
  EXPECT_EQ(p.pairDepth(995'000'000), 0);     // on the other side too
  EXPECT_EQ(p.pairDepth(1'005'000'001), std::nullopt);  // one nanosecond beyond
  EXPECT_EQ(p.pairDepth(994'999'999), std::nullopt);
  EXPECT_EQ(p.counts().paired, 2u);
  EXPECT_EQ(p.counts().depth_unmatched, 2u);
  // Tolerance 0: only the same stamp.
  TimestampPairer exact(2, 0);
  exact.pushColour(7);
  EXPECT_EQ(exact.pairDepth(7), 0);
  EXPECT_EQ(exact.pairDepth(8), std::nullopt);
}

TEST(TimestampPairer, ExtremeStampsDoNotOverflow) {
  constexpr int64_t kMin = std::numeric_limits<int64_t>::min();
  constexpr int64_t kMax = std::numeric_limits<int64_t>::max();
  TimestampPairer p(2, kMax);
  p.pushColour(kMin);
  EXPECT_EQ(p.pairDepth(kMax), std::nullopt);  // 2^64 - 1 apart: beyond even kMax
  EXPECT_EQ(p.pairDepth(-1), 0);                // kMax apart: within
  TimestampPairer q(2, 10);
  q.pushColour(kMax);
  EXPECT_EQ(q.pairDepth(kMin), std::nullopt);
  EXPECT_EQ(q.pairDepth(kMax - 10), 0);
}

TEST(TimestampPairer, ClockGoingBackwardsIsCountedAndResetsTheHistory) {
  TimestampPairer p(4, 1'000);
  p.pushColour(10'000);  // slot 0, paired below
  p.pushColour(20'000);  // slot 1, never paired
  EXPECT_EQ(p.pairDepth(10'100), 0);
  const int slot = p.nextColourSlot();
  EXPECT_EQ(slot, 2);
  p.pushColour(5'000);  // a clock step: the frame written into slot 2 is kept, alone
  EXPECT_EQ(p.counts().stamps_backwards, 1u);
  EXPECT_EQ(p.counts().colour_dropped, 1u);  // 20'000 was never paired
  EXPECT_EQ(p.size(), 1u);
  EXPECT_EQ(p.pairDepth(20'000), std::nullopt);  // forgotten
  EXPECT_EQ(p.pairDepth(5'100), slot);
  // The ring goes on from there: the next slots are the free ones.
  EXPECT_EQ(p.nextColourSlot(), 3);
  p.pushColour(6'000);
  EXPECT_EQ(p.nextColourSlot(), 0);
}

TEST(TimestampPairer, CapacityOneKeepsOnlyTheNewestFrame) {
  TimestampPairer p(1, 1'000);
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(p.nextColourSlot(), 0);
    p.pushColour(10'000 * (i + 1));
    EXPECT_EQ(p.size(), 1u);
  }
  EXPECT_EQ(p.counts().colour_dropped, 4u);  // four displaced unpaired
  EXPECT_EQ(p.pairDepth(40'000), std::nullopt);  // displaced
  EXPECT_EQ(p.pairDepth(50'500), 0);
  p.pushColour(60'000);
  EXPECT_EQ(p.counts().colour_dropped, 4u);  // 50'000 was paired: not a drop
  // A capacity of 0 is taken as 1 (the constructor never fails).
  TimestampPairer zero(0, -5);
  EXPECT_EQ(zero.nextColourSlot(), 0);
  EXPECT_EQ(zero.toleranceNs(), 0);
  zero.pushColour(3);
  EXPECT_EQ(zero.pairDepth(3), 0);
}

TEST(TimestampPairer, CountsFramesDisplacedUnpairedOnlyOnce) {
  TimestampPairer p(2, 10);
  p.pushColour(100);
  p.pushColour(200);
  EXPECT_EQ(p.pairDepth(200), 1);
  EXPECT_EQ(p.pairDepth(205), 1);  // a colour frame may pair with several depth frames
  p.pushColour(300);               // displaces 100 (unpaired)
  p.pushColour(400);               // displaces 200 (paired)
  EXPECT_EQ(p.counts().colour_dropped, 1u);
  EXPECT_EQ(p.counts().paired, 2u);
  p.clear();  // 300 and 400 never paired
  EXPECT_EQ(p.counts().colour_dropped, 3u);
  EXPECT_EQ(p.size(), 0u);
  EXPECT_EQ(p.pairDepth(300), std::nullopt);
  EXPECT_EQ(p.counts().depth_unmatched, 1u);
  EXPECT_EQ(p.nextColourSlot(), 0);
}

TEST(TimestampPairer, SlotsCycleThroughTheRing) {
  TimestampPairer p(3, 0);
  std::set<int> seen;
  for (int i = 0; i < 3; ++i) {
    const int slot = p.nextColourSlot();
    EXPECT_TRUE(seen.insert(slot).second) << "slot " << slot << " given twice before the ring is full";
    p.pushColour(i);
  }
  EXPECT_EQ(p.nextColourSlot(), *p.pairDepth(0));  // full: the oldest's slot
}

TEST(TimestampPairer, NothingAllocatesAfterConstruction) {
  TimestampPairer p(4, 2'000'000);
  test::AllocationScope scope;
  int64_t t = 0;
  for (int i = 0; i < 10'000; ++i) {
    (void)p.nextColourSlot();
    p.pushColour(i % 1000 == 999 ? t - 5 : t);
    (void)p.pairDepth(t + 1'000'000);
    if (i % 777 == 0) p.clear();
    t += 33'000'000;
  }
  EXPECT_EQ(scope.allocations(), 0u);
  EXPECT_GT(p.counts().paired, 0u);
}

}  // namespace
}  // namespace fovea::hal
