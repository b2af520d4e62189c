// Sliding replay window over a sender's sequence numbers (docs/protocol.md,
// "Replay window"). Sequence numbers start at 1; 0 is never valid. The window
// remembers the highest accepted number and which of the kWindow numbers below
// it were seen: duplicates and numbers at or below highest - kWindow are
// rejected, reordering within the window is accepted.
//
// check() is done before authentication (cheap), commit() only after the datagram
// authenticated, so forged datagrams cannot move the window.
#pragma once

#include <array>
#include <cstdint>

namespace fovea::net {

class ReplayWindow {
 public:
  static constexpr uint64_t kWindow = 1024;

  enum class Verdict : uint8_t { kFresh, kDuplicate, kTooOld };

  Verdict check(uint64_t seq) const {
    if (seq == 0) return Verdict::kTooOld;
    if (seq > highest_) return Verdict::kFresh;
    if (highest_ - seq >= kWindow) return Verdict::kTooOld;
    return testBit(seq) ? Verdict::kDuplicate : Verdict::kFresh;
  }

  // Marks seq as seen; call only after check(seq) == kFresh and authentication.
  void commit(uint64_t seq) {
    if (seq > highest_) {
      const uint64_t shift = seq - highest_;
      if (shift >= kWindow) {
        bits_.fill(0);
      } else {
        // Clear the slots of the numbers that enter the window (highest_+1 .. seq).
        // (Counted by shift, not up to seq: seq may be UINT64_MAX.)
        for (uint64_t i = 1; i <= shift; ++i) clearBit(highest_ + i);
      }
      highest_ = seq;
    }
    setBit(seq);
  }

  void reset() {
    bits_.fill(0);
    highest_ = 0;
  }
  uint64_t highest() const { return highest_; }

 private:
  static constexpr std::size_t kWords = kWindow / 64;
  bool testBit(uint64_t seq) const { return (bits_[(seq / 64) % kWords] >> (seq % 64)) & 1U; }
  void setBit(uint64_t seq) { bits_[(seq / 64) % kWords] |= uint64_t{1} << (seq % 64); }
  void clearBit(uint64_t seq) { bits_[(seq / 64) % kWords] &= ~(uint64_t{1} << (seq % 64)); }

  std::array<uint64_t, kWords> bits_{};
  uint64_t highest_ = 0;
};

}  // namespace fovea::net
