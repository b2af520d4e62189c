// Pairs depth frames with colour frames by capture time, for cameras whose
// depth and colour arrive as separate streams (two V4L2 nodes; a libcamera
// colour camera beside a depth source). No I/O, no clock, no allocation after
// construction. The backend keeps `capacity` colour slots (converted RGB
// images); it writes each new colour frame into nextColourSlot(), commits it
// with pushColour(), and for each depth frame asks which slot holds the colour
// frame nearest in time within the tolerance.
//
// Contract (tests/unit/hal/test_pairing.cpp checks it against a brute-force scan):
// - a colour frame matches a depth frame when |depth - colour| <= tolerance_ns
//   (inclusive; computed without overflow for any int64 stamps);
// - of the matching frames kept, the nearest wins; on a tie the earlier stamp,
//   and between equal stamps the one pushed first;
// - a colour frame may pair with several depth frames; it stays until displaced;
// - colour_dropped counts every colour frame that leaves the history without
//   ever having been paired (displaced by a newer one, or forgotten by clear()
//   or a clock step);
// - a colour stamp strictly older than the newest kept one is a clock step:
//   counted, the history is forgotten, and the new frame is kept alone (in the
//   slot nextColourSlot() gave; equal stamps are not a step).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

namespace fovea::hal {

struct PairingCounts {
  uint64_t paired = 0;
  uint64_t depth_unmatched = 0;   // no colour frame within the tolerance
  uint64_t colour_dropped = 0;    // colour frames pushed out unused
  uint64_t stamps_backwards = 0;  // a colour stamp older than the previous one (clock step): history reset
};

class TimestampPairer {
 public:
  // Keeps up to `capacity` colour frames; pairs within tolerance_ns. The
  // constructor never fails: a capacity of 0 is taken as 1 and a negative
  // tolerance as 0.
  TimestampPairer(std::size_t capacity, int64_t tolerance_ns);

  // The slot (0 .. capacity-1) the next colour frame goes into: a free one,
  // else the oldest frame's (which is then counted as dropped if never paired).
  int nextColourSlot() const;
  // Commits the colour frame just written into nextColourSlot().
  void pushColour(int64_t stamp_ns);
  // The slot of the colour frame nearest to depth_stamp_ns within the
  // tolerance (ties: the earlier frame), or nothing (counted as unmatched).
  std::optional<int> pairDepth(int64_t depth_stamp_ns);
  // Forgets every colour frame (stream restarted).
  void clear();

  std::size_t size() const { return size_; }
  int64_t toleranceNs() const { return tolerance_ns_; }
  const PairingCounts& counts() const { return counts_; }

 private:
  struct Entry {
    int64_t stamp_ns = 0;
    int slot = -1;
    bool used = false;  // paired at least once
  };
  std::vector<Entry> ring_;  // oldest at head_
  std::size_t head_ = 0;
  std::size_t size_ = 0;
  int64_t tolerance_ns_;
  PairingCounts counts_;
};

}  // namespace fovea::hal
