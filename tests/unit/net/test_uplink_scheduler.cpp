// The uplink's budget, cuts and pacing, driven by a simulated clock.
#include "net/uplink_scheduler.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace fovea::net {
namespace {

constexpr int64_t kMs = 1'000'000;

// Runs the scheduler until the frame is done or `until_ns`, sleeping as told;
// returns the chunks sent, in order, and their send times.
struct Sent {
  std::vector<std::size_t> chunks;
  std::vector<int64_t> times_ns;
};
Sent drain(UplinkScheduler& s, int64_t& now_ns, int64_t until_ns) {
  Sent sent;
  while (now_ns < until_ns) {
    const auto step = s.next(now_ns);
    if (step.kind == UplinkScheduler::Step::Kind::kDone) break;
    if (step.kind == UplinkScheduler::Step::Kind::kWait) {
      EXPECT_GT(step.wait_ns, 0);
      now_ns += step.wait_ns;
      continue;
    }
    sent.chunks.push_back(step.chunk);
    sent.times_ns.push_back(now_ns);
  }
  return sent;
}

TEST(TokenBucket, RefillsAtTheRateUpToTheBurst) {
  TokenBucket b(1000.0, 500.0, 0);  // 1000 B/s, starts full at 500
  EXPECT_TRUE(b.tryConsume(500, 0));
  EXPECT_FALSE(b.tryConsume(1, 0));
  EXPECT_EQ(b.waitNs(100, 0), 100 * kMs);  // 100 B at 1000 B/s
  EXPECT_DOUBLE_EQ(b.available(100 * kMs), 100.0);
  EXPECT_DOUBLE_EQ(b.available(10'000 * kMs), 500.0);  // capped at the burst
  b.charge(700, 10'000 * kMs);                          // debt
  EXPECT_DOUBLE_EQ(b.available(10'000 * kMs), -200.0);
  EXPECT_EQ(b.waitNs(100, 10'000 * kMs), 300 * kMs);
  // Time running backwards earns nothing.
  EXPECT_DOUBLE_EQ(b.available(0), -200.0);
}

TEST(UplinkScheduler, SendsEverythingThatFitsInOrder) {
  auto s = UplinkScheduler::create(16, 1e6, 10'000, 0).value();
  const std::vector<uint32_t> bytes = {1000, 1000, 1000, 1000};
  const std::vector<uint8_t> regions = {0, 1, 1, 3};
  ASSERT_TRUE(s.beginFrame(bytes, regions, 0, 33 * kMs).isOk());
  EXPECT_EQ(s.plannedChunks(), 4u);
  int64_t now = 0;
  const Sent sent = drain(s, now, 33 * kMs);
  EXPECT_EQ(sent.chunks, (std::vector<std::size_t>{0, 1, 2, 3}));
  EXPECT_TRUE(s.frameDone());
  EXPECT_EQ(s.counters().chunks_sent, 4u);
  EXPECT_EQ(s.counters().bytes_sent, 4000u);
  EXPECT_EQ(s.counters().chunks_cut, 0u);
}

TEST(UplinkScheduler, CutsTheOutermostRegionsFirstNeverTheFovea) {
  // 100 kB/s and a 2 kB burst: a 10 ms interval allows 2 kB + 1 kB = 3 kB.
  auto s = UplinkScheduler::create(16, 100'000, 2000, 0).value();
  const std::vector<uint32_t> bytes = {1000, 1000, 1000, 1000, 1000};
  const std::vector<uint8_t> regions = {0, 1, 2, 2, 3};
  ASSERT_TRUE(s.beginFrame(bytes, regions, 0, 10 * kMs).isOk());
  EXPECT_EQ(s.plannedChunks(), 3u);
  EXPECT_EQ(s.cutPerRegion()[3], 1);
  EXPECT_EQ(s.cutPerRegion()[2], 1);
  EXPECT_EQ(s.cutPerRegion()[1], 0);
  EXPECT_EQ(s.plannedPerRegion()[0], 1);
  EXPECT_EQ(s.plannedPerRegion()[2], 1);
  EXPECT_EQ(s.counters().chunks_cut, 2u);
  EXPECT_EQ(s.counters().frames_cut, 1u);
  EXPECT_EQ(s.counters().chunks_cut_per_region[3], 1u);

  // A fovea larger than any budget is still planned whole.
  ASSERT_TRUE(s.beginFrame(std::vector<uint32_t>(10, 1000), std::vector<uint8_t>(10, 0), 0, 0).isOk());
  EXPECT_EQ(s.plannedChunks(), 10u);
}

TEST(UplinkScheduler, PacesToTheBudget) {
  // 1 MB/s, burst of one 1000-byte datagram: one datagram per millisecond.
  auto s = UplinkScheduler::create(64, 1e6, 1000, 0).value();
  const std::vector<uint32_t> bytes(20, 1000);
  const std::vector<uint8_t> regions(20, 1);
  ASSERT_TRUE(s.beginFrame(bytes, regions, 0, 100 * kMs).isOk());
  int64_t now = 0;
  const Sent sent = drain(s, now, 100 * kMs);
  ASSERT_EQ(sent.chunks.size(), 20u);
  for (std::size_t i = 1; i < sent.times_ns.size(); ++i) {
    EXPECT_GE(sent.times_ns[i] - sent.times_ns[i - 1], 1 * kMs - 1) << i;
  }
  // 19 intervals of 1 ms after the first datagram, which the full bucket sent at once.
  EXPECT_NEAR(static_cast<double>(sent.times_ns.back()), 19.0 * kMs, 0.01 * kMs);
}

TEST(UplinkScheduler, TheNextFrameDropsTheUnsentTail) {
  auto s = UplinkScheduler::create(64, 1e6, 1000, 0).value();
  const std::vector<uint32_t> bytes(20, 1000);
  const std::vector<uint8_t> regions(20, 0);  // all fovea: nothing is cut at planning
  ASSERT_TRUE(s.beginFrame(bytes, regions, 0, 0).isOk());
  int64_t now = 0;
  const Sent sent = drain(s, now, 5 * kMs);  // the next frame comes after 5 ms
  EXPECT_GE(sent.chunks.size(), 5u);
  EXPECT_LE(sent.chunks.size(), 6u);
  ASSERT_TRUE(s.beginFrame(bytes, regions, now, 0).isOk());
  EXPECT_EQ(s.counters().chunks_superseded, 20u - sent.chunks.size());
  EXPECT_EQ(s.counters().frames_superseded, 1u);
  // The new frame starts from its own first chunk.
  const auto step = s.next(now + 2 * kMs);
  ASSERT_EQ(step.kind, UplinkScheduler::Step::Kind::kSend);
  EXPECT_EQ(step.chunk, 0u);
}

// A new session's room (its MTU changes what the codec makes): the frame under
// way is dropped as the next frame would drop it, counted, and the new room
// holds exactly max_chunks.
TEST(UplinkScheduler, NewRoomDropsTheFrameUnderWayAndHoldsItsSize) {
  auto s = UplinkScheduler::create(64, 1e6, 1000, 0).value();
  const std::vector<uint32_t> bytes(20, 1000);
  const std::vector<uint8_t> regions(20, 0);
  ASSERT_TRUE(s.beginFrame(bytes, regions, 0, 0).isOk());
  int64_t now = 0;
  const Sent sent = drain(s, now, 5 * kMs);
  ASSERT_LT(sent.chunks.size(), 20u);
  s.setMaxChunks(100);
  EXPECT_EQ(s.counters().chunks_superseded, 20u - sent.chunks.size());
  EXPECT_EQ(s.counters().frames_superseded, 1u);
  EXPECT_TRUE(s.frameDone());
  EXPECT_EQ(s.next(now).kind, UplinkScheduler::Step::Kind::kDone);
  EXPECT_TRUE(s.beginFrame(std::vector<uint32_t>(100, 10), std::vector<uint8_t>(100, 0), now, 0).isOk());
  EXPECT_EQ(s.beginFrame(std::vector<uint32_t>(101, 10), std::vector<uint8_t>(101, 0), now, 0).code(),
            ErrorCode::kCapacityExceeded);
  s.setMaxChunks(2);  // smaller
  EXPECT_EQ(s.beginFrame(std::vector<uint32_t>(3, 10), std::vector<uint8_t>(3, 0), now, 0).code(),
            ErrorCode::kCapacityExceeded);
  EXPECT_TRUE(s.beginFrame(std::vector<uint32_t>(2, 10), std::vector<uint8_t>(2, 0), now, 0).isOk());
}

TEST(UplinkScheduler, OversizedDatagramPassesOnAFullBucket) {
  auto s = UplinkScheduler::create(4, 1e6, 1000, 0).value();
  ASSERT_TRUE(s.beginFrame(std::vector<uint32_t>{4000}, std::vector<uint8_t>{0}, 0, 0).isOk());
  int64_t now = 0;
  const Sent sent = drain(s, now, 1000 * kMs);
  EXPECT_EQ(sent.chunks.size(), 1u);
}

TEST(UplinkScheduler, RejectsBadPlans) {
  EXPECT_FALSE(UplinkScheduler::create(0, 1e6, 2000, 0).isOk());
  EXPECT_FALSE(UplinkScheduler::create(4, 0.0, 2000, 0).isOk());
  EXPECT_FALSE(UplinkScheduler::create(4, 1e6, 10, 0).isOk());
  auto s = UplinkScheduler::create(4, 1e6, 2000, 0).value();
  EXPECT_EQ(s.beginFrame(std::vector<uint32_t>{1, 2}, std::vector<uint8_t>{0}, 0, 0).code(), ErrorCode::kInvalidInput);
  EXPECT_EQ(s.beginFrame(std::vector<uint32_t>{1, 2}, std::vector<uint8_t>{1, 0}, 0, 0).code(), ErrorCode::kInvalidInput);
  EXPECT_EQ(s.beginFrame(std::vector<uint32_t>{1}, std::vector<uint8_t>{9}, 0, 0).code(), ErrorCode::kInvalidInput);
  EXPECT_EQ(s.beginFrame(std::vector<uint32_t>(5, 1), std::vector<uint8_t>(5, 0), 0, 0).code(),
            ErrorCode::kCapacityExceeded);
}

// Property: over random frames, bytes sent in any window never exceed the
// burst plus the rate times the window, and the plan is a prefix that keeps
// every fovea chunk and cuts regions outermost first.
TEST(UplinkScheduler, RandomFramesRespectTheBudget) {
  std::mt19937 rng(7);
  const double rate = 2e6, burst = 3000;
  auto s = UplinkScheduler::create(256, rate, burst, 0).value();
  int64_t now = 0;
  std::vector<std::pair<int64_t, uint32_t>> log;  // (time, bytes)
  for (int frame = 0; frame < 200; ++frame) {
    const std::size_t n = std::uniform_int_distribution<std::size_t>(0, 200)(rng);
    std::vector<uint32_t> bytes(n);
    std::vector<uint8_t> regions(n);
    uint8_t r = 0;
    for (std::size_t i = 0; i < n; ++i) {
      bytes[i] = std::uniform_int_distribution<uint32_t>(100, 1200)(rng);
      if (std::uniform_int_distribution<int>(0, 9)(rng) == 0 && r < 7) ++r;
      regions[i] = r;
    }
    const int64_t interval = std::uniform_int_distribution<int64_t>(1, 50)(rng) * kMs;
    ASSERT_TRUE(s.beginFrame(bytes, regions, now, interval).isOk());
    const std::size_t keep = s.plannedChunks();
    for (std::size_t i = keep; i < n; ++i) EXPECT_NE(regions[i], 0) << "fovea chunk cut";
    const int64_t deadline = now + interval;
    for (;;) {
      const auto step = s.next(now);
      if (step.kind == UplinkScheduler::Step::Kind::kDone) break;
      if (step.kind == UplinkScheduler::Step::Kind::kWait) {
        if (now + step.wait_ns > deadline) break;
        now += step.wait_ns;
        continue;
      }
      log.emplace_back(now, bytes[step.chunk]);
    }
    now = deadline;
  }
  // Sliding windows starting at each send.
  for (std::size_t i = 0; i < log.size(); i += 7) {
    double sum = 0;
    for (std::size_t j = i; j < log.size(); ++j) {
      sum += log[j].second;
      const double window_s = static_cast<double>(log[j].first - log[i].first) * 1e-9;
      ASSERT_LE(sum, burst + rate * window_s + 1e-6) << "window " << i << ".." << j;
    }
  }
  EXPECT_GT(s.counters().chunks_sent, 1000u);
}

}  // namespace
}  // namespace fovea::net
