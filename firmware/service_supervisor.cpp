// The service's supervisor, the thread that calls run(): every few ms it drives
// the status GPIO lines from the stages' health, logs what changed, keeps
// systemd's watchdog fed and writes the status line; it applies SIGHUP's
// reloads and watches USB hot-plug.
#include "firmware/service.h"

#include <cinttypes>

#include "core/clock.h"
#include "firmware/options.h"
#include "firmware/sleep_ns.h"

namespace fovea::firmware {

namespace {

constexpr int64_t kSuperviseEveryNs = 5'000'000;  // status lines, watchdog, signals

}  // namespace

void Service::run(uint64_t max_frames, int64_t max_duration_ns) {
  const int64_t end_ns = max_duration_ns > 0 ? monotonicNs() + max_duration_ns : INT64_MAX;
  max_frames_.store(max_frames, std::memory_order_relaxed);
  while (!stop_requested_.load(std::memory_order_acquire)) {
    const int64_t now = monotonicNs();
    if (now >= end_ns) break;
    // The capture stage ends itself after max_frames; stop() drains the rest.
    if (max_frames > 0 && !capture_alive_.load(std::memory_order_acquire)) break;
    if (reload_requested_.exchange(false, std::memory_order_acquire)) applyReload();
    supervise(now);
    sleepNs(kSuperviseEveryNs);
  }
  stop();
}

void Service::startUsbMonitor() {
  if (Status s = usb_monitor_->start(); !s) {
    log().log(LogLevel::kInfo, "usb: hot-plug of RGB-D cameras not watched: %s", s.message().c_str());
    return;
  }
  log().log(LogLevel::kInfo, "usb: watching arrivals and removals of %zu known RGB-D camera models",
            hal::usb::knownUsbCameras().size());
  if (!usb_monitor_->warning().empty()) log().log(LogLevel::kWarning, "usb: %s", usb_monitor_->warning().c_str());
  drainUsbEvents();  // the ones present at start
}

void Service::drainUsbEvents() {
  hal::usb::UsbEvent event;
  while (usb_monitor_->poll(event)) {
    char line[160];
    hal::usb::formatUsbEvent(event, line, sizeof line);
    log().log(event.kind == hal::usb::UsbEvent::Kind::kLeft ? LogLevel::kWarning : LogLevel::kNotice, "%s", line);
  }
}

void Service::supervise(int64_t now_ns) {
  drainUsbEvents();
  // Healthy: frames arrive (within the stall timeout) and the capture stage is not
  // retrying a failing camera.
  const bool frames_flow = now_ns - last_frame_ns_.load(std::memory_order_relaxed) <= stall_timeout_ns_;
  const bool capture_failing = capture_failing_.load(std::memory_order_relaxed);
  const bool healthy = frames_flow && !capture_failing;
  // A stale pose is a fault (the line, the status) but not unhealthy: systemd's
  // watchdog restarting fovead would not bring the robot's localisation back.
  const bool pose_stale = pose_stale_.load(std::memory_order_relaxed);
  const int64_t gaze_ns = gaze_received_ns_.load(std::memory_order_relaxed);
  StatusInputs inputs;
  inputs.healthy = healthy;
  inputs.operator_connected = operator_connected_.load(std::memory_order_relaxed);
  inputs.gaze_fresh = gaze_ns != 0 && now_ns - gaze_ns <= config_.stream.gaze.timeout_ns;
  // Tracking: a lost track is a fault; a stale outside pose is then only the
  // prior's absence (the tracker carries on), shown in the status line.
  const bool tracking_lost = tracking_lost_.load(std::memory_order_relaxed);
  inputs.fault = !healthy || (pose_stale && !tracking_) || tracking_lost;
  const bool was_privacy = status_lines_->state().privacy_active;
  const bool was_fault = status_lines_->state().fault;
  const StatusState& state = status_lines_->update(inputs, now_ns);
  publishStatusState(state);
  if (state.privacy_active != was_privacy) {
    log().log(LogLevel::kNotice, state.privacy_active ? "privacy input active: streaming paused (frames are captured, none sent)"
                                                     : "privacy input released: streaming resumes");
  }
  if (pose_stale != pose_was_stale_) {
    pose_was_stale_ = pose_stale;
    logPoseChange(pose_stale);
  }
  if (tracking_lost != tracking_was_lost_) {
    tracking_was_lost_ = tracking_lost;
    logTrackingChange(tracking_lost);
  }
  if (state.fault != was_fault) logFaultChange(state.fault, healthy, frames_flow, pose_stale, now_ns);
  keepWatchdogAlive(healthy, now_ns);
  if (now_ns >= next_status_ns_) writeStatusLine(now_ns);
}

// The lines as just driven, for stats() and the stages (stream_allowed_).
void Service::publishStatusState(const StatusState& state) {
  stream_allowed_.store(state.stream_allowed, std::memory_order_relaxed);
  heartbeat_toggles_.store(status_lines_->counters().heartbeat_toggles, std::memory_order_relaxed);
  streaming_line_.store(state.streaming, std::memory_order_relaxed);
  fault_line_.store(state.fault, std::memory_order_relaxed);
  privacy_active_.store(state.privacy_active, std::memory_order_relaxed);
}

void Service::logPoseChange(bool pose_stale) {
  const hal::PoseCounters pc = pose_source_->counters();
  if (pose_stale && tracking_) {
    log().log(LogLevel::kWarning,
              "pose: the outside pose is stale (no pose within camera.pose.max_age_ms of the frame's stamp): "
              "the tracker goes on alone, without its prior");
  } else if (pose_stale) {
    log().log(LogLevel::kWarning,
              "fault: the pose is stale (no pose within camera.pose.max_age_ms of the frame's stamp; %" PRIu64
              " poses received, %" PRIu64 " malformed, %" PRIu64 " out of order): frames keep the nearest pose",
              pc.received, pc.malformed, pc.out_of_order);
  } else {
    log().log(LogLevel::kNotice, "pose fresh again (%" PRIu64 " frames had a stale pose)", pc.frames_stale);
  }
}

void Service::logTrackingChange(bool tracking_lost) {
  if (tracking_lost) {
    const std::string_view why =
        pipeline::map::lostReasonName(static_cast<pipeline::map::LostReason>(tracking_lost_reason_.load()));
    log().log(LogLevel::kWarning,
              "fault: pose LOST (tracking: %.*s): frames are not fused; relocalising against the map at the last good pose",
              static_cast<int>(why.size()), why.data());
  } else {
    log().log(LogLevel::kNotice, "pose tracked again (%" PRIu64 " frames were lost)",
              frames_track_lost_.load(std::memory_order_relaxed));
  }
}

void Service::logFaultChange(bool fault, bool healthy, bool frames_flow, bool pose_stale, int64_t now_ns) {
  if (fault && healthy) {
    // The pose's own line, logged just before (logPoseChange, logTrackingChange), says why.
  } else if (fault) {
    if (!frames_flow) {
      log().log(LogLevel::kWarning, "fault: no frame for %" PRId64 " ms (camera stalled); watchdog keep-alives stop",
                (now_ns - last_frame_ns_.load(std::memory_order_relaxed)) / 1'000'000);
    } else {
      log().log(LogLevel::kWarning, "fault: the camera fails (capture retrying); watchdog keep-alives stop");
    }
  } else {
    log().log(LogLevel::kNotice, "fault cleared: frames flow again%s", pose_stale ? "" : " (and the pose is fresh)");
  }
}

// WATCHDOG=1 every half of systemd's watchdog interval, only while healthy.
void Service::keepWatchdogAlive(bool healthy, int64_t now_ns) {
  if (config_.runtime.systemd_notify && healthy && notifier_.watchdogNs() > 0 && now_ns >= next_watchdog_ns_) {
    if (notifier_.notify("WATCHDOG=1")) watchdog_keepalives_.fetch_add(1, std::memory_order_relaxed);
    next_watchdog_ns_ = now_ns + notifier_.watchdogNs() / 2;
  }
}

void Service::applyReload() {
  reloads_requested_.fetch_add(1, std::memory_order_relaxed);
  if (!reloader_) {
    log().log(LogLevel::kWarning, "reload (SIGHUP): no configuration source to reload from; nothing changes");
    return;
  }
  Result<ServiceConfig> loaded = reloader_();
  if (!loaded) {
    reload_failures_.fetch_add(1, std::memory_order_relaxed);
    log().log(LogLevel::kError, "reload (SIGHUP): %s; the running configuration stays", loaded.status().message().c_str());
    return;
  }
  if (Result<pipeline::RegionModel> model = pipeline::RegionModel::create(loaded->foveation.acuity); !model) {
    reload_failures_.fetch_add(1, std::memory_order_relaxed);
    log().log(LogLevel::kError, "reload (SIGHUP): foveation: %s; the running configuration stays",
              model.status().message().c_str());
    return;
  }
  for (fovea::LatestValue<ReloadedParameters>* box : {&reload_to_foveation_, &reload_to_send_}) {
    ReloadedParameters& p = box->writeBuffer();
    p.foveation = loaded->foveation;
    p.budget_bytes_per_s = loaded->stream.link.max_budget_bytes_per_s;
    box->publish();
  }
  log().log(LogLevel::kNotice, "reload (SIGHUP): foveation %s, budget up to %.2f MB/s (from the next frame)",
            describeFoveation(loaded->foveation).c_str(),
            static_cast<double>(loaded->stream.link.max_budget_bytes_per_s) / 1e6);
}

}  // namespace fovea::firmware
