#include "firmware/streamer.h"

#include <algorithm>
#include <ctime>
#include <utility>

#include <Eigen/Geometry>

#include "core/clock.h"

namespace fovea::firmware {

namespace {

int64_t monotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Milliseconds to wait in poll() for a wait of wait_ns: rounded up, so a
// loop never spins on a zero timeout while it has time to wait.
int pollMs(int64_t wait_ns) {
  return static_cast<int>(std::clamp<int64_t>((wait_ns + 999'999) / 1'000'000, 0, 1000));
}

}  // namespace

Result<std::unique_ptr<Streamer>> Streamer::create(const StreamConfig& config, std::size_t max_points) {
  if (Status s = config.gaze.validate(); !s) return s;
  if (Status s = net::validate(config.codec); !s) return s;
  if (!(config.burst_ms > 0.0 && config.burst_ms <= 1000.0)) {
    return Result<std::unique_ptr<Streamer>>(ErrorCode::kInvalidArgument, "stream burst: must be within 0 .. 1000 ms");
  }
  if (max_points == 0) return Result<std::unique_ptr<Streamer>>(ErrorCode::kInvalidArgument, "stream: max_points is 0");
  Result<std::unique_ptr<net::RobotLink>> link = net::RobotLink::create(config.link);
  if (!link) return link.status();
  // A chunk holds at least one point, so a frame has at most max_points chunks.
  Result<net::UplinkScheduler> scheduler =
      net::UplinkScheduler::create(max_points, static_cast<double>(config.link.max_budget_bytes_per_s),
                                   static_cast<double>(4 * net::kMaxMtu), monotonicNs());
  if (!scheduler) return scheduler.status();
  return std::unique_ptr<Streamer>(
      new Streamer(config, std::move(link.value()), std::move(scheduler.value()), max_points));
}

Streamer::Streamer(const StreamConfig& config, std::unique_ptr<net::RobotLink> link, net::UplinkScheduler scheduler,
                   std::size_t max_points)
    : config_(config),
      link_(std::move(link)),
      scheduler_(std::move(scheduler)),
      max_points_(max_points),
      chunk_bytes_(max_points),
      chunk_regions_(max_points) {}

void Streamer::idleUntil(int64_t until_ns) {
  for (int64_t now = monotonicNs(); now < until_ns; now = monotonicNs()) {
    link_->poll(pollMs(until_ns - now));
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
  const double burst = std::max(budget * config_.burst_ms * 1e-3, 4.0 * session.mtu_bytes);
  return scheduler_.setBudget(budget, burst, now_ns);
}

Status Streamer::beginSession(int64_t now_ns) {
  const net::SessionInfo& session = *link_->session();
  net::CodecConfig codec = config_.codec;
  codec.max_payload = session.mtu_bytes - net::kDatagramOverhead;
  // Allocation at session start, never per frame.
  Result<net::ChunkEncoder> encoder = net::ChunkEncoder::create(codec, max_points_);
  if (!encoder) return encoder.status();
  encoder_.emplace(std::move(encoder.value()));
  if (Status s = applyBudget(now_ns); !s) return s;
  session_started_ns_ = session.started_ns;
  return Status::ok();
}

Result<FrameSendReport> Streamer::sendFrame(const pipeline::FoveatedCloud& cloud,
                                            const pipeline::FoveationStats& stats, uint32_t frame_id,
                                            int64_t capture_ns, int64_t deadline_ns, int64_t interval_ns) {
  FrameSendReport report;
  link_->poll(0);
  if (!link_->hasSession()) return report;
  report.had_session = true;
  int64_t now = monotonicNs();
  if (link_->session()->started_ns != session_started_ns_) {
    if (Status s = beginSession(now); !s) return s;
  }

  std::array<double, pipeline::kMaxRegions> voxel_size_m{};
  for (int r = 0; r < stats.region_count; ++r) voxel_size_m[r] = stats.regions[r].voxel_size_m;
  const int64_t t0 = monotonicNs();
  if (Status s = encoder_->encode(cloud, std::span<const double>(voxel_size_m.data(), stats.region_count), frame_id,
                                  static_cast<uint64_t>(capture_ns));
      !s) {
    return s;
  }
  const std::size_t chunks = encoder_->chunkCount();
  for (std::size_t i = 0; i < chunks; ++i) {
    chunk_bytes_[i] = static_cast<uint32_t>(encoder_->chunk(i).size() + net::kDatagramOverhead);
    chunk_regions_[i] = encoder_->chunkRegion(i);
  }
  now = monotonicNs();
  report.encode_ns = now - t0;
  report.chunks = static_cast<uint32_t>(chunks);
  // A frame that comes late (the pipeline took longer than a frame period) still
  // gets a quarter period: its fovea goes out, the periphery is cut to fit.
  deadline_ns = std::max(deadline_ns, now + interval_ns / 4);
  // The plan fits what the budget earns until the deadline, not a whole period.
  if (Status s = scheduler_.beginFrame(std::span<const uint32_t>(chunk_bytes_.data(), chunks),
                                       std::span<const uint8_t>(chunk_regions_.data(), chunks), now, deadline_ns - now);
      !s) {
    return s;
  }
  for (std::size_t r = 0; r < pipeline::kMaxRegions; ++r) report.chunks_cut += scheduler_.cutPerRegion()[r];

  const uint64_t bytes_before = scheduler_.counters().bytes_sent;
  const int64_t send_start = now;
  while (now < deadline_ns && link_->hasSession()) {
    const net::UplinkScheduler::Step step = scheduler_.next(now);
    if (step.kind == net::UplinkScheduler::Step::Kind::kDone) {
      const std::span<const uint8_t> summary =
          encoder_->encodeSummary(frame_id, scheduler_.plannedPerRegion(), scheduler_.cutPerRegion());
      if (link_->send(net::MessageType::kFrameSummary, summary) == net::SendResult::kSent) {
        scheduler_.chargeExtra(summary.size() + net::kDatagramOverhead, now);
      }
      report.completed = true;
      break;
    }
    if (step.kind == net::UplinkScheduler::Step::Kind::kWait) {
      // Gaze keeps arriving while the uplink waits for tokens. poll() counts
      // in milliseconds and a datagram's tokens often take less: sleep those.
      const int64_t wait_ns = std::min(step.wait_ns, deadline_ns - now);
      if (wait_ns >= 1'000'000) {
        link_->poll(static_cast<int>(wait_ns / 1'000'000));
      } else {
        link_->poll(0);
        const timespec pause{0, static_cast<long>(wait_ns)};
        nanosleep(&pause, nullptr);
      }
    } else {
      if (link_->send(net::MessageType::kChunk, encoder_->chunk(step.chunk)) == net::SendResult::kSent) {
        ++report.chunks_sent;
      }
    }
    now = monotonicNs();
  }
  report.send_ns = monotonicNs() - send_start;
  report.bytes_sent = scheduler_.counters().bytes_sent - bytes_before;
  return report;
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
