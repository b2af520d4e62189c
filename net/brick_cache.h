// The operator's copy of the map: the bricks the robot streams (point chunks
// with a brick tag, net/codec.h), kept by version in memory sized once
// (issue 26; docs/protocol.md, "Map bricks").
//
// A brick version arrives in parts (one chunk each). The cache draws the newest
// version it holds whole and assembles the next beside it: a version replaces
// the one drawn only when all its parts arrived, and never one that is newer
// (versions compare in serial-number order, so they may wrap). A part of a
// version older than the one drawn or assembled is stale: counted, dropped.
//
// Points live in a pool of fixed-size blocks; a brick's version is a chain of
// them. When a part finds no free block or no free brick entry, the cache
// evicts the brick needed least recently (touch() marks a brick needed: the
// viewer calls it for what it draws; a part arriving counts too), never the
// brick the part belongs to, and lists it in evicted() so that the robot learns
// the operator lacks it. Every part taken is listed in received() for the
// acknowledgement. Memory is allocated by create(); add() never allocates.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "core/grid_table.h"
#include "core/result.h"
#include "net/codec.h"
#include "net/messages.h"
#include "pipeline/point_cloud.h"

namespace fovea::net {

struct BrickCacheConfig {
  std::size_t max_bricks = 4096;        // bricks held (and one version in assembly each)
  std::size_t max_points = 1u << 22;    // points over all of them (16 bytes each)
  std::size_t block_points = 256;       // points per pool block
  std::size_t max_parts = 1024;         // parts of one brick version
  std::size_t max_pending_acks = 4096;  // parts received and not yet acknowledged
  Status validate() const;
};

struct BrickCacheCounters {
  uint64_t parts = 0;              // taken into a version
  uint64_t duplicate_parts = 0;    // of a part already held
  uint64_t stale_parts = 0;        // of a version older than the one drawn or assembled
  uint64_t superseded_versions = 0;  // dropped in assembly when a newer one began
  uint64_t versions = 0;           // completed (drawn from then on)
  uint64_t evicted = 0;            // bricks dropped to make room
  uint64_t no_room_parts = 0;      // dropped: more points than the whole pool, or too many parts
  uint64_t bad_parts = 0;          // without a brick tag, or a part index beyond its count
  uint64_t acks_dropped = 0;       // received() was full
};

class BrickCache {
 public:
  static Result<BrickCache> create(const BrickCacheConfig& config);

  enum class Outcome : uint8_t { kStored, kCompleted, kDuplicate, kStale, kNoRoom, kBad };
  // Takes one decoded part: `chunk` from decodeChunk and the points it appended
  // to `cloud` from index `first` (world = cloud.origin_m + point). now_ns: the
  // caller's clock, for the eviction order. Never allocates.
  Outcome add(const DecodedChunk& chunk, const pipeline::FoveatedCloud& cloud, std::size_t first, int64_t now_ns);

  // Marks a brick needed now (a viewer drawing it).
  void touch(const BrickKey& key, int64_t now_ns);

  // The bricks drawn: for i < slotCount(), held(i) says whether slot i holds a
  // version; its points are read with forEachPoint.
  std::size_t slotCount() const { return entries_.size(); }
  bool held(std::size_t slot) const { return entries_[slot].used && entries_[slot].has_current; }
  const BrickKey& key(std::size_t slot) const { return entries_[slot].key; }
  uint32_t version(std::size_t slot) const { return entries_[slot].current.version; }
  uint8_t level(std::size_t slot) const { return entries_[slot].current.level; }
  double stepM(std::size_t slot) const { return entries_[slot].current.step_m; }
  uint32_t pointCount(std::size_t slot) const { return entries_[slot].current.points; }
  // f(world position as Eigen::Vector3d, rgb) for each point of the drawn version.
  template <typename F>
  void forEachPoint(std::size_t slot, F&& f) const {
    const Entry& e = entries_[slot];
    uint32_t left = e.current.points;
    for (uint32_t b = e.current.blocks; b != kNone && left > 0; b = next_block_[b]) {
      const uint32_t n = std::min<uint32_t>(left, static_cast<uint32_t>(block_points_));
      const std::size_t base = static_cast<std::size_t>(b) * block_points_;
      for (uint32_t i = 0; i < n; ++i) {
        f(e.anchor + Eigen::Vector3d(x_[base + i], y_[base + i], z_[base + i]), rgb_[base + i]);
      }
      left -= n;
    }
  }
  // Finds the slot of a held brick (-1: not held).
  int find(const BrickKey& key) const;

  std::size_t bricksHeld() const;
  std::size_t pointsHeld() const;
  std::size_t freeBlocks() const { return free_count_; }

  // Parts taken since the last clearReceived() (for the acknowledgement), and
  // bricks evicted since the last clearEvicted() (the robot must learn it).
  std::span<const BrickPartId> received() const { return {acks_.data(), ack_count_}; }
  void clearReceived() { ack_count_ = 0; }
  std::span<const BrickKey> evicted() const { return {evicted_.data(), evicted_count_}; }
  void clearEvicted() { evicted_count_ = 0; }

  const BrickCacheCounters& counters() const { return counters_; }
  std::size_t memoryBytes() const;

 private:
  static constexpr uint32_t kNone = 0xffffffffu;
  struct Version {
    uint32_t version = 0;
    uint32_t blocks = kNone;  // chain head
    uint32_t tail = kNone;    // last block of the chain
    uint32_t points = 0;
    uint16_t parts_needed = 0;
    uint16_t parts_received = 0;
    uint8_t level = 0;
    double step_m = 0.0;
  };
  struct Entry {
    bool used = false;
    BrickKey key;
    Eigen::Vector3d anchor = Eigen::Vector3d::Zero();  // points are stored relative to it
    Version current;   // drawn, when has_current (an emptied brick's has no points)
    Version pending;   // in assembly, when has_pending
    bool has_current = false;
    bool has_pending = false;
    int64_t needed_ns = 0;
  };

  explicit BrickCache(const BrickCacheConfig& config);
  // The index cell holding key, or the empty cell where it would go.
  std::size_t probe(const BrickKey& key) const;
  int findOrInsert(const BrickKey& key, int64_t now_ns, std::size_t keep_slot);
  void erase(std::size_t slot);
  void freeChain(Version& v);
  bool evictOne(std::size_t keep_slot);
  // Appends n points to v's chain; false when the pool ran out even after eviction.
  bool appendPoints(std::size_t slot, Version& v, const pipeline::FoveatedCloud& cloud, std::size_t first,
                    std::size_t n);
  uint8_t* partBits(std::size_t slot) { return part_bits_.data() + slot * part_bytes_; }
  // add()'s steps, in order.
  std::optional<Outcome> settleVersion(Entry& e, const BrickPartId& part);
  bool openPending(std::size_t slot, Entry& e, const DecodedChunk& chunk);
  Outcome storePart(std::size_t slot, Entry& e, const BrickPartId& part, const pipeline::FoveatedCloud& cloud,
                    std::size_t first, std::size_t n);
  Outcome acknowledge(const BrickPartId& part, Outcome outcome);

  BrickCacheConfig config_;
  std::size_t block_points_ = 0;
  std::size_t part_bytes_ = 0;
  std::vector<Entry> entries_;            // fixed slots; free ones have used == false
  std::vector<uint32_t> free_entries_;
  std::size_t free_entry_count_ = 0;
  GridTable index_;                       // key -> entry
  std::vector<uint8_t> part_bits_;        // per entry: max_parts bits of the pending version
  std::vector<float> x_, y_, z_;
  std::vector<uint32_t> rgb_;
  std::vector<uint32_t> next_block_;
  std::vector<uint32_t> free_blocks_;
  std::size_t free_count_ = 0;
  std::size_t used_entries_ = 0;
  std::vector<BrickPartId> acks_;
  std::size_t ack_count_ = 0;
  std::vector<BrickKey> evicted_;
  std::size_t evicted_count_ = 0;
  BrickCacheCounters counters_;
};

}  // namespace fovea::net
