#include "firmware/session_recorder.h"

#include <time.h>

#include <Eigen/Geometry>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <string>

#include "firmware/recording_schemas.h"

namespace fovea::firmware {

namespace {

// MCAP log times are wall-clock nanoseconds (what viewers show on their timeline);
// the payloads keep their own monotonic stamps.
uint64_t wallNs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<uint64_t>(ts.tv_sec) * 1'000'000'000ull + static_cast<uint64_t>(ts.tv_nsec);
}

std::span<const uint8_t> bytesOf(std::string_view s) { return {reinterpret_cast<const uint8_t*>(s.data()), s.size()}; }

std::vector<uint8_t> concat(std::initializer_list<std::span<const uint8_t>> parts) {
  std::vector<uint8_t> out;
  for (std::span<const uint8_t> p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

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
    "points": {"type": "integer", "description": "points in the foveated cloud"}
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
  char version[160];
  std::snprintf(version, sizeof version,
                "fovea stream protocol version %u: point chunk payloads as sent (plaintext), "
                "laid out as the document below says\n\n",
                static_cast<unsigned>(net::kProtocolVersion));
  const std::vector<uint8_t> chunk_schema = concat({bytesOf(version), protocolChunksText()});
  const std::vector<uint8_t> control_schema = concat({controlFbsText(), bytesOf("\n// geometry.fbs\n"), geometryFbsText()});
  auto schema = [&](const char* name, const char* encoding, std::span<const uint8_t> data) -> Result<uint16_t> {
    return m.addSchema(name, encoding, data);
  };
  Result<uint16_t> chunk_id = schema("fovea.Chunk", "fovea.chunk", chunk_schema);
  Result<uint16_t> summary_id = schema("fovea.net.wire.FrameSummary", "fovea.flatbuffer.fbs", chunkFbsText());
  Result<uint16_t> gaze_id = schema("fovea.net.wire.Gaze", "fovea.flatbuffer.fbs", control_schema);
  Result<uint16_t> pose_id = schema("fovea.CameraPose", "jsonschema", bytesOf(kPoseSchema));
  Result<uint16_t> status_id = schema("fovea.StatusLine", "jsonschema", bytesOf(kStatusSchema));
  for (const Result<uint16_t>* id : {&chunk_id, &summary_id, &gaze_id, &pose_id, &status_id}) {
    if (!*id) return id->status();
  }
  char protocol[8];
  std::snprintf(protocol, sizeof protocol, "%u", static_cast<unsigned>(net::kProtocolVersion));
  const std::pair<std::string, std::string> meta[] = {{"protocol_version", protocol}};
  Result<uint16_t> chunks = m.addChannel("/fovea/chunks", "fovea.chunk", *chunk_id, meta);
  Result<uint16_t> summaries = m.addChannel("/fovea/frame_summary", "fovea.flatbuffer", *summary_id, meta);
  Result<uint16_t> bricks = m.addChannel("/fovea/brick_chunks", "fovea.chunk", *chunk_id, meta);
  Result<uint16_t> gaze = m.addChannel("/fovea/gaze", "fovea.flatbuffer", *gaze_id, meta);
  Result<uint16_t> pose = m.addChannel("/fovea/camera_pose", "json", *pose_id);
  Result<uint16_t> status = m.addChannel("/fovea/status", "json", *status_id);
  for (const Result<uint16_t>* id : {&chunks, &summaries, &bricks, &gaze, &pose, &status}) {
    if (!*id) return id->status();
  }
  r->chunks_ = *chunks;
  r->summaries_ = *summaries;
  r->bricks_ = *bricks;
  r->gaze_ = *gaze;
  r->pose_ = *pose;
  r->status_channel_ = *status;
  r->send_ = m.addProducer(settings.send_slots, settings.max_datagram_bytes);
  r->frames_ = m.addProducer(settings.frame_slots, 512);
  r->status_ = m.addProducer(settings.status_slots, 2048);
  return r;
}

SessionRecorder::~SessionRecorder() { (void)close(); }

Status SessionRecorder::start() { return recorder_->start(); }

Status SessionRecorder::close() { return recorder_ ? recorder_->close() : Status::ok(); }

void SessionRecorder::onSent(net::MessageType type, std::span<const uint8_t> payload, uint32_t, int64_t) {
  uint16_t channel = 0;
  switch (type) {
    case net::MessageType::kChunk: channel = chunks_; break;
    case net::MessageType::kFrameSummary: channel = summaries_; break;
    case net::MessageType::kBrickChunk: channel = bricks_; break;
    default: return;
  }
  (void)send_->record(channel, wallNs(), payload);
}

void SessionRecorder::onReceived(net::MessageType type, std::span<const uint8_t> payload, int64_t) {
  if (type == net::MessageType::kGaze) (void)send_->record(gaze_, wallNs(), payload);
}

void SessionRecorder::onFrame(uint32_t frame_id, int64_t captured_ns, const hal::RgbdFrame& frame, bool pose_fresh,
                              const pipeline::FoveatedCloud& cloud) {
  const hal::Pose& pose = frame.T_world_cam;
  const Eigen::Quaterniond q(pose.R_world_cam);
  char json[512];
  const int n = std::snprintf(
      json, sizeof json,
      "{\"frame_id\":%" PRIu32 ",\"stamp_ns\":%" PRId64 ",\"captured_ns\":%" PRId64
      ",\"translation_m\":[%.17g,%.17g,%.17g],\"rotation_xyzw\":[%.17g,%.17g,%.17g,%.17g],\"pose_fresh\":%s"
      ",\"points\":%zu}",
      frame_id, frame.stamp_ns, captured_ns, pose.t_world_cam.x(), pose.t_world_cam.y(), pose.t_world_cam.z(), q.x(),
      q.y(), q.z(), q.w(), pose_fresh ? "true" : "false", cloud.size());
  if (n > 0 && static_cast<std::size_t>(n) < sizeof json) {
    (void)frames_->record(pose_, wallNs(), {reinterpret_cast<const uint8_t*>(json), static_cast<std::size_t>(n)});
  }
  // Channels built from the frame (foxglove.PointCloud from cloud.points, with
  // cloud.region per point; foxglove.FrameTransform from `pose`) go here, each
  // into a producer of its own made in create().
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
  (void)status_->record(status_channel_, wallNs(), {reinterpret_cast<const uint8_t*>(json), n});
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
