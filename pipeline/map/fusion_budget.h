// Fusion's time budget (issue 41, part 4; docs/map.md, "The time budget").
//
// On a board too slow to fuse every frame at the camera's rate, fusion runs on
// a share of the frames so that its time, on average, stays within a budget a
// frame; a frame it does not fuse is counted and goes to the operator whole, as
// a frame the map refused does, so nothing the camera saw is withheld. The rule
// is a token bucket: each frame earns the budget, a fused frame spends what its
// fusion took, and a frame is fused while the credit is not negative. The
// credit saves up at most one frame's budget, so fusion never runs back to back
// to catch up after a quiet spell. A budget of 0 fuses every frame.
//
// It bounds fusion's average share of a frame, not a frame's own time: a fused
// frame still takes as long as its fusion in the stage that runs it.
#pragma once

#include <algorithm>
#include <cstdint>

namespace fovea::pipeline::map {

class FusionBudget {
 public:
  explicit FusionBudget(int64_t budget_ns = 0) : budget_ns_(std::max<int64_t>(budget_ns, 0)) {}

  // A frame arrives: whether to fuse it (counted as skipped when not).
  bool admit() {
    if (budget_ns_ == 0) return true;
    credit_ns_ = std::min(credit_ns_ + budget_ns_, budget_ns_);
    if (credit_ns_ >= 0) return true;
    ++skipped_;
    return false;
  }
  // What the admitted frame's fusion took.
  void spent(int64_t ns) {
    if (budget_ns_ > 0) credit_ns_ -= std::max<int64_t>(ns, 0);
  }

  int64_t budgetNs() const { return budget_ns_; }
  uint64_t skipped() const { return skipped_; }

 private:
  int64_t budget_ns_ = 0;
  int64_t credit_ns_ = 0;
  uint64_t skipped_ = 0;
};

}  // namespace fovea::pipeline::map
