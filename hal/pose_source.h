// Where the camera is in the world, frame by frame (docs/pose.md):
//  - kNone: the pose the camera reports stays (identity for a real camera: the
//    world is the camera's frame; a mock or a TUM recording knows its own).
//  - kFixed: a fixed mount, T_world_cam from the board profile.
//  - kSocket: the robot's localisation sends timestamped poses to a Unix
//    datagram socket, one ASCII pose per datagram:
//        "stamp_ns tx ty tz qx qy qz qw\n"
//    stamp_ns on CLOCK_MONOTONIC (the frames' clock; Python: time.monotonic_ns()),
//    the pose of the robot in the world (metres, quaternion x y z w). The
//    camera's pose is that pose times the mount (T_world_cam = T_world_robot *
//    T_robot_cam; the mount defaults to the identity: the sender sends the
//    camera's own pose).
//
// apply() drains the socket without blocking (no thread: the capture thread
// does it once per frame) into a ring of `capacity` poses allocated by
// create(), then interpolates the frame's pose at its capture stamp (linear
// translation, slerp). A frame is stale when no pose was received, or when its
// stamp lies more than max_age_ns beyond the newest pose (the localisation
// stopped or lags) or before the oldest one kept: it keeps the nearest pose
// there is (the newest, or the oldest), or the camera's own when none came
// yet, and apply() returns false; the service raises its fault line while
// frames are stale (docs/pose.md: keep the frame, flag the fault).
//
// Counted, never logged per datagram: malformed datagrams (not 8 numbers, not
// finite, a quaternion far from unit length, longer than 255 bytes), stamps
// that do not increase (dropped), poses dropped from a full ring (the oldest
// go), and frames posed fresh and stale. Nothing allocates after create().
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"
#include "hal/frame.h"
#include "hal/pose.h"

namespace fovea::hal {

struct PoseSourceConfig {
  enum class Kind : uint8_t { kNone, kFixed, kSocket };
  Kind kind = Kind::kNone;
  // kFixed: T_world_cam. kSocket: the camera's mount on the robot, T_robot_cam.
  Pose pose;
  std::string socket_path;              // kSocket
  int64_t max_age_ns = 100'000'000;     // how far beyond the newest pose a frame may be
  std::size_t capacity = 256;           // poses kept (at 200 Hz: 1.3 s)
};

std::string_view poseSourceKindName(PoseSourceConfig::Kind kind);

struct PoseCounters {
  uint64_t received = 0;      // poses accepted into the ring
  uint64_t malformed = 0;     // datagrams that were no pose
  uint64_t out_of_order = 0;  // stamps not after the newest one: dropped
  uint64_t overwritten = 0;   // the ring was full: the oldest pose was dropped
  uint64_t frames_fresh = 0;  // frames given an interpolated (or held, within max_age) pose
  uint64_t frames_stale = 0;  // frames given the nearest pose there was, or none
};

// The longest datagram accepted: a pose is ~120 bytes of text.
inline constexpr std::size_t kMaxPoseDatagramBytes = 255;

// Parses one datagram ("stamp_ns tx ty tz qx qy qz qw", whitespace separated,
// a trailing newline allowed). False when malformed; the quaternion is
// normalised (hal::normalisedQuaternion). Never allocates.
[[nodiscard]] bool parsePoseDatagram(std::string_view text, StampedPose& out);

class PoseSource {
 public:
  // kSocket: binds the socket (a stale socket file left by a dead process is
  // replaced; one another process still serves is an error), allocates the ring.
  // kInvalidArgument for a bad configuration, kNotFound when the socket's
  // folder is missing, kIoError when binding fails (naming the path and why).
  static Result<std::unique_ptr<PoseSource>> create(const PoseSourceConfig& config);
  ~PoseSource();  // closes and removes the socket
  PoseSource(const PoseSource&) = delete;
  PoseSource& operator=(const PoseSource&) = delete;

  // Sets frame.T_world_cam for frame.stamp_ns (kNone: leaves it). False when
  // the pose is stale (see above). Never allocates; capture thread only.
  bool apply(RgbdFrame& frame);
  // The same for a stamp, for tests and tools: out is set unless nothing was received.
  bool poseAt(int64_t stamp_ns, Pose& out);
  // Reads every datagram waiting (bounded per call, so a flood cannot hold the
  // capture thread). apply() calls it; tests may too. Never allocates.
  void drain();

  const PoseSourceConfig& config() const { return config_; }
  PoseCounters counters() const;
  // The last apply() was stale (for the supervisor, any thread).
  bool stale() const { return stale_.load(std::memory_order_relaxed); }
  std::size_t size() const { return count_; }  // poses in the ring (capture thread)
  // One line for the log: "socket /run/fovea/pose.sock (ring 256 poses, max age 100 ms)".
  std::string describe() const;

 private:
  explicit PoseSource(const PoseSourceConfig& config);
  const StampedPose& at(std::size_t i) const { return ring_[(head_ + i) % ring_.size()]; }
  void push(const StampedPose& pose);

  PoseSourceConfig config_;
  int fd_ = -1;
  bool bound_ = false;  // the socket file is ours to remove
  std::vector<StampedPose> ring_;
  std::size_t head_ = 0;   // the oldest
  std::size_t count_ = 0;
  std::atomic<bool> stale_{false};
  std::atomic<uint64_t> received_{0}, malformed_{0}, out_of_order_{0}, overwritten_{0}, frames_fresh_{0},
      frames_stale_{0};
};

}  // namespace fovea::hal
