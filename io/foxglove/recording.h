// Foxglove's messages in an MCAP recording (docs/recording.md), one way for
// both ends: fovead serve --record (the camera) and fovea-operator --record (the
// head). A hot path records raw bytes (a cloud's arrays, a pose, a ray, a line)
// into its producer ring; the recorder's writer thread turns them into
// Foxglove's Protobuf with the transcoders added here (mcap::Recorder::
// setTranscoder), so the encoding costs the stages nothing. A raw record that
// makes no message is counted by the recorder (dropped_transcode).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "core/result.h"
#include "io/foxglove/foxglove.h"
#include "io/mcap/recorder.h"
#include "pipeline/point_cloud.h"

namespace fovea::foxglove {

struct RecordingOptions {
  std::size_t max_cloud_points = 0;   // the largest cloud; 0: no cloud channel
  std::string_view pose_topic = kCameraTopic;  // the FrameTransform's topic
  std::string pose_child = "camera";           // ... and its child frame
  std::string log_name = "fovead";             // foxglove.Log's name
};

class RecordingChannels {
 public:
  // Adds the channels (kCloudTopic, pose_topic, kGazeRayTopic, kLogTopic) with
  // their schemas and transcoders to a recorder before its start(). The
  // channels must outlive the recorder's writer thread (close it first).
  static Result<std::unique_ptr<RecordingChannels>> add(mcap::Recorder& recorder, const RecordingOptions& options);
  ~RecordingChannels();

  // The bytes of a producer slot that holds a cloud of max_cloud_points.
  std::size_t cloudRecordBytes() const;

  // From a hot path (never allocates; false: dropped, counted by the producer).
  bool recordCloud(mcap::RecorderProducer& producer, uint64_t log_time_ns, const pipeline::PointCloud& cloud);
  bool recordPose(mcap::RecorderProducer& producer, uint64_t log_time_ns, const std::array<double, 3>& translation_m,
                  const std::array<double, 4>& rotation_wxyz);
  bool recordRay(mcap::RecorderProducer& producer, uint64_t log_time_ns, const std::array<double, 3>& origin_m,
                 const std::array<double, 3>& direction);
  bool recordLog(mcap::RecorderProducer& producer, uint64_t log_time_ns, std::string_view line);

  bool hasCloud() const { return cloud_channel_ != 0; }

 private:
  struct Encoders;
  RecordingChannels() = default;
  std::unique_ptr<Encoders> encoders_;
  std::size_t max_cloud_points_ = 0;
  uint16_t cloud_channel_ = 0, pose_channel_ = 0, ray_channel_ = 0, log_channel_ = 0;
};

}  // namespace fovea::foxglove
