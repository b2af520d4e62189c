#include "io/foxglove/recording.h"

#include <cstring>
#include <span>

namespace fovea::foxglove {
namespace {

// The raw forms (native byte order: they never leave the process).
struct CloudHeader {
  double origin_m[3];
  uint32_t count;
  uint32_t has_color;
};
struct PoseRecord {
  double translation_m[3];
  double rotation_wxyz[4];
};
struct RayRecord {
  double origin_m[3];
  double direction[3];
};

std::size_t cloudBytes(std::size_t points) { return sizeof(CloudHeader) + points * 16; }

template <class T>
bool readRecord(std::span<const uint8_t> raw, T& out) {
  if (raw.size() != sizeof out) return false;
  std::memcpy(&out, raw.data(), sizeof out);
  return true;
}

template <class T>
std::span<const uint8_t> bytesOf(const T& value) {
  return {reinterpret_cast<const uint8_t*>(&value), sizeof value};
}

}  // namespace

struct RecordingChannels::Encoders {
  explicit Encoders(std::size_t max_points, const RecordingOptions& o)
      : points(max_points), pose_child(o.pose_child), log_name(o.log_name) {
    cloud_encoder.reserve(max_points);
  }

  // The cloud's arrays back into a PointCloud, then foxglove.PointCloud.
  std::span<const uint8_t> cloud(std::span<const uint8_t> raw, uint64_t t) {
    CloudHeader h;
    if (raw.size() < sizeof h) return {};
    std::memcpy(&h, raw.data(), sizeof h);
    if (h.count > points.capacity() || raw.size() != cloudBytes(h.count) || !points.resize(h.count)) return {};
    const uint8_t* p = raw.data() + sizeof h;
    std::memcpy(points.x(), p, h.count * 4);
    std::memcpy(points.y(), p + h.count * 4, h.count * 4);
    std::memcpy(points.z(), p + h.count * 8, h.count * 4);
    std::memcpy(points.rgb(), p + h.count * 12, h.count * 4);
    points.origin_m = {h.origin_m[0], h.origin_m[1], h.origin_m[2]};
    points.has_color = h.has_color != 0;
    return cloud_encoder.encode(points, kWorldFrame, static_cast<int64_t>(t));
  }
  std::span<const uint8_t> pose(std::span<const uint8_t> raw, uint64_t t) {
    PoseRecord r;
    if (!readRecord(raw, r)) return {};
    return pose_encoder.encode(kWorldFrame, pose_child, {r.translation_m[0], r.translation_m[1], r.translation_m[2]},
                               {r.rotation_wxyz[0], r.rotation_wxyz[1], r.rotation_wxyz[2], r.rotation_wxyz[3]},
                               static_cast<int64_t>(t));
  }
  std::span<const uint8_t> ray(std::span<const uint8_t> raw, uint64_t t) {
    RayRecord r;
    if (!readRecord(raw, r)) return {};
    return ray_encoder.encode(kWorldFrame, {r.origin_m[0], r.origin_m[1], r.origin_m[2]},
                              {r.direction[0], r.direction[1], r.direction[2]}, 2.0, static_cast<int64_t>(t));
  }
  std::span<const uint8_t> log(std::span<const uint8_t> raw, uint64_t t) {
    const std::string_view line(reinterpret_cast<const char*>(raw.data()), raw.size());
    return log_encoder.encode(LogLevel::kInfo, line, log_name, static_cast<int64_t>(t));
  }

  pipeline::PointCloud points;
  std::string pose_child;
  std::string log_name;
  PointCloudEncoder cloud_encoder;
  FrameTransformEncoder pose_encoder;
  GazeRayEncoder ray_encoder;
  LogEncoder log_encoder;
};

RecordingChannels::~RecordingChannels() = default;

Result<std::unique_ptr<RecordingChannels>> RecordingChannels::add(mcap::Recorder& m, const RecordingOptions& options) {
  std::unique_ptr<RecordingChannels> r(new RecordingChannels());
  r->encoders_ = std::make_unique<Encoders>(options.max_cloud_points, options);
  r->max_cloud_points_ = options.max_cloud_points;
  using Method = std::span<const uint8_t> (Encoders::*)(std::span<const uint8_t>, uint64_t);
  struct Spec {
    std::string_view topic;
    Schema schema;
    Method method;
    uint16_t* channel;
  };
  const Spec specs[] = {{kCloudTopic, pointCloudSchema(), &Encoders::cloud, &r->cloud_channel_},
                        {options.pose_topic, frameTransformSchema(), &Encoders::pose, &r->pose_channel_},
                        {kGazeRayTopic, sceneUpdateSchema(), &Encoders::ray, &r->ray_channel_},
                        {kLogTopic, logSchema(), &Encoders::log, &r->log_channel_}};
  Encoders* encoders = r->encoders_.get();
  for (const Spec& spec : specs) {
    if (spec.channel == &r->cloud_channel_ && options.max_cloud_points == 0) continue;
    Result<uint16_t> schema = m.addSchema(spec.schema.name, spec.schema.encoding, spec.schema.data);
    if (!schema) return schema.status();
    Result<uint16_t> channel = m.addChannel(spec.topic, kMessageEncoding, *schema);
    if (!channel) return channel.status();
    *spec.channel = *channel;
    const Method method = spec.method;
    if (Status s = m.setTranscoder(*channel, [encoders, method](std::span<const uint8_t> raw, uint64_t t) {
          return (encoders->*method)(raw, t);
        });
        !s) {
      return s;
    }
  }
  return r;
}

std::size_t RecordingChannels::cloudRecordBytes() const { return cloudBytes(max_cloud_points_); }

bool RecordingChannels::recordCloud(mcap::RecorderProducer& producer, uint64_t t, const pipeline::PointCloud& c) {
  if (cloud_channel_ == 0) return false;
  const CloudHeader h{{c.origin_m.x(), c.origin_m.y(), c.origin_m.z()}, static_cast<uint32_t>(c.size()),
                      c.has_color ? 1u : 0u};
  const std::size_t n = c.size();
  const std::span<const uint8_t> parts[] = {
      bytesOf(h),
      {reinterpret_cast<const uint8_t*>(c.x()), n * 4},
      {reinterpret_cast<const uint8_t*>(c.y()), n * 4},
      {reinterpret_cast<const uint8_t*>(c.z()), n * 4},
      {reinterpret_cast<const uint8_t*>(c.rgb()), n * 4},
  };
  return producer.record(cloud_channel_, t, parts);
}

bool RecordingChannels::recordPose(mcap::RecorderProducer& producer, uint64_t t, const std::array<double, 3>& tr,
                                   const std::array<double, 4>& q) {
  const PoseRecord r{{tr[0], tr[1], tr[2]}, {q[0], q[1], q[2], q[3]}};
  return producer.record(pose_channel_, t, bytesOf(r));
}

bool RecordingChannels::recordRay(mcap::RecorderProducer& producer, uint64_t t, const std::array<double, 3>& o,
                                  const std::array<double, 3>& d) {
  const RayRecord r{{o[0], o[1], o[2]}, {d[0], d[1], d[2]}};
  return producer.record(ray_channel_, t, bytesOf(r));
}

bool RecordingChannels::recordLog(mcap::RecorderProducer& producer, uint64_t t, std::string_view line) {
  return producer.record(log_channel_, t, {reinterpret_cast<const uint8_t*>(line.data()), line.size()});
}

}  // namespace fovea::foxglove
