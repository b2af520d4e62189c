// The latest-wins SPSC ring: unit cases, a property test against a brute-force
// model (one thread, random interleavings), and a two-thread stress test.
#include "core/ring.h"

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <deque>
#include <random>
#include <set>
#include <thread>
#include <vector>

namespace fovea {
namespace {

TEST(SlotRing, CacheLineSizeIsPinnedAndIndicesDoNotShareALine) {
  static_assert(kCacheLineBytes == 64);
  EXPECT_GE(alignof(SlotRing), kCacheLineBytes);
}

TEST(SlotRing, SlotCountIsDepthPlusProducerPlusConsumerHolds) {
  SlotRing ring(3, 2);
  EXPECT_EQ(ring.depth(), 3u);
  EXPECT_EQ(ring.slotCount(), 6u);
}

TEST(SlotRing, FifoWithoutOverflow) {
  SlotRing ring(4);
  std::vector<SlotIndex> published;
  for (int i = 0; i < 3; ++i) {
    SlotIndex s = 99;
    ASSERT_TRUE(ring.tryAcquire(s));
    published.push_back(s);
    ring.publish(s);
  }
  EXPECT_EQ(ring.sizeApprox(), 3u);
  for (SlotIndex expected : published) {
    SlotIndex s = 99;
    ASSERT_TRUE(ring.tryTake(s));
    EXPECT_EQ(s, expected);
    EXPECT_TRUE(ring.release(s));
  }
  SlotIndex s = 99;
  EXPECT_FALSE(ring.tryTake(s));
  const RingCounters c = ring.counters();
  EXPECT_EQ(c.published, 3u);
  EXPECT_EQ(c.taken, 3u);
  EXPECT_EQ(c.dropped, 0u);
}

TEST(SlotRing, OverflowDropsTheOldestAndCountsIt) {
  SlotRing ring(2);
  std::vector<SlotIndex> published;
  for (int i = 0; i < 5; ++i) {
    SlotIndex s = 99;
    ASSERT_TRUE(ring.tryAcquire(s)) << i;  // a dropped slot comes back to the producer
    published.push_back(s);
    ring.publish(s);
  }
  EXPECT_EQ(ring.counters().dropped, 3u);
  EXPECT_EQ(ring.sizeApprox(), 2u);
  SlotIndex s = 99;
  ASSERT_TRUE(ring.tryTake(s));
  EXPECT_EQ(s, published[3]);
  ASSERT_TRUE(ring.release(s));
  ASSERT_TRUE(ring.tryTake(s));
  EXPECT_EQ(s, published[4]);
  ASSERT_TRUE(ring.release(s));
  EXPECT_FALSE(ring.tryTake(s));
}

TEST(SlotRing, DepthOneAlwaysGivesTheNewest) {
  SlotPoolRing<int> pool(1, 1, -1);
  for (int frame = 0; frame < 10; ++frame) {
    SlotIndex s = 0;
    ASSERT_TRUE(pool.ring().tryAcquire(s));
    pool.slot(s) = frame;
    pool.ring().publish(s);
  }
  SlotIndex s = 0;
  ASSERT_TRUE(pool.ring().tryTake(s));
  EXPECT_EQ(pool.slot(s), 9);
  EXPECT_EQ(pool.ring().counters().dropped, 9u);
}

TEST(SlotRing, AConsumerHoldingMoreThanPromisedMakesAcquireFailNotCorrupt) {
  SlotRing ring(1, 1);  // 3 slots
  SlotIndex held[3];
  // The consumer takes two (one more than promised); the producer then has none.
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(ring.tryAcquire(held[i]));
    ring.publish(held[i]);
    ASSERT_TRUE(ring.tryTake(held[i]));
  }
  ASSERT_TRUE(ring.tryAcquire(held[2]));
  ring.publish(held[2]);
  SlotIndex s = 99;
  EXPECT_FALSE(ring.tryAcquire(s));
  EXPECT_EQ(ring.counters().acquire_failures, 1u);
  ASSERT_TRUE(ring.release(held[0]));
  ASSERT_TRUE(ring.tryAcquire(s));
  EXPECT_EQ(s, held[0]);
  ring.cancel(s);
  ASSERT_TRUE(ring.tryAcquire(s));
  EXPECT_EQ(s, held[0]);
}

TEST(SlotRing, ReleasingMoreThanWasTakenOrAnIndexOutOfRangeIsRefused) {
  SlotRing ring(1, 1);
  EXPECT_FALSE(ring.release(3));
  // Three releases fit (3 slots); a fourth would overwrite the free queue.
  EXPECT_TRUE(ring.release(0));
  EXPECT_TRUE(ring.release(1));
  EXPECT_TRUE(ring.release(2));
  EXPECT_FALSE(ring.release(0));
}

// ---- property test: random interleavings against a brute-force model ----

enum class Owner { kFree, kProducer, kQueued, kConsumer };

struct Payload {
  uint64_t seq = 0;
};

void runModel(std::size_t depth, std::size_t holds, uint32_t seed, int steps) {
  SCOPED_TRACE(testing::Message() << "depth " << depth << " holds " << holds << " seed " << seed);
  SlotPoolRing<Payload> pool(depth, holds, Payload{});
  SlotRing& ring = pool.ring();
  const std::size_t n = ring.slotCount();
  std::vector<Owner> owner(n, Owner::kFree);
  struct Item {
    uint64_t seq;
    SlotIndex slot;
  };
  std::deque<Item> model;  // the queue as it must be: oldest first
  uint64_t model_dropped = 0, model_published = 0, model_taken = 0, next_seq = 0;
  bool producing = false;
  SlotIndex produced_slot = 0;
  std::vector<SlotIndex> consuming;
  uint64_t last_taken_seq = 0;
  bool any_taken = false;

  std::mt19937 rng(seed);
  for (int step = 0; step < steps; ++step) {
    switch (rng() % 5) {
      case 0: {  // producer: acquire, or publish/cancel what it holds
        if (!producing) {
          SlotIndex s = 0;
          ASSERT_TRUE(ring.tryAcquire(s)) << "step " << step;  // the consumer holds <= holds
          ASSERT_LT(s, n);
          ASSERT_EQ(owner[s], Owner::kFree) << "step " << step;
          owner[s] = Owner::kProducer;
          producing = true;
          produced_slot = s;
        } else if (rng() % 8 == 0) {
          owner[produced_slot] = Owner::kFree;
          ring.cancel(produced_slot);
          producing = false;
        } else {
          const SlotIndex s = produced_slot;
          pool.slot(s).seq = next_seq;
          if (model.size() == depth) {
            owner[model.front().slot] = Owner::kFree;  // dropped: back to the producer
            model.pop_front();
            ++model_dropped;
          }
          model.push_back({next_seq++, s});
          owner[s] = Owner::kQueued;
          ring.publish(s);
          ++model_published;
          producing = false;
        }
        break;
      }
      case 1:
      case 2: {  // consumer: take
        if (consuming.size() == holds) break;
        SlotIndex s = 0;
        const bool took = ring.tryTake(s);
        ASSERT_EQ(took, !model.empty()) << "step " << step;
        if (!took) break;
        ASSERT_EQ(s, model.front().slot) << "step " << step;
        ASSERT_EQ(owner[s], Owner::kQueued);
        ASSERT_EQ(pool.slot(s).seq, model.front().seq);
        if (any_taken) {
          ASSERT_GT(pool.slot(s).seq, last_taken_seq);
        }
        last_taken_seq = pool.slot(s).seq;
        any_taken = true;
        model.pop_front();
        ++model_taken;
        owner[s] = Owner::kConsumer;
        consuming.push_back(s);
        break;
      }
      default: {  // consumer: release one it holds (any order)
        if (consuming.empty()) break;
        const std::size_t i = rng() % consuming.size();
        const SlotIndex s = consuming[i];
        consuming.erase(consuming.begin() + static_cast<std::ptrdiff_t>(i));
        owner[s] = Owner::kFree;
        ASSERT_TRUE(ring.release(s));
        break;
      }
    }
    const RingCounters c = ring.counters();
    ASSERT_EQ(c.published, model_published);
    ASSERT_EQ(c.dropped, model_dropped);
    ASSERT_EQ(c.taken, model_taken);
    ASSERT_EQ(c.acquire_failures, 0u);
    ASSERT_EQ(ring.sizeApprox(), model.size());
    ASSERT_EQ(c.taken + c.dropped + model.size(), c.published);
  }
}

TEST(SlotRing, MatchesABruteForceModelOverRandomInterleavings) {
  for (std::size_t depth : {1u, 2u, 3u, 7u}) {
    for (std::size_t holds : {1u, 2u}) {
      for (uint32_t seed = 1; seed <= 4; ++seed) {
        runModel(depth, holds, seed * 7919u + static_cast<uint32_t>(depth * 31 + holds), 40'000);
        if (HasFatalFailure()) return;
      }
    }
  }
}

// ---- two threads ----

struct StressSlot {
  uint64_t seq = 0;
  std::array<uint64_t, 7> check{};  // derived from seq: a torn or stale slot shows
};

// producer_pace, consumer_slowness: out of 64 items, how many are followed by a
// short spin on that side; they set the mix of takes and drops.
void runStress(std::size_t depth, uint64_t items, int producer_pace, int consumer_slowness) {
  SCOPED_TRACE(testing::Message() << "depth " << depth << " items " << items);
  SlotPoolRing<StressSlot> pool(depth, 1, StressSlot{});
  SlotRing& ring = pool.ring();
  const std::size_t n = ring.slotCount();
  // 0: with the ring (free or queued), 1: producer, 2: consumer.
  std::unique_ptr<std::atomic<int>[]> owner(new std::atomic<int>[n]);
  for (std::size_t i = 0; i < n; ++i) owner[i].store(0);
  std::atomic<bool> done{false};
  std::atomic<bool> consumer_ready{false};
  std::atomic<uint64_t> ownership_violations{0};

  std::thread producer([&] {
    std::mt19937 producer_rng(777);
    std::atomic<uint64_t> pace{0};
    while (!consumer_ready.load(std::memory_order_acquire)) std::this_thread::yield();
    for (uint64_t seq = 0; seq < items; ++seq) {
      if (static_cast<int>(producer_rng() % 64) < producer_pace) {
        for (int spin = 0; spin < 100; ++spin) pace.fetch_add(1, std::memory_order_relaxed);
      }
      SlotIndex s = 0;
      while (!ring.tryAcquire(s)) {
      }
      if (owner[s].exchange(1, std::memory_order_relaxed) != 0) ownership_violations.fetch_add(1);
      StressSlot& slot = pool.slot(s);
      slot.seq = seq;
      for (std::size_t k = 0; k < slot.check.size(); ++k) slot.check[k] = seq * 0x9E3779B97F4A7C15ull + k;
      owner[s].store(0, std::memory_order_relaxed);
      ring.publish(s);
    }
    done.store(true, std::memory_order_release);
  });

  uint64_t received = 0, last_seq = 0, bad_order = 0, bad_payload = 0;
  bool any = false;
  std::mt19937 rng(12345);
  std::atomic<uint64_t> dawdle{0};
  consumer_ready.store(true, std::memory_order_release);
  for (;;) {
    SlotIndex s = 0;
    if (!ring.tryTake(s)) {
      if (done.load(std::memory_order_acquire)) {
        if (!ring.tryTake(s)) break;
      } else {
        continue;
      }
    }
    if (owner[s].exchange(2, std::memory_order_relaxed) != 0) ownership_violations.fetch_add(1);
    const StressSlot& slot = pool.slot(s);
    if (any && slot.seq <= last_seq) ++bad_order;
    for (std::size_t k = 0; k < slot.check.size(); ++k) {
      if (slot.check[k] != slot.seq * 0x9E3779B97F4A7C15ull + k) ++bad_payload;
    }
    last_seq = slot.seq;
    any = true;
    ++received;
    // Sometimes dawdle, so that the queue overflows and drops race with takes.
    if (consumer_slowness > 0 && static_cast<int>(rng() % 64) < consumer_slowness) {
      for (int spin = 0; spin < 200; ++spin) dawdle.fetch_add(1, std::memory_order_relaxed);
    }
    owner[s].store(0, std::memory_order_relaxed);
    ASSERT_TRUE(ring.release(s));
  }
  producer.join();

  const RingCounters c = ring.counters();
  EXPECT_EQ(ownership_violations.load(), 0u);
  EXPECT_EQ(bad_order, 0u);
  EXPECT_EQ(bad_payload, 0u);
  EXPECT_EQ(c.published, items);
  EXPECT_EQ(c.taken, received);
  EXPECT_EQ(received + c.dropped, items);
  EXPECT_TRUE(any);
  EXPECT_EQ(last_seq, items - 1);  // the newest is never dropped
  // Every slot came back exactly once: the producer can now acquire each of them
  // once, and not one more.
  std::set<SlotIndex> all;
  for (std::size_t i = 0; i < n; ++i) {
    SlotIndex s = 0;
    ASSERT_TRUE(ring.tryAcquire(s)) << i;
    EXPECT_TRUE(all.insert(s).second) << "slot " << s << " twice";
  }
  SlotIndex s = 0;
  EXPECT_FALSE(ring.tryAcquire(s));
  EXPECT_EQ(all.size(), n);
  std::printf("depth %zu: %llu produced, %llu received, %llu dropped, %llu acquire retries\n", depth,
              static_cast<unsigned long long>(items), static_cast<unsigned long long>(received),
              static_cast<unsigned long long>(c.dropped), static_cast<unsigned long long>(c.acquire_failures));
}

TEST(SlotRingStress, TwoThreadsDepthOne) { runStress(1, 1'000'000, 32, 16); }
TEST(SlotRingStress, TwoThreadsDepthFourSlowConsumer) { runStress(4, 1'000'000, 32, 40); }
TEST(SlotRingStress, TwoThreadsDepthFourFastConsumer) { runStress(4, 1'000'000, 32, 0); }

}  // namespace
}  // namespace fovea
