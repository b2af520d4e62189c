#include "tools/operator/map_holder.h"

#include <algorithm>
#include <cstdio>
#include <limits>
#include <utility>

#include "net/codec.h"

namespace fovea::tools {

namespace {

// Room for any chunk that decodes: its data is at most kMaxChunkRawBytes and a
// point takes at least a byte of it. A larger one is refused by the decoder
// (kCapacityExceeded) and counted as bad.
constexpr std::size_t kScratchPoints = net::kMaxChunkRawBytes;

void addCounters(net::BrickCacheCounters& sum, const net::BrickCacheCounters& c) {
  sum.parts += c.parts;
  sum.duplicate_parts += c.duplicate_parts;
  sum.stale_parts += c.stale_parts;
  sum.superseded_versions += c.superseded_versions;
  sum.versions += c.versions;
  sum.evicted += c.evicted;
  sum.no_room_parts += c.no_room_parts;
  sum.bad_parts += c.bad_parts;
  sum.acks_dropped += c.acks_dropped;
}

}  // namespace

Result<MapHolder> MapHolder::create(const net::BrickCacheConfig& config) {
  Result<net::BrickCache> cache = net::BrickCache::create(config);
  if (!cache) return Result<MapHolder>(cache.status().code(), cache.status().message());
  return MapHolder(config, std::move(cache.value()));
}

MapHolder::MapHolder(const net::BrickCacheConfig& config, net::BrickCache cache)
    : config_(config), cache_(std::move(cache)), scratch_(kScratchPoints) {}

net::BrickCache::Outcome MapHolder::add(std::span<const uint8_t> payload, int64_t now_ns) {
  ++payloads_;
  scratch_.clear();
  Result<net::DecodedChunk> chunk = net::decodeChunk(payload, scratch_);
  if (!chunk) {
    ++undecodable_;
    return net::BrickCache::Outcome::kBad;
  }
  return cache_->add(chunk.value(), scratch_, 0, now_ns);
}

bool MapHolder::ackDue(int64_t now_ns, std::size_t max_payload) const {
  const std::size_t parts = cache_->received().size(), evicted = cache_->evicted().size();
  if (parts == 0 && evicted == 0) return false;
  return now_ns - last_ack_ns_ >= kBrickAckPeriodNs || parts > net::BrickAckMsg::partsThatFit(max_payload, 0) ||
         evicted > net::BrickAckMsg::kMaxEvicted;
}

int64_t MapHolder::nextAckNs() const {
  if (cache_->received().empty() && cache_->evicted().empty()) return std::numeric_limits<int64_t>::max();
  return last_ack_ns_ + kBrickAckPeriodNs;
}

bool MapHolder::fillAck(std::size_t max_payload, AckCursor& cursor) {
  const std::span<const net::BrickPartId> parts = cache_->received();
  const std::span<const net::BrickKey> evicted = cache_->evicted();
  // As many evicted keys as leave room for at least one part (at the smallest
  // MTU 11 of them), so that every message moves both lists on.
  std::size_t keys = std::min(net::BrickAckMsg::kMaxEvicted, evicted.size() - cursor.evicted);
  while (keys > 0 && net::BrickAckMsg::partsThatFit(max_payload, keys) == 0) --keys;
  const std::size_t n = std::min(net::BrickAckMsg::partsThatFit(max_payload, keys), parts.size() - cursor.parts);
  if (keys == 0 && n == 0) return false;  // all sent (or an MTU too small for anything: validated by the link)
  std::copy_n(evicted.begin() + static_cast<std::ptrdiff_t>(cursor.evicted), keys, ack_.evicted.begin());
  std::copy_n(parts.begin() + static_cast<std::ptrdiff_t>(cursor.parts), n, ack_.parts.begin());
  ack_.evicted_count = keys;
  ack_.part_count = n;
  cursor.evicted += keys;
  cursor.parts += n;
  return true;
}

void MapHolder::finishAcks(int64_t now_ns) {
  cache_->clearReceived();
  cache_->clearEvicted();
  last_ack_ns_ = now_ns;
}

void MapHolder::reset() {
  addCounters(earlier_, cache_->counters());
  cache_.reset();  // the old pool goes before the new one is made: memory never doubles
  cache_.emplace(std::move(net::BrickCache::create(config_).value()));  // the config was validated by create()
  last_ack_ns_ = 0;
}

MapTotals MapHolder::totals() const {
  net::BrickCacheCounters c = earlier_;
  addCounters(c, cache_->counters());
  MapTotals t;
  t.bricks_held = cache_->bricksHeld();
  t.points_held = cache_->pointsHeld();
  t.payloads = payloads_;
  t.parts = c.parts;
  t.duplicate_parts = c.duplicate_parts;
  t.stale_parts = c.stale_parts;
  t.versions = c.versions;
  t.evicted = c.evicted;
  t.no_room_parts = c.no_room_parts;
  t.bad_parts = c.bad_parts + undecodable_;
  t.acks_sent = acks_sent_;
  t.ack_send_failures = ack_send_failures_;
  t.acks_dropped = c.acks_dropped;
  return t;
}

std::string mapLiveText(const MapTotals& now, const MapTotals& before) {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "map %zu bricks %zu pts, +%llu parts +%llu versions, %llu evicted, %llu dup %llu stale %llu bad, %llu acks",
                now.bricks_held, now.points_held, static_cast<unsigned long long>(now.parts - before.parts),
                static_cast<unsigned long long>(now.versions - before.versions),
                static_cast<unsigned long long>(now.evicted - before.evicted),
                static_cast<unsigned long long>(now.duplicate_parts - before.duplicate_parts),
                static_cast<unsigned long long>(now.stale_parts - before.stale_parts),
                static_cast<unsigned long long>(now.bad_parts - before.bad_parts),
                static_cast<unsigned long long>(now.acks_sent - before.acks_sent));
  return buf;
}

std::string mapSummaryJson(const MapTotals& t) {
  const auto member = [](const char* name, uint64_t v) { return std::string(", \"") + name + "\": " + std::to_string(v); };
  std::string s = ", \"map\": {\"bricks_held\": " + std::to_string(t.bricks_held);
  s += member("points_held", t.points_held);
  s += member("payloads", t.payloads);
  s += member("parts", t.parts);
  s += member("versions_completed", t.versions);
  s += member("evicted", t.evicted);
  s += member("duplicate_parts", t.duplicate_parts);
  s += member("stale_parts", t.stale_parts);
  s += member("no_room_parts", t.no_room_parts);
  s += member("bad_parts", t.bad_parts);
  s += member("acks_sent", t.acks_sent);
  s += member("ack_send_failures", t.ack_send_failures);
  s += member("acks_dropped", t.acks_dropped);
  return s + "}";
}

}  // namespace fovea::tools
