// A libcamera colour camera (a board's camera connector) paired with a depth
// camera from another backend. Spec
// "libcamera:N|ID[,size=WxH,format=F,buffers=N],depth=SPEC", see
// libcameraCameraHelp() and docs/cameras-libcamera.md.
//
// - libcamera delivers colour only, so depth= is required and names a camera
//   of another backend ("depth=v4l2:serial=123,colour=none"); it is created
//   with hal::createCamera() and owned here. depth= takes the rest of the spec
//   (the depth camera's own options have commas), so it comes last.
// - Registration: the colour image is registered to the depth image through
//   the calibration (setCalibration(): the colour camera's intrinsics and
//   distortion, T_colour_depth; depth intrinsics from the depth camera unless
//   the calibration gives them) with hal::DepthToColourRegistration. No
//   calibration: open() says what to give.
// - Pairing: colour frames (libcamera stamps them on CLOCK_MONOTONIC, from the
//   V4L2 buffers) are paired with depth frames by capture time through
//   hal::TimestampPairer (tolerance half a colour frame period). The depth
//   camera must stamp on CLOCK_MONOTONIC too (openni2 and v4l2 do; mock and
//   tum do not, and pair with nothing). A depth frame without a colour frame
//   is delivered without colour (has_rgb false), counted by the pairer.
// - libcamera 0.0.3 (Debian 12): one CameraManager per process,
//   reference-counted; a FrameBufferAllocator at open(), every plane's dmabuf
//   mmap()ed here (0.0.3 has no public mapped-buffer helper); requests
//   completed on libcamera's thread pass to acquire() through a fixed-size
//   queue (mutex and condition variable) allocated at open(), and are queued
//   again after their frame is converted.
// - Formats: the packed RGB formats libcamera's ISPs give (BGR888, RGB888,
//   XBGR8888, XRGB8888; libcamera names them by DRM fourcc, so RGB888 is B, G,
//   R in memory). YUYV and MJPEG (UVC webcams through libcamera's uvcvideo
//   handler) are refused with a pointer to the v4l2 backend, which reads such
//   cameras directly.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "hal/camera.h"
#include "hal/camera/pairing.h"

namespace fovea::hal::libcam {

struct LibcameraCameraOptions {
  std::string camera;     // an index ("0") or a libcamera camera id
  int width = 0;          // 0: the camera's default for the viewfinder role
  int height = 0;
  std::string format;     // "" : the first packed RGB format the camera offers
  int buffers = 4;
  std::string depth_spec;  // required
};

// Parses "N|ID[,size=WxH,format=F,buffers=N],depth=SPEC" (after "libcamera:").
Result<LibcameraCameraOptions> parseLibcameraCameraOptions(std::string_view args);
std::string libcameraCameraHelp();
// The cameras libcamera sees now (an empty list when there are none).
Result<std::vector<DeviceListing>> discoverLibcameraCameras();

// The packed RGB formats this backend converts, by libcamera's name; 0 when
// not one of them. bytes per pixel and where R, G and B sit in a pixel.
struct PackedRgbLayout {
  int bytes_per_pixel = 0;
  int r = 0, g = 0, b = 0;
};
std::optional<PackedRgbLayout> packedRgbLayout(std::string_view libcamera_format_name);
// One frame of a packed RGB format into RGB8 (rows of `stride` bytes); false,
// nothing written, when `bytes` is shorter than the frame needs.
[[nodiscard]] bool packedRgbToRgb8(const PackedRgbLayout& layout, const uint8_t* src, std::size_t bytes,
                                   std::size_t stride, int width, int height, uint8_t* rgb);

// A colour frame source: libcamera's (ColourStream), or a test's.
struct ColourFrame {
  const uint8_t* data = nullptr;  // first plane, mapped
  std::size_t bytes = 0;          // bytes the camera filled
  std::size_t stride = 0;
  int64_t stamp_ns = 0;           // CLOCK_MONOTONIC
  uint64_t token = 0;             // give back with release()
};

class ColourSource {
 public:
  virtual ~ColourSource() = default;
  virtual Status open(const LibcameraCameraOptions& options) = 0;
  virtual Status start() = 0;
  // The next completed frame, waiting up to timeout; kUnavailable on timeout.
  virtual Status next(ColourFrame& frame, std::chrono::nanoseconds timeout) = 0;
  // Gives the frame's buffer back to the camera.
  virtual void release(const ColourFrame& frame) = 0;
  virtual void stop() = 0;
  virtual void close() = 0;

  virtual const std::string& id() const = 0;
  virtual const std::string& model() const = 0;
  virtual int width() const = 0;
  virtual int height() const = 0;
  virtual const PackedRgbLayout& layout() const = 0;
  virtual uint64_t failedFrames() const = 0;  // completed with an error, not delivered
  virtual std::size_t mappedBytes() const = 0;
};

// The colour side: one libcamera camera streaming into mmap()ed buffers.
// Constructed empty; open() does the I/O.
class ColourStream final : public ColourSource {
 public:
  using Frame = ColourFrame;
  ColourStream();
  ~ColourStream() override;
  ColourStream(const ColourStream&) = delete;
  ColourStream& operator=(const ColourStream&) = delete;

  Status open(const LibcameraCameraOptions& options) override;
  Status start() override;
  Status next(Frame& frame, std::chrono::nanoseconds timeout) override;
  void release(const Frame& frame) override;
  void stop() override;
  void close() override;

  const std::string& id() const override;
  const std::string& model() const override;
  int width() const override;
  int height() const override;
  const std::string& formatName() const;
  const PackedRgbLayout& layout() const override;
  uint64_t failedFrames() const override;
  std::size_t mappedBytes() const override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

class LibcameraCamera final : public Camera {
 public:
  // Makes the depth camera from its spec. The backend table (hal/camera.cpp)
  // hands in hal::createCamera, so this library does not link the table that
  // links it (no cycle of static libraries).
  using DepthCameraFactory = Result<std::unique_ptr<Camera>> (*)(std::string_view spec);

  LibcameraCamera(LibcameraCameraOptions options, DepthCameraFactory make_depth);
  // With a given depth camera and colour source (tests).
  LibcameraCamera(LibcameraCameraOptions options, std::unique_ptr<Camera> depth, std::unique_ptr<ColourSource> colour);
  ~LibcameraCamera() override;
  static Result<std::unique_ptr<Camera>> create(std::string_view args, DepthCameraFactory make_depth);

  Status open() override;
  Status start() override;
  Status acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) override;
  void stop() override;
  Status setCalibration(const CameraCalibration& calibration) override;

  const CameraInfo& info() const override { return info_; }
  CameraCounters counters() const override;
  const PairingCounts& pairingCounts() const { return pairer_.counts(); }

 private:
  struct Registration;
  void drainColour(std::chrono::nanoseconds wait);

  LibcameraCameraOptions options_;
  DepthCameraFactory make_depth_ = nullptr;  // null: the depth camera was given
  CameraInfo info_;
  std::optional<CameraCalibration> calibration_;
  std::unique_ptr<Camera> depth_;
  std::unique_ptr<ColourSource> colour_;
  std::unique_ptr<Registration> registration_;
  std::vector<std::vector<uint8_t>> colour_slots_;  // converted RGB8 colour frames
  TimestampPairer pairer_{1, 0};
  int64_t newest_colour_ns_ = INT64_MIN;
  bool opened_ = false;
  bool started_ = false;
  CameraCounterSet counters_;  // this camera's own (depth's are added in counters())
};

}  // namespace fovea::hal::libcam
