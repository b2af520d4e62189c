#include "firmware/session_recorder.h"

#include <time.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>

#include "core/clock.h"
#include "firmware/frame_record.h"
#include "io/foxglove/recording.h"
#include "net/messages.h"
#include "net/stream_channels.h"

namespace fovea::firmware {

namespace {

std::span<const uint8_t> bytesOf(std::string_view s) { return {reinterpret_cast<const uint8_t*>(s.data()), s.size()}; }

constexpr const char* kPoseSchema = R"json({
  "title": "fovea.CameraPose",
  "description": "The camera's pose (world from camera) of one frame foveated by fovead (firmware/session_recorder.h)",
  "type": "object",
  "properties": {
    "frame_id": {"type": "integer", "description": "the frame's sequence (the chunks' frame id)"},
    "stamp_ns": {"type": "integer", "description": "the camera's stamp (CLOCK_MONOTONIC or the recording's clock)"},
    "captured_ns": {"type": "integer", "description": "when acquire returned, CLOCK_MONOTONIC"},
    "translation_m": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
    "rotation_xyzw": {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4},
    "pose_fresh": {"type": "boolean", "description": "the pose source had a pose for the frame's stamp"},
    "points": {"type": "integer", "description": "points in the foveated cloud"},
    "tracking": {"type": "string", "description": "with tracking: the frame's outcome (tracked, relocalised, lost, first-frame)"},
    "lost_reason": {"type": "string", "description": "with tracking, a lost frame: why (docs/tracking.md)"},
    "moving_share": {"type": "number", "description": "with tracking: the share of the frame's valid pixels found moving (not fused)"}
  }
})json";

constexpr const char* kStatusSchema = R"json({
  "title": "fovea.StatusLine",
  "description": "fovead's status line (docs/service.md), as logged",
  "type": "object",
  "properties": {
    "line": {"type": "string"}
  }
})json";

}  // namespace

Result<std::unique_ptr<SessionRecorder>> SessionRecorder::create(const RecordSettings& settings, Logger& log) {
  mcap::RecorderConfig config;
  config.slots = settings.send_slots;
  config.slot_bytes = settings.max_datagram_bytes;
  config.writer.chunk_bytes = 1 << 20;
  config.writer.index_entries_per_chunk = 8192;
  Logger* logger = &log;
  Result<std::unique_ptr<mcap::Recorder>> recorder = mcap::Recorder::open(
      settings.path, config, [logger](std::string_view line) {
        logger->log(LogLevel::kError, "%.*s", static_cast<int>(line.size()), line.data());
      });
  if (!recorder) return Status(recorder.status().code(), "--record: " + recorder.status().message());
  std::unique_ptr<SessionRecorder> r(new SessionRecorder());
  r->recorder_ = std::move(recorder.value());
  mcap::Recorder& m = *r->recorder_;
  // What travels the link: the channels both ends record (net/stream_channels.h).
  Result<net::StreamChannels> stream = net::addStreamChannels(m);
  if (!stream) return stream.status();
  Result<uint16_t> pose_id = m.addSchema("fovea.CameraPose", "jsonschema", bytesOf(kPoseSchema));
  Result<uint16_t> status_id = m.addSchema("fovea.StatusLine", "jsonschema", bytesOf(kStatusSchema));
  for (const Result<uint16_t>* id : {&pose_id, &status_id}) {
    if (!*id) return id->status();
  }
  Result<uint16_t> pose = m.addChannel("/fovea/camera_pose", "json", *pose_id);
  Result<uint16_t> status = m.addChannel("/fovea/status", "json", *status_id);
  for (const Result<uint16_t>* id : {&pose, &status}) {
    if (!*id) return id->status();
  }
  r->stream_ = *stream;
  r->pose_ = *pose;
  r->status_channel_ = *status;
  r->send_ = m.addProducer(settings.send_slots, settings.max_datagram_bytes);
  r->frames_ = m.addProducer(settings.frame_slots, 512);
  r->status_ = m.addProducer(settings.status_slots, 2048);
  // The Foxglove channels, encoded on the writer thread (io/foxglove/recording.h).
  foxglove::RecordingOptions fx;
  fx.max_cloud_points = settings.max_cloud_points;
  Result<std::unique_ptr<foxglove::RecordingChannels>> channels = foxglove::RecordingChannels::add(m, fx);
  if (!channels) return channels.status();
  r->foxglove_ = std::move(channels.value());
  if (r->foxglove_->hasCloud()) r->cloud_ = m.addProducer(settings.cloud_slots, r->foxglove_->cloudRecordBytes());
  if (settings.frames) {
    if (settings.frame_width <= 0 || settings.frame_height <= 0) {
      return invalidArgument("--record-frames: the camera's frame size is unknown");
    }
    Result<uint16_t> schema = m.addSchema(kFrameRecordSchemaName, "fovea.frame_record", frameRecordSchemaText());
    if (!schema) return schema.status();
    Result<uint16_t> channel = m.addChannel(kFramesTopic, "fovea.frame_record", *schema);
    if (!channel) return channel.status();
    r->frames_channel_ = *channel;
    r->raw_ = m.addProducer(settings.frame_record_slots,
                            frameRecordBytes(settings.frame_width, settings.frame_height, true));
  }
  return r;
}

SessionRecorder::~SessionRecorder() { (void)close(); }

Status SessionRecorder::start() { return recorder_->start(); }

Status SessionRecorder::close() { return recorder_ ? recorder_->close() : Status::ok(); }

void SessionRecorder::onSent(net::MessageType type, std::span<const uint8_t> payload, uint32_t, int64_t) {
  if (type == net::MessageType::kGaze) return;
  if (const uint16_t channel = stream_.channelOf(type); channel != 0) (void)send_->record(channel, static_cast<uint64_t>(wallClockNs()), payload);
}

void SessionRecorder::onReceived(net::MessageType type, std::span<const uint8_t> payload, int64_t) {
  if (type != net::MessageType::kGaze) return;
  const auto now = static_cast<uint64_t>(wallClockNs());
  (void)send_->record(stream_.gaze, now, payload);
  // Foxglove's arrow of the gaze (decoded here from an aligned copy: a microsecond;
  // a sample without a gaze, confidence 0, draws none).
  alignas(net::kPayloadAlignment) std::array<uint8_t, net::kMaxMtu> aligned;
  if (payload.size() > aligned.size()) return;
  std::memcpy(aligned.data(), payload.data(), payload.size());
  net::GazeSample g;
  if (!net::decode(std::span<const uint8_t>(aligned.data(), payload.size()), g) && g.confidence > 0.0f) {
    (void)foxglove_->recordRay(*send_, now, {g.gaze_origin_m.x, g.gaze_origin_m.y, g.gaze_origin_m.z},
                               {g.gaze_direction.x, g.gaze_direction.y, g.gaze_direction.z});
  }
}

void SessionRecorder::onFrame(uint32_t frame_id, int64_t captured_ns, const hal::RgbdFrame& frame, bool pose_fresh,
                              const pipeline::FoveatedCloud& cloud, const pipeline::map::TrackStats* track) {
  const hal::Pose& pose = frame.T_world_cam;
  const Eigen::Quaterniond q(pose.R_world_cam);
  char tracking[160] = "";
  if (track != nullptr) {
    const std::string_view outcome = pipeline::map::trackOutcomeName(track->outcome);
    const bool lost = track->outcome == pipeline::map::TrackOutcome::kLost;
    const std::string_view reason = lost ? pipeline::map::lostReasonName(track->lost_reason) : std::string_view();
    std::snprintf(tracking, sizeof tracking, ",\"tracking\":\"%.*s\"%s%.*s%s,\"moving_share\":%.4f",
                  static_cast<int>(outcome.size()), outcome.data(), lost ? ",\"lost_reason\":\"" : "",
                  static_cast<int>(reason.size()), reason.data(), lost ? "\"" : "", track->moving_share);
  }
  char json[640];
  const int n = std::snprintf(
      json, sizeof json,
      "{\"frame_id\":%" PRIu32 ",\"stamp_ns\":%" PRId64 ",\"captured_ns\":%" PRId64
      ",\"translation_m\":[%.17g,%.17g,%.17g],\"rotation_xyzw\":[%.17g,%.17g,%.17g,%.17g],\"pose_fresh\":%s"
      ",\"points\":%zu%s}",
      frame_id, frame.stamp_ns, captured_ns, pose.t_world_cam.x(), pose.t_world_cam.y(), pose.t_world_cam.z(), q.x(),
      q.y(), q.z(), q.w(), pose_fresh ? "true" : "false", cloud.size(), tracking);
  if (n > 0 && static_cast<std::size_t>(n) < sizeof json) {
    (void)frames_->record(pose_, static_cast<uint64_t>(wallClockNs()), {reinterpret_cast<const uint8_t*>(json), static_cast<std::size_t>(n)});
  }
  // Foxglove's camera transform and cloud, raw: the writer thread encodes them.
  const auto now = static_cast<uint64_t>(wallClockNs());
  (void)foxglove_->recordPose(*frames_, now, {pose.t_world_cam.x(), pose.t_world_cam.y(), pose.t_world_cam.z()},
                              {q.w(), q.x(), q.y(), q.z()});
  if (cloud_ != nullptr) (void)foxglove_->recordCloud(*cloud_, now, cloud.points);
}

void SessionRecorder::onCapture(const hal::RgbdFrame& frame) {
  if (raw_ == nullptr) return;
  std::array<uint8_t, kFrameRecordHeaderBytes> header;
  encodeFrameRecordHeader(frame, header);
  const std::size_t pixels = frame.pixelCount();
  const std::span<const uint8_t> parts[] = {
      header,
      {reinterpret_cast<const uint8_t*>(frame.depth()), pixels * 2},
      {frame.rgb(), frame.has_rgb ? pixels * 3 : 0},
  };
  (void)raw_->record(frames_channel_, static_cast<uint64_t>(wallClockNs()), parts);
}

void SessionRecorder::onStatusLine(std::string_view line) {
  char json[2048];
  std::size_t n = 0;
  const char* head = "{\"line\":\"";
  std::memcpy(json, head, std::strlen(head));
  n = std::strlen(head);
  for (char c : line) {
    if (n + 8 >= sizeof json) break;
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      json[n++] = '\\';
      json[n++] = c;
    } else if (u < 0x20) {
      n += static_cast<std::size_t>(std::snprintf(json + n, 7, "\\u%04x", u));
    } else {
      json[n++] = c;
    }
  }
  json[n++] = '"';
  json[n++] = '}';
  const auto now = static_cast<uint64_t>(wallClockNs());
  (void)status_->record(status_channel_, now, {reinterpret_cast<const uint8_t*>(json), n});
  (void)foxglove_->recordLog(*status_, now, line.substr(0, 2048));
}

std::string SessionRecorder::summary() const {
  const mcap::RecorderCounters c = recorder_->counters();
  char line[400];
  std::snprintf(line, sizeof line,
                "recording %s: %" PRIu64 " messages, %.2f MB (%.2f MB/min); dropped: ring full %" PRIu64
                ", too big %" PRIu64 ", disk %" PRIu64 ", after close %" PRIu64,
                recorder_->path().c_str(), c.messages_written, static_cast<double>(c.bytes_written) / 1e6,
                c.mb_per_minute, c.dropped_ring_full, c.dropped_too_big, c.dropped_disk, c.dropped_closed);
  return line;
}

}  // namespace fovea::firmware
