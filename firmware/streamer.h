// The robot side of a stream: the link to the operator, the chunk encoder and
// the uplink scheduler, driven once per frame by whoever sends (fovead run's
// loop, or the service's send thread), which also picks the gaze with its own
// GazePolicy from operatorGaze(). Everything is allocated by create(), the
// chunk encoders for the largest MTU; a session at another MTU makes new ones
// when it starts; a frame allocates nothing.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "core/grid_table.h"
#include "core/result.h"
#include "firmware/brick_feedback.h"
#include "firmware/gaze_policy.h"
#include "hal/frame.h"
#include "net/codec.h"
#include "net/brick_sender.h"
#include "net/key.h"
#include "net/robot_link.h"
#include "net/uplink_scheduler.h"
#include "pipeline/foveator.h"
#include "pipeline/map/brick_batch.h"

namespace fovea::firmware {

struct StreamConfig {
  net::RobotLinkConfig link;  // listen address, key, MTU and budget limits
  GazePolicyConfig gaze;
  net::CodecConfig codec;     // max_payload follows each session's MTU
  // Burst of the token bucket: this many milliseconds of the budget (at least
  // four datagrams). 0 (the default): one frame period (sendFrame's
  // interval_ns), so a frame that fits what the budget earns over a period
  // leaves at once instead of being paced out across it; the budget still holds
  // over any window (at most a period's worth above it).
  double burst_ms = 0.0;
  // The map's bricks (foveation.source = map with map.delta, docs/map-delta.md):
  // sent beside the frame's live points, kept until acknowledged, resent.
  bool map_bricks = false;
  net::BrickSenderConfig brick_sender;
  std::size_t max_brick_points = 1u << 16;        // one brick's points at most (its encoder's size)
  std::size_t max_frame_brick_points = 1u << 18;  // one frame's bricks' points at most
  std::size_t max_frame_bricks = 1024;            // ... and bricks
  std::size_t max_resend_parts = 512;             // brick parts resent with one frame at most
};

// What happened to one frame on the way out.
struct FrameSendReport {
  bool had_session = false;
  uint32_t chunks = 0;        // made by the encoder
  uint32_t chunks_sent = 0;
  uint32_t chunks_cut = 0;    // planned out for the budget
  uint64_t bytes_sent = 0;    // datagram bytes, summary included
  int64_t encode_ns = 0;
  int64_t send_ns = 0;        // first datagram to last (or to the deadline)
  bool completed = false;     // everything planned went out before the deadline
  bool fovea_completed = false;  // everything of the fovea (region 0: its bricks, the frame's fovea) went out
  // The map's bricks (map_bricks): versions begun, their parts, parts resent,
  // and brick parts that went out (new and resent).
  uint32_t bricks = 0;
  uint32_t brick_parts = 0;
  uint32_t brick_resends = 0;
  uint32_t brick_parts_sent = 0;
  // Bricks of the batch that could not be staged (their encode failed, they
  // need more parts than a version may have, or the frame's share of the
  // store is full): told to the planner, due again.
  uint32_t bricks_unstaged = 0;
};

class Streamer {
 public:
  static Result<std::unique_ptr<Streamer>> create(const StreamConfig& config, std::size_t max_points);

  // Non-empty in insecure mode: log it loudly.
  const std::string& notice() const { return link_->notice(); }
  net::Endpoint localEndpoint() const { return link_->localEndpoint(); }
  const net::RobotLink& link() const { return *link_; }

  // Handles waiting datagrams (hello, gaze, bye, brick acknowledgements) without blocking.
  void poll() {
    link_->poll(0);
    takeBrickAcks();
  }
  // Handles datagrams until now >= until_ns (waits in poll, no busy loop).
  void idleUntil(int64_t until_ns);

  // The operator's newest valid gaze sample while a session stands, with the
  // head's forward axis from its HMD pose, when it arrived and its operator stamp;
  // out.valid (returned) is false otherwise.
  bool operatorGaze(OperatorGaze& out) const;

  // Caps the uplink below the budget sessions negotiate (a reloaded
  // configuration): applies to the session in progress and the next ones.
  // Never allocates.
  Status setBudgetCap(uint64_t bytes_per_s, int64_t now_ns);

  // Encodes a foveated frame and sends it, fovea first, paced to the session's
  // budget, until everything planned is out or deadline_ns passes (what is left
  // is dropped when the next frame begins, and counted). The plan cuts the
  // outermost regions to what the budget allows until the deadline; a late
  // frame gets at least interval_ns / 4 (the frame period) so its fovea goes
  // out. Without a session it only polls.
  //
  // With `bricks` (map_bricks) the frame also carries the map's bricks the
  // planner put in it, and the send order is: the fovea's bricks, the frame's
  // live points, the other bricks, then brick parts unacknowledged for
  // resend_after_ns; the budget cuts from the end. Every brick part is kept
  // (net/brick_sender.h) until the operator acknowledges it; a version that can
  // no longer be delivered, a brick the operator evicted and every brick of a
  // frame that could not go are told to the BrickFeedback.
  Result<FrameSendReport> sendFrame(const pipeline::FoveatedCloud& cloud, const pipeline::FoveationStats& stats,
                                    uint32_t frame_id, int64_t capture_ns, int64_t deadline_ns, int64_t interval_ns,
                                    const pipeline::map::BrickBatch* bricks = nullptr);

  // The map's bricks. Where the streamer tells what the operator lacks (owned by
  // the caller, shared with the planner); required with map_bricks before the
  // first sendFrame.
  void attachBrickFeedback(BrickFeedback* feedback) { feedback_ = feedback; }
  // Called after each poll of the link while a frame's datagrams are paced out
  // (the service hands the operator's newest gaze on from there: a frame's
  // sending may take longer than the gaze timeout). Null: none.
  using PollHook = void (*)(void* context);
  void setPollHook(PollHook hook, void* context) {
    poll_hook_ = hook;
    poll_hook_context_ = context;
  }
  // Called once per sendFrame with bricks, when it reads the batch no more (its
  // bricks staged or discarded), before the frame's datagrams are paced out:
  // the caller may plan the next frame's bricks into it meanwhile. Null: none.
  using BricksDoneHook = void (*)(void* context);
  void setBricksDoneHook(BricksDoneHook hook, void* context) {
    bricks_done_hook_ = hook;
    bricks_done_context_ = context;
  }
  // What a recording (firmware/session_recorder.h) taps: every datagram payload
  // sendFrame hands the link and the link took (chunks, brick chunks, frame
  // summaries, as they went: plaintext, before sealing), and every operator
  // message the link decoded (gaze samples with their HMD pose). With
  // record_unsent, a frame without a session is still encoded (all of it, at
  // the encoder's MTU, nothing cut) and its chunks and summary tapped, so a
  // recording has the stream whether or not an operator watched. Called in the
  // caller's thread (the send stage); the tap must not block or allocate.
  using SendTap = void (*)(void* context, net::MessageType type, std::span<const uint8_t> payload, uint32_t frame_id,
                           int64_t capture_ns);
  void setSendTap(SendTap tap, void* context, bool record_unsent) {
    send_tap_ = tap;
    send_tap_context_ = context;
    record_unsent_ = record_unsent;
  }
  void setReceiveTap(net::RobotLink::ReceiveTap tap, void* context) { link_->setReceiveTap(tap, context); }
  // A frame's bricks that will not be sent (no session, privacy): due again.
  void discardBricks(const pipeline::map::BrickBatch& bricks);
  // The budget of the session in progress (bytes/s, under the cap); 0 without one.
  uint64_t sessionBudgetBytesPerS() const;
  // The brick sender's counters (null without map_bricks); acknowledgements
  // for no brick the robot knows are counted in acks_unknown.
  const net::BrickSenderCounters* brickCounters() const { return brick_sender_ ? &brick_sender_->counters() : nullptr; }
  // Brick versions sent and not yet acknowledged whole.
  std::size_t bricksInFlight() const { return brick_sender_ ? brick_sender_->inFlight() : 0; }
  uint64_t bricksUnstaged() const { return bricks_unstaged_; }  // FrameSendReport::bricks_unstaged, summed
  uint64_t bricksTooLarge() const { return bricks_too_large_; }  // of them, too large for a version at their level

  // A status report with the link's and the uplink's figures and the caller's
  // frame counts (frames_dropped adds the frames the uplink superseded); the
  // caller adds the latency quantiles it measures.
  net::StatusReport statusReport(uint64_t frames_captured, uint64_t frames_sent, uint64_t frames_dropped,
                                 int64_t now_ns) const;
  // Sends a status report to the operator (about once a second).
  void sendStatus(const net::StatusReport& report);

  const net::UplinkCounters& uplinkCounters() const { return scheduler_.counters(); }
  // Datagrams one frame can stage (the tables sized by makeEncoders for the
  // encoders' MTU): the live frame's chunks, its bricks' parts, the resends.
  std::size_t datagramCapacity() const { return outgoing_.size(); }
  // The token bucket's burst in bytes (StreamConfig::burst_ms; 0: a frame period).
  double burstBytes() const { return scheduler_.bucket().burstBytes(); }

 private:
  Streamer(const StreamConfig& config, std::unique_ptr<net::RobotLink> link, net::UplinkScheduler scheduler,
           std::size_t max_points);
  // Sets the encoder and the budget up for a new session.
  Status beginSession(int64_t now_ns);
  // (Re)makes the chunk encoders for datagrams of mtu_bytes, and sizes the
  // frame's tables of datagrams for what they can make.
  Status makeEncoders(uint32_t mtu_bytes);
  // The most datagrams one frame can stage at codec.max_payload: the live
  // frame's chunks, its bricks' parts and the resends.
  std::size_t frameDatagrams(const net::CodecConfig& codec) const;
  // Budget and burst for the current session, under the cap.
  Status applyBudget(int64_t now_ns);
  // Hands the operator's brick acknowledgements and evictions to the sender.
  void takeBrickAcks();
  // The map slot the robot sent `key` from (-1: none).
  int brickSlot(const net::BrickKey& key) const;
  void rememberBrickSlot(uint16_t slot, const net::BrickKey& key);
  // Queues one datagram of the frame in send order.
  struct Outgoing {
    const uint8_t* data = nullptr;
    uint16_t size = 0;
    net::MessageType type = net::MessageType::kChunk;
  };
  void stage(std::span<const uint8_t> payload, net::MessageType type, uint8_t region);
  // Encodes one brick of the batch, keeps its parts and queues them; false when
  // it cannot (then the feedback has it).
  bool stageBrick(const pipeline::map::BrickBatch& batch, const pipeline::map::BrickBatchEntry& e, uint8_t region,
                  uint32_t frame_id, int64_t now_ns, FrameSendReport& report);

  StreamConfig config_;
  std::unique_ptr<net::RobotLink> link_;
  net::UplinkScheduler scheduler_;
  std::size_t max_points_;
  std::optional<net::ChunkEncoder> encoder_;
  uint32_t encoder_mtu_ = 0;  // the MTU encoder_ (and brick_encoder_) were made for; 0: none
  std::vector<uint32_t> chunk_bytes_;   // datagram bytes per chunk, frameDatagrams() at the encoders' MTU
  std::vector<uint8_t> chunk_regions_;
  std::vector<Outgoing> outgoing_;       // the frame's datagrams in send order
  std::size_t outgoing_count_ = 0;
  // The map's bricks (map_bricks).
  std::optional<net::BrickSender> brick_sender_;
  std::optional<net::ChunkEncoder> brick_encoder_;  // made with encoder_
  // The two encoders' per-point arrays, one set for both (both encode on the
  // send stage, one after the other), sized for the larger and made once: a
  // session at another MTU remakes the encoders, not these.
  std::shared_ptr<net::ChunkEncoder::PointScratch> encoder_points_;
  std::vector<net::BrickKey> slot_key_;             // per map slot: the key sent from it
  GridTable slot_index_;                            // key -> the map slot it was sent from
  std::size_t brick_store_staged_ = 0;              // bytes kept this frame (must stay under the store)
  uint64_t bricks_unstaged_ = 0;
  uint64_t bricks_too_large_ = 0;
  BrickFeedback* feedback_ = nullptr;
  // sendFrame's steps. The frame's chunks per region, planned and cut (its summary's).
  using RegionCounts = std::array<uint16_t, pipeline::kMaxRegions>;
  // Where the frame's own chunks are among outgoing_: [first, end).
  struct LiveChunks {
    std::size_t first = 0;
    std::size_t end = 0;
  };
  // Encodes the frame with encoder_ (its regions' voxel sizes from stats).
  Status encodeFrame(const pipeline::FoveatedCloud& cloud, const pipeline::FoveationStats& stats, uint32_t frame_id,
                     int64_t capture_ns);
  // Notes the frame period sendFrame was given; with burst_ms 0 a change sets
  // the session's burst again.
  Status followFrameInterval(int64_t interval_ns, int64_t now_ns);
  // Queues the frame's datagrams in send order (the bricks' and the resends'
  // with them); an encoding error discards the bricks.
  Status stageFrame(const pipeline::FoveatedCloud& cloud, const pipeline::FoveationStats& stats, uint32_t frame_id,
                    int64_t capture_ns, const pipeline::map::BrickBatch* bricks, int64_t now_ns,
                    FrameSendReport& report, LiveChunks& live);
  // Counts the frame's chunks the plan kept and cut, per region.
  void countPlanned(const LiveChunks& live, RegionCounts& planned, RegionCounts& cut, FrameSendReport& report) const;
  // Sends the plan's steps as the budget allows until everything planned is
  // out (then the frame summary) or deadline_ns passes.
  void paceFrame(uint32_t frame_id, int64_t capture_ns, int64_t deadline_ns, int64_t now_ns,
                 const RegionCounts& planned, const RegionCounts& cut, FrameSendReport& report);
  // Waits wait_ns for the uplink's tokens, handling datagrams meanwhile.
  void waitForTokens(int64_t wait_ns);
  // Encodes a frame without a session for the send tap (record_unsent).
  Status tapUnsent(const pipeline::FoveatedCloud& cloud, const pipeline::FoveationStats& stats, uint32_t frame_id,
                   int64_t capture_ns);
  PollHook poll_hook_ = nullptr;
  SendTap send_tap_ = nullptr;
  void* send_tap_context_ = nullptr;
  bool record_unsent_ = false;
  void* poll_hook_context_ = nullptr;
  BricksDoneHook bricks_done_hook_ = nullptr;
  void* bricks_done_context_ = nullptr;
  uint64_t unknown_brick_keys_ = 0;
  int64_t frame_interval_ns_ = 33'333'333;  // the last sendFrame's interval_ns (burst_ms 0)
  // The session the encoder and budget were set up for (its start time).
  int64_t session_started_ns_ = -1;
  uint64_t budget_cap_bytes_per_s_ = UINT64_MAX;
};

}  // namespace fovea::firmware
