// A recorded TUM RGB-D sequence as a camera (https://cvg.cit.tum.de/data/datasets/rgbd-dataset).
// Spec "tum:PATH[,loop=on|off|bounce,realtime=on|off,frames=N,groundtruth=auto|on|off,intrinsics=fr1|fr2|fr3|ros]",
// PATH the sequence folder holding associations.txt (`t_rgb rgb/x.png t_depth
// depth/y.png` per line; without it, rgb.txt and depth.txt are paired here as
// TUM's associate.py pairs them), rgb/*.png (8-bit RGB), depth/*.png (16-bit,
// 5000 units per metre, 0 = no measurement) and groundtruth.txt (`timestamp tx
// ty tz qx qy qz qw`; optional unless groundtruth=on).
//
// - Intrinsics: by the sensor the folder's name says (freiburg1, 2 or 3; fr3 when
//   none: fx 535.4, fy 539.2, cx 320.1, cy 247.6, 640x480), or intrinsics=...; the
//   fr3 images are already undistorted and depth is registered to colour.
// - Pose: groundtruth.txt gives T_world_cam (OpenCV camera axes: x right, y down,
//   z forward), the convention of hal::Pose. It is interpolated at the depth
//   timestamp by hal::interpolatePose (hal/pose.h). A frame up to
//   kPoseClampNs outside the ground truth's time span takes the nearest pose
//   (the slice in shared/data starts 9 ms before its first pose); frames farther
//   out are skipped at open() and counted (framesWithoutPose()).
// - Memory: libpng allocates internally on every decode, so open() decodes every
//   frame into memory (1.5 MB per 640x480 frame: 92 MB for 60 frames) and
//   acquire() only copies, allocating nothing. frames=N keeps the first N frames
//   to bound that for long sequences.
// - Time: stamp_ns is the depth timestamp in ns on the recording's clock, plus
//   one recording length (and one mean frame period) per completed loop so it
//   keeps increasing; realtime=on paces acquire() to those stamps.
// - loop=bounce plays the recording forwards, then backwards, and so on (its
//   ends not repeated), each frame stamped the recorded gap to the one before
//   it later: the camera's path stays continuous, where loop=on jumps from the
//   last pose to the first (a tracker without an outside pose is lost there;
//   fovea-eval's tum-track dataset).
// - After the last frame with loop=off, acquire() returns kUnavailable
//   ("end of recording") and finished() is true.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

#include "hal/camera.h"
#include "hal/pose.h"  // StampedPose, interpolatePose

namespace fovea::hal::tum {

inline constexpr int kWidth = 640;
inline constexpr int kHeight = 480;
inline constexpr double kFx = 535.4;
inline constexpr double kFy = 539.2;
inline constexpr double kCx = 320.1;
inline constexpr double kCy = 247.6;
inline constexpr double kDepthScaleM = 1.0 / 5000.0;
inline constexpr int64_t kPoseClampNs = 20'000'000;  // TUM's own association tolerance

// The benchmark's published colour intrinsics by sensor (depth is registered to
// colour): Freiburg 1, 2 and 3, and ROS's defaults that TUM suggests when the
// sensor is unknown. fr1 and fr2 images also have lens distortion, which fovea
// does not undo (fr3's are already undistorted).
enum class TumSensor : uint8_t { kFr1, kFr2, kFr3, kRos };
CameraIntrinsics tumIntrinsics(TumSensor sensor);
// The sensor a sequence's folder names ("rgbd_dataset_freiburg1_desk": kFr1);
// kFr3 when none does (the slice in shared/data is fr3).
TumSensor tumSensorForPath(std::string_view path);

struct TumCameraOptions {
  std::string path;
  bool loop = true;
  bool realtime = false;
  std::size_t max_frames = 0;  // 0: all
  bool bounce = false;  // loop=bounce (loop is then true too)
  // groundtruth.txt: required (on), not read (off), or read when it is there
  // (auto, the default: a sequence whose ground truth is withheld, tracked by
  // fovead map --pose track, still plays; its frames' poses are the identity).
  enum class GroundTruth : uint8_t { kAuto, kOn, kOff };
  GroundTruth groundtruth = GroundTruth::kAuto;
  // intrinsics=fr1|fr2|fr3|ros; unset: by the folder's name (tumSensorForPath).
  std::optional<TumSensor> sensor = std::nullopt;
};

// Pairs each depth stamp with the nearest colour stamp within max_difference_ns,
// one to one, as TUM's associate.py does (candidates by increasing difference,
// each stamp used once); the pairs in depth order. For a sequence without
// associations.txt (rgb.txt and depth.txt are what TUM publishes).
struct TumAssociation {
  std::size_t rgb = 0, depth = 0;  // indexes into the two lists
};
std::vector<TumAssociation> associateTumStamps(const std::vector<int64_t>& rgb_ns, const std::vector<int64_t>& depth_ns,
                                               int64_t max_difference_ns = 20'000'000);

// Parses "PATH[,loop=on|off|bounce,realtime=on|off,frames=N,...]" (the spec after "tum:").
Result<TumCameraOptions> parseTumCameraOptions(std::string_view args);
std::string tumCameraHelp();

// A TUM timestamp ("1341841873.405990", seconds with up to 9 decimals) in ns,
// parsed exactly (a double holds such a stamp only to ~0.2 us).
Result<int64_t> parseTumTimestampNs(std::string_view text);

// Reads groundtruth.txt lines (comments with '#'); stamps must increase.
// kParseError naming the line otherwise.
Result<std::vector<StampedPose>> parseGroundTruth(std::string_view text, const std::string& path_for_errors);

class TumCamera final : public Camera {
 public:
  explicit TumCamera(TumCameraOptions options);
  static Result<std::unique_ptr<Camera>> create(std::string_view args);

  // Reads the lists and ground truth and decodes every frame. kNotFound naming
  // the path for a missing folder or file, kParseError naming the file for a
  // malformed list, a corrupt PNG or an image that is not 640x480.
  Status open() override;
  Status start() override;
  Status acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) override;
  void stop() override;

  const CameraInfo& info() const override { return info_; }
  CameraCounters counters() const override { return counters_.snapshot(); }

  std::size_t frameCount() const { return frames_.size(); }
  std::size_t framesWithoutPose() const { return frames_without_pose_; }
  bool finished() const { return finished_; }

 private:
  struct Frame {
    int64_t depth_stamp_ns = 0;
    Pose pose;
    std::vector<uint16_t> depth;
    std::vector<uint8_t> rgb;
  };
  // open()'s list-and-decode step; poses is nullptr without ground truth.
  Status readFrames(const std::filesystem::path& folder, bool have_associations,
                    const std::vector<StampedPose>* poses);
  // acquire()'s step to the frame after next_: its index, direction and stamp.
  void advance();

  TumCameraOptions options_;
  CameraInfo info_;
  std::vector<Frame> frames_;
  std::size_t frames_without_pose_ = 0;
  int64_t loop_period_ns_ = 0;  // first-to-last span plus one mean frame period

  bool opened_ = false;
  bool started_ = false;
  bool finished_ = false;
  std::size_t next_ = 0;  // index of the next frame
  int64_t next_stamp_ns_ = 0;  // ... and its stamp
  bool backwards_ = false;     // loop=bounce: playing towards the first frame
  int64_t period_ns_ = 0;      // the recording's mean frame period
  uint64_t sequence_ = 0;
  std::chrono::steady_clock::time_point start_time_;
  int64_t start_stamp_ns_ = 0;

  CameraCounterSet counters_;
};

}  // namespace fovea::hal::tum
