// The operator's copy of the robot's map (issue 26; docs/map-delta.md): takes the
// brick chunks (kBrickChunk payloads) into a net::BrickCache and produces the
// acknowledgements (BrickAckMsg) the robot's BrickSender waits for. No sockets:
// fovea-operator hands it payloads and sends the messages it fills, so that it
// is tested alone (tests/unit/tools/test_map_holder.cpp).
//
// Memory is allocated by create() (the cache, one chunk's scratch cloud, one
// acknowledgement message); add() and sendAcks() never allocate.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include "core/result.h"
#include "net/brick_cache.h"
#include "net/messages.h"
#include "pipeline/point_cloud.h"

namespace fovea::tools {

// Acknowledge at a few tens of hertz: the robot resends a part it has not heard
// of for 100 ms (net::BrickSenderConfig::resend_after_ns), so 25 ms keeps
// resends for lost parts only.
inline constexpr int64_t kBrickAckPeriodNs = 25'000'000;

// Everything counted since start (across sessions), and what is held now.
struct MapTotals {
  std::size_t bricks_held = 0;
  std::size_t points_held = 0;
  uint64_t payloads = 0;         // kBrickChunk payloads handed to add()
  uint64_t parts = 0;            // taken into a version
  uint64_t duplicate_parts = 0;
  uint64_t stale_parts = 0;
  uint64_t versions = 0;         // brick versions completed (drawn from then on)
  uint64_t evicted = 0;          // bricks dropped to make room (and reported to the robot)
  uint64_t no_room_parts = 0;    // a version of more parts or points than the cache holds
  uint64_t bad_parts = 0;        // undecodable, or a chunk without a brick tag
  uint64_t acks_sent = 0;        // BrickAckMsgs sent
  uint64_t ack_send_failures = 0;
  uint64_t acks_dropped = 0;     // parts not acknowledged: the cache's list was full
};

class MapHolder {
 public:
  // Errors: kInvalidArgument naming the bad field (BrickCacheConfig::validate).
  static Result<MapHolder> create(const net::BrickCacheConfig& config);

  // Decodes one kBrickChunk payload (8-byte aligned, as the link returns it) and
  // adds it to the cache. A payload that does not decode is counted (kBad).
  net::BrickCache::Outcome add(std::span<const uint8_t> payload, int64_t now_ns);

  // Whether acknowledgements should go now: something to acknowledge and either
  // kBrickAckPeriodNs since the last, or more parts than one message of
  // max_payload bytes takes (the cache's list would only grow).
  bool ackDue(int64_t now_ns, std::size_t max_payload) const;
  // When ackDue() turns true by the clock; INT64_MAX with nothing to acknowledge.
  int64_t nextAckNs() const;

  // Sends every part received and every brick evicted since the last call, in
  // as many messages as max_payload (the session's MTU less kDatagramOverhead)
  // needs; send(const net::BrickAckMsg&) -> bool (false: counted as a failure,
  // the robot resends the parts). Then clears the cache's lists. Returns the
  // messages sent.
  template <typename Send>
  std::size_t sendAcks(std::size_t max_payload, int64_t now_ns, Send&& send) {
    std::size_t messages = 0;
    AckCursor cursor;
    while (fillAck(max_payload, cursor)) {
      if (send(static_cast<const net::BrickAckMsg&>(ack_))) {
        ++acks_sent_;
      } else {
        ++ack_send_failures_;
      }
      ++messages;
    }
    finishAcks(now_ns);
    return messages;
  }

  // A new session: the robot starts its delivery afresh (and a restarted robot
  // numbers versions from the start, which the old copy would take as stale),
  // so the copy starts empty. Allocates (once per session, not per datagram).
  void reset();

  net::BrickCache& cache() { return *cache_; }
  const net::BrickCache& cache() const { return *cache_; }
  MapTotals totals() const;

 private:
  struct AckCursor {
    std::size_t parts = 0;    // of received() already in a message
    std::size_t evicted = 0;  // of evicted()
  };
  explicit MapHolder(const net::BrickCacheConfig& config, net::BrickCache cache);
  bool fillAck(std::size_t max_payload, AckCursor& cursor);
  void finishAcks(int64_t now_ns);

  net::BrickCacheConfig config_;
  std::optional<net::BrickCache> cache_;
  net::BrickCacheCounters earlier_{};  // of the caches reset() dropped
  pipeline::FoveatedCloud scratch_;    // one chunk's points
  net::BrickAckMsg ack_{};
  int64_t last_ack_ns_ = 0;
  uint64_t payloads_ = 0, undecodable_ = 0, acks_sent_ = 0, ack_send_failures_ = 0;
};

// The map's part of the once-a-second line, for the window since `before`.
std::string mapLiveText(const MapTotals& now, const MapTotals& before);
// The map's members of --summary's JSON (", \"map\": {...}").
std::string mapSummaryJson(const MapTotals& t);

}  // namespace fovea::tools
