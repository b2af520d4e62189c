// Foxglove's messages as Protobuf (docs/foxglove.md): encoders for
// foxglove.PointCloud, foxglove.FrameTransform, foxglove.Log and the gaze as a
// foxglove.SceneUpdate (one arrow), and the schemas a reader needs to decode them.
//
// The .proto files come from the @foxglove/schemas npm package at build time
// (io/foxglove/CMakeLists.txt); each schema's data is protoc's
// FileDescriptorSet of the message with everything it imports, which is what an
// MCAP schema record (encoding "protobuf") and a Foxglove WebSocket
// advertisement (schemaEncoding "protobuf") carry.
//
// Each encoder keeps its message and its output buffer: after the first
// messages of the largest size, encode() allocates nothing. The returned bytes
// are valid until the encoder's next encode().
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>

#include "pipeline/point_cloud.h"

namespace fovea::foxglove {

struct Schema {
  std::string_view name;                   // "foxglove.PointCloud"
  std::string_view encoding = "protobuf";  // the schema's encoding (MCAP) / schemaEncoding (WebSocket)
  std::span<const uint8_t> data;           // FileDescriptorSet, with imports
};

// The topics of Foxglove's messages, one set for every place that publishes
// them: fovead serve --record's file, fovea-operator --foxglove and --record.
inline constexpr std::string_view kCloudTopic = "/fovea/cloud";       // foxglove.PointCloud, frame "world"
inline constexpr std::string_view kCameraTopic = "/fovea/camera";     // foxglove.FrameTransform world -> camera
inline constexpr std::string_view kHeadTopic = "/fovea/head";         // foxglove.FrameTransform world -> head
inline constexpr std::string_view kGazeRayTopic = "/fovea/gaze_ray";  // foxglove.SceneUpdate, the gaze as an arrow
inline constexpr std::string_view kLogTopic = "/fovea/log";           // foxglove.Log
inline constexpr std::string_view kWorldFrame = "world";

// The message encoding of every message here (MCAP's message_encoding, the
// WebSocket channel's encoding).
inline constexpr std::string_view kMessageEncoding = "protobuf";

Schema pointCloudSchema();
Schema frameTransformSchema();
Schema logSchema();
Schema sceneUpdateSchema();
// The FileDescriptorSet of "foxglove.<Message>" for the messages above; empty for any other name.
std::span<const uint8_t> schemaData(std::string_view name);

// A point cloud: each point x, y, z (float32, relative to the pose's position)
// and rgba (uint32, 0xAARRGGBB, as Foxglove's 3D panel and rviz read a packed
// "rgba" field: little-endian bytes blue, green, red, alpha); 16 bytes a point.
inline constexpr uint32_t kPointStride = 16;

class PointCloudEncoder {
 public:
  PointCloudEncoder();
  ~PointCloudEncoder();
  PointCloudEncoder(PointCloudEncoder&&) noexcept;
  PointCloudEncoder& operator=(PointCloudEncoder&&) noexcept;

  // The cloud's points in frame_id: the message's pose is the cloud's origin_m
  // (so the float coordinates are kept as they are), colour from the packed rgb
  // (opaque; grey when the cloud has none).
  std::span<const uint8_t> encode(const pipeline::PointCloud& cloud, std::string_view frame_id, int64_t stamp_ns);
  // Room for clouds of up to `points` now, so that no later cloud allocates
  // (a larger cloud than any before would grow the buffers).
  void reserve(std::size_t points);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

class FrameTransformEncoder {
 public:
  FrameTransformEncoder();
  ~FrameTransformEncoder();
  FrameTransformEncoder(FrameTransformEncoder&&) noexcept;
  FrameTransformEncoder& operator=(FrameTransformEncoder&&) noexcept;

  // child's pose in parent: translation (m) and rotation (quaternion w, x, y, z).
  std::span<const uint8_t> encode(std::string_view parent, std::string_view child, const std::array<double, 3>& translation,
                                  const std::array<double, 4>& rotation_wxyz, int64_t stamp_ns);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// foxglove.Log's levels.
enum class LogLevel : int { kDebug = 1, kInfo = 2, kWarning = 3, kError = 4, kFatal = 5 };

class LogEncoder {
 public:
  LogEncoder();
  ~LogEncoder();
  LogEncoder(LogEncoder&&) noexcept;
  LogEncoder& operator=(LogEncoder&&) noexcept;

  std::span<const uint8_t> encode(LogLevel level, std::string_view message, std::string_view name, int64_t stamp_ns);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The gaze as a ray: a SceneUpdate with one entity (id "gaze") holding one
// arrow from the eye along the gaze direction.
class GazeRayEncoder {
 public:
  GazeRayEncoder();
  ~GazeRayEncoder();
  GazeRayEncoder(GazeRayEncoder&&) noexcept;
  GazeRayEncoder& operator=(GazeRayEncoder&&) noexcept;

  // direction need not be normalised (a zero one points along +x); length_m: the arrow's.
  std::span<const uint8_t> encode(std::string_view frame_id, const std::array<double, 3>& origin_m,
                                  const std::array<double, 3>& direction, double length_m, int64_t stamp_ns);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fovea::foxglove
