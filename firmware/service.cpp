#include "firmware/service.h"

#include <malloc.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <algorithm>
#include <cerrno>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <utility>

#include "core/clock.h"
#include "core/sanitizer.h"
#include "firmware/camera_setup.h"
#include "firmware/mcap_camera.h"
#include "firmware/options.h"
#include "hal/capture_retry.h"
#include "net/codec.h"
#include "net/key.h"

namespace fovea::firmware {

namespace {

constexpr int64_t kIdleSleepNs = 500'000;        // a stage with nothing to do
constexpr int64_t kSuperviseEveryNs = 5'000'000;  // status lines, watchdog, signals
constexpr auto kAcquireTimeout = std::chrono::milliseconds(200);  // bounds how long a stop waits for the camera
constexpr double kMiB = 1024.0 * 1024.0;

void sleepNs(int64_t ns) {
  const timespec pause{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
  nanosleep(&pause, nullptr);
}

// Bytes the C heap has handed out: the start-up phase measures each pool as the
// difference around its allocation (what the components really reserve,
// including their own bookkeeping, without asking each for a size method).
std::size_t heapInUse() {
#ifdef FOVEA_SANITIZER_ALLOCATOR
  // The sanitizer's allocator serves malloc; glibc's statistics would read zero.
  return __sanitizer_get_current_allocated_bytes();
#else
  const struct mallinfo2 m = mallinfo2();
  return m.uordblks + m.hblkhd;
#endif
}

std::size_t delta(std::size_t before, std::size_t after) { return after > before ? after - before : 0; }

// The nearest-rank quantile of the counts in [0, buckets), as the bucket's upper edge in ms; -1 when empty.
double histogramQuantileMs(const uint64_t* counts, std::size_t buckets, double q) {
  uint64_t total = 0;
  for (std::size_t i = 0; i < buckets; ++i) total += counts[i];
  if (total == 0) return -1.0;
  const auto rank = static_cast<uint64_t>(std::max(1.0, std::ceil(q * static_cast<double>(total))));
  uint64_t seen = 0;
  for (std::size_t i = 0; i < buckets; ++i) {
    seen += counts[i];
    if (seen >= rank) return static_cast<double>((i + 1) * LatencyHistogram::kBucketNs) * 1e-6;
  }
  return static_cast<double>(buckets * LatencyHistogram::kBucketNs) * 1e-6;
}

}  // namespace

// ---- MemoryBudget ----

void MemoryBudget::add(const char* name, std::size_t count, std::size_t bytes) {
  if (pool_count < kMaxPools) pools[pool_count++] = {name, count, bytes};
}

std::size_t MemoryBudget::totalBytes() const {
  std::size_t total = 0;
  for (std::size_t i = 0; i < pool_count; ++i) total += pools[i].bytes;
  return total;
}

std::string MemoryBudget::summary() const {
  char line[96];
  std::snprintf(line, sizeof line, "memory: %.1f MiB in %zu pools", static_cast<double>(totalBytes()) / kMiB,
                pool_count);
  return line;
}

std::string MemoryBudget::breakdown() const {
  std::string out;
  for (std::size_t i = 0; i < pool_count; ++i) {
    const MemoryPool& p = pools[i];
    char line[160];
    std::snprintf(line, sizeof line, "  %-42s %3zu x %8.3f MiB = %8.3f MiB\n", p.name, p.count,
                  p.count ? static_cast<double>(p.bytes) / static_cast<double>(p.count) / kMiB : 0.0,
                  static_cast<double>(p.bytes) / kMiB);
    out += line;
  }
  return out;
}

// ---- Service ----

Result<std::unique_ptr<Service>> Service::create(const ServiceConfig& config, Environment environment) {
  using R = Result<std::unique_ptr<Service>>;
  const RuntimeSettings& rt = config.runtime;
  if (rt.ring_depth < 1 || rt.ring_depth > 64) {
    return R(ErrorCode::kInvalidArgument, "runtime.ring_depth = " + std::to_string(rt.ring_depth) + ": must be within 1 .. 64");
  }
  if (rt.status_interval_ms < 10) {
    return R(ErrorCode::kInvalidArgument, "runtime.status_interval_ms: must be at least 10");
  }
  for (const ThreadPlacement* p : {&rt.capture_thread, &rt.foveation_thread, &rt.send_thread}) {
    if (p->realtime_priority < 0 || p->realtime_priority > 99) {
      return R(ErrorCode::kInvalidArgument, "runtime.*_thread.realtime_priority: must be within 0 .. 99");
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
  const std::size_t camera_bytes = delta(heap_before_camera, heapInUse());
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

Status Service::allocate() {
  const hal::CameraIntrinsics& k = camera_->info().intrinsics;
  const auto depth = static_cast<std::size_t>(config_.runtime.ring_depth);
  const std::size_t pixels = static_cast<std::size_t>(k.width) * static_cast<std::size_t>(k.height);
  pipeline::PipelineCapacity capacity = config_.pipeline;
  if (capacity.max_points < pixels) {
    return {ErrorCode::kInvalidArgument, "pipeline.max_points = " + std::to_string(capacity.max_points) + " is below the camera's " +
                                             std::to_string(k.width) + "x" + std::to_string(k.height) + " = " +
                                             std::to_string(pixels) + " pixels: raise pipeline.max_points"};
  }
  capacity.max_points = pixels;  // a frame has no more points than pixels
  capacity.max_voxels = std::min(capacity.max_voxels, pixels);

  std::size_t before = heapInUse();
  {
    CapturedFrame prototype{hal::RgbdFrame(k.width, k.height), 0};
    frames_ = std::make_unique<fovea::SlotPoolRing<CapturedFrame>>(depth, 1, prototype);
  }
  memory_.add("frame slots (RGB-D, capture -> foveation)", frames_->slotCount(), delta(before, heapInUse()));

  // The foveated output: the fovea whole and a point per voxel, at most
  // pipeline.max_output_points (0: the pixels). A preset that keeps every point
  // (FREF) needs the pixels; the map source foveates the map's surfels too, so
  // its clouds hold them (the map's memory on top of the frame's). The pyramid
  // source keeps the pixels too: at ACUITY's default margin it sends more points
  // than the voxel methods, and with the cap (0.35 of the pixels) the mock room's
  // scan lost 18 frames in 10 s as over capacity (toolchain/run-latency).
  std::size_t points = FrameFoveator::cloudCapacity(pixels, config_.map);
  if (config_.map.source == FoveationSource::kFrame && config_.foveation.acuity.preset != pipeline::Preset::kFRef &&
      config_.max_output_points > 0) {
    points = std::min(points, config_.max_output_points);
  }
  before = heapInUse();
  map_bricks_ = config_.map.source == FoveationSource::kMap && config_.map.delta;
  {
    FoveatedFrame prototype;
    prototype.cloud = pipeline::FoveatedCloud(points);
    if (map_bricks_) {
      prototype.bricks = pipeline::map::BrickBatch(config_.map.max_frame_brick_points, config_.map.max_frame_bricks);
    }
    foveated_ = std::make_unique<fovea::SlotPoolRing<FoveatedFrame>>(depth, 1, prototype);
  }
  memory_.add(map_bricks_ ? "foveated cloud and brick slots (foveation -> send)" : "foveated cloud slots (foveation -> send)",
              foveated_->slotCount(), delta(before, heapInUse()));

  before = heapInUse();
  MapSettings map_settings = config_.map;
  map_settings.tracking = poseTracking(config_.camera);
  tracking_ = map_settings.tracking != pipeline::map::PoseTracking::kOff;
  Result<FrameFoveator> stage =
      FrameFoveator::create(capacity, config_.foveation, config_.camera.depth, map_settings, k.width, k.height);
  if (!stage) return stage.status();
  stage_ = std::make_unique<FrameFoveator>(std::move(stage.value()));
  const std::size_t map_bytes = stage_->mapMemoryBytes();
  if (map_bytes > 0) {
    memory_.add("surfel map (pool, bricks, scratch, eye depth buffer)", 1, map_bytes);
    before += map_bytes;  // the foveator's line below is the rest
  }
  if (const std::size_t pyramid_bytes = stage_->pyramidMemoryBytes(); pyramid_bytes > 0) {
    memory_.add("image pyramid (cell sums, scratch)", 1, pyramid_bytes);
    before += pyramid_bytes;
  }
  if (Status s = config_.stream.gaze.validate(); !s) return s;
  policy_ = std::make_unique<GazePolicy>(config_.stream.gaze, config_.foveation);
  const std::size_t cloud_bytes = stage_->cloud().capacity() * (3 * sizeof(float) + sizeof(uint32_t));
  const std::size_t stage_bytes = delta(before, heapInUse());
  memory_.add("point cloud (back-projection)", 1, std::min(cloud_bytes, stage_bytes));
  memory_.add("foveator (partition, sampler, workers)", 1, stage_bytes - std::min(cloud_bytes, stage_bytes));

  if (!config_.stream.link.listen.empty()) {
    StreamConfig stream = config_.stream;
    if (!config_.key_file.empty()) {
      Result<net::LoadedKey> key = net::loadKeyFile(config_.key_file);
      if (!key) return {key.status().code(), "key_file: " + key.status().message()};
      if (!key->warning.empty()) log().log(LogLevel::kWarning, "key_file: %s", key->warning.c_str());
      stream.link.key = key->key;
    }
    if (map_bricks_) {
      stream.map_bricks = true;
      stream.brick_sender.max_bricks = config_.map.map.max_bricks;
      stream.max_brick_points = config_.map.max_brick_surfels;
      stream.max_frame_brick_points = config_.map.max_frame_brick_points;
    }
    before = heapInUse();
    Result<std::unique_ptr<Streamer>> streamer = Streamer::create(stream, points);
    if (!streamer) return streamer.status();
    streamer_ = std::move(streamer.value());
    if (map_bricks_) {
      brick_feedback_ = std::make_unique<BrickFeedback>(config_.map.map.max_bricks);
      streamer_->attachBrickFeedback(brick_feedback_.get());
    }
    // The chunk encoders are made for the largest MTU here (a session at another
    // MTU makes its own when it starts, in place of these).
    memory_.add(map_bricks_ ? "streamer (link, scheduler, 2 chunk encoders)"
                            : "streamer (link, scheduler, chunk encoder)",
                1, delta(before, heapInUse()));
  }

  before = heapInUse();
  status_lines_ = std::make_unique<StatusLines>(*gpio_, config_.gpio.lines);
  hal::usb::UsbMonitorOptions usb_options;
  usb_options.report_present = true;  // the log says which known cameras are there at start
  usb_monitor_ = std::make_unique<hal::usb::UsbMonitor>(usb_options);
  histogram_scratch_.reset(new uint64_t[LatencyHistogram::kBuckets]);
  for (auto& h : histogram_previous_) h.reset(new uint64_t[LatencyHistogram::kBuckets]());
  threads_.reserve(3);
  memory_.add("status, latency histograms", 1, delta(before, heapInUse()) + 4 * sizeof(LatencyHistogram));

  if (!config_.runtime.timing_log.empty()) {
    before = heapInUse();
    std::FILE* file = std::fopen(config_.runtime.timing_log.c_str(), "w");
    if (file == nullptr) {
      return {ErrorCode::kIoError, "timing log " + config_.runtime.timing_log + ": " + std::strerror(errno)};
    }
    timing_log_.reset(file);
    // Our buffer, so that writing never allocates; a line per frame, flushed when full.
    constexpr std::size_t kTimingBufferBytes = 64 * 1024;
    timing_log_buffer_.reset(new char[kTimingBufferBytes]);
    std::setvbuf(file, timing_log_buffer_.get(), _IOFBF, kTimingBufferBytes);
    std::fputs(kTimingLogHeader, file);
    memory_.add("timing log buffer", 1, delta(before, heapInUse()));
  }

  if (!config_.runtime.record.path.empty()) {
    before = heapInUse();
    RecordSettings record = config_.runtime.record;
    // --record-frames: slots for the camera's frames (as the capture ring's).
    record.frame_width = camera_->info().intrinsics.width;
    record.frame_height = camera_->info().intrinsics.height;
    // The Foxglove cloud channel: slots for the largest foveated cloud.
    record.max_cloud_points = record.foxglove_cloud ? foveated_->slot(0).cloud.points.capacity() : 0;
    // A datagram's payload is at most the largest MTU a session may have.
    if (streamer_) record.max_datagram_bytes = std::min<std::size_t>(record.max_datagram_bytes, config_.stream.link.max_mtu_bytes);
    Result<std::unique_ptr<SessionRecorder>> recorder = SessionRecorder::create(record, log());
    if (!recorder) return recorder.status();
    recorder_ = std::move(recorder.value());
    if (streamer_) {
      // The send stage's taps: what went out and the gaze that came in.
      streamer_->setSendTap(
          [](void* r, net::MessageType type, std::span<const uint8_t> payload, uint32_t frame_id, int64_t capture_ns) {
            static_cast<SessionRecorder*>(r)->onSent(type, payload, frame_id, capture_ns);
          },
          recorder_.get(), /*record_unsent=*/true);
      streamer_->setReceiveTap(
          [](void* r, net::MessageType type, std::span<const uint8_t> payload, int64_t now_ns) {
            static_cast<SessionRecorder*>(r)->onReceived(type, payload, now_ns);
          },
          recorder_.get());
    }
    memory_.add("recording (rings, chunk and compression buffers)", 1, delta(before, heapInUse()));
  }
  return Status::ok();
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
  if (config_.runtime.systemd_notify) notifier_.notify("READY=1");
  return Status::ok();
}

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
  }
}

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

void Service::foveationLoop() {
  placeThread("fovea-foveate", config_.runtime.foveation_thread);
  static LogRateLimit foveate_site;
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
    if (o.bricks_pending) {  // the ring dropped the frame before the send stage took it
      stage_->forgetBatch(o.bricks);
      o.bricks_pending = false;
    }
    const int64_t t0 = monotonicNs();
    pipeline::BackprojectCounts counts;
    const bool pose_usable = stage_->trackPose(f.frame, f.pose_fresh);
    if (tracking_) publishTracking();
    Status s = stage_->backproject(f.frame, counts, pose_usable);
    o.backproject_ns = monotonicNs() - t0;
    if (const pipeline::map::SurfelMap* map = stage_->map()) publishMapFigures(*map);
    GazePolicy::Decision decision;
    if (s) {
      // The newest gaze after the back-projection, not from before it: fusing a
      // frame into the map takes tens of milliseconds, the gaze timeout is 100,
      // and the operator's eye may have moved meanwhile.
      (void)gaze_box_.update();
      decision = policy_->decide(gaze_box_.current(), monotonicNs(), f.frame.T_world_cam);
      // Logged where it is decided: the policy reports a change once, and a frame
      // that then fails (over capacity, say) would otherwise lose it for good.
      if (decision.changed) {
        const std::string_view name = gazeSourceName(decision.source);
        log().log(LogLevel::kInfo, "gaze: %.*s", static_cast<int>(name.size()), name.data());
      }
      s = stage_->use(decision.foveation);
    }
    if (s) s = stage_->foveate(decision.gaze, o.cloud, o.stats);
    if (s && map_bricks_) {
      if (brick_feedback_) {
        brick_feedback_->drain([&](std::size_t brick) { stage_->forgetBrick(static_cast<uint16_t>(brick)); },
                               [&] { stage_->forgetAllBricks(); });
      }
      // The frame's share of the budget is the time since the last frame's, not
      // the camera's period: fusing a large frame can take longer than that, and
      // the link would idle between frames (at most four periods' worth).
      const int64_t now = monotonicNs();
      o.send_window_ns = last_plan_ns_ > 0 ? std::clamp(now - last_plan_ns_, period_ns_, 4 * period_ns_) : period_ns_;
      last_plan_ns_ = now;
      const double budget = static_cast<double>(brick_budget_bytes_per_s_.load(std::memory_order_relaxed)) *
                            static_cast<double>(o.send_window_ns) * 1e-9;
      s = stage_->planBricks(decision.gaze, budget, static_cast<double>(o.cloud.size()) * kWireBytesPerPointEstimate,
                             o.bricks);
      if (s) {
        const MapFrameFigures& figures = stage_->mapFigures();
        bricks_planned_.fetch_add(figures.bricks_planned, std::memory_order_relaxed);
        o.bricks_waiting = figures.bricks_waiting;
        o.fovea_bricks_waiting = figures.fovea_bricks_waiting;
      } else {
        stage_->forgetBatch(o.bricks);
      }
    }
    o.gaze_stamp_ns = decision.source == GazeSource::kOperator ? gaze_box_.current().stamp_ns : 0;
    o.frame_id = static_cast<uint32_t>(f.frame.sequence);
    o.captured_ns = f.captured_ns;
    o.acquire_ns = f.acquire_ns;
    o.foveation_start_ns = t0;
    (void)in_ring.release(in);
    if (!s) {
      out_ring.cancel(out);
      foveate_errors_.fetch_add(1, std::memory_order_relaxed);
      if (s.code() == ErrorCode::kCapacityExceeded) {
        // More voxels or output points than the configuration allows: the frame
        // is dropped and counted (the status line's "over capacity").
        frames_over_capacity_.fetch_add(1, std::memory_order_relaxed);
        (void)log().logLimited(foveate_site, LogLevel::kWarning,
                               "foveation: %s (frame dropped; pipeline.max_voxels %zu, pipeline.max_output_points %zu)",
                               s.toString().c_str(), stage_->foveator().capacity().max_voxels, o.cloud.points.capacity());
      } else {
        (void)log().logLimited(foveate_site, LogLevel::kWarning, "foveation: %s", s.toString().c_str());
      }
      continue;
    }
    // The recording's per-frame channels: the frame's pose and points are here.
    if (recorder_) recorder_->onFrame(o.frame_id, f.captured_ns, f.frame, f.pose_fresh, o.cloud);
    o.foveated_ns = monotonicNs();
    foveate_latency_.add(o.foveated_ns - t0);
    frames_foveated_.fetch_add(1, std::memory_order_relaxed);
    o.bricks_pending = !o.bricks.entries().empty();
    out_ring.publish(out);
  }
  foveation_alive_.store(false, std::memory_order_release);
}

void Service::publishTracking() {
  const pipeline::map::TrackStats& t = stage_->mapFigures().track;
  track_ns_.store(t.track_ns, std::memory_order_relaxed);
  if (t.outcome == pipeline::map::TrackOutcome::kLost) {
    tracking_lost_reason_.store(static_cast<uint8_t>(t.lost_reason), std::memory_order_relaxed);
    frames_track_lost_.fetch_add(1, std::memory_order_relaxed);
    tracking_lost_.store(true, std::memory_order_relaxed);
    return;
  }
  if (t.outcome == pipeline::map::TrackOutcome::kRelocalised) frames_relocalised_.fetch_add(1, std::memory_order_relaxed);
  frames_tracked_.fetch_add(1, std::memory_order_relaxed);
  prior_disagreement_m_.store(t.prior_disagreement_m, std::memory_order_relaxed);
  tracking_lost_.store(false, std::memory_order_relaxed);
}

void Service::publishMapFigures(const pipeline::map::SurfelMap& map) {
  const MapFrameFigures& figures = stage_->mapFigures();
  if (figures.fuse.outcome == pipeline::map::FuseOutcome::kFused) fuse_latency_.add(figures.fuse.fuse_ns);
  const pipeline::map::SurfelMapCounters& c = map.counters();
  map_surfels_.store(map.size(), std::memory_order_relaxed);
  map_frames_fused_.store(c.frames_fused, std::memory_order_relaxed);
  map_refused_no_pose_.store(c.refused_no_pose, std::memory_order_relaxed);
  map_refused_other_.store(c.refused() - c.refused_no_pose, std::memory_order_relaxed);
  map_evicted_.store(c.evicted, std::memory_order_relaxed);
}

void Service::sendLoop() {
  placeThread("fovea-send", config_.runtime.send_thread);
  static LogRateLimit send_site;
  fovea::SlotRing& ring = foveated_->ring();
  auto publishGaze = [this] { publishOperatorGaze(); };
  if (streamer_) {
    streamer_->setPollHook([](void* service) { static_cast<Service*>(service)->publishOperatorGaze(); }, this);
  }
  int64_t next_report_ns = monotonicNs() + 1'000'000'000;
  for (;;) {
    const bool foveation_done = !foveation_alive_.load(std::memory_order_acquire);
    if (streamer_) {
      if (reload_to_send_.update()) {
        const uint64_t budget = reload_to_send_.current().budget_bytes_per_s;
        if (Status s = streamer_->setBudgetCap(budget, monotonicNs()); !s) {
          log().log(LogLevel::kError, "reload: budget: %s", s.message().c_str());
        }
      }
      streamer_->poll();
      publishGaze();
      if (map_bricks_) {
        brick_budget_bytes_per_s_.store(streamer_->sessionBudgetBytesPerS(), std::memory_order_relaxed);
        // Acknowledgements arrive between frames too.
        bricks_in_flight_.store(streamer_->bricksInFlight(), std::memory_order_relaxed);
      }
    }
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
    f.bricks_pending = false;
    const pipeline::map::BrickBatch* bricks = map_bricks_ && streamer_ ? &f.bricks : nullptr;
    if (!streamer_) {
      frames_unsent_.fetch_add(1, std::memory_order_relaxed);
      if (map_bricks_ && brick_feedback_) {
        for (const pipeline::map::BrickBatchEntry& e : f.bricks.entries()) brick_feedback_->forget(e.brick);
      }
    } else if (!stream_allowed_.load(std::memory_order_relaxed)) {
      frames_withheld_.fetch_add(1, std::memory_order_relaxed);  // privacy: captured, never sent
      if (bricks) streamer_->discardBricks(*bricks);
    } else {
      const int64_t t0 = monotonicNs();
      // A frame must be out before the next one is due; what is not goes unsent
      // (brick parts are kept and resent). With the map's bricks the next frame is
      // due a window after this one's plan (the foveation stage's pace).
      const int64_t window_ns = map_bricks_ ? f.send_window_ns : period_ns_;
      const int64_t deadline_ns = t0 + window_ns - std::min<int64_t>(window_ns / 10, 2'000'000);
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
      wire_bytes_.store(streamer_->link().counters().bytes_sent, std::memory_order_relaxed);
      if (const net::BrickSenderCounters* bc = streamer_->brickCounters()) {
        brick_versions_.store(bc->versions, std::memory_order_relaxed);
        brick_parts_.store(bc->parts, std::memory_order_relaxed);
        brick_resends_.store(bc->resends, std::memory_order_relaxed);
        brick_versions_done_.store(bc->versions_done, std::memory_order_relaxed);
        brick_versions_lost_.store(bc->versions_lost, std::memory_order_relaxed);
        brick_acks_unknown_.store(bc->acks_unknown, std::memory_order_relaxed);
        bricks_waiting_.store(f.bricks_waiting, std::memory_order_relaxed);
        fovea_bricks_waiting_.store(f.fovea_bricks_waiting, std::memory_order_relaxed);
        bricks_in_flight_.store(streamer_->bricksInFlight(), std::memory_order_relaxed);
      }
      if (sent && sent->fovea_completed) sent_gaze_stamp_ns_.store(f.gaze_stamp_ns, std::memory_order_release);
    }
    if (!ring.release(slot)) foveate_errors_.fetch_add(1, std::memory_order_relaxed);
    if (streamer_) {
      publishGaze();
      if (const int64_t now = monotonicNs(); now >= next_report_ns) {
        const uint64_t captured = frames_->ring().counters().published;
        net::StatusReport report =
            streamer_->statusReport(captured, frames_sent_.load(std::memory_order_relaxed),
                                    frames_->ring().counters().dropped + foveated_->ring().counters().dropped, now);
        streamer_->sendStatus(report);
        next_report_ns += 1'000'000'000 * ((now - next_report_ns) / 1'000'000'000 + 1);
      }
    }
  }
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
  stream_allowed_.store(state.stream_allowed, std::memory_order_relaxed);
  heartbeat_toggles_.store(status_lines_->counters().heartbeat_toggles, std::memory_order_relaxed);
  streaming_line_.store(state.streaming, std::memory_order_relaxed);
  fault_line_.store(state.fault, std::memory_order_relaxed);
  privacy_active_.store(state.privacy_active, std::memory_order_relaxed);
  if (state.privacy_active != was_privacy) {
    log().log(LogLevel::kNotice, state.privacy_active ? "privacy input active: streaming paused (frames are captured, none sent)"
                                                     : "privacy input released: streaming resumes");
  }
  if (pose_stale != pose_was_stale_) {
    pose_was_stale_ = pose_stale;
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
  if (tracking_lost != tracking_was_lost_) {
    tracking_was_lost_ = tracking_lost;
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
  if (state.fault != was_fault) {
    if (state.fault && healthy) {
      // The pose's own line above says why.
    } else if (state.fault) {
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
  if (config_.runtime.systemd_notify && healthy && notifier_.watchdogNs() > 0 && now_ns >= next_watchdog_ns_) {
    if (notifier_.notify("WATCHDOG=1")) watchdog_keepalives_.fetch_add(1, std::memory_order_relaxed);
    next_watchdog_ns_ = now_ns + notifier_.watchdogNs() / 2;
  }
  if (now_ns >= next_status_ns_) {
    char line[kLogLineBytes];
    std::memcpy(line, "STATUS=", 7);
    const std::size_t n = formatStatusLine(line + 7, sizeof line - 7);
    log().log(LogLevel::kInfo, "%s", line + 7);
    if (recorder_) recorder_->onStatusLine(std::string_view(line + 7, n));
    status_lines_written_.fetch_add(1, std::memory_order_relaxed);
    if (config_.runtime.systemd_notify) notifier_.notify(std::string_view(line, 7 + n));
    const int64_t interval_ns = config_.runtime.status_interval_ms * 1'000'000;
    next_status_ns_ += interval_ns * ((now_ns - next_status_ns_) / interval_ns + 1);
  }
}

std::size_t Service::formatStatusLine(char* out, std::size_t size) {
  const int64_t now = monotonicNs();
  const double dt_s = std::max(1e-9, static_cast<double>(now - window_.at_ns) * 1e-9);
  const fovea::RingCounters capture_ring = frames_->ring().counters();
  const fovea::RingCounters foveation_ring = foveated_->ring().counters();
  Window w;
  w.at_ns = now;
  w.captured = capture_ring.published;
  w.foveated = frames_foveated_.load(std::memory_order_relaxed);
  w.sent = frames_sent_.load(std::memory_order_relaxed);
  w.wire_bytes = wire_bytes_.load(std::memory_order_relaxed);
  w.capture_drops = capture_ring.dropped;
  w.foveation_drops = foveation_ring.dropped;
  double p50[4], p99[4];
  const LatencyHistogram* histograms[4] = {&capture_latency_, &foveate_latency_, &send_latency_, &fuse_latency_};
  for (int i = 0; i < 4; ++i) {
    histograms[i]->snapshot(histogram_scratch_.get());
    uint64_t* previous = histogram_previous_[i].get();
    for (std::size_t b = 0; b < LatencyHistogram::kBuckets; ++b) {
      const uint64_t now_count = histogram_scratch_[b];
      histogram_scratch_[b] = now_count - previous[b];
      previous[b] = now_count;
    }
    p50[i] = histogramQuantileMs(histogram_scratch_.get(), LatencyHistogram::kBuckets, 0.5);
    p99[i] = histogramQuantileMs(histogram_scratch_.get(), LatencyHistogram::kBuckets, 0.99);
  }
  char latency[4][24];
  for (int i = 0; i < 4; ++i) {
    if (p50[i] < 0) {
      std::snprintf(latency[i], sizeof latency[i], "-");
    } else {
      std::snprintf(latency[i], sizeof latency[i], "%.1f/%.1f", p50[i], p99[i]);
    }
  }
  const int64_t gaze_ns = gaze_received_ns_.load(std::memory_order_relaxed);
  // USB hot-plug counts since start: "arrived 1 left 0", or "off" when not watched.
  const hal::usb::UsbMonitorCounters usb_counts = usb_monitor_->counters();
  char usb[48];
  if (usb_counts.available) {
    std::snprintf(usb, sizeof usb, "arrived %" PRIu64 " left %" PRIu64, usb_counts.arrivals, usb_counts.removals);
  } else {
    std::snprintf(usb, sizeof usb, "off");
  }
  char gaze_age[32];
  if (gaze_ns == 0) {
    std::snprintf(gaze_age, sizeof gaze_age, "none");
  } else {
    std::snprintf(gaze_age, sizeof gaze_age, "%" PRId64 " ms", (now - gaze_ns) / 1'000'000);
  }
  char pose[192] = "";
  int pose_used = 0;
  if (pose_source_->config().kind == hal::PoseSourceConfig::Kind::kSocket) {
    const hal::PoseCounters pc = pose_source_->counters();
    pose_used = std::snprintf(pose, sizeof pose, " | pose %s, %" PRIu64 " stale frames",
                              pose_stale_.load() ? "STALE" : "fresh", pc.frames_stale);
  }
  if (tracking_ && pose_used >= 0 && static_cast<std::size_t>(pose_used) < sizeof pose) {
    // "pose LOST" while lost: what an operator greps for.
    std::snprintf(pose + pose_used, sizeof pose - static_cast<std::size_t>(pose_used),
                  " | pose %s, track %.1f ms, lost %" PRIu64 " frames, relocalised %" PRIu64 ", prior off by %.1f cm",
                  tracking_lost_.load(std::memory_order_relaxed) ? "LOST" : "tracked",
                  static_cast<double>(track_ns_.load(std::memory_order_relaxed)) * 1e-6,
                  frames_track_lost_.load(std::memory_order_relaxed), frames_relocalised_.load(std::memory_order_relaxed),
                  prior_disagreement_m_.load(std::memory_order_relaxed) * 100.0);
  }
  // The map: its size, this window's fusion time, and since start the surfels
  // evicted and the frames refused (no pose; anything else).
  char map[256] = "";
  if (stage_->map() != nullptr) {
    const int used = std::snprintf(
        map, sizeof map,
        " | map %" PRIu64 " surfels, fuse %s ms, evicted %" PRIu64 ", refused %" PRIu64 " no pose %" PRIu64 " other",
        map_surfels_.load(std::memory_order_relaxed), latency[3], map_evicted_.load(std::memory_order_relaxed),
        map_refused_no_pose_.load(std::memory_order_relaxed), map_refused_other_.load(std::memory_order_relaxed));
    if (map_bricks_ && used > 0 && static_cast<std::size_t>(used) < sizeof map) {
      std::snprintf(map + used, sizeof map - static_cast<std::size_t>(used),
                    ", brick versions %" PRIu64 " sent %" PRIu64 " acknowledged %" PRIu64 " lost",
                    brick_versions_.load(std::memory_order_relaxed), brick_versions_done_.load(std::memory_order_relaxed),
                    brick_versions_lost_.load(std::memory_order_relaxed));
    }
  }
  // Frames dropped since start for more voxels or points than configured (only once there is one).
  char over[48] = "";
  if (const uint64_t n_over = frames_over_capacity_.load(std::memory_order_relaxed); n_over > 0) {
    std::snprintf(over, sizeof over, " over capacity %" PRIu64, n_over);
  }
  const int n = std::snprintf(
      out, size,
      "status: fps in %.1f foveated %.1f out %.1f | drops capture %" PRIu64 " foveation %" PRIu64
      "%s | ms p50/p99 capture %s foveate %s send %s | wire %.2f MB/s | gaze age %s%s%s%s | memory %.1f MiB"
      " | lines heartbeat %s streaming %d fault %d | usb %s",
      static_cast<double>(w.captured - window_.captured) / dt_s, static_cast<double>(w.foveated - window_.foveated) / dt_s,
      static_cast<double>(w.sent - window_.sent) / dt_s, w.capture_drops - window_.capture_drops,
      w.foveation_drops - window_.foveation_drops, over, latency[0], latency[1], latency[2],
      static_cast<double>(w.wire_bytes - window_.wire_bytes) / dt_s / 1e6, gaze_age,
      status_lines_->state().privacy_active ? " | privacy pause" : "", pose, map,
      static_cast<double>(memory_.totalBytes()) / kMiB,
      // The heartbeat's level changes every half period: report whether it toggles.
      heartbeat_toggles_.load(std::memory_order_relaxed) != window_heartbeat_toggles_ ? "toggling" : "held",
      status_lines_->state().streaming ? 1 : 0, status_lines_->state().fault ? 1 : 0, usb);
  window_heartbeat_toggles_ = heartbeat_toggles_.load(std::memory_order_relaxed);
  window_ = w;
  return n < 0 ? 0 : std::min(static_cast<std::size_t>(n), size - 1);
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
                "map: %" PRIu64 " surfels from %" PRIu64 " fused frames; %" PRIu64 " evicted; refused %" PRIu64
                " frames without a pose, %" PRIu64 " for another reason",
                s.map.surfels, s.map.frames_fused, s.map.evicted, s.map.refused_no_pose, s.map.refused_other);
      if (map_bricks_) {
        log().log(LogLevel::kInfo,
                  "map bricks: %" PRIu64 " planned; %" PRIu64 " versions in %" PRIu64 " parts sent, %" PRIu64
                  " parts resent; %" PRIu64 " versions acknowledged whole, %" PRIu64 " lost (sent again); %" PRIu64
                  " acknowledgements for nothing in flight",
                  s.map.bricks_planned, s.map.brick_versions, s.map.brick_parts, s.map.brick_resends,
                  s.map.brick_versions_done, s.map.brick_versions_lost, s.map.brick_acks_unknown);
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
  s.map.surfels = map_surfels_.load(std::memory_order_relaxed);
  s.map.frames_fused = map_frames_fused_.load(std::memory_order_relaxed);
  s.map.refused_no_pose = map_refused_no_pose_.load(std::memory_order_relaxed);
  s.map.refused_other = map_refused_other_.load(std::memory_order_relaxed);
  s.map.evicted = map_evicted_.load(std::memory_order_relaxed);
  s.map.bricks_planned = bricks_planned_.load(std::memory_order_relaxed);
  s.map.brick_versions = brick_versions_.load(std::memory_order_relaxed);
  s.map.brick_parts = brick_parts_.load(std::memory_order_relaxed);
  s.map.brick_resends = brick_resends_.load(std::memory_order_relaxed);
  s.map.brick_versions_done = brick_versions_done_.load(std::memory_order_relaxed);
  s.map.brick_versions_lost = brick_versions_lost_.load(std::memory_order_relaxed);
  s.map.brick_acks_unknown = brick_acks_unknown_.load(std::memory_order_relaxed);
  s.sent_gaze_stamp_ns = sent_gaze_stamp_ns_.load(std::memory_order_acquire);
  s.map.bricks_waiting = bricks_waiting_.load(std::memory_order_relaxed);
  s.map.fovea_bricks_waiting = fovea_bricks_waiting_.load(std::memory_order_relaxed);
  s.map.bricks_in_flight = bricks_in_flight_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace fovea::firmware
