// The service's memory plan: allocate(), which makes every buffer the service
// uses before a thread starts (rings of slots, the foveator, the streamer, the
// supervisor's state, the timing log, the recording), and measures each pool.
#include "firmware/service.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "firmware/camera_setup.h"
#include "net/key.h"

namespace fovea::firmware {

namespace {

// With the map's bricks a frame carries only the points the map does not
// explain yet: map.max_live_points caps its output and its voxels
// (FrameFoveator::capsLivePoints).
bool capsLivePoints(const ServiceConfig& config) {
  return FrameFoveator::capsLivePoints(config.map, config.foveation.acuity.preset);
}

// The pipeline's capacity for the camera's frames: a frame has no more points
// than pixels; an error when pipeline.max_points is below them.
Result<pipeline::PipelineCapacity> frameCapacity(const ServiceConfig& config, const hal::CameraIntrinsics& k) {
  pipeline::PipelineCapacity capacity = config.pipeline;
  const std::size_t pixels = static_cast<std::size_t>(k.width) * static_cast<std::size_t>(k.height);
  if (capacity.max_points < pixels) {
    return Result<pipeline::PipelineCapacity>(
        ErrorCode::kInvalidArgument, "pipeline.max_points = " + std::to_string(capacity.max_points) +
                                         " is below the camera's " + std::to_string(k.width) + "x" +
                                         std::to_string(k.height) + " = " + std::to_string(pixels) +
                                         " pixels: raise pipeline.max_points");
  }
  capacity.max_points = pixels;  // a frame has no more points than pixels
  capacity.max_voxels = std::min(capacity.max_voxels, pixels);
  if (capsLivePoints(config)) {
    capacity.max_voxels = std::min(capacity.max_voxels, liveFramePoints(config.map.max_live_points, pixels));
  }
  return capacity;
}

// The foveated output: the fovea whole and a point per voxel, at most
// pipeline.max_output_points (0: the pixels). A preset that keeps every point
// (FREF) needs the pixels; the map source without bricks foveates the map's
// surfels too, so its clouds hold them (the map's memory on top of the
// frame's); with bricks its clouds are the frame's live points, capped as the
// frame source's and by map.max_live_points, and the map goes in the brick
// slots. The pyramid
// source keeps the pixels too: at ACUITY's default margin it sends more points
// than the voxel methods, and with the cap (0.35 of the pixels) the mock room's
// scan lost 18 frames in 10 s as over capacity (toolchain/run-latency).
std::size_t foveatedCloudPoints(const ServiceConfig& config, std::size_t pixels) {
  std::size_t points = FrameFoveator::cloudCapacity(pixels, config.map);
  const bool frame_points_only = config.map.source == FoveationSource::kFrame || FrameFoveator::streamsLiveOnly(config.map);
  if (frame_points_only && config.foveation.acuity.preset != pipeline::Preset::kFRef &&
      config.max_output_points > 0) {
    points = std::min(points, config.max_output_points);
  }
  if (capsLivePoints(config)) points = std::min(points, liveFramePoints(config.map.max_live_points, pixels));
  return points;
}

}  // namespace

Status Service::allocate() {
  const hal::CameraIntrinsics& k = camera_->info().intrinsics;
  const auto depth = static_cast<std::size_t>(config_.runtime.ring_depth);
  const std::size_t pixels = static_cast<std::size_t>(k.width) * static_cast<std::size_t>(k.height);
  Result<pipeline::PipelineCapacity> capacity = frameCapacity(config_, k);
  if (!capacity) return capacity.status();
  allocateFrameSlots(k, depth);
  const std::size_t points = foveatedCloudPoints(config_, pixels);
  live_points_capped_ = capsLivePoints(config_);
  map_bricks_ = config_.map.source == FoveationSource::kMap && config_.map.delta;
  if (map_bricks_ && config_.map.max_frame_brick_points == 0) {
    config_.map.max_frame_brick_points = frameBrickPoints(static_cast<double>(config_.stream.link.max_budget_bytes_per_s),
                                                          camera_->info().fps, config_.map.max_brick_surfels);
  }
  allocateFoveatedSlots(points, depth);
  if (Status s = allocateFoveator(capacity.value(), k); !s) return s;
  if (!config_.stream.link.listen.empty()) {
    if (Status s = allocateStreamer(points); !s) return s;
  }
  allocateSupervisorState();
  if (!config_.runtime.timing_log.empty()) {
    if (Status s = openTimingLog(); !s) return s;
  }
  if (!config_.runtime.record.path.empty()) {
    if (Status s = allocateRecorder(); !s) return s;
  }
  return Status::ok();
}

void Service::allocateFrameSlots(const hal::CameraIntrinsics& k, std::size_t depth) {
  const std::size_t before = heapInUse();
  {
    CapturedFrame prototype{hal::RgbdFrame(k.width, k.height), 0};
    frames_ = std::make_unique<fovea::SlotPoolRing<CapturedFrame>>(depth, 1, prototype);
  }
  memory_.add("frame slots (RGB-D, capture -> foveation)", frames_->slotCount(), heapGrowthSince(before));
}

void Service::allocateFoveatedSlots(std::size_t points, std::size_t depth) {
  // Without weights: the send stage and the recorder never read them.
  constexpr auto kNoWeights = pipeline::FoveatedCloud::Weights::kNone;
  std::size_t before = heapInUse();
  {
    FoveatedFrame prototype;
    prototype.cloud = pipeline::FoveatedCloud(points, kNoWeights);
    foveated_ = std::make_unique<fovea::SlotPoolRing<FoveatedFrame>>(depth, 1, prototype);
  }
  memory_.add("foveated cloud slots (foveation -> send)", foveated_->slotCount(), heapGrowthSince(before));
  if (!map_bricks_) return;
  before = heapInUse();
  bricks_ = std::make_unique<SharedBrickBatch>(pipeline::map::BrickBatch(
      config_.map.max_frame_brick_points, config_.map.max_frame_bricks, kNoWeights));
  memory_.add("map: a frame's bricks (foveation -> send, one batch)", 1, heapGrowthSince(before));
}

// The frame foveator and the gaze policy. The map and the pyramid report their
// own bytes; the rest of the stage's growth is the cloud and the foveator's.
Status Service::allocateFoveator(const pipeline::PipelineCapacity& capacity, const hal::CameraIntrinsics& k) {
  std::size_t before = heapInUse();
  MapSettings map_settings = config_.map;
  map_settings.tracking = poseTracking(config_.camera);
  tracking_ = map_settings.tracking != pipeline::map::PoseTracking::kOff;
  Result<FrameFoveator> stage =
      FrameFoveator::create(capacity, config_.foveation, config_.camera.depth, map_settings, k.width, k.height);
  if (!stage) return stage.status();
  stage_ = std::make_unique<FrameFoveator>(std::move(stage.value()));
  addMapMemory(stage_->mapMemory());
  before += stage_->mapMemoryBytes();  // the foveator's line below is the rest
  if (const std::size_t pyramid_bytes = stage_->pyramidMemoryBytes(); pyramid_bytes > 0) {
    memory_.add("image pyramid (cell sums, scratch)", 1, pyramid_bytes);
    before += pyramid_bytes;
  }
  if (Status s = config_.stream.gaze.validate(); !s) return s;
  policy_ = std::make_unique<GazePolicy>(config_.stream.gaze, config_.foveation);
  const std::size_t cloud_bytes = stage_->cloud().capacity() * (3 * sizeof(float) + sizeof(uint32_t));
  const std::size_t stage_bytes = heapGrowthSince(before);
  memory_.add("point cloud (back-projection)", 1, std::min(cloud_bytes, stage_bytes));
  memory_.add("foveator (partition, sampler, workers)", 1, stage_bytes - std::min(cloud_bytes, stage_bytes));
  return Status::ok();
}

// The map's parts, a line each (those it has).
void Service::addMapMemory(const pipeline::map::MapperMemory& m) {
  const std::pair<const char*, std::size_t> parts[] = {
      {"map: surfel pool (32 B a surfel, 6 B its links)", m.map.pool},
      {"map: bricks (table, culling, lists, counts)", m.map.bricks},
      {"map: fusion's per-pixel scratch", m.map.pixels},
      {"map: eviction histogram", m.map.eviction},
      {"map: eye depth buffer", m.eye},
      {"map: bricks the operator holds, plan, sampler", m.delta},
      {"map: the last fused view (explained depths), the live points' cone bits", m.view},
      {"map: the frame handed to the fusion thread", m.handoff},
      {"map: tracker (frame and model pyramids)", m.tracker},
  };
  for (const auto& [name, bytes] : parts) {
    if (bytes > 0) memory_.add(name, 1, bytes);
  }
}

// The streamer (config.stream.link.listen set), with the key from key_file
// when one is set, and the map's bricks' feedback.
Status Service::allocateStreamer(std::size_t points) {
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
    stream.max_frame_bricks = config_.map.max_frame_bricks;
  }
  const std::size_t before = heapInUse();
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
              1, heapGrowthSince(before));
  return Status::ok();
}

// The status lines, the USB monitor, the status line's histogram snapshots
// and room for the three stage threads.
void Service::allocateSupervisorState() {
  const std::size_t before = heapInUse();
  status_lines_ = std::make_unique<StatusLines>(*gpio_, config_.gpio.lines);
  hal::usb::UsbMonitorOptions usb_options;
  usb_options.report_present = true;  // the log says which known cameras are there at start
  usb_monitor_ = std::make_unique<hal::usb::UsbMonitor>(usb_options);
  histogram_scratch_.reset(new uint64_t[LatencyHistogram::kBuckets]);
  for (auto& h : histogram_previous_) h.reset(new uint64_t[LatencyHistogram::kBuckets]());
  threads_.reserve(4);
  memory_.add("status, latency histograms", 1, heapGrowthSince(before) + 4 * sizeof(LatencyHistogram));
}

// --timing-log: the file, its header and our buffer for it.
Status Service::openTimingLog() {
  const std::size_t before = heapInUse();
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
  memory_.add("timing log buffer", 1, heapGrowthSince(before));
  return Status::ok();
}

// --record: the session recorder, sized for the camera's frames, the largest
// foveated cloud and the largest datagram, with the streamer's taps on it.
Status Service::allocateRecorder() {
  const std::size_t before = heapInUse();
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
  memory_.add("recording (rings, chunk and compression buffers)", 1, heapGrowthSince(before));
  return Status::ok();
}

}  // namespace fovea::firmware
