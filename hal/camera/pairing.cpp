#include "hal/camera/pairing.h"

#include <algorithm>

namespace fovea::hal {

namespace {

// |a - b| without signed overflow: the modular difference of the unsigned
// images is the exact distance, which always fits in 64 unsigned bits.
uint64_t distanceNs(int64_t a, int64_t b) {
  const auto ua = static_cast<uint64_t>(a);
  const auto ub = static_cast<uint64_t>(b);
  return a >= b ? ua - ub : ub - ua;
}

}  // namespace

TimestampPairer::TimestampPairer(std::size_t capacity, int64_t tolerance_ns)
    : ring_(std::max<std::size_t>(capacity, 1)), tolerance_ns_(std::max<int64_t>(tolerance_ns, 0)) {
  // A frame's slot is its ring position: the ring is the slot table.
  for (std::size_t i = 0; i < ring_.size(); ++i) ring_[i].slot = static_cast<int>(i);
}

int TimestampPairer::nextColourSlot() const {
  // Not full: the position after the newest; full: the oldest's (the same place).
  return static_cast<int>((head_ + size_) % ring_.size());
}

void TimestampPairer::pushColour(int64_t stamp_ns) {
  const std::size_t slot = (head_ + size_) % ring_.size();
  if (size_ > 0) {
    const Entry& newest = ring_[(head_ + size_ - 1) % ring_.size()];
    if (stamp_ns < newest.stamp_ns) {
      ++counts_.stamps_backwards;
      clear();
      head_ = slot;  // the frame was already written there
    }
  }
  if (size_ == ring_.size()) {
    // Full: the oldest (at `slot`, which is head_) is displaced.
    if (!ring_[head_].used) ++counts_.colour_dropped;
    head_ = (head_ + 1) % ring_.size();
    --size_;
  }
  Entry& e = ring_[slot];
  e.stamp_ns = stamp_ns;
  e.used = false;
  ++size_;
}

std::optional<int> TimestampPairer::pairDepth(int64_t depth_stamp_ns) {
  const auto tolerance = static_cast<uint64_t>(tolerance_ns_);
  Entry* best = nullptr;
  uint64_t best_distance = 0;
  // Oldest first; only a strictly nearer frame replaces the best, so ties go to
  // the earlier stamp (stamps never decrease along the ring).
  for (std::size_t k = 0; k < size_; ++k) {
    Entry& e = ring_[(head_ + k) % ring_.size()];
    const uint64_t d = distanceNs(depth_stamp_ns, e.stamp_ns);
    if (d > tolerance) continue;
    if (best == nullptr || d < best_distance) {
      best = &e;
      best_distance = d;
    }
  }
  if (best == nullptr) {
    ++counts_.depth_unmatched;
    return std::nullopt;
  }
  best->used = true;
  ++counts_.paired;
  return best->slot;
}

void TimestampPairer::clear() {
  for (std::size_t k = 0; k < size_; ++k) {
    if (!ring_[(head_ + k) % ring_.size()].used) ++counts_.colour_dropped;
  }
  head_ = 0;
  size_ = 0;
}

}  // namespace fovea::hal
