#include "firmware/streamer.h"

#include <algorithm>
#include <ctime>
#include <type_traits>
#include <utility>

#include <Eigen/Geometry>

#include "core/clock.h"
#include "core/grid_table.h"

namespace fovea::firmware {

namespace {

// Milliseconds to wait in poll() for a wait of wait_ns: rounded up, so a
// loop never spins on a zero timeout while it has time to wait.
int pollMs(int64_t wait_ns) {
  return static_cast<int>(std::clamp<int64_t>((wait_ns + 999'999) / 1'000'000, 0, 1000));
}

}  // namespace

Result<std::unique_ptr<Streamer>> Streamer::create(const StreamConfig& config, std::size_t max_points) {
  if (Status s = config.gaze.validate(); !s) return s;
  if (Status s = net::validate(config.codec); !s) return s;
  if (!(config.burst_ms >= 0.0 && config.burst_ms <= 1000.0)) {
    return Result<std::unique_ptr<Streamer>>(ErrorCode::kInvalidArgument,
                                             "stream burst: must be within 0 .. 1000 ms (0: a frame period)");
  }
  if (max_points == 0) return Result<std::unique_ptr<Streamer>>(ErrorCode::kInvalidArgument, "stream: max_points is 0");
  if (config.map_bricks) {
    if (Status s = config.brick_sender.validate(); !s) return s;
    if (config.max_brick_points == 0 || config.max_brick_points > config.max_frame_brick_points ||
        config.max_resend_parts == 0 || config.max_frame_bricks == 0) {
      return Result<std::unique_ptr<Streamer>>(
          ErrorCode::kInvalidArgument,
          "stream bricks: max_brick_points must be in [1, max_frame_brick_points], max_resend_parts and max_frame_bricks > 0");
    }
  }
  Result<std::unique_ptr<net::RobotLink>> link = net::RobotLink::create(config.link);
  if (!link) return link.status();
  // Sized for one datagram here; makeEncoders() sizes it for the MTU.
  Result<net::UplinkScheduler> scheduler =
      net::UplinkScheduler::create(1, static_cast<double>(config.link.max_budget_bytes_per_s),
                                   static_cast<double>(4 * net::kMaxMtu), monotonicNs());
  if (!scheduler) return scheduler.status();
  std::unique_ptr<Streamer> streamer(
      new Streamer(config, std::move(link.value()), std::move(scheduler.value()), max_points));
  if (config.map_bricks) {
    Result<net::BrickSender> sender = net::BrickSender::create(config.brick_sender);
    if (!sender) return sender.status();
    streamer->brick_sender_.emplace(std::move(sender.value()));
    streamer->slot_key_.resize(config.brick_sender.max_bricks);
    streamer->slot_index_ = GridTable(config.brick_sender.max_bricks);
  }
  // The chunk encoders and the datagram tables for the largest MTU, made once
  // here: a session at that MTU (the default's) uses them, and only another
  // MTU makes new ones when it starts.
  if (Status s = streamer->makeEncoders(config.link.max_mtu_bytes); !s) return s;
  return streamer;
}

Streamer::Streamer(const StreamConfig& config, std::unique_ptr<net::RobotLink> link, net::UplinkScheduler scheduler,
                   std::size_t max_points)
    : config_(config),
      link_(std::move(link)),
      scheduler_(std::move(scheduler)),
      max_points_(max_points) {}

void Streamer::idleUntil(int64_t until_ns) {
  for (int64_t now = monotonicNs(); now < until_ns; now = monotonicNs()) {
    const int64_t wait_ns = until_ns - now;
    if (wait_ns >= 1'000'000) {
      link_->poll(pollMs(wait_ns));
    } else {
      // poll() counts in milliseconds: a shorter wait (the send stage's idle
      // step) would take a whole one, and a frame foveated meanwhile would wait.
      link_->poll(0);
      const timespec pause{0, static_cast<long>(wait_ns)};
      nanosleep(&pause, nullptr);
    }
  }
}

bool Streamer::operatorGaze(OperatorGaze& out) const {
  out = {};
  const auto& latest = link_->latestGaze();
  if (!link_->hasSession() || !latest) return false;
  const net::GazeSample& s = latest->sample;
  // Confidence 0: the operator's station keeps the session but does not know
  // where the eye is (no tracker sample yet); the robot falls back as without gaze.
  if (!(s.confidence > 0.0f)) return false;
  out.gaze.origin_m = {s.gaze_origin_m.x, s.gaze_origin_m.y, s.gaze_origin_m.z};
  out.gaze.direction = {s.gaze_direction.x, s.gaze_direction.y, s.gaze_direction.z};
  // The head's forward axis: the eye's z axis turned into the world (docs/protocol.md).
  const Eigen::Quaterniond q(s.hmd_orientation.w, s.hmd_orientation.x, s.hmd_orientation.y, s.hmd_orientation.z);
  out.gaze.view_forward = q.normalized() * Eigen::Vector3d::UnitZ();
  out.gaze.view_known = true;
  out.received_ns = latest->received_ns;
  out.stamp_ns = s.operator_stamp_ns;
  out.valid = true;
  return true;
}

Status Streamer::setBudgetCap(uint64_t bytes_per_s, int64_t now_ns) {
  if (bytes_per_s == 0) return {ErrorCode::kInvalidArgument, "stream budget cap: must be positive"};
  budget_cap_bytes_per_s_ = bytes_per_s;
  if (session_started_ns_ >= 0 && link_->hasSession() && link_->session()->started_ns == session_started_ns_) {
    return applyBudget(now_ns);
  }
  return Status::ok();
}

Status Streamer::applyBudget(int64_t now_ns) {
  const net::SessionInfo& session = *link_->session();
  const double budget = static_cast<double>(std::min(session.budget_bytes_per_s, budget_cap_bytes_per_s_));
  const double burst_s = config_.burst_ms > 0.0 ? config_.burst_ms * 1e-3 : static_cast<double>(frame_interval_ns_) * 1e-9;
  const double burst = std::max(budget * burst_s, 4.0 * session.mtu_bytes);
  return scheduler_.setBudget(budget, burst, now_ns);
}

Status Streamer::makeEncoders(uint32_t mtu_bytes) {
  net::CodecConfig codec = config_.codec;
  codec.max_payload = mtu_bytes - net::kDatagramOverhead;
  // The old ones go first, so that the heap never holds both.
  encoder_.reset();
  brick_encoder_.reset();
  encoder_mtu_ = 0;
  const bool bricks_too = brick_sender_ || config_.map_bricks;
  if (!encoder_points_) {
    encoder_points_ =
        net::ChunkEncoder::makePointScratch(std::max(max_points_, bricks_too ? config_.max_brick_points : std::size_t{0}));
  }
  Result<net::ChunkEncoder> encoder = net::ChunkEncoder::create(codec, max_points_, encoder_points_);
  if (!encoder) return encoder.status();
  encoder_.emplace(std::move(encoder.value()));
  if (bricks_too) {
    // A brick version of more parts than the sender keeps cannot go: the
    // arena holds that many, not a worst-case brick's (1 414 chunks at the
    // default MTU for 65 536 points, against 256 parts).
    Result<net::ChunkEncoder> bricks = net::ChunkEncoder::create(codec, config_.max_brick_points, encoder_points_,
                                                                 config_.brick_sender.max_parts);
    if (!bricks) return bricks.status();
    brick_encoder_.emplace(std::move(bricks.value()));
  }
  // The frame's datagram tables follow the codec: at the largest MTU a few
  // thousand entries, where one per point (the bound before) was 25 bytes a
  // point of the frame and of its bricks.
  const std::size_t datagrams = frameDatagrams(codec);
  auto fresh = [datagrams](auto& table) {
    std::remove_reference_t<decltype(table)>().swap(table);  // the old one goes first
    table.resize(datagrams);
  };
  fresh(chunk_bytes_);
  fresh(chunk_regions_);
  fresh(outgoing_);
  outgoing_count_ = 0;
  scheduler_.setMaxChunks(datagrams);
  encoder_mtu_ = mtu_bytes;
  return Status::ok();
}

std::size_t Streamer::frameDatagrams(const net::CodecConfig& codec) const {
  // The live frame: what its encoder can make, and at most 65535 (the codec's
  // chunk index is 16 bits).
  std::size_t datagrams = std::min<std::size_t>(net::maxChunks(codec, max_points_), 0xffff);
  if (config_.map_bricks) {
    // Its bricks, each encoded alone: their points' chunks as one encode's, plus
    // for each brick a region's partial last chunk and the encoder's region slack.
    datagrams += net::maxChunks(codec, config_.max_frame_brick_points) +
                 config_.max_frame_bricks * (pipeline::kMaxRegions + 2) + config_.max_resend_parts;
  }
  return datagrams;
}

Status Streamer::beginSession(int64_t now_ns) {
  const net::SessionInfo& session = *link_->session();
  // Allocation at session start, never per frame, and only for an MTU other
  // than the one the encoders were made for.
  if (session.mtu_bytes != encoder_mtu_) {
    if (Status s = makeEncoders(session.mtu_bytes); !s) return s;
  }
  if (brick_sender_) {
    // A new operator (or one that restarted) holds nothing: every brick is due.
    brick_sender_->reset();
    if (feedback_) feedback_->forgetAll();
  }
  if (Status s = applyBudget(now_ns); !s) return s;
  session_started_ns_ = session.started_ns;
  return Status::ok();
}

uint64_t Streamer::sessionBudgetBytesPerS() const {
  if (!link_->hasSession()) return 0;
  return std::min(link_->session()->budget_bytes_per_s, budget_cap_bytes_per_s_);
}

int Streamer::brickSlot(const net::BrickKey& key) const {
  return slot_index_.find(key, [this](uint32_t slot) -> const net::BrickKey& { return slot_key_[slot]; });
}

void Streamer::rememberBrickSlot(uint16_t slot, const net::BrickKey& key) {
  if (brickSlot(key) == slot) return;
  auto key_of = [this](uint32_t s) -> const net::BrickKey& { return slot_key_[s]; };
  // The map gives an emptied brick's slot to a new place (SurfelMap::pinBrick):
  // the slot's old key goes first, so that the index holds at most max_bricks
  // entries and an acknowledgement for the old place names no slot.
  if (const net::BrickKey& old = slot_key_[slot]; brickSlot(old) == slot) slot_index_.erase(old, key_of);
  slot_key_[slot] = key;
  slot_index_.place(slot_index_.probe(key, key_of), slot);
}

void Streamer::takeBrickAcks() {
  if (!brick_sender_) return;
  for (const net::BrickPartId& id : link_->brickAcks()) {
    const int slot = brickSlot(id.key);
    if (slot < 0) {
      ++unknown_brick_keys_;
      continue;
    }
    (void)brick_sender_->acknowledge(static_cast<uint16_t>(slot), id.version, id.part);
  }
  for (const net::BrickKey& key : link_->brickEvictions()) {
    const int slot = brickSlot(key);
    if (slot < 0) {
      ++unknown_brick_keys_;
      continue;
    }
    brick_sender_->drop(static_cast<uint16_t>(slot));
    if (feedback_) feedback_->forget(static_cast<std::size_t>(slot));
  }
  link_->takeBrickAcks();
}

void Streamer::discardBricks(const pipeline::map::BrickBatch& bricks) {
  if (!feedback_) return;
  for (const pipeline::map::BrickBatchEntry& e : bricks.entries()) feedback_->forget(e.brick);
}

void Streamer::stage(std::span<const uint8_t> payload, net::MessageType type, uint8_t region) {
  outgoing_[outgoing_count_] = {payload.data(), static_cast<uint16_t>(payload.size()), type};
  chunk_bytes_[outgoing_count_] = static_cast<uint32_t>(payload.size() + net::kDatagramOverhead);
  chunk_regions_[outgoing_count_] = region;
  ++outgoing_count_;
}

bool Streamer::stageBrick(const pipeline::map::BrickBatch& batch, const pipeline::map::BrickBatchEntry& e,
                          uint8_t region, uint32_t frame_id, int64_t now_ns, FrameSendReport& report) {
  auto fail = [&] {
    if (feedback_) feedback_->forget(e.brick);
    ++report.bricks_unstaged;
    ++bricks_unstaged_;
    return false;
  };
  // Parts staged this frame are sent from the sender's store: they must not be
  // overwritten before the frame's pacing reaches them.
  if (brick_store_staged_ + static_cast<std::size_t>(e.count) * 8 > config_.brick_sender.store_bytes / 2) return fail();
  // The brick's slice of the batch, encoded where it lies (an empty brick
  // encodes too: its surfels all went).
  const std::optional<net::EncodeInput> points = net::EncodeInput::slice(batch.points, e.first, e.count);
  if (!points) return fail();
  const net::BrickTag tag{e.key.x, e.key.y, e.key.z, e.version, e.level};
  const Status encoded =
      brick_encoder_->encode(*points, std::span<const double>(batch.level_step_m.data(), e.level + 1u), frame_id, 0, &tag);
  // More parts than a version may have (the encoder's arena holds max_parts),
  // or more points than it takes: never fits at this level, so the planner
  // goes coarser (MapDelta::tooLarge) rather than plan it so again each frame.
  if (encoded.code() == ErrorCode::kCapacityExceeded) {
    ++bricks_too_large_;
    if (feedback_) feedback_->tooLarge(e.brick);
  }
  if (!encoded) return fail();
  const std::size_t parts = brick_encoder_->chunkCount();
  if (parts == 0 || parts > config_.brick_sender.max_parts || outgoing_count_ + parts > outgoing_.size()) return fail();
  const net::BrickKey key{e.key.x, e.key.y, e.key.z};
  rememberBrickSlot(e.brick, key);
  int lost = -1;
  if (!brick_sender_->begin(e.brick, e.version, static_cast<uint16_t>(parts), now_ns, &lost)) return fail();
  if (lost >= 0 && feedback_) feedback_->forget(static_cast<std::size_t>(lost));
  for (std::size_t i = 0; i < parts; ++i) {
    std::span<const uint8_t> stored;
    if (!brick_sender_->addPart(static_cast<uint16_t>(i), brick_encoder_->chunk(i), &stored)) {
      brick_sender_->drop(e.brick);
      return fail();
    }
    brick_store_staged_ += stored.size();
    stage(stored, net::MessageType::kBrickChunk, region);
  }
  ++report.bricks;
  report.brick_parts += static_cast<uint32_t>(parts);
  return true;
}

Status Streamer::tapUnsent(const pipeline::FoveatedCloud& cloud, const pipeline::FoveationStats& stats,
                           uint32_t frame_id, int64_t capture_ns) {
  if (!encoder_) return Status::ok();
  if (Status s = encodeFrame(cloud, stats, frame_id, capture_ns); !s) return s;
  RegionCounts planned{}, cut{};
  const std::size_t chunks = encoder_->chunkCount();
  for (std::size_t i = 0; i < chunks; ++i) {
    send_tap_(send_tap_context_, net::MessageType::kChunk, encoder_->chunk(i), frame_id, capture_ns);
    ++planned[encoder_->chunkRegion(i)];
  }
  send_tap_(send_tap_context_, net::MessageType::kFrameSummary, encoder_->encodeSummary(frame_id, planned, cut),
            frame_id, capture_ns);
  return Status::ok();
}

Status Streamer::encodeFrame(const pipeline::FoveatedCloud& cloud, const pipeline::FoveationStats& stats,
                             uint32_t frame_id, int64_t capture_ns) {
  std::array<double, pipeline::kMaxRegions> voxel_size_m{};
  for (int r = 0; r < stats.region_count; ++r) voxel_size_m[r] = stats.regions[r].voxel_size_m;
  return encoder_->encode(cloud, std::span<const double>(voxel_size_m.data(), stats.region_count), frame_id,
                          static_cast<uint64_t>(capture_ns));
}

Result<FrameSendReport> Streamer::sendFrame(const pipeline::FoveatedCloud& cloud,
                                            const pipeline::FoveationStats& stats, uint32_t frame_id,
                                            int64_t capture_ns, int64_t deadline_ns, int64_t interval_ns,
                                            const pipeline::map::BrickBatch* bricks) {
  FrameSendReport report;
  // The caller hears once that the batch is read no more: after staging, or
  // on whichever path ends the frame before it.
  struct BricksDone {
    const Streamer& streamer;
    bool pending;
    void run() {
      if (pending && streamer.bricks_done_hook_) streamer.bricks_done_hook_(streamer.bricks_done_context_);
      pending = false;
    }
    ~BricksDone() { run(); }
  } bricks_done{*this, bricks != nullptr};
  if (bricks && !brick_sender_) return Status(ErrorCode::kInvalidArgument, "stream: bricks without map_bricks");
  link_->poll(0);
  if (!link_->hasSession()) {
    if (bricks) discardBricks(*bricks);
    if (send_tap_ && record_unsent_) {
      if (Status s = tapUnsent(cloud, stats, frame_id, capture_ns); !s) return s;
    }
    return report;
  }
  report.had_session = true;
  // A frame that fails before its bricks are staged: the planner must hear
  // that they never went (staged ones are the sender's to resend).
  auto unsent = [&](Status s) {
    if (bricks) discardBricks(*bricks);
    return s;
  };
  int64_t now = monotonicNs();
  if (Status s = followFrameInterval(interval_ns, now); !s) return unsent(s);
  if (link_->session()->started_ns != session_started_ns_) {
    if (Status s = beginSession(now); !s) return unsent(s);
  }
  takeBrickAcks();

  const int64_t t0 = monotonicNs();
  LiveChunks live;
  if (Status s = stageFrame(cloud, stats, frame_id, capture_ns, bricks, now, report, live); !s) return s;
  bricks_done.run();
  now = monotonicNs();
  report.encode_ns = now - t0;
  report.chunks = static_cast<uint32_t>(encoder_->chunkCount());
  // A frame that comes late (the pipeline took longer than a frame period) still
  // gets a quarter period: its fovea goes out, the periphery is cut to fit.
  deadline_ns = std::max(deadline_ns, now + interval_ns / 4);
  // The plan fits what the budget earns until the deadline, not a whole period.
  if (Status s = scheduler_.beginFrame(std::span<const uint32_t>(chunk_bytes_.data(), outgoing_count_),
                                       std::span<const uint8_t>(chunk_regions_.data(), outgoing_count_), now,
                                       deadline_ns - now);
      !s) {
    return s;
  }
  RegionCounts planned{}, cut{};
  countPlanned(live, planned, cut, report);
  const uint64_t bytes_before = scheduler_.counters().bytes_sent;
  const int64_t send_start = now;
  paceFrame(frame_id, capture_ns, deadline_ns, now, planned, cut, report);
  takeBrickAcks();
  report.send_ns = monotonicNs() - send_start;
  report.bytes_sent = scheduler_.counters().bytes_sent - bytes_before;
  return report;
}

// The burst follows the frame period (burst_ms 0): set again when it changes.
Status Streamer::followFrameInterval(int64_t interval_ns, int64_t now_ns) {
  if (interval_ns <= 0 || interval_ns == frame_interval_ns_) return Status::ok();
  frame_interval_ns_ = interval_ns;
  if (config_.burst_ms <= 0.0 && link_->session()->started_ns == session_started_ns_) return applyBudget(now_ns);
  return Status::ok();
}

Status Streamer::stageFrame(const pipeline::FoveatedCloud& cloud, const pipeline::FoveationStats& stats,
                            uint32_t frame_id, int64_t capture_ns, const pipeline::map::BrickBatch* bricks,
                            int64_t now_ns, FrameSendReport& report, LiveChunks& live) {
  // The send order: the fovea's bricks (region 0, never cut), the frame's live
  // chunks (fovea first), then the other bricks and the resends as the
  // outermost region, which the budget cuts first.
  constexpr auto kLast = static_cast<uint8_t>(pipeline::kMaxRegions - 1);
  outgoing_count_ = 0;
  brick_store_staged_ = 0;
  if (bricks) {
    for (const pipeline::map::BrickBatchEntry& e : bricks->entries()) {
      if (e.fovea) (void)stageBrick(*bricks, e, 0, frame_id, now_ns, report);
    }
  }
  if (Status s = encodeFrame(cloud, stats, frame_id, capture_ns); !s) {
    if (bricks) discardBricks(*bricks);
    return s;
  }
  live.first = outgoing_count_;
  const std::size_t chunks = encoder_->chunkCount();
  for (std::size_t i = 0; i < chunks; ++i) stage(encoder_->chunk(i), net::MessageType::kChunk, encoder_->chunkRegion(i));
  live.end = outgoing_count_;
  if (bricks) {
    for (const pipeline::map::BrickBatchEntry& e : bricks->entries()) {
      if (!e.fovea) (void)stageBrick(*bricks, e, kLast, frame_id, now_ns, report);
    }
  }
  if (brick_sender_) {
    const std::size_t room = std::min(config_.max_resend_parts, outgoing_.size() - outgoing_count_);
    report.brick_resends = static_cast<uint32_t>(brick_sender_->collectResends(
        now_ns, room,
        [&](uint16_t, uint16_t, std::span<const uint8_t> payload) {
          stage(payload, net::MessageType::kBrickChunk, kLast);
        },
        [&](uint16_t brick) {
          if (feedback_) feedback_->forget(brick);
        }));
  }
  return Status::ok();
}

void Streamer::countPlanned(const LiveChunks& live, RegionCounts& planned, RegionCounts& cut,
                            FrameSendReport& report) const {
  // The frame summary counts the frame's own chunks only (a brick part is no
  // part of a frame): planned are those before the plan's end.
  for (std::size_t i = live.first; i < live.end; ++i) {
    ++(i < scheduler_.plannedChunks() ? planned : cut)[chunk_regions_[i]];
  }
  for (std::size_t r = 0; r < pipeline::kMaxRegions; ++r) report.chunks_cut += cut[r];
}

void Streamer::paceFrame(uint32_t frame_id, int64_t capture_ns, int64_t deadline_ns, int64_t now_ns,
                         const RegionCounts& planned, const RegionCounts& cut, FrameSendReport& report) {
  // The send order begins with everything of region 0 (the fovea's bricks, the
  // frame's fovea): the fovea is out once that many steps were sent.
  std::size_t fovea_chunks = 0;
  while (fovea_chunks < outgoing_count_ && chunk_regions_[fovea_chunks] == 0) ++fovea_chunks;
  std::size_t steps_sent = 0;
  report.fovea_completed = fovea_chunks == 0;
  for (int64_t now = now_ns; now < deadline_ns && link_->hasSession(); now = monotonicNs()) {
    const net::UplinkScheduler::Step step = scheduler_.next(now);
    if (step.kind == net::UplinkScheduler::Step::Kind::kDone) {
      const std::span<const uint8_t> summary = encoder_->encodeSummary(frame_id, planned, cut);
      if (link_->send(net::MessageType::kFrameSummary, summary) == net::SendResult::kSent) {
        scheduler_.chargeExtra(summary.size() + net::kDatagramOverhead, now);
        if (send_tap_) send_tap_(send_tap_context_, net::MessageType::kFrameSummary, summary, frame_id, capture_ns);
      }
      report.completed = true;
      report.fovea_completed = true;
      break;
    }
    if (step.kind == net::UplinkScheduler::Step::Kind::kWait) {
      waitForTokens(std::min(step.wait_ns, deadline_ns - now));
      continue;
    }
    report.fovea_completed = ++steps_sent >= fovea_chunks;
    const Outgoing& o = outgoing_[step.chunk];
    if (link_->send(o.type, std::span<const uint8_t>(o.data, o.size)) == net::SendResult::kSent) {
      if (send_tap_) send_tap_(send_tap_context_, o.type, {o.data, o.size}, frame_id, capture_ns);
      if (o.type == net::MessageType::kChunk) {
        ++report.chunks_sent;
      } else {
        ++report.brick_parts_sent;
      }
    }
  }
}

void Streamer::waitForTokens(int64_t wait_ns) {
  // Gaze keeps arriving while the uplink waits for tokens. poll() counts
  // in milliseconds and a datagram's tokens often take less: sleep those.
  if (wait_ns >= 1'000'000) {
    link_->poll(static_cast<int>(wait_ns / 1'000'000));
  } else {
    link_->poll(0);
    const timespec pause{0, static_cast<long>(wait_ns)};
    nanosleep(&pause, nullptr);
  }
  if (poll_hook_) poll_hook_(poll_hook_context_);
}

net::StatusReport Streamer::statusReport(uint64_t frames_captured, uint64_t frames_sent, uint64_t frames_dropped,
                                         int64_t now_ns) const {
  const net::UplinkCounters& up = scheduler_.counters();
  const net::RobotLinkCounters& lc = link_->counters();
  net::StatusReport status;
  status.frames_captured = frames_captured;
  status.frames_sent = frames_sent;
  status.frames_dropped = frames_dropped + up.frames_superseded;
  status.chunks_cut = up.chunks_cut;
  status.datagrams_sent = lc.datagrams_sent;
  status.bytes_sent = lc.bytes_sent;
  status.datagrams_received = lc.datagrams_received;
  status.datagrams_dropped = lc.dropped.total();
  if (const auto& g = link_->latestGaze()) {
    status.gaze_age_ns = now_ns - g->received_ns;
    if (g->sample.confidence > 0.0f) {
      status.gaze_origin_m = g->sample.gaze_origin_m;
      status.gaze_direction = g->sample.gaze_direction;
    }
  }
  status.rtt_ns = link_->lastRttNs();
  return status;
}

void Streamer::sendStatus(const net::StatusReport& report) {
  if (link_->hasSession()) link_->sendStatus(report);
}

}  // namespace fovea::firmware
