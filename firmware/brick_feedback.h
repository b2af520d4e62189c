// What the sending side learns that the brick planner must hear (issue 26):
// the operator does not hold a brick (its version was lost on the way, the
// operator evicted it, or it never went out), or holds nothing at all (a new
// session). The send stage writes; the foveation stage, which owns the map and
// its MapDelta, drains it once a frame. Lock-free and fixed in size: a bit per
// brick slot, so it never overflows however much the operator says, and an
// epoch for "everything".
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>

namespace fovea::firmware {

class BrickFeedback {
 public:
  explicit BrickFeedback(std::size_t max_bricks)
      : words_((max_bricks + 63) / 64), bits_(new std::atomic<uint64_t>[words_]) {
    for (std::size_t w = 0; w < words_; ++w) bits_[w].store(0, std::memory_order_relaxed);
  }
  BrickFeedback(const BrickFeedback&) = delete;
  BrickFeedback& operator=(const BrickFeedback&) = delete;

  std::size_t maxBricks() const { return words_ * 64; }

  // ---- any thread ----
  void forget(std::size_t brick) {
    if (brick >= maxBricks()) return;
    bits_[brick / 64].fetch_or(uint64_t{1} << (brick % 64), std::memory_order_release);
  }
  void forgetAll() { epoch_.fetch_add(1, std::memory_order_release); }

  // ---- the planner (one thread) ----
  // Calls forget_one(brick) for each brick forgotten since the last drain, and
  // forget_all() first if everything was (a new session).
  template <typename One, typename All>
  void drain(One&& forget_one, All&& forget_all) {
    const uint64_t epoch = epoch_.load(std::memory_order_acquire);
    if (epoch != seen_epoch_) {
      seen_epoch_ = epoch;
      forget_all();
    }
    for (std::size_t w = 0; w < words_; ++w) {
      if (bits_[w].load(std::memory_order_relaxed) == 0) continue;
      uint64_t bits = bits_[w].exchange(0, std::memory_order_acquire);
      while (bits != 0) {
        const int b = __builtin_ctzll(bits);
        bits &= bits - 1;
        forget_one(w * 64 + static_cast<std::size_t>(b));
      }
    }
  }

 private:
  const std::size_t words_;
  const std::unique_ptr<std::atomic<uint64_t>[]> bits_;
  std::atomic<uint64_t> epoch_{0};
  uint64_t seen_epoch_ = 0;  // the planner's
};

}  // namespace fovea::firmware
