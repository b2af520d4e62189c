// What the sending side learns that the brick planner must hear (issue 26):
// the operator does not hold a brick (its version was lost on the way, the
// operator evicted it, or it never went out), or holds nothing at all (a new
// session), and a brick whose version had more parts than a version may have
// (to be sent coarser). The send stage writes; the foveation stage, which owns
// the map and its MapDelta, drains it once a frame. Lock-free and fixed in
// size: a bit per brick slot and kind, so it never overflows however much the
// operator says, and an epoch for "everything".
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>

namespace fovea::firmware {

class BrickFeedback {
 public:
  explicit BrickFeedback(std::size_t max_bricks) : lacking_(max_bricks), too_large_(max_bricks) {}
  BrickFeedback(const BrickFeedback&) = delete;
  BrickFeedback& operator=(const BrickFeedback&) = delete;

  std::size_t maxBricks() const { return lacking_.size(); }

  // ---- any thread ----
  void forget(std::size_t brick) { lacking_.set(brick); }
  void forgetAll() { epoch_.fetch_add(1, std::memory_order_release); }
  // A version of `brick` had more parts than a version may have: the planner
  // should send it coarser (pipeline::map::MapDelta::tooLarge). Says nothing
  // of whether the operator holds it: the sender forgets it too.
  void tooLarge(std::size_t brick) { too_large_.set(brick); }

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
    lacking_.drain(forget_one);
  }
  // Calls too_large_one(brick) for each brick found too large since the last call.
  template <typename One>
  void drainTooLarge(One&& too_large_one) {
    too_large_.drain(too_large_one);
  }

 private:
  // A bit per brick slot, set by any thread, taken by one.
  class Bits {
   public:
    explicit Bits(std::size_t n) : words_((n + 63) / 64), bits_(new std::atomic<uint64_t>[words_]) {
      for (std::size_t w = 0; w < words_; ++w) bits_[w].store(0, std::memory_order_relaxed);
    }
    std::size_t size() const { return words_ * 64; }
    void set(std::size_t i) {
      if (i < size()) bits_[i / 64].fetch_or(uint64_t{1} << (i % 64), std::memory_order_release);
    }
    template <typename One>
    void drain(One&& one) {
      for (std::size_t w = 0; w < words_; ++w) {
        if (bits_[w].load(std::memory_order_relaxed) == 0) continue;
        uint64_t bits = bits_[w].exchange(0, std::memory_order_acquire);
        while (bits != 0) {
          const int b = __builtin_ctzll(bits);
          bits &= bits - 1;
          one(w * 64 + static_cast<std::size_t>(b));
        }
      }
    }

   private:
    const std::size_t words_;
    const std::unique_ptr<std::atomic<uint64_t>[]> bits_;
  };

  Bits lacking_, too_large_;
  std::atomic<uint64_t> epoch_{0};
  uint64_t seen_epoch_ = 0;  // the planner's
};

}  // namespace fovea::firmware
