// What the uplink sends of a frame, and when (issue 4's robot side).
//
// A frame's chunks arrive in send order: the fovea first, then the regions
// outward. At the start of a frame the scheduler decides what fits: the frame
// may use the tokens in the bucket now plus what the budget earns until the next
// frame is due. When the frame does not fit, chunks are cut from the outermost
// region inwards (the tail of the send order), never from the fovea, and counted.
// Then it paces the chunks through the token bucket. A frame never delays the
// next: beginFrame() drops whatever the previous frame has not sent yet, and
// counts it as superseded.
//
// No socket I/O and no clock: time is an argument (KCP's shape), so the tests
// drive it with a simulated clock. Memory is allocated by create() only.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/result.h"
#include "net/token_bucket.h"
#include "pipeline/acuity.h"

namespace fovea::net {

struct UplinkCounters {
  uint64_t frames = 0;             // frames begun
  uint64_t frames_cut = 0;         // frames that lost chunks to the budget
  uint64_t frames_superseded = 0;  // frames whose unsent tail the next frame dropped
  uint64_t chunks_sent = 0;
  uint64_t chunks_cut = 0;         // planned out at frame start for the budget
  uint64_t chunks_superseded = 0;  // still unsent when the next frame began
  uint64_t bytes_sent = 0;         // datagram bytes, summaries included
  std::array<uint64_t, pipeline::kMaxRegions> chunks_cut_per_region{};
};

class UplinkScheduler {
 public:
  // max_chunks: the most chunks one frame can have (sized from the codec).
  static Result<UplinkScheduler> create(std::size_t max_chunks, double budget_bytes_per_s, double burst_bytes,
                                        int64_t now_ns);

  // Room for max_chunks (>= 1) a frame from now on (a new session whose MTU
  // changes what the codec can make): allocates, never on the frame path.
  void setMaxChunks(std::size_t max_chunks);

  // Changes the budget (a new session); keeps the counters.
  Status setBudget(double budget_bytes_per_s, double burst_bytes, int64_t now_ns);

  // Plans a frame. datagram_bytes[i] and region[i] describe chunk i in send
  // order; regions must not decrease. frame_interval_ns: time until the next
  // frame is expected (0: only the tokens there now). kInvalidInput for
  // mismatched spans, decreasing regions or a region >= kMaxRegions;
  // kCapacityExceeded for more than max_chunks.
  Status beginFrame(std::span<const uint32_t> datagram_bytes, std::span<const uint8_t> region, int64_t now_ns,
                    int64_t frame_interval_ns);

  struct Step {
    enum class Kind { kSend, kWait, kDone };
    Kind kind = Kind::kDone;
    std::size_t chunk = 0;  // kSend: the chunk to send now (its tokens are taken)
    int64_t wait_ns = 0;    // kWait: when to ask again
  };
  // The next step at now_ns. A kSend counts the chunk as sent.
  Step next(int64_t now_ns);

  // Charges a datagram sent outside the plan (the frame summary, status).
  void chargeExtra(std::size_t datagram_bytes, int64_t now_ns);

  // Of the current frame, per region: chunks planned to be sent, and cut.
  std::span<const uint16_t> plannedPerRegion() const { return planned_per_region_; }
  std::span<const uint16_t> cutPerRegion() const { return cut_per_region_; }
  // Chunks of the current frame kept by the plan (a prefix of the send order).
  std::size_t plannedChunks() const { return planned_; }
  bool frameDone() const { return next_ == planned_; }

  const UplinkCounters& counters() const { return counters_; }
  const TokenBucket& bucket() const { return bucket_; }

 private:
  UplinkScheduler() = default;

  std::size_t max_chunks_ = 0;
  std::vector<uint32_t> bytes_;  // of the current frame, max_chunks_ entries
  std::size_t planned_ = 0;      // chunks [0, planned_) are to be sent
  std::size_t next_ = 0;         // the next of them
  std::array<uint16_t, pipeline::kMaxRegions> planned_per_region_{};
  std::array<uint16_t, pipeline::kMaxRegions> cut_per_region_{};
  TokenBucket bucket_;
  UplinkCounters counters_;
};

}  // namespace fovea::net
