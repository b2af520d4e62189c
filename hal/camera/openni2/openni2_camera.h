// OpenNI2 RGB-D cameras (PrimeSense Carmine, Asus Xtion, Orbbec Astra class) and
// OpenNI2's synthetic device. Spec "openni2:[URI][,key=value...]", see
// openni2CameraHelp() and docs/cameras-openni2.md.
//
// - Runtime: openni::OpenNI::initialize() once per process, reference-counted
//   across cameras (and discovery); shut down when the last user goes.
// - Modes: chosen from the sensor's supported video modes at open(); depth
//   PIXEL_FORMAT_DEPTH_1_MM (depth_scale_m 0.001) or DEPTH_100_UM (0.0001),
//   colour RGB888. No match: an error listing every mode the device offers.
// - Registration: IMAGE_REGISTRATION_DEPTH_TO_COLOR when the device offers it
//   (the depth image is then in the colour camera's view, so the intrinsics are
//   the colour stream's). When it does not (the Dummy device), colour is
//   delivered unregistered only when it has the depth image's size and field of
//   view (said once at open()); otherwise open() refuses with what to do
//   (colour=off, or registration through a calibration once fovea's software
//   registration lands: see docs/cameras-openni2.md).
// - Intrinsics: from the stream's horizontal and vertical fields of view, as
//   OpenNI's own CoordinateConverter does (fx = w / (2 tan(hfov / 2)),
//   cx = w / 2). A calibration (setCalibration) overrides them. A device that
//   reports no field of view (the Dummy reports 0) gets the PrimeSense nominal
//   58 x 45 degrees, said once at open().
// - Time: OpenNI stamps frames in microseconds on the device's clock. stamp_ns
//   is that stamp moved onto CLOCK_MONOTONIC by an offset measured at the first
//   frame after each start() (host receive time minus device stamp), so it is
//   late by that first frame's transport delay (a few ms) and follows the
//   device crystal's drift (tens of ppm) until the next start().
// - Pairing: depth and colour arrive as separate streams and are paired by
//   device stamp (hal::TimestampPairer, tolerance half a frame period).
// - Out of step: when 8 depth frames in a row find no colour frame while
//   colour keeps coming, the streams' stamps disagree for good (the Dummy's
//   colour thread can fall whole frames behind its depth thread under load;
//   its stamps count frames). acquire() returns kUnavailable "out of step",
//   counted as an error; stop() and start() (hal::CaptureRetry's reopen)
//   align them again.
// - Memory: acquire() copies into the caller's slot and the colour slots
//   allocated at open(). libOpenNI2 itself allocates one 24-byte list node
//   every time a frame is given back to its pool (oniFrameRelease, measured);
//   fovea's own code allocates nothing per frame. framesReleased() counts them
//   so tests can bound that allocation exactly.
// - .oni recordings: Debian's OpenNI2 2.2 plays them back without frames and
//   can crash in libOniFile, so open() refuses a .oni URI and says what to use.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "hal/camera.h"
#include "hal/camera/pairing.h"

namespace fovea::hal::openni2 {

struct OpenNI2CameraOptions {
  std::string uri;        // "" : the first device OpenNI2 finds
  int width = 0;          // 0 : the device's default mode
  int height = 0;
  int fps = 0;            // 0 : any
  bool colour = true;
  bool registration = true;
  bool sync = true;       // the device's depth/colour frame sync, where offered
};

// Parses "[URI][,size=WxH,fps=N,colour=on|off,registration=on|off,sync=on|off]"
// (the spec after "openni2:").
Result<OpenNI2CameraOptions> parseOpenNI2CameraOptions(std::string_view args);
std::string openni2CameraHelp();

// The devices OpenNI2 enumerates now (the synthetic "Dummy" device is not
// enumerated by OpenNI2 until something opens it, and never listed here).
Result<std::vector<DeviceListing>> discoverOpenNI2Cameras();

// One video mode of a sensor, as OpenNI2 lists them (pixel_format is
// openni::PixelFormat's value).
struct VideoModeDesc {
  int width = 0;
  int height = 0;
  int fps = 0;
  int pixel_format = 0;
};
std::string describeVideoMode(const VideoModeDesc& mode);  // "640x480 @ 30 fps DEPTH_1_MM"

// The index of the mode to use: of the modes whose format is in `formats`
// (best first), the one of the requested size and fps (0: any); with no size
// requested, `preferred` when it qualifies, else the first that does. An error
// naming `sensor` and listing every mode otherwise.
Result<int> chooseVideoMode(const std::vector<VideoModeDesc>& modes, const std::vector<int>& formats, int width,
                            int height, int fps, const VideoModeDesc& preferred, std::string_view sensor);

// Pinhole intrinsics of a w x h image with the given fields of view (radians),
// OpenNI's convention (principal point at the image centre, w / 2).
CameraIntrinsics intrinsicsFromFov(int width, int height, double hfov_rad, double vfov_rad);

// True when the URI names an .oni recording (by extension, any case).
bool isOniRecordingUri(std::string_view uri);

// Maps device stamps (us) onto CLOCK_MONOTONIC ns: the offset is taken at the
// first stamp after reset() and again when the device clock steps backwards.
class DeviceClockMapper {
 public:
  void reset() { anchored_ = false; }
  int64_t toHostNs(uint64_t device_us, int64_t host_now_ns);
  uint64_t reanchors() const { return reanchors_; }

 private:
  bool anchored_ = false;
  int64_t offset_ns_ = 0;
  int64_t last_device_ns_ = 0;
  uint64_t reanchors_ = 0;
};

class OpenNI2Camera final : public Camera {
 public:
  explicit OpenNI2Camera(OpenNI2CameraOptions options);
  ~OpenNI2Camera() override;
  OpenNI2Camera(const OpenNI2Camera&) = delete;
  OpenNI2Camera& operator=(const OpenNI2Camera&) = delete;

  static Result<std::unique_ptr<Camera>> create(std::string_view args);

  Status open() override;
  Status start() override;
  Status acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) override;
  void stop() override;
  Status setCalibration(const CameraCalibration& calibration) override;

  const CameraInfo& info() const override { return info_; }
  CameraCounters counters() const override { return counters_.snapshot(); }

  // What open() chose, for tests and logs.
  const VideoModeDesc& depthMode() const { return depth_mode_; }
  const VideoModeDesc& colourMode() const { return colour_mode_; }
  bool colourEnabled() const { return colour_enabled_; }
  bool hardwareRegistration() const { return hardware_registration_; }
  // Frames read from OpenNI2 and given back to its pool (each may allocate
  // inside libOpenNI2, see above).
  uint64_t framesReleased() const { return frames_released_; }
  const PairingCounts& pairingCounts() const { return pairer_.counts(); }
  // Open()'s one-time remarks (unregistered colour, nominal field of view).
  const std::vector<std::string>& notes() const { return notes_; }

 private:
  struct Impl;  // the OpenNI2 objects, kept out of this header
  void close();
  // open()'s steps, in order: each returns why open() fails (open() then
  // closes what the steps made).
  Status openDevice();
  Status openDepthStream(const std::string& uri);
  Status openColourStream(const std::string& uri);
  Status chooseIntrinsics(const std::string& uri);
  Status checkUnregisteredColour(const std::string& uri);
  Status readColour();
  Status readDepth(RgbdFrame& slot, bool& delivered);
  bool deliverOldestPending(RgbdFrame& slot);

  OpenNI2CameraOptions options_;
  std::unique_ptr<Impl> impl_;
  CameraInfo info_;
  std::optional<CameraCalibration> calibration_;
  VideoModeDesc depth_mode_;
  VideoModeDesc colour_mode_;
  bool colour_enabled_ = false;
  bool hardware_registration_ = false;
  bool runtime_held_ = false;
  bool opened_ = false;
  bool started_ = false;
  bool depth_seen_ = false;   // a frame came from the stream since start()
  bool colour_seen_ = false;
  std::vector<std::string> notes_;

  std::vector<std::vector<uint8_t>> colour_slots_;  // RGB8 colour frames awaiting their depth frame
  struct PendingDepth {
    std::vector<uint16_t> depth;
    int64_t device_ns = 0;  // device stamp, for pairing
    int64_t host_ns = 0;    // the same on CLOCK_MONOTONIC, for stamp_ns
  };
  std::vector<PendingDepth> pending_;  // depth frames awaiting their colour frame, a ring
  std::size_t pending_head_ = 0;
  std::size_t pending_size_ = 0;
  uint64_t unmatched_run_ = 0;  // consecutive depth frames without colour
  TimestampPairer pairer_{1, 0};
  int64_t newest_colour_ns_ = INT64_MIN;
  DeviceClockMapper clock_;
  uint64_t sequence_ = 0;
  uint64_t frames_released_ = 0;
  std::shared_ptr<std::atomic<bool>> disconnected_;  // set from OpenNI2's thread

  CameraCounterSet counters_;
};

}  // namespace fovea::hal::openni2
