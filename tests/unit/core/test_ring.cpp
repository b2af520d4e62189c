// The latest-wins SPSC ring: unit cases, a property test against a brute-force
// model (one thread, random interleavings), and a two-thread stress test.
#include "core/ring.h"

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <memory>
#include <random>
#include <set>
#include <thread>
#include <vector>

#include "tests/support/test_time.h"

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

// The ring beside the model of what it must hold: each step does one random
// operation on both and checks the ring against the model.
class RingModel {
 public:
  RingModel(std::size_t depth, std::size_t holds)
      : depth_(depth), holds_(holds), pool_(depth, holds, Payload{}), ring_(pool_.ring()), n_(ring_.slotCount()),
        owner_(n_, Owner::kFree) {}

  // Producer: acquire, or publish/cancel what it holds.
  void producerStep(std::mt19937& rng, int step) {
    if (!producing_) {
      SlotIndex s = 0;
      ASSERT_TRUE(ring_.tryAcquire(s)) << "step " << step;  // the consumer holds <= holds
      ASSERT_LT(s, n_);
      ASSERT_EQ(owner_[s], Owner::kFree) << "step " << step;
      owner_[s] = Owner::kProducer;
      producing_ = true;
      produced_slot_ = s;
    } else if (rng() % 8 == 0) {
      owner_[produced_slot_] = Owner::kFree;
      ring_.cancel(produced_slot_);
      producing_ = false;
    } else {
      publishProduced();
    }
  }

  // Consumer: take.
  void consumerTake(int step) {
    if (consuming_.size() == holds_) return;
    SlotIndex s = 0;
    const bool took = ring_.tryTake(s);
    ASSERT_EQ(took, !model_.empty()) << "step " << step;
    if (!took) return;
    ASSERT_EQ(s, model_.front().slot) << "step " << step;
    ASSERT_EQ(owner_[s], Owner::kQueued);
    ASSERT_EQ(pool_.slot(s).seq, model_.front().seq);
    if (any_taken_) {
      ASSERT_GT(pool_.slot(s).seq, last_taken_seq_);
    }
    last_taken_seq_ = pool_.slot(s).seq;
    any_taken_ = true;
    model_.pop_front();
    ++model_taken_;
    owner_[s] = Owner::kConsumer;
    consuming_.push_back(s);
  }

  // Consumer: release one it holds (any order).
  void consumerRelease(std::mt19937& rng) {
    if (consuming_.empty()) return;
    const std::size_t i = rng() % consuming_.size();
    const SlotIndex s = consuming_[i];
    consuming_.erase(consuming_.begin() + static_cast<std::ptrdiff_t>(i));
    owner_[s] = Owner::kFree;
    ASSERT_TRUE(ring_.release(s));
  }

  // The ring's counters and size after every step, as the model has them.
  void checkCounters() const {
    const RingCounters c = ring_.counters();
    ASSERT_EQ(c.published, model_published_);
    ASSERT_EQ(c.dropped, model_dropped_);
    ASSERT_EQ(c.taken, model_taken_);
    ASSERT_EQ(c.acquire_failures, 0u);
    ASSERT_EQ(ring_.sizeApprox(), model_.size());
    ASSERT_EQ(c.taken + c.dropped + model_.size(), c.published);
  }

 private:
  struct Item {
    uint64_t seq;
    SlotIndex slot;
  };

  void publishProduced() {
    const SlotIndex s = produced_slot_;
    pool_.slot(s).seq = next_seq_;
    if (model_.size() == depth_) {
      owner_[model_.front().slot] = Owner::kFree;  // dropped: back to the producer
      model_.pop_front();
      ++model_dropped_;
    }
    model_.push_back({next_seq_++, s});
    owner_[s] = Owner::kQueued;
    ring_.publish(s);
    ++model_published_;
    producing_ = false;
  }

  const std::size_t depth_, holds_;
  SlotPoolRing<Payload> pool_;
  SlotRing& ring_;
  const std::size_t n_;
  std::vector<Owner> owner_;
  std::deque<Item> model_;  // the queue as it must be: oldest first
  uint64_t model_dropped_ = 0, model_published_ = 0, model_taken_ = 0, next_seq_ = 0;
  bool producing_ = false;
  SlotIndex produced_slot_ = 0;
  std::vector<SlotIndex> consuming_;
  uint64_t last_taken_seq_ = 0;
  bool any_taken_ = false;
};

void runModel(std::size_t depth, std::size_t holds, uint32_t seed, int steps) {
  SCOPED_TRACE(testing::Message() << "depth " << depth << " holds " << holds << " seed " << seed);
  RingModel model(depth, holds);
  std::mt19937 rng(seed);
  for (int step = 0; step < steps; ++step) {
    switch (rng() % 5) {
      case 0:
        ASSERT_NO_FATAL_FAILURE(model.producerStep(rng, step));
        break;
      case 1:
      case 2:
        ASSERT_NO_FATAL_FAILURE(model.consumerTake(step));
        break;
      default:
        ASSERT_NO_FATAL_FAILURE(model.consumerRelease(rng));
        break;
    }
    ASSERT_NO_FATAL_FAILURE(model.checkCounters());
  }
}

TEST(SlotRing, MatchesABruteForceModelOverRandomInterleavings) {
  // The trees that build the unit tests are the slow ones (sanitizers, qemu): a
  // quarter of the steps there, still 320 000 over the 32 runs (docs/ci.md).
  const int steps = test::repetitions(40'000, 10'000);
  for (std::size_t depth : {1u, 2u, 3u, 7u}) {
    for (std::size_t holds : {1u, 2u}) {
      for (uint32_t seed = 1; seed <= 4; ++seed) {
        runModel(depth, holds, seed * 7919u + static_cast<uint32_t>(depth * 31 + holds), steps);
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

// What the two threads share: the ring, and who holds each slot.
struct StressRing {
  explicit StressRing(std::size_t depth)
      : pool(depth, 1, StressSlot{}), ring(pool.ring()), n(ring.slotCount()), owner(new std::atomic<int>[n]) {
    for (std::size_t i = 0; i < n; ++i) owner[i].store(0);
  }
  SlotPoolRing<StressSlot> pool;
  SlotRing& ring;
  const std::size_t n;
  // 0: with the ring (free or queued), 1: producer, 2: consumer.
  std::unique_ptr<std::atomic<int>[]> owner;
  std::atomic<bool> done{false};
  std::atomic<bool> consumer_ready{false};
  std::atomic<uint64_t> ownership_violations{0};
};

// The producer thread: `items` slots filled and published, with a short spin
// after `producer_pace` items out of 64.
void produceStressItems(StressRing& shared, uint64_t items, int producer_pace) {
  std::mt19937 producer_rng(777);
  std::atomic<uint64_t> pace{0};
  while (!shared.consumer_ready.load(std::memory_order_acquire)) std::this_thread::yield();
  for (uint64_t seq = 0; seq < items; ++seq) {
    if (static_cast<int>(producer_rng() % 64) < producer_pace) {
      for (int spin = 0; spin < 100; ++spin) pace.fetch_add(1, std::memory_order_relaxed);
    }
    SlotIndex s = 0;
    while (!shared.ring.tryAcquire(s)) {
    }
    if (shared.owner[s].exchange(1, std::memory_order_relaxed) != 0) shared.ownership_violations.fetch_add(1);
    StressSlot& slot = shared.pool.slot(s);
    slot.seq = seq;
    for (std::size_t k = 0; k < slot.check.size(); ++k) slot.check[k] = seq * 0x9E3779B97F4A7C15ull + k;
    shared.owner[s].store(0, std::memory_order_relaxed);
    shared.ring.publish(s);
  }
  shared.done.store(true, std::memory_order_release);
}

// What the consumer saw.
struct StressTally {
  uint64_t received = 0, last_seq = 0, bad_order = 0, bad_payload = 0;
  bool any = false;
};

// The consumer, on this thread: takes until the producer is done and the ring
// is empty, checking each slot's order and payload.
void consumeStressItems(StressRing& shared, int consumer_slowness, StressTally& tally) {
  std::mt19937 rng(12345);
  std::atomic<uint64_t> dawdle{0};
  shared.consumer_ready.store(true, std::memory_order_release);
  for (;;) {
    SlotIndex s = 0;
    if (!shared.ring.tryTake(s)) {
      if (shared.done.load(std::memory_order_acquire)) {
        if (!shared.ring.tryTake(s)) break;
      } else {
        continue;
      }
    }
    if (shared.owner[s].exchange(2, std::memory_order_relaxed) != 0) shared.ownership_violations.fetch_add(1);
    const StressSlot& slot = shared.pool.slot(s);
    if (tally.any && slot.seq <= tally.last_seq) ++tally.bad_order;
    for (std::size_t k = 0; k < slot.check.size(); ++k) {
      if (slot.check[k] != slot.seq * 0x9E3779B97F4A7C15ull + k) ++tally.bad_payload;
    }
    tally.last_seq = slot.seq;
    tally.any = true;
    ++tally.received;
    // Sometimes dawdle, so that the queue overflows and drops race with takes.
    if (consumer_slowness > 0 && static_cast<int>(rng() % 64) < consumer_slowness) {
      for (int spin = 0; spin < 200; ++spin) dawdle.fetch_add(1, std::memory_order_relaxed);
    }
    shared.owner[s].store(0, std::memory_order_relaxed);
    ASSERT_TRUE(shared.ring.release(s));
  }
}

// Every slot came back exactly once: the producer can now acquire each of them
// once, and not one more.
void expectEverySlotBackOnce(SlotRing& ring, std::size_t n) {
  std::set<SlotIndex> all;
  for (std::size_t i = 0; i < n; ++i) {
    SlotIndex s = 0;
    ASSERT_TRUE(ring.tryAcquire(s)) << i;
    EXPECT_TRUE(all.insert(s).second) << "slot " << s << " twice";
  }
  SlotIndex s = 0;
  EXPECT_FALSE(ring.tryAcquire(s));
  EXPECT_EQ(all.size(), n);
}

// producer_pace, consumer_slowness: out of 64 items, how many are followed by a
// short spin on that side; they set the mix of takes and drops.
void runStress(std::size_t depth, uint64_t items, int producer_pace, int consumer_slowness) {
  SCOPED_TRACE(testing::Message() << "depth " << depth << " items " << items);
  StressRing shared(depth);
  std::thread producer([&] { produceStressItems(shared, items, producer_pace); });
  StressTally tally;
  ASSERT_NO_FATAL_FAILURE(consumeStressItems(shared, consumer_slowness, tally));
  producer.join();

  const RingCounters c = shared.ring.counters();
  EXPECT_EQ(shared.ownership_violations.load(), 0u);
  EXPECT_EQ(tally.bad_order, 0u);
  EXPECT_EQ(tally.bad_payload, 0u);
  EXPECT_EQ(c.published, items);
  EXPECT_EQ(c.taken, tally.received);
  EXPECT_EQ(tally.received + c.dropped, items);
  EXPECT_TRUE(tally.any);
  EXPECT_EQ(tally.last_seq, items - 1);  // the newest is never dropped
  ASSERT_NO_FATAL_FAILURE(expectEverySlotBackOnce(shared.ring, shared.n));
  std::printf("depth %zu: %llu produced, %llu received, %llu dropped, %llu acquire retries\n", depth,
              static_cast<unsigned long long>(items), static_cast<unsigned long long>(tally.received),
              static_cast<unsigned long long>(c.dropped), static_cast<unsigned long long>(c.acquire_failures));
}

// A million items natively; a quarter of them under the sanitizers and qemu, where
// each costs 10 to 40 times as much and ThreadSanitizer checks every take and drop
// that does happen (docs/ci.md).
uint64_t stressItems() { return static_cast<uint64_t>(test::repetitions(1'000'000, 250'000)); }

TEST(SlotRingStress, TwoThreadsDepthOne) { runStress(1, stressItems(), 32, 16); }
TEST(SlotRingStress, TwoThreadsDepthFourSlowConsumer) { runStress(4, stressItems(), 32, 40); }
TEST(SlotRingStress, TwoThreadsDepthFourFastConsumer) { runStress(4, stressItems(), 32, 0); }

}  // namespace
}  // namespace fovea
