// A session recorded with `fovead serve --record FILE.mcap --record-frames` as a
// camera: spec "mcap:FILE[,loop=on|off,realtime=on|off]". It replays the frames
// of the recording's /fovea/frames channel (firmware/frame_record.h: the depth
// and colour images, intrinsics, pose, stamp and sequence exactly as the camera
// gave them), so another preset, another foveation mode or the map runs on what
// a robot saw, bit for bit.
//
// - open() maps the file and reads it through once (io/mcap/reader.h): the
//   frames are counted and checked, the size, intrinsics and frame rate come
//   from them. A file that stops being readable (a power cut, corruption) plays
//   up to its last readable frame; where and why it stopped is in info().model
//   and stopReason(). A file without frames says how to record them.
// - acquire() decodes the next frame straight from the mapped file with the
//   reader of open()'s pass, rewound: it keeps its chunk buffer (grown to the
//   file's largest chunk) and the schemas and channels it met, so acquire()
//   allocates nothing, a loop's restart included.
// - Time: stamp_ns is the recorded stamp, plus one recording length (and one
//   mean frame period) per completed loop; realtime=on paces acquire() to those
//   stamps. The sequence is the recorded one plus the frame count per loop.
// - After the last frame with loop=off, acquire() returns kUnavailable
//   ("end of record") and finished() is true.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "firmware/frame_record.h"
#include "hal/camera.h"
#include "io/mcap/mapped_file.h"
#include "io/mcap/reader.h"

namespace fovea::firmware {

struct McapCameraOptions {
  std::string path;
  bool loop = true;
  bool realtime = false;
};

Result<McapCameraOptions> parseMcapCameraOptions(std::string_view args);
std::string mcapCameraHelp();

class McapCamera final : public hal::Camera {
 public:
  explicit McapCamera(McapCameraOptions options);
  ~McapCamera() override;
  static Result<std::unique_ptr<hal::Camera>> create(std::string_view args);

  Status open() override;
  Status start() override;
  Status acquire(hal::RgbdFrame& slot, std::chrono::nanoseconds timeout) override;
  void stop() override;
  const hal::CameraInfo& info() const override { return info_; }
  hal::CameraCounters counters() const override { return counters_.snapshot(); }

  std::size_t frameCount() const { return frame_count_; }
  bool finished() const { return finished_; }
  // Where the file stopped being readable ("" when it was read to its footer).
  const std::string& stopReason() const { return stop_reason_; }

 private:
  void unmap();
  // The next frame message of the frames channel; false at the end of the file.
  bool nextFrameMessage(std::span<const uint8_t>& data);
  // open()'s steps: the pass through the file (each frame checked and counted),
  // the error of a file without frames, then the frame rate and info().model.
  struct Scan;
  Status scanFrames(Scan& scan);
  void scanFrame(std::span<const uint8_t> data, Scan& scan);
  Status noFramesError(const Scan& scan) const;
  void describeRecording(const Scan& scan);

  McapCameraOptions options_;
  hal::CameraInfo info_;
  mcap::MappedFile file_;
  std::unique_ptr<mcap::Reader> reader_;
  uint16_t frames_channel_ = 0;
  std::size_t frame_count_ = 0;
  std::span<const uint8_t> pending_;  // a frame read but not delivered (a timeout, a small slot)
  int64_t loop_period_ns_ = 0;
  std::string stop_reason_;

  bool opened_ = false;
  bool started_ = false;
  bool finished_ = false;
  uint64_t loops_ = 0;
  std::chrono::steady_clock::time_point start_time_;
  int64_t start_stamp_ns_ = 0;
  bool start_stamp_known_ = false;

  hal::CameraCounterSet counters_;
};

// hal::createCamera with the cameras the firmware adds (mcap:), for every
// program that takes a --camera spec.
Result<std::unique_ptr<hal::Camera>> createCamera(std::string_view spec);
// hal::cameraSpecHelp with the mcap: line.
std::string cameraSpecHelp();

}  // namespace fovea::firmware
