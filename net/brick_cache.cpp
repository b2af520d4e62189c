#include "net/brick_cache.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <limits>

namespace fovea::net {

Status BrickCacheConfig::validate() const {
  auto bad = [](const char* what) { return Status(ErrorCode::kInvalidArgument, std::string("brick_cache.") + what); };
  if (max_bricks == 0 || max_bricks > (std::size_t{1} << 20)) return bad("max_bricks: must be in [1, 2^20]");
  if (block_points == 0 || block_points > 65536) return bad("block_points: must be in [1, 65536]");
  if (max_points < block_points || max_points / block_points >= std::numeric_limits<uint32_t>::max()) {
    return bad("max_points: must be at least block_points, and below 2^32 blocks");
  }
  if (max_parts == 0 || max_parts > 65535) return bad("max_parts: must be in [1, 65535]");
  if (max_pending_acks == 0) return bad("max_pending_acks: must be at least 1");
  return Status::ok();
}

Result<BrickCache> BrickCache::create(const BrickCacheConfig& config) {
  if (Status s = config.validate(); !s) return Result<BrickCache>(s.code(), s.message());
  return BrickCache(config);
}

BrickCache::BrickCache(const BrickCacheConfig& config) : config_(config), block_points_(config.block_points) {
  part_bytes_ = (config.max_parts + 7) / 8;
  entries_.resize(config.max_bricks);
  free_entries_.resize(config.max_bricks);
  for (std::size_t i = 0; i < config.max_bricks; ++i) free_entries_[i] = static_cast<uint32_t>(config.max_bricks - 1 - i);
  free_entry_count_ = config.max_bricks;
  index_ = GridTable(config.max_bricks);
  part_bits_.assign(config.max_bricks * part_bytes_, 0);
  const std::size_t blocks = config.max_points / config.block_points;
  const std::size_t points = blocks * config.block_points;
  x_.resize(points);
  y_.resize(points);
  z_.resize(points);
  rgb_.resize(points);
  next_block_.assign(blocks, kNone);
  free_blocks_.resize(blocks);
  for (std::size_t i = 0; i < blocks; ++i) free_blocks_[i] = static_cast<uint32_t>(blocks - 1 - i);
  free_count_ = blocks;
  acks_.resize(config.max_pending_acks);
  evicted_.resize(config.max_bricks);
}

std::size_t BrickCache::memoryBytes() const {
  return entries_.capacity() * sizeof(Entry) + free_entries_.capacity() * sizeof(uint32_t) +
         index_.memoryBytes() + part_bits_.capacity() +
         (x_.capacity() + y_.capacity() + z_.capacity()) * sizeof(float) + rgb_.capacity() * sizeof(uint32_t) +
         (next_block_.capacity() + free_blocks_.capacity()) * sizeof(uint32_t) +
         acks_.capacity() * sizeof(BrickPartId) + evicted_.capacity() * sizeof(BrickKey);
}

std::size_t BrickCache::probe(const BrickKey& key) const {
  return index_.probe(key, [this](uint32_t slot) -> const BrickKey& { return entries_[slot].key; });
}

int BrickCache::find(const BrickKey& key) const { return index_.slotAt(probe(key)); }

int BrickCache::findOrInsert(const BrickKey& key, int64_t now_ns, std::size_t keep_slot) {
  std::size_t cell = probe(key);
  if (const int32_t slot = index_.slotAt(cell); slot >= 0) return slot;
  if (free_entry_count_ == 0) {
    if (!evictOne(keep_slot)) return -1;
    cell = probe(key);  // the eviction moved cells
  }
  const uint32_t slot = free_entries_[--free_entry_count_];
  Entry& e = entries_[slot];
  e = Entry{};
  e.used = true;
  e.key = key;
  e.needed_ns = now_ns;
  index_.place(cell, slot);
  ++used_entries_;
  return static_cast<int>(slot);
}

void BrickCache::freeChain(Version& v) {
  for (uint32_t b = v.blocks; b != kNone;) {
    const uint32_t next = next_block_[b];
    next_block_[b] = kNone;
    free_blocks_[free_count_++] = b;
    b = next;
  }
  v.blocks = v.tail = kNone;
  v.points = 0;
}

void BrickCache::erase(std::size_t slot) {
  Entry& e = entries_[slot];
  freeChain(e.current);
  freeChain(e.pending);
  index_.erase(e.key, [this](uint32_t s) -> const BrickKey& { return entries_[s].key; });
  e.used = false;
  e.has_current = e.has_pending = false;
  free_entries_[free_entry_count_++] = static_cast<uint32_t>(slot);
  --used_entries_;
}

bool BrickCache::evictOne(std::size_t keep_slot) {
  std::size_t victim = entries_.size();
  int64_t oldest = std::numeric_limits<int64_t>::max();
  for (std::size_t s = 0; s < entries_.size(); ++s) {
    if (!entries_[s].used || s == keep_slot) continue;
    if (entries_[s].needed_ns < oldest) {
      oldest = entries_[s].needed_ns;
      victim = s;
    }
  }
  if (victim == entries_.size()) return false;
  if (evicted_count_ < evicted_.size()) evicted_[evicted_count_++] = entries_[victim].key;
  erase(victim);
  ++counters_.evicted;
  return true;
}

bool BrickCache::appendPoints(std::size_t slot, Version& v, const pipeline::FoveatedCloud& cloud, std::size_t first,
                              std::size_t n) {
  const std::size_t in_tail = v.points % block_points_;
  const std::size_t room_in_tail = in_tail == 0 || v.tail == kNone ? 0 : block_points_ - in_tail;
  const std::size_t new_blocks = n > room_in_tail ? (n - room_in_tail + block_points_ - 1) / block_points_ : 0;
  if (new_blocks > next_block_.size()) return false;
  while (free_count_ < new_blocks) {
    if (!evictOne(slot)) return false;
  }
  const Entry& e = entries_[slot];
  const Eigen::Vector3d shift = cloud.points.origin_m - e.anchor;
  for (std::size_t i = 0; i < n; ++i) {
    if (v.points % block_points_ == 0 || v.tail == kNone) {
      const uint32_t b = free_blocks_[--free_count_];
      next_block_[b] = kNone;
      if (v.tail == kNone) {
        v.blocks = b;
      } else {
        next_block_[v.tail] = b;
      }
      v.tail = b;
    }
    const std::size_t at = static_cast<std::size_t>(v.tail) * block_points_ + v.points % block_points_;
    const std::size_t p = first + i;
    x_[at] = static_cast<float>(shift.x() + cloud.points.x()[p]);
    y_[at] = static_cast<float>(shift.y() + cloud.points.y()[p]);
    z_[at] = static_cast<float>(shift.z() + cloud.points.z()[p]);
    rgb_[at] = cloud.points.rgb()[p];
    ++v.points;
  }
  return true;
}

BrickCache::Outcome BrickCache::add(const DecodedChunk& chunk, const pipeline::FoveatedCloud& cloud, std::size_t first,
                                    int64_t now_ns) {
  if (!chunk.has_brick || chunk.chunk_count == 0 || chunk.chunk_index >= chunk.chunk_count || first > cloud.size()) {
    ++counters_.bad_parts;
    return Outcome::kBad;
  }
  const std::size_t n = cloud.size() - first;
  if (chunk.chunk_count > config_.max_parts || n > x_.size()) {
    ++counters_.no_room_parts;
    return Outcome::kNoRoom;
  }
  const BrickPartId part{BrickKey{chunk.brick.x, chunk.brick.y, chunk.brick.z}, chunk.brick.version, chunk.chunk_index};
  const int found = findOrInsert(part.key, now_ns, entries_.size());
  if (found < 0) {
    ++counters_.no_room_parts;
    return Outcome::kNoRoom;
  }
  const auto slot = static_cast<std::size_t>(found);
  Entry& e = entries_[slot];
  if (!e.has_current && !e.has_pending) e.anchor = cloud.points.origin_m;
  e.needed_ns = std::max(e.needed_ns, now_ns);
  if (const std::optional<Outcome> settled = settleVersion(e, part)) return *settled;
  if (!openPending(slot, e, chunk)) {
    ++counters_.bad_parts;  // the same version cut into another number of parts: not the robot's
    return Outcome::kBad;
  }
  return storePart(slot, e, part, cloud, first, n);
}

// A part of the current version or an older one ends here (duplicate or stale);
// a part of a version newer than the pending one supersedes it. nullopt: the
// part goes on to the pending version.
std::optional<BrickCache::Outcome> BrickCache::settleVersion(Entry& e, const BrickPartId& part) {
  if (e.has_current && !serialNewer(part.version, e.current.version)) {
    if (part.version == e.current.version) {
      ++counters_.duplicate_parts;
      return acknowledge(part, Outcome::kDuplicate);
    }
    ++counters_.stale_parts;
    return Outcome::kStale;
  }
  if (e.has_pending && part.version != e.pending.version) {
    if (!serialNewer(part.version, e.pending.version)) {
      ++counters_.stale_parts;
      return Outcome::kStale;
    }
    freeChain(e.pending);
    e.has_pending = false;
    ++counters_.superseded_versions;
  }
  return std::nullopt;
}

// The pending version the chunk is a part of, begun by its first part; false
// when the chunk's part count differs from the pending version's.
bool BrickCache::openPending(std::size_t slot, Entry& e, const DecodedChunk& chunk) {
  if (!e.has_pending) {
    e.pending = Version{};
    e.pending.version = chunk.brick.version;
    e.pending.parts_needed = chunk.chunk_count;
    e.pending.level = chunk.brick.level;
    e.pending.step_m = chunk.step_m;
    std::memset(partBits(slot), 0, part_bytes_);
    e.has_pending = true;
    return true;
  }
  return chunk.chunk_count == e.pending.parts_needed;
}

// The part's n points (cloud from first on) into the pending version, which
// becomes the current one with its last part.
BrickCache::Outcome BrickCache::storePart(std::size_t slot, Entry& e, const BrickPartId& part,
                                          const pipeline::FoveatedCloud& cloud, std::size_t first, std::size_t n) {
  uint8_t* bits = partBits(slot);
  const uint8_t mask = static_cast<uint8_t>(1u << (part.part % 8));
  if (bits[part.part / 8] & mask) {
    ++counters_.duplicate_parts;
    return acknowledge(part, Outcome::kDuplicate);
  }
  // The entry may not move, but eviction may take others: e stays valid (entries are fixed slots).
  if (!appendPoints(slot, e.pending, cloud, first, n)) {
    ++counters_.no_room_parts;
    return Outcome::kNoRoom;
  }
  bits[part.part / 8] |= mask;
  ++e.pending.parts_received;
  ++counters_.parts;
  if (e.pending.parts_received < e.pending.parts_needed) return acknowledge(part, Outcome::kStored);
  freeChain(e.current);
  e.current = e.pending;
  e.pending = Version{};
  e.has_current = true;
  e.has_pending = false;
  ++counters_.versions;
  return acknowledge(part, Outcome::kCompleted);
}

// Lists the part as received (for the operator's next acknowledgement); outcome.
BrickCache::Outcome BrickCache::acknowledge(const BrickPartId& part, Outcome outcome) {
  if (ack_count_ < acks_.size()) {
    acks_[ack_count_++] = part;
  } else {
    ++counters_.acks_dropped;
  }
  return outcome;
}

void BrickCache::touch(const BrickKey& key, int64_t now_ns) {
  const int slot = find(key);
  if (slot >= 0) entries_[static_cast<std::size_t>(slot)].needed_ns = std::max(entries_[static_cast<std::size_t>(slot)].needed_ns, now_ns);
}

std::size_t BrickCache::bricksHeld() const {
  std::size_t n = 0;
  for (const Entry& e : entries_) n += e.used && e.has_current ? 1 : 0;
  return n;
}

std::size_t BrickCache::pointsHeld() const {
  std::size_t n = 0;
  for (const Entry& e : entries_) n += e.used && e.has_current ? e.current.points : 0;
  return n;
}

}  // namespace fovea::net
