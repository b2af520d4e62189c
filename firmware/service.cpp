// The service's life: create() (configuration checks, the camera, the GPIO
// chip, then allocate()), start(), stop() with its drain and summary, and
// stats(). The rest of Service lives by concern: service_memory.cpp (the memory
// plan), service_stages.cpp (the stage threads), service_supervisor.cpp (the
// supervisor, reloads), service_status.cpp (the status line).
#include "firmware/service.h"

#include <sys/mman.h>

#include <cerrno>
#include <cinttypes>
#include <cstring>
#include <utility>

#include "core/clock.h"
#include "firmware/camera_setup.h"
#include "firmware/mcap_camera.h"

namespace fovea::firmware {

Result<std::unique_ptr<Service>> Service::create(const ServiceConfig& config, Environment environment) {
  using R = Result<std::unique_ptr<Service>>;
  const RuntimeSettings& rt = config.runtime;
  if (rt.ring_depth < 1 || rt.ring_depth > 64) {
    return R(ErrorCode::kInvalidArgument, "runtime.ring_depth = " + std::to_string(rt.ring_depth) + ": must be within 1 .. 64");
  }
  if (rt.status_interval_ms < 10) {
    return R(ErrorCode::kInvalidArgument, "runtime.status_interval_ms: must be at least 10");
  }
  for (const ThreadPlacement* p : {&rt.capture_thread, &rt.foveation_thread, &rt.send_thread, &rt.map_thread}) {
    if (p->realtime_priority < 0 || p->realtime_priority > 99) {
      return R(ErrorCode::kInvalidArgument, "runtime.*_thread.realtime_priority: must be within 0 .. 99");
    }
    if (p->nice < -20 || p->nice > 19) {
      return R(ErrorCode::kInvalidArgument, "runtime.*_thread.nice: must be within -20 .. 19");
    }
  }
  if (Status s = config.camera.depth.validate(); !s) return s;
  const std::size_t heap_before_camera = heapInUse();
  if (!environment.camera) {
    Result<std::unique_ptr<hal::Camera>> camera = createCamera(config.camera.spec);
    if (!camera) return R(camera.status().code(), "camera.spec: " + camera.status().message());
    environment.camera = std::move(camera.value());
  }
  // Calibration before open(): the camera uses it from then on.
  Result<std::string> calibrated = applyCameraCalibration(*environment.camera, config.camera);
  if (!calibrated) return calibrated.status();
  Result<std::unique_ptr<hal::PoseSource>> pose_source = createPoseSource(config.camera);
  if (!pose_source) return pose_source.status();
  if (Status s = environment.camera->open(); !s) {
    return R(s.code(), "camera " + environment.camera->info().name + ": " + s.message());
  }
  const std::size_t camera_bytes = heapGrowthSince(heap_before_camera);
  if (!environment.gpio) {
    Result<std::unique_ptr<hal::Gpio>> gpio = hal::createGpio(config.gpio.spec);
    if (!gpio) return R(gpio.status().code(), "gpio.spec: " + gpio.status().message());
    environment.gpio = std::move(gpio.value());
  }
  const double fps = environment.camera->info().fps;
  const int64_t period_ns = fps > 0 ? static_cast<int64_t>(1e9 / fps) : 33'333'333;
  std::unique_ptr<Service> service(new Service(config, std::move(environment), period_ns));
  service->memory_.add("camera backend", 1, camera_bytes);
  // Streaming buffers a device maps outside the heap (V4L2 mmap) are memory too.
  if (const std::size_t mapped = service->camera_->info().device_buffer_bytes; mapped > 0) {
    service->memory_.add("camera device buffers (mapped)", 1, mapped);
  }
  service->pose_source_ = std::move(pose_source.value());
  if (!calibrated->empty()) service->log().log(LogLevel::kInfo, "camera: %s", calibrated->c_str());
  service->log().log(LogLevel::kInfo, "pose: %s", describePose(config.camera, *service->pose_source_).c_str());
  if (Status s = service->allocate(); !s) return s;
  service->log().log(LogLevel::kInfo, "%s", service->memory_.summary().c_str());
  return service;
}

Service::Service(const ServiceConfig& config, Environment environment, int64_t period_ns)
    : config_(config),
      camera_(std::move(environment.camera)),
      gpio_(std::move(environment.gpio)),
      reloader_(std::move(environment.reloader)),
      logger_(environment.logger ? environment.logger : &firmware::logger()),
      period_ns_(period_ns),
      stall_timeout_ns_(config.camera.stall_timeout_ms > 0 ? config.camera.stall_timeout_ms * 1'000'000
                                                           : 3 * period_ns) {}

Service::~Service() { stop(); }

net::Endpoint Service::localEndpoint() const { return streamer_ ? streamer_->localEndpoint() : net::Endpoint{}; }

Status Service::start() {
  if (Status s = status_lines_->start(); !s) return {s.code(), "gpio: " + s.message()};
  if (config_.runtime.memory_lock) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
      log().log(LogLevel::kWarning, "memory: mlockall refused (%s): running unlocked", std::strerror(errno));
    } else {
      log().log(LogLevel::kInfo, "memory: locked (mlockall)");
    }
  }
  if (Status s = camera_->start(); !s) {
    status_lines_->stop();
    return {s.code(), "camera " + camera_->info().name + ": " + s.message()};
  }
  if (recorder_) {
    if (Status s = recorder_->start(); !s) {
      camera_->stop();
      status_lines_->stop();
      return s;
    }
    log().log(LogLevel::kInfo, "recording to %s", recorder_->path().c_str());
  }
  startUsbMonitor();
  started_ns_ = monotonicNs();
  last_frame_ns_.store(started_ns_, std::memory_order_relaxed);  // start-up counts as fresh
  next_status_ns_ = started_ns_ + config_.runtime.status_interval_ms * 1'000'000;
  next_watchdog_ns_ = started_ns_;
  window_.at_ns = started_ns_;
  capture_alive_.store(true, std::memory_order_relaxed);
  foveation_alive_.store(true, std::memory_order_relaxed);
  running_.store(true, std::memory_order_release);
  threads_.emplace_back([this] { captureLoop(); });
  threads_.emplace_back([this] { foveationLoop(); });
  threads_.emplace_back([this] { sendLoop(); });
  if (stage_->fusionThread()) threads_.emplace_back([this] { mapLoop(); });
  if (config_.runtime.systemd_notify) notifier_.notify("READY=1");
  return Status::ok();
}

void Service::stop() {
  if (stopped_) return;
  stopped_ = true;
  const bool was_running = running_.exchange(false, std::memory_order_acq_rel);
  if (was_running && config_.runtime.systemd_notify) notifier_.notify("STOPPING=1");
  for (std::thread& t : threads_) t.join();
  threads_.clear();
  if (usb_monitor_) usb_monitor_->stop();
  if (was_running) camera_->stop();
  streamer_.reset();  // says Bye to the operator
  if (timing_log_) std::fflush(timing_log_.get());
  if (recorder_) {
    // Every thread that feeds it has ended: drain, summary, footer.
    const Status closed = recorder_->close();
    log().log(closed ? LogLevel::kInfo : LogLevel::kError, "%s%s%s", recorder_->summary().c_str(),
              closed ? "" : "; the file is readable up to its last complete chunk: ",
              closed ? "" : closed.message().c_str());
  }
  if (status_lines_) status_lines_->stop();
  if (was_running) {
    const ServiceStats s = stats();
    log().log(LogLevel::kInfo,
              "stopped: %" PRIu64 " frames captured, %" PRIu64 " foveated, %" PRIu64 " sent, %" PRIu64
              " withheld (privacy); drops capture %" PRIu64 " foveation %" PRIu64 "; %" PRIu64 " reloads applied",
              s.frames_captured, s.frames_foveated, s.frames_sent, s.frames_withheld, s.capture_ring.dropped,
              s.foveation_ring.dropped, s.reloads_applied);
    if (stage_->map() != nullptr) {
      log().log(LogLevel::kInfo,
                "map: %" PRIu64 " surfels from %" PRIu64 " fused frames; %" PRIu64 " evicted; %" PRIu64
                " new surfels dropped (%" PRIu64 " for want of a brick); %" PRIu64 " empty bricks reused; refused %" PRIu64
                " frames without a pose, %" PRIu64 " for another reason",
                s.map.surfels, s.map.frames_fused, s.map.evicted, s.map.dropped, s.map.dropped_no_brick,
                s.map.bricks_reused, s.map.refused_no_pose, s.map.refused_other);
      if (stage_->fusionThread()) {
        log().log(LogLevel::kInfo,
                  "map: fused on its own thread; %" PRIu64 " frames left unfused while it was busy (sent without what "
                  "the last fused view explained)",
                  s.map.fusion_busy);
      }
      if (stage_->hasFusionBudget()) {
        log().log(LogLevel::kInfo,
                  "map: %" PRIu64 " frames left unfused by map.fuse_budget_ms (sent without what the last fused "
                  "view explained)",
                  s.map.unfused);
      }
      if (map_bricks_) {
        log().log(LogLevel::kInfo,
                  "map: %" PRIu64 " frames' live points thinned to fit their cloud (a grid of pixels outside the "
                  "eye's cone, or inside it too when the operator holds little: the map's first frames, turns "
                  "into unmapped space, a new session)",
                  s.map.live_thinned);
        log().log(LogLevel::kInfo,
                  "map bricks: %" PRIu64 " planned; %" PRIu64 " versions in %" PRIu64 " parts sent, %" PRIu64
                  " parts resent; %" PRIu64 " versions acknowledged whole, %" PRIu64 " lost (sent again); %" PRIu64
                  " acknowledgements for nothing in flight; %" PRIu64
                  " not staged (due again), %" PRIu64
                  " of them with more parts than a version may have (due a level coarser), the rest for lack of room"
                  " this frame; %" PRIu64
                  " frames planned while the last frame's bricks were still being encoded (due next frame)",
                  s.map.bricks_planned, s.map.brick_versions, s.map.brick_parts, s.map.brick_resends,
                  s.map.brick_versions_done, s.map.brick_versions_lost, s.map.brick_acks_unknown, s.map.bricks_unstaged,
                  s.map.bricks_too_large, s.map.brick_plans_deferred);
      }
    }
  }
}

ServiceStats Service::stats() const {
  ServiceStats s;
  s.capture_ring = frames_->ring().counters();
  s.foveation_ring = foveated_->ring().counters();
  s.frames_captured = s.capture_ring.published;
  s.capture_errors = capture_errors_.load(std::memory_order_relaxed);
  s.frames_foveated = frames_foveated_.load(std::memory_order_relaxed);
  s.foveate_errors = foveate_errors_.load(std::memory_order_relaxed);
  s.frames_over_capacity = frames_over_capacity_.load(std::memory_order_relaxed);
  s.frames_coarsened = frames_coarsened_.load(std::memory_order_relaxed);
  s.frames_sent = frames_sent_.load(std::memory_order_relaxed);
  s.frames_withheld = frames_withheld_.load(std::memory_order_relaxed);
  s.frames_unsent = frames_unsent_.load(std::memory_order_relaxed);
  s.reloads_requested = reloads_requested_.load(std::memory_order_relaxed);
  s.reloads_applied = reloads_applied_.load(std::memory_order_relaxed);
  s.reload_failures = reload_failures_.load(std::memory_order_relaxed);
  s.watchdog_keepalives = watchdog_keepalives_.load(std::memory_order_relaxed);
  s.status_lines = status_lines_written_.load(std::memory_order_relaxed);
  s.wire_bytes = wire_bytes_.load(std::memory_order_relaxed);
  s.operator_connected = operator_connected_.load(std::memory_order_relaxed);
  s.heartbeat_toggles = heartbeat_toggles_.load(std::memory_order_relaxed);
  s.streaming_line = streaming_line_.load(std::memory_order_relaxed);
  s.fault_line = fault_line_.load(std::memory_order_relaxed);
  s.privacy_active = privacy_active_.load(std::memory_order_relaxed);
  if (usb_monitor_) s.usb = usb_monitor_->counters();
  s.pose = pose_source_->counters();
  s.pose_stale = pose_stale_.load(std::memory_order_relaxed);
  s.tracking.enabled = tracking_;
  s.tracking.lost = tracking_lost_.load(std::memory_order_relaxed);
  s.tracking.tracked = frames_tracked_.load(std::memory_order_relaxed);
  s.tracking.lost_frames = frames_track_lost_.load(std::memory_order_relaxed);
  s.tracking.relocalised = frames_relocalised_.load(std::memory_order_relaxed);
  s.tracking.prior_disagreement_m = prior_disagreement_m_.load(std::memory_order_relaxed);
  s.tracking.moving_share = moving_share_.load(std::memory_order_relaxed);
  s.map.surfels = map_surfels_.load(std::memory_order_relaxed);
  s.map.frames_fused = map_frames_fused_.load(std::memory_order_relaxed);
  s.map.refused_no_pose = map_refused_no_pose_.load(std::memory_order_relaxed);
  s.map.refused_other = map_refused_other_.load(std::memory_order_relaxed);
  s.map.evicted = map_evicted_.load(std::memory_order_relaxed);
  s.map.dropped = map_dropped_.load(std::memory_order_relaxed);
  s.map.dropped_no_brick = map_dropped_no_brick_.load(std::memory_order_relaxed);
  s.map.bricks_reused = map_bricks_reused_.load(std::memory_order_relaxed);
  s.map.unfused = map_fusion_skipped_.load(std::memory_order_relaxed);
  s.map.fusion_busy = map_fusion_busy_.load(std::memory_order_relaxed);
  s.map.live_thinned = map_live_thinned_.load(std::memory_order_relaxed);
  s.map.bricks_planned = bricks_planned_.load(std::memory_order_relaxed);
  s.map.brick_versions = brick_versions_.load(std::memory_order_relaxed);
  s.map.brick_parts = brick_parts_.load(std::memory_order_relaxed);
  s.map.brick_resends = brick_resends_.load(std::memory_order_relaxed);
  s.map.brick_versions_done = brick_versions_done_.load(std::memory_order_relaxed);
  s.map.brick_versions_lost = brick_versions_lost_.load(std::memory_order_relaxed);
  s.map.brick_acks_unknown = brick_acks_unknown_.load(std::memory_order_relaxed);
  s.map.bricks_unstaged = bricks_unstaged_.load(std::memory_order_relaxed);
  s.map.bricks_too_large = bricks_too_large_.load(std::memory_order_relaxed);
  s.map.brick_plans_deferred = brick_plans_deferred_.load(std::memory_order_relaxed);
  s.sent_gaze_stamp_ns = sent_gaze_stamp_ns_.load(std::memory_order_acquire);
  s.map.bricks_waiting = bricks_waiting_.load(std::memory_order_relaxed);
  s.map.fovea_bricks_waiting = fovea_bricks_waiting_.load(std::memory_order_relaxed);
  s.map.bricks_in_flight = bricks_in_flight_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace fovea::firmware
