// The robot's side of delivering map bricks (issue 26; docs/map-delta.md): it
// keeps a copy of every part of the brick versions in flight, takes the
// operator's acknowledgements, and gives back the parts that went
// unacknowledged for resend_after_ns, so that a lost part is sent again as
// the same bytes (a brick is never re-encoded for a resend: the map may have
// moved on, and parts of two encodings would not fit together).
//
// A version is done when every part is acknowledged. A newer version of the
// brick replaces it (the operator drops the older one itself). It is lost, and
// the caller told so that the brick becomes due again (MapDelta::forget), when
// its unacknowledged parts were overwritten in the store (a part is intact
// while fewer than store_bytes were written after it), or when the table of
// versions in flight is full and it is the oldest.
//
// Memory: the ring and the tables, allocated by create(); nothing after.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/result.h"

namespace fovea::net {

struct BrickSenderConfig {
  std::size_t store_bytes = 4u << 20;  // about 0.3 s at 12.5 MB/s
  std::size_t max_in_flight = 512;     // brick versions
  std::size_t max_parts = 256;         // parts of one version
  std::size_t max_bricks = 16384;      // the map's (brick slots the caller names)
  int64_t resend_after_ns = 100'000'000;
  Status validate() const;
};

struct BrickSenderCounters {
  uint64_t versions = 0;           // begun
  uint64_t versions_done = 0;      // every part acknowledged
  uint64_t versions_lost = 0;      // overwritten or crowded out before done
  uint64_t versions_replaced = 0;  // a newer version of the brick began first
  uint64_t parts = 0;
  uint64_t resends = 0;
  uint64_t acks = 0;               // that acknowledged a part in flight
  uint64_t acks_unknown = 0;       // for no version in flight (late, duplicate, never sent, forged)
};

class BrickSender {
 public:
  static Result<BrickSender> create(const BrickSenderConfig& config);

  // Starts a version of `brick` (the caller's slot, < max_bricks) with `parts`
  // parts; replaces the brick's version in flight. `lost` (may be null) gets
  // the brick whose version had to go to make room. false: parts out of range.
  bool begin(uint16_t brick, uint32_t version, uint16_t parts, int64_t now_ns, int* lost);
  // Stores part `part` of the version begun last (its datagram payload); the
  // parts come in order, from 0. false when the part is not the next one,
  // empty, or larger than a tenth of the store.
  // `stored` (may be null) gets the copy in the store, which stays valid until
  // store_bytes more are written: the caller may send from it.
  bool addPart(uint16_t part, std::span<const uint8_t> payload, std::span<const uint8_t>* stored = nullptr);

  enum class Ack : uint8_t { kPart, kDone, kUnknown };
  // An acknowledgement of part `part` of `version` of `brick`.
  Ack acknowledge(uint16_t brick, uint32_t version, uint16_t part);
  // The operator dropped the brick: nothing of it is in flight any more.
  void drop(uint16_t brick);
  // A new session: nothing is in flight (the counters stay).
  void reset();

  // Calls resend(brick, part, payload) for every part unacknowledged for
  // resend_after_ns, at most max_parts parts, and lost(brick) for each
  // version whose parts the store no longer holds. Returns the parts given.
  template <typename Resend, typename Lost>
  std::size_t collectResends(int64_t now_ns, std::size_t max_parts, Resend&& resend, Lost&& lost);

  std::size_t inFlight() const { return in_flight_; }
  bool inFlight(uint16_t brick) const { return record_of_[brick] >= 0; }
  const BrickSenderCounters& counters() const { return counters_; }
  std::size_t memoryBytes() const;

 private:
  struct Record {
    bool used = false;
    uint16_t brick = 0;
    uint32_t version = 0;
    uint16_t parts = 0;
    uint16_t stored = 0;     // parts added, in order
    uint16_t acked = 0;
    int64_t sent_ns = 0;     // last (re)send
    uint64_t begun = 0;      // order of begin(), for crowding out the oldest
    uint64_t written = 0;    // the store's written_ at begin(): its first part starts here (or at the ring's start)
  };
  explicit BrickSender(const BrickSenderConfig& config);
  void release(std::size_t r);
  // Where a part of `length` bytes goes when the store's writes stand at
  // `written`: there, or at the ring's start when it would wrap (absolute).
  uint64_t placed(uint64_t written, uint16_t length) const;
  bool intact(uint64_t position) const { return written_ - position <= ring_.size(); }
  uint8_t* bits(std::size_t r) { return ack_bits_.data() + r * part_bytes_; }
  bool acked(std::size_t r, uint16_t part) { return (bits(r)[part / 8] & (1u << (part % 8))) != 0; }
  uint16_t* lengths(std::size_t r) { return part_length_.data() + r * config_.max_parts; }

  BrickSenderConfig config_;
  std::size_t part_bytes_ = 0;
  std::vector<uint8_t> ring_;
  uint64_t written_ = 0;                 // bytes ever written (absolute ring position)
  std::vector<Record> records_;
  std::vector<int32_t> record_of_;       // per brick: its record, -1 none
  std::vector<uint8_t> ack_bits_;        // per record: max_parts bits
  // Per record and part: the length (0: not stored; no part is empty). A
  // record's parts lie one after the other from its written, each placed as
  // addPart() placed it, so their positions are walked from the lengths (a
  // table of positions beside them was 4 bytes a part: 0.5 MiB).
  std::vector<uint16_t> part_length_;
  std::size_t in_flight_ = 0;
  std::size_t current_ = SIZE_MAX;       // the record begin() started
  uint64_t begun_ = 0;
  std::size_t scan_ = 0;                 // collectResends' round-robin start
  BrickSenderCounters counters_;
};

template <typename Resend, typename Lost>
std::size_t BrickSender::collectResends(int64_t now_ns, std::size_t max_parts, Resend&& resend, Lost&& lost) {
  std::size_t given = 0;
  const std::size_t n = records_.size();
  for (std::size_t k = 0; k < n && given < max_parts; ++k) {
    const std::size_t r = (scan_ + k) % n;
    Record& rec = records_[r];
    if (!rec.used || now_ns - rec.sent_ns < config_.resend_after_ns) continue;
    bool whole = rec.stored == rec.parts;
    for (uint64_t at = rec.written, p = 0; whole && p < rec.parts; ++p) {
      at = placed(at, lengths(r)[p]);
      whole = acked(r, static_cast<uint16_t>(p)) || intact(at);
      at += lengths(r)[p];
    }
    if (!whole) {
      const uint16_t brick = rec.brick;
      ++counters_.versions_lost;
      release(r);
      lost(brick);
      continue;
    }
    for (uint64_t at = rec.written, p = 0; p < rec.parts && given < max_parts; ++p) {
      const uint16_t length = lengths(r)[p];
      at = placed(at, length);
      if (!acked(r, static_cast<uint16_t>(p))) {
        resend(rec.brick, static_cast<uint16_t>(p),
               std::span<const uint8_t>(ring_.data() + static_cast<std::size_t>(at % ring_.size()), length));
        ++given;
        ++counters_.resends;
      }
      at += length;
    }
    rec.sent_ns = now_ns;
    if (given >= max_parts) scan_ = (r + 1) % n;
  }
  return given;
}

}  // namespace fovea::net
