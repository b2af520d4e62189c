#include "net/replay_window.h"

#include <gtest/gtest.h>

#include <limits>
#include <random>
#include <set>

namespace fovea::net {
namespace {

using V = ReplayWindow::Verdict;

// check() then commit() when fresh, as the channel does after authentication.
V accept(ReplayWindow& w, uint64_t seq) {
  const V v = w.check(seq);
  if (v == V::kFresh) w.commit(seq);
  return v;
}

TEST(ReplayWindow, InOrderAcceptedDuplicatesRejected) {
  ReplayWindow w;
  for (uint64_t s = 1; s <= 3000; ++s) EXPECT_EQ(accept(w, s), V::kFresh) << s;
  EXPECT_EQ(accept(w, 3000), V::kDuplicate);
  EXPECT_EQ(accept(w, 2999), V::kDuplicate);
  EXPECT_EQ(accept(w, 3000 - ReplayWindow::kWindow), V::kTooOld);
}

TEST(ReplayWindow, ZeroIsNeverValid) {
  ReplayWindow w;
  EXPECT_EQ(w.check(0), V::kTooOld);
}

TEST(ReplayWindow, HighestPossibleSequenceNumber) {
  ReplayWindow w;
  const uint64_t top = std::numeric_limits<uint64_t>::max();
  EXPECT_EQ(accept(w, top - 5), V::kFresh);
  EXPECT_EQ(accept(w, top), V::kFresh);
  EXPECT_EQ(accept(w, top), V::kDuplicate);
  EXPECT_EQ(accept(w, top - 5), V::kDuplicate);
  EXPECT_EQ(accept(w, top - 1), V::kFresh);
}

TEST(ReplayWindow, ReorderedWithinWindowAccepted) {
  ReplayWindow w;
  EXPECT_EQ(accept(w, 10), V::kFresh);
  EXPECT_EQ(accept(w, 7), V::kFresh);
  EXPECT_EQ(accept(w, 9), V::kFresh);
  EXPECT_EQ(accept(w, 7), V::kDuplicate);
  EXPECT_EQ(accept(w, 8), V::kFresh);
  EXPECT_EQ(accept(w, 1), V::kFresh);
}

TEST(ReplayWindow, EdgeOfWindow) {
  ReplayWindow w;
  const uint64_t top = 5000;
  EXPECT_EQ(accept(w, top), V::kFresh);
  EXPECT_EQ(accept(w, top - ReplayWindow::kWindow + 1), V::kFresh);  // the oldest slot still inside
  EXPECT_EQ(accept(w, top - ReplayWindow::kWindow), V::kTooOld);
}

TEST(ReplayWindow, LargeJumpForgetsOldSlots) {
  ReplayWindow w;
  EXPECT_EQ(accept(w, 5), V::kFresh);
  EXPECT_EQ(accept(w, 5 + ReplayWindow::kWindow), V::kFresh);  // slot of 5 reused
  EXPECT_EQ(accept(w, 6), V::kFresh);
  EXPECT_EQ(accept(w, 1'000'000), V::kFresh);
  EXPECT_EQ(accept(w, 1'000'000 - 1), V::kFresh);
  EXPECT_EQ(accept(w, 1'000'000 - ReplayWindow::kWindow), V::kTooOld);
}

// Property: the bitmap agrees with a brute-force reference (every number ever
// accepted, and the highest) on random sequences mixing progress, reordering,
// duplicates and jumps.
TEST(ReplayWindow, MatchesBruteForceReference) {
  std::mt19937_64 rng(1234);
  for (int round = 0; round < 20; ++round) {
    ReplayWindow w;
    std::set<uint64_t> seen;
    uint64_t highest = 0;
    for (int i = 0; i < 20000; ++i) {
      uint64_t seq = 0;
      switch (rng() % 6) {
        case 0: seq = highest + 1; break;
        case 1: seq = highest + 1 + rng() % 2000; break;           // jump (maybe past the window)
        case 2: seq = highest > 0 ? highest - rng() % std::min<uint64_t>(highest, 1100) : 0; break;  // around the edge
        case 3: seq = highest > 8 ? highest - rng() % 8 : 1; break;  // recent duplicates
        case 4: seq = rng() % (highest + 2); break;
        default: seq = highest + 1 + rng() % 4; break;
      }
      V expected;
      if (seq == 0 || (highest >= ReplayWindow::kWindow && seq <= highest - ReplayWindow::kWindow)) {
        expected = V::kTooOld;
      } else if (seen.count(seq)) {
        expected = V::kDuplicate;
      } else {
        expected = V::kFresh;
      }
      ASSERT_EQ(accept(w, seq), expected) << "round " << round << " step " << i << " seq " << seq << " highest "
                                          << highest;
      if (expected == V::kFresh) {
        seen.insert(seq);
        highest = std::max(highest, seq);
      }
    }
  }
}

}  // namespace
}  // namespace fovea::net
