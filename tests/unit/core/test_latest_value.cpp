// The latest-value mailbox (triple buffer): newest wins, never torn, under contention.
#include "core/latest_value.h"

#include <array>
#include <atomic>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/test_time.h"

namespace fovea {
namespace {

TEST(LatestValue, InitialValueUntilTheFirstWrite) {
  LatestValue<int> box(7);
  EXPECT_FALSE(box.update());
  EXPECT_EQ(box.current(), 7);
}

TEST(LatestValue, ReaderGetsOnlyTheNewest) {
  LatestValue<int> box;
  box.write(1);
  box.write(2);
  box.write(3);
  ASSERT_TRUE(box.update());
  EXPECT_EQ(box.current(), 3);
  EXPECT_FALSE(box.update());  // nothing new: the value stays
  EXPECT_EQ(box.current(), 3);
  box.write(4);
  ASSERT_TRUE(box.update());
  EXPECT_EQ(box.current(), 4);
  EXPECT_EQ(box.writes(), 4u);
}

TEST(LatestValue, NonTrivialTypes) {
  LatestValue<std::vector<double>> box;
  box.write({1.0, 2.0});
  ASSERT_TRUE(box.update());
  EXPECT_EQ(box.current(), (std::vector<double>{1.0, 2.0}));
}

// A value whose fields must agree: a torn read would mix two writes.
struct Wide {
  std::array<uint64_t, 32> words{};
};

TEST(LatestValue, TwoThreadsNeverTornAndNeverBackwards) {
  LatestValue<Wide> box;
  // A quarter of the writes in the slow trees (the only ones that build the unit tests).
  const auto writes = static_cast<uint64_t>(test::repetitions(2'000'000, 500'000));
  std::atomic<bool> done{false};
  std::thread writer([&] {
    for (uint64_t n = 1; n <= writes; ++n) {
      Wide& w = box.writeBuffer();
      for (std::size_t i = 0; i < w.words.size(); ++i) w.words[i] = n * (i + 1);
      box.publish();
    }
    done.store(true, std::memory_order_release);
  });
  uint64_t last = 0, updates = 0, torn = 0, backwards = 0;
  for (;;) {
    const bool finished = done.load(std::memory_order_acquire);
    if (box.update()) {
      ++updates;
      const Wide& w = box.current();
      const uint64_t n = w.words[0];
      for (std::size_t i = 0; i < w.words.size(); ++i) torn += w.words[i] != n * (i + 1);
      backwards += n <= last;
      last = n;
    }
    if (finished && !box.update()) break;
    if (finished) {  // the update above took the last value
      last = box.current().words[0];
      break;
    }
  }
  writer.join();
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(backwards, 0u);
  EXPECT_GT(updates, 0u);
  EXPECT_EQ(last, writes);  // the newest value always arrives
}

}  // namespace
}  // namespace fovea
