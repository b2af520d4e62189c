// The service's three stage threads: their placement (name, core, priority)
// and their loops, capture -> foveation -> send, with what each publishes for
// the supervisor. Nothing here takes a lock or, after start-up, allocates.
#include "firmware/service.h"

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cinttypes>
#include <cstdio>
#include <cstring>

#include "core/clock.h"
#include "firmware/sleep_ns.h"
#include "hal/capture_retry.h"

namespace fovea::firmware {

namespace {

constexpr int64_t kIdleSleepNs = 500'000;  // a stage with nothing to do
constexpr auto kAcquireTimeout = std::chrono::milliseconds(200);  // bounds how long a stop waits for the camera

}  // namespace

void Service::placeThread(const char* name, const ThreadPlacement& placement) {
  pthread_setname_np(pthread_self(), name);
  if (placement.core >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(placement.core, &set);
    if (const int e = pthread_setaffinity_np(pthread_self(), sizeof set, &set); e != 0) {
      log().log(LogLevel::kWarning, "%s: pinning to core %d refused (%s): running on any core", name, placement.core,
                std::strerror(e));
    }
  }
  if (placement.realtime_priority > 0) {
    sched_param param{};
    param.sched_priority = placement.realtime_priority;
    if (const int e = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param); e != 0) {
      log().log(LogLevel::kWarning, "%s: SCHED_FIFO priority %d refused (%s): running on the normal scheduler", name,
                placement.realtime_priority, std::strerror(e));
    }
  } else if (placement.nice != 0) {
    // Relative to the thread's start (the process's, which `nice` may have
    // set), so that the stages keep their lead; Linux keeps a nice value per
    // thread (PRIO_PROCESS with its id).
    const auto tid = static_cast<id_t>(::gettid());
    errno = 0;
    const int base = ::getpriority(PRIO_PROCESS, tid);
    const int target = std::clamp((errno == 0 ? base : 0) + placement.nice, -20, 19);
    if (::setpriority(PRIO_PROCESS, tid, target) != 0) {
      log().log(LogLevel::kWarning, "%s: nice %d refused (%s): running at the process's", name, target,
                std::strerror(errno));
    }
  }
}

// ---- capture ----

void Service::captureLoop() {
  placeThread("fovea-capture", config_.runtime.capture_thread);
  static LogRateLimit capture_site;
  // Retries, backoff and reopening after a disconnect: hal/capture_retry.h.
  hal::CaptureRetryConfig retry_config;
  retry_config.acquire_timeout = kAcquireTimeout;
  retry_config.initial_backoff_ns = config_.camera.retry_initial_ms * 1'000'000;
  retry_config.max_backoff_ns = config_.camera.retry_max_ms * 1'000'000;
  hal::CaptureRetry retry(*camera_, retry_config);
  hal::CaptureRetryStats failing_since;  // the counts when the current failure began
  fovea::SlotRing& ring = frames_->ring();
  while (running_.load(std::memory_order_acquire)) {
    const uint64_t limit = max_frames_.load(std::memory_order_relaxed);
    if (limit > 0 && ring.counters().published >= limit) break;  // run()'s frame limit: drain and stop
    fovea::SlotIndex slot;
    if (!ring.tryAcquire(slot)) {
      sleepNs(kIdleSleepNs);
      continue;
    }
    CapturedFrame& f = frames_->slot(slot);
    const int64_t t0 = monotonicNs();
    const hal::CaptureStep step = retry.step(t0, f.frame);
    if (step.event == hal::CaptureEvent::kFailing) {
      failing_since = retry.stats();
      capture_failing_.store(true, std::memory_order_relaxed);
      log().log(LogLevel::kWarning, "capture: failing (%s); retrying with backoff from %" PRId64 " ms",
                errorCodeName(step.error), config_.camera.retry_initial_ms);
    } else if (step.event == hal::CaptureEvent::kRecovered) {
      capture_failing_.store(false, std::memory_order_relaxed);
      const hal::CaptureRetryStats& now_stats = retry.stats();
      log().log(LogLevel::kNotice, "capture: recovered after %" PRIu64 " failed acquires and %" PRIu64 " reopens",
                now_stats.acquire_failures - failing_since.acquire_failures, now_stats.reopens - failing_since.reopens);
    }
    switch (step.action) {
      case hal::CaptureAction::kFrame:
        // The pose at the frame's capture stamp; a stale one keeps the frame
        // with the nearest pose and raises the fault (docs/pose.md).
        f.pose_fresh = pose_source_->apply(f.frame);
        pose_stale_.store(!f.pose_fresh, std::memory_order_relaxed);
        f.captured_ns = monotonicNs();
        f.acquire_ns = f.captured_ns - t0;
        if (recorder_) recorder_->onCapture(f.frame);  // --record-frames: a copy into its ring, or a counted drop
        capture_latency_.add(f.acquire_ns);
        last_frame_ns_.store(f.captured_ns, std::memory_order_relaxed);
        ring.publish(slot);
        continue;
      case hal::CaptureAction::kAcquireFailed:
      case hal::CaptureAction::kReopenFailed:
        capture_errors_.fetch_add(1, std::memory_order_relaxed);
        (void)log().logLimited(capture_site, LogLevel::kWarning, "capture: %s %s",
                               step.action == hal::CaptureAction::kReopenFailed ? "reopen failed:" : "acquire failed:",
                               errorCodeName(step.error));
        break;
      case hal::CaptureAction::kReopened:
        log().log(LogLevel::kNotice, "capture: camera reopened");
        break;
      case hal::CaptureAction::kWait:
        break;
    }
    ring.cancel(slot);
    // Wait for the next attempt in short sleeps, so a stop is never held up.
    while (running_.load(std::memory_order_relaxed)) {
      const int64_t left = step.next_ns - monotonicNs();
      if (left <= 0) break;
      sleepNs(std::min<int64_t>(left, 10'000'000));
    }
  }
  // After the last publish: the foveation stage drains what is queued, then ends.
  capture_alive_.store(false, std::memory_order_release);
}

// ---- foveation ----

void Service::foveationLoop() {
  placeThread("fovea-foveate", config_.runtime.foveation_thread);
  fovea::SlotRing& in_ring = frames_->ring();
  fovea::SlotRing& out_ring = foveated_->ring();
  for (;;) {
    // Read before tryTake: once the capture stage is seen done, every frame it
    // published is visible, so an empty ring means drained.
    const bool capture_done = !capture_alive_.load(std::memory_order_acquire);
    if (reload_to_foveation_.update()) {
      // Copies the configuration (allocates only if custom bounds outgrow the old ones).
      policy_->setOperatorConfig(reload_to_foveation_.current().foveation);
      stage_->invalidate();
      reloads_applied_.fetch_add(1, std::memory_order_relaxed);
    }
    (void)gaze_box_.update();
    fovea::SlotIndex in;
    if (!in_ring.tryTake(in)) {
      if (capture_done) break;
      sleepNs(kIdleSleepNs);
      continue;
    }
    fovea::SlotIndex out;
    if (!out_ring.tryAcquire(out)) {  // only if the send stage held more than it promised (a bug)
      (void)in_ring.release(in);
      foveate_errors_.fetch_add(1, std::memory_order_relaxed);
      continue;
    }
    CapturedFrame& f = frames_->slot(in);  // this stage's while taken: tracking sets its pose
    FoveatedFrame& o = foveated_->slot(out);
    const Status s = foveateFrame(f, o, out);
    if (!s) {
      (void)in_ring.release(in);
      out_ring.cancel(out);
      countFoveationError(s, o);
      continue;
    }
    // The recording's per-frame channels: the frame's pose and points are here.
    // It reads the captured frame, so the slot goes back to the capture stage
    // only after it (released first, the capture stage could refill the slot
    // while the recorder copied it).
    if (recorder_) {
      recorder_->onFrame(o.frame_id, f.captured_ns, f.frame, f.pose_fresh, o.cloud,
                         tracking_ ? &stage_->mapFigures().track : nullptr);
    }
    (void)in_ring.release(in);
    o.foveated_ns = monotonicNs();
    foveate_latency_.add(o.foveated_ns - o.foveation_start_ns);
    frames_foveated_.fetch_add(1, std::memory_order_relaxed);
    if (o.stats.coarsened > 0) frames_coarsened_.fetch_add(1, std::memory_order_relaxed);
    out_ring.publish(out);
  }
  foveation_alive_.store(false, std::memory_order_release);
}

Status Service::foveateFrame(CapturedFrame& f, FoveatedFrame& o, fovea::SlotIndex out) {
  if (bricks_ && bricks_->ownedBy(out)) {  // the ring dropped the frame before the send stage took it
    stage_->forgetBatch(bricks_->batch());
    bricks_->takeBack();
  }
  const int64_t t0 = monotonicNs();
  pipeline::BackprojectCounts counts;
  Status s = stage_->backproject(f.frame, counts, f.pose_fresh);  // with tracking, it poses the frame first
  if (tracking_) publishTracking();
  o.backproject_ns = monotonicNs() - t0;
  if (stage_->map() != nullptr) publishMapFigures();
  GazePolicy::Decision decision;
  if (s) {
    decision = decideGaze(f.frame);
    s = stage_->use(decision.foveation);
  }
  if (s) s = stage_->foveate(decision.gaze, o.cloud, o.stats);
  if (s && map_bricks_) s = planFrameBricks(decision.gaze, o, out);
  o.gaze_stamp_ns = decision.source == GazeSource::kOperator ? gaze_box_.current().stamp_ns : 0;
  o.frame_id = static_cast<uint32_t>(f.frame.sequence);
  o.captured_ns = f.captured_ns;
  o.acquire_ns = f.acquire_ns;
  o.foveation_start_ns = t0;
  return s;
}

GazePolicy::Decision Service::decideGaze(const hal::RgbdFrame& frame) {
  // The newest gaze after the back-projection, not from before it: fusing a
  // frame into the map takes tens of milliseconds, the gaze timeout is 100,
  // and the operator's eye may have moved meanwhile.
  (void)gaze_box_.update();
  const GazePolicy::Decision decision = policy_->decide(gaze_box_.current(), monotonicNs(), frame.T_world_cam);
  // Logged where it is decided: the policy reports a change once, and a frame
  // that then fails (over capacity, say) would otherwise lose it for good.
  if (decision.changed) {
    const std::string_view name = gazeSourceName(decision.source);
    log().log(LogLevel::kInfo, "gaze: %.*s", static_cast<int>(name.size()), name.data());
  }
  return decision;
}

// The map's bricks for the frame: what the operator was found to lack is
// forgotten first, then the planner fills the frame's share of the budget into
// the batch, which the frame's slot then owns. While the send stage still
// encodes the last batch the frame goes without (counted); the next plan's
// window then spans both frames.
Status Service::planFrameBricks(const pipeline::Gaze& gaze, FoveatedFrame& o, fovea::SlotIndex out) {
  if (brick_feedback_) {
    brick_feedback_->drain([&](std::size_t brick) { stage_->forgetBrick(static_cast<uint16_t>(brick)); },
                           [&] { stage_->forgetAllBricks(); });
    brick_feedback_->drainTooLarge([&](std::size_t brick) { stage_->brickTooLarge(static_cast<uint16_t>(brick)); });
  }
  o.bricks_deferred = !bricks_->available();
  if (o.bricks_deferred) {
    brick_plans_deferred_.fetch_add(1, std::memory_order_relaxed);
    o.send_window_ns = period_ns_;
    return Status::ok();
  }
  // The frame's share of the budget is the time since the last frame's, not
  // the camera's period: fusing a large frame can take longer than that, and
  // the link would idle between frames (at most four periods' worth).
  const int64_t now = monotonicNs();
  o.send_window_ns = last_plan_ns_ > 0 ? std::clamp(now - last_plan_ns_, period_ns_, 4 * period_ns_) : period_ns_;
  last_plan_ns_ = now;
  const double budget = static_cast<double>(brick_budget_bytes_per_s_.load(std::memory_order_relaxed)) *
                        static_cast<double>(o.send_window_ns) * 1e-9;
  pipeline::map::BrickBatch& batch = bricks_->batch();
  const Status s =
      stage_->planBricks(gaze, budget, static_cast<double>(o.cloud.size()) * kWireBytesPerPointEstimate, batch);
  if (!s) {
    stage_->forgetBatch(batch);
    return s;
  }
  const MapFrameFigures& figures = stage_->mapFigures();
  bricks_planned_.fetch_add(figures.plan.bricks_planned, std::memory_order_relaxed);
  o.bricks_waiting = figures.plan.bricks_waiting;
  o.fovea_bricks_waiting = figures.plan.fovea_bricks_waiting;
  if (!batch.entries().empty()) bricks_->lend(out);
  return s;
}

void Service::countFoveationError(const Status& s, const FoveatedFrame& o) {
  static LogRateLimit foveate_site;
  foveate_errors_.fetch_add(1, std::memory_order_relaxed);
  if (s.code() == ErrorCode::kCapacityExceeded) {
    // More voxels or output points than the configuration allows: the frame
    // is dropped and counted (the status line's "over capacity").
    frames_over_capacity_.fetch_add(1, std::memory_order_relaxed);
    (void)log().logLimited(foveate_site, LogLevel::kWarning,
                           "foveation: %s (frame dropped; pipeline.max_voxels %zu, pipeline.max_output_points %zu%s)",
                           s.toString().c_str(), stage_->foveator().capacity().max_voxels, o.cloud.points.capacity(),
                           live_points_capped_ ? ", both at most map.max_live_points with the map's bricks" : "");
  } else {
    (void)log().logLimited(foveate_site, LogLevel::kWarning, "foveation: %s", s.toString().c_str());
  }
}

void Service::publishTracking() {
  const pipeline::map::TrackStats& t = stage_->mapFigures().track;
  track_ns_.store(t.track_ns, std::memory_order_relaxed);
  if (t.model_ns > 0) model_ns_.store(t.model_ns, std::memory_order_relaxed);  // frames fused only
  if (t.outcome == pipeline::map::TrackOutcome::kLost) {
    tracking_lost_reason_.store(static_cast<uint8_t>(t.lost_reason), std::memory_order_relaxed);
    frames_track_lost_.fetch_add(1, std::memory_order_relaxed);
    tracking_lost_.store(true, std::memory_order_relaxed);
    return;
  }
  if (t.outcome == pipeline::map::TrackOutcome::kRelocalised) frames_relocalised_.fetch_add(1, std::memory_order_relaxed);
  frames_tracked_.fetch_add(1, std::memory_order_relaxed);
  prior_disagreement_m_.store(t.prior_disagreement_m, std::memory_order_relaxed);
  moving_share_.store(t.moving_share, std::memory_order_relaxed);
  tracking_lost_.store(false, std::memory_order_relaxed);
}

// The map's figures after a frame: this frame's fusion, or with a fusion
// thread the last it finished; the counters as the map has them now.
void Service::publishMapFigures() {
  const MapFrameFigures& figures = stage_->mapFigures();
  if (figures.fused()) fuse_latency_.add(figures.fuse.fuse_ns);
  if (figures.live.stride > 1) map_live_thinned_.fetch_add(1, std::memory_order_relaxed);
  pipeline::map::MapperFrame fused;
  if (stage_->takeFused(fused) && fused.fused()) {
    fuse_latency_.add(fused.fuse.fuse_ns);
    if (fused.track.model_ns > 0) model_ns_.store(fused.track.model_ns, std::memory_order_relaxed);
  }
  map_fusion_skipped_.store(stage_->fusionSkipped(), std::memory_order_relaxed);
  const pipeline::map::MapperStatus status = stage_->mapStatus();
  const pipeline::map::SurfelMapCounters& c = status.counters;
  map_fusion_busy_.store(status.fusion_busy, std::memory_order_relaxed);
  map_surfels_.store(status.surfels, std::memory_order_relaxed);
  map_frames_fused_.store(c.frames_fused, std::memory_order_relaxed);
  map_refused_no_pose_.store(c.refused_no_pose, std::memory_order_relaxed);
  map_refused_other_.store(c.refused() - c.refused_no_pose, std::memory_order_relaxed);
  map_evicted_.store(c.evicted, std::memory_order_relaxed);
  map_dropped_.store(c.dropped_full, std::memory_order_relaxed);
  map_bricks_reused_.store(c.bricks_reused, std::memory_order_relaxed);
  // A full table gives its empty bricks to new places; with none empty (or
  // all the operator's still) new places go unmapped: said once, the counts
  // on the stop line.
  if (c.dropped_no_brick > 0 && map_dropped_no_brick_.exchange(c.dropped_no_brick, std::memory_order_relaxed) == 0) {
    log().log(LogLevel::kWarning,
              "map: the brick table is full (map.max_bricks = %zu) and none of its bricks is free: surfaces outside "
              "them are not mapped until one empties",
              config_.map.map.max_bricks);
  }
}

// ---- map (map.fusion_thread) ----

// Fuses each frame the foveation stage hands over, until that stage ended and
// nothing waits.
void Service::mapLoop() {
  placeThread("fovea-map", config_.runtime.map_thread);
  for (;;) {
    const bool foveation_done = !foveation_alive_.load(std::memory_order_acquire);
    if (stage_->fuseSubmitted()) continue;
    if (foveation_done) break;
    sleepNs(kIdleSleepNs);
  }
}

// ---- send ----

void Service::sendLoop() {
  placeThread("fovea-send", config_.runtime.send_thread);
  fovea::SlotRing& ring = foveated_->ring();
  if (streamer_) {
    streamer_->setPollHook([](void* service) { static_cast<Service*>(service)->publishOperatorGaze(); }, this);
    if (bricks_) {
      streamer_->setBricksDoneHook(
          [](void* service) {
            auto* self = static_cast<Service*>(service);
            (void)self->bricks_->giveBack(self->sending_slot_);
          },
          this);
    }
  }
  int64_t next_report_ns = monotonicNs() + 1'000'000'000;
  for (;;) {
    const bool foveation_done = !foveation_alive_.load(std::memory_order_acquire);
    if (streamer_) pollOperator();
    fovea::SlotIndex slot;
    if (!ring.tryTake(slot)) {
      if (foveation_done) break;  // drained
      if (streamer_) {
        streamer_->idleUntil(monotonicNs() + kIdleSleepNs);
      } else {
        sleepNs(kIdleSleepNs);
      }
      continue;
    }
    FoveatedFrame& f = foveated_->slot(slot);
    const pipeline::map::BrickBatch* bricks = bricks_ && bricks_->ownedBy(slot) ? &bricks_->batch() : nullptr;
    if (!streamer_) {
      frames_unsent_.fetch_add(1, std::memory_order_relaxed);
      if (bricks && brick_feedback_) {
        for (const pipeline::map::BrickBatchEntry& e : bricks->entries()) brick_feedback_->forget(e.brick);
      }
    } else if (!stream_allowed_.load(std::memory_order_relaxed)) {
      frames_withheld_.fetch_add(1, std::memory_order_relaxed);  // privacy: captured, never sent
      if (bricks) streamer_->discardBricks(*bricks);
    } else {
      sendToOperator(f, slot, bricks);
    }
    if (bricks) (void)bricks_->giveBack(slot);  // sendFrame's hook gave it back already if it ran
    if (!ring.release(slot)) foveate_errors_.fetch_add(1, std::memory_order_relaxed);
    if (streamer_) {
      publishOperatorGaze();
      next_report_ns = sendStatusReportWhenDue(next_report_ns);
    }
  }
}

void Service::pollOperator() {
  if (reload_to_send_.update()) {
    const uint64_t budget = reload_to_send_.current().budget_bytes_per_s;
    if (Status s = streamer_->setBudgetCap(budget, monotonicNs()); !s) {
      log().log(LogLevel::kError, "reload: budget: %s", s.message().c_str());
    }
  }
  streamer_->poll();
  publishOperatorGaze();
  if (map_bricks_) {
    brick_budget_bytes_per_s_.store(streamer_->sessionBudgetBytesPerS(), std::memory_order_relaxed);
    // Acknowledgements arrive between frames too.
    bricks_in_flight_.store(streamer_->bricksInFlight(), std::memory_order_relaxed);
  }
}

void Service::sendToOperator(FoveatedFrame& f, fovea::SlotIndex slot, const pipeline::map::BrickBatch* bricks) {
  static LogRateLimit send_site;
  const int64_t t0 = monotonicNs();
  // A frame must be out before the next one is due; what is not goes unsent
  // (brick parts are kept and resent). With the map's bricks the next frame is
  // due a window after this one's plan (the foveation stage's pace).
  const int64_t window_ns = map_bricks_ ? f.send_window_ns : period_ns_;
  const int64_t deadline_ns = t0 + window_ns - std::min<int64_t>(window_ns / 10, 2'000'000);
  sending_slot_ = slot;
  Result<FrameSendReport> sent =
      streamer_->sendFrame(f.cloud, f.stats, f.frame_id, f.captured_ns, deadline_ns, period_ns_, bricks);
  if (!sent) {
    (void)log().logLimited(send_site, LogLevel::kWarning, "send: %s", sent.status().toString().c_str());
  } else if (sent->had_session) {
    send_latency_.add(monotonicNs() - t0);
    frames_sent_.fetch_add(1, std::memory_order_relaxed);
    if (timing_log_) logTiming(f, t0, sent.value());
  } else {
    frames_unsent_.fetch_add(1, std::memory_order_relaxed);
  }
  publishSendCounters(f);
  if (sent && sent->fovea_completed && !f.bricks_deferred) {
    sent_gaze_stamp_ns_.store(f.gaze_stamp_ns, std::memory_order_release);
  }
}

void Service::publishSendCounters(const FoveatedFrame& f) {
  wire_bytes_.store(streamer_->link().counters().bytes_sent, std::memory_order_relaxed);
  if (const net::BrickSenderCounters* bc = streamer_->brickCounters()) {
    brick_versions_.store(bc->versions, std::memory_order_relaxed);
    brick_parts_.store(bc->parts, std::memory_order_relaxed);
    brick_resends_.store(bc->resends, std::memory_order_relaxed);
    brick_versions_done_.store(bc->versions_done, std::memory_order_relaxed);
    brick_versions_lost_.store(bc->versions_lost, std::memory_order_relaxed);
    brick_acks_unknown_.store(bc->acks_unknown, std::memory_order_relaxed);
    bricks_unstaged_.store(streamer_->bricksUnstaged(), std::memory_order_relaxed);
    bricks_too_large_.store(streamer_->bricksTooLarge(), std::memory_order_relaxed);
    if (!f.bricks_deferred) {  // a deferred frame's plan is the last frame's
      bricks_waiting_.store(f.bricks_waiting, std::memory_order_relaxed);
      fovea_bricks_waiting_.store(f.fovea_bricks_waiting, std::memory_order_relaxed);
    }
    bricks_in_flight_.store(streamer_->bricksInFlight(), std::memory_order_relaxed);
  }
}

int64_t Service::sendStatusReportWhenDue(int64_t next_report_ns) {
  const int64_t now = monotonicNs();
  if (now < next_report_ns) return next_report_ns;
  const uint64_t captured = frames_->ring().counters().published;
  net::StatusReport report =
      streamer_->statusReport(captured, frames_sent_.load(std::memory_order_relaxed),
                              frames_->ring().counters().dropped + foveated_->ring().counters().dropped, now);
  streamer_->sendStatus(report);
  return next_report_ns + 1'000'000'000 * ((now - next_report_ns) / 1'000'000'000 + 1);
}

void Service::publishOperatorGaze() {
  OperatorGaze gaze;
  const bool valid = streamer_->operatorGaze(gaze);
  const int64_t received_ns = gaze.received_ns;
  if (valid != sent_gaze_valid_ || (valid && received_ns != sent_gaze_received_ns_)) {
    gaze_box_.writeBuffer() = gaze;
    gaze_box_.publish();
    sent_gaze_valid_ = valid;
    sent_gaze_received_ns_ = received_ns;
    gaze_received_ns_.store(valid ? received_ns : 0, std::memory_order_relaxed);
  }
  operator_connected_.store(streamer_->link().hasSession(), std::memory_order_relaxed);
}

void Service::logTiming(const FoveatedFrame& f, int64_t send_start_ns, const FrameSendReport& sent) {
  // Microseconds as integers: integer formatting never allocates.
  const auto us = [](int64_t ns) { return ns / 1000; };
  const pipeline::FoveationStats& st = f.stats;
  std::fprintf(timing_log_.get(),
               "%u,%" PRId64 ",%" PRId64 ",%" PRId64 ",%" PRId64 ",%" PRId64 ",%" PRId64 ",%" PRId64 ",%" PRId64
               ",%" PRId64 ",%" PRId64 ",%u,%u,%" PRIu64 ",%d\n",
               f.frame_id, f.captured_ns, us(f.acquire_ns), us(f.foveation_start_ns - f.captured_ns),
               us(f.backproject_ns), us(st.partition_ns), us(st.fixation_ns + st.sample_ns),
               us(send_start_ns - f.foveated_ns), us(sent.encode_ns), us(sent.send_ns),
               us(monotonicNs() - f.captured_ns), st.points_out, sent.chunks_sent, sent.bytes_sent,
               sent.completed ? 1 : 0);
}

}  // namespace fovea::firmware
