// A UVC depth camera through V4L2: spec "v4l2:DEPTH[,key=value...]", DEPTH the
// depth node as /dev/videoN, serial=SERIAL (the USB serial) or bus=BUS_INFO
// (VIDIOC_QUERYCAP's bus_info, "usb-0000:01:00.0-1", or the USB port "1-1");
// see v4l2CameraHelp() for the options and docs/cameras-v4l2.md for cameras.
//
// - Depth: Z16 or Y16 (see pixel_formats.h) through raw ioctls, copied into the
//   slot as uint16 units of depth_scale_m (default 0.001: millimetres).
// - Colour: none by default (has_rgb false: the pipeline makes uncoloured
//   clouds). colour=auto takes the colour node of the depth node's USB device
//   (a RealSense or Orbbec exposes depth and colour as sibling nodes),
//   colour=/dev/videoM|serial=..|bus=.. a named one. Colour frames are
//   converted to RGB into a few slots allocated at open, paired with each
//   depth frame by timestamp (hal::TimestampPairer; tolerance
//   pair_tolerance_ms, default half the depth frame period) and registered to
//   the depth image (hal::DepthToColourRegistration). A depth frame
//   without colour in time is dropped and counted; kMaxUnpairedDepth in a row
//   fail acquire() with kInvalidInput (a counted error) so the capture retry
//   sees the fault.
// - Calibration: a V4L2 node reports no intrinsics. They come from
//   setCalibration() (board profile), calib=FILE, or, explicitly
//   approximate, hfov_deg=D (and colour_hfov_deg=D): a pinhole with square
//   pixels and a centred principal point from the datasheet's horizontal field
//   of view. Colour also needs the depth-to-colour extrinsics, or
//   extrinsics=identity to accept colour shifted by the camera's baseline.
//   Without them open() refuses with a message saying what to give: a wrong
//   guess would put every point in the wrong place without a word.
// - Memory: open() maps `buffers` streaming buffers per node
//   (CameraInfo::device_buffer_bytes) and allocates the colour slots;
//   acquire() allocates nothing (MJPEG aside: libjpeg-turbo's per-image
//   working memory, see pixel_formats.h).
// - Time: stamp_ns is the driver's buffer timestamp when it is
//   CLOCK_MONOTONIC (uvcvideo, vivid), else the dequeue time.
// - Reconnection: a node that vanishes (unplugged, driver unloaded) makes
//   acquire() return kNotFound (a disconnect). open() finds the device again
//   by serial or bus path, and a camera named by path whose node now belongs
//   to something else (or is gone) is looked for under the bus_info and
//   serial seen at the first open, so it is found under another /dev/videoN.
// - Pose: identity (the world is the camera's frame); the service's pose
//   source sets it.
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
#include "hal/camera/v4l2/node_selection.h"
#include "hal/camera/v4l2/pixel_formats.h"
#include "hal/camera/v4l2/sysfs.h"
#include "hal/camera/v4l2/v4l2_node.h"
#include "hal/camera/v4l2/v4l2_options.h"

namespace fovea::hal {
class DepthToColourRegistration;
}

namespace fovea::hal::v4l2 {

inline constexpr int kColourSlots = 4;
inline constexpr int kMaxUnpairedDepth = 30;

std::string v4l2CameraHelp();

// Every capture node that offers depth (Z16/Y16) with its modes and colour
// siblings, and colour-only nodes, with the spec to paste. No nodes: an empty
// list. Permission denied on a node: an error naming the video group and the
// udev rule.
Result<std::vector<DeviceListing>> discoverV4l2Cameras();
Result<std::vector<DeviceListing>> discoverV4l2CamerasIn(const V4l2Paths& paths);

// Depth intrinsics of a pinhole with square pixels and a centred principal
// point from a horizontal field of view (hfov_deg=).
CameraIntrinsics intrinsicsFromHfov(int width, int height, double hfov_deg);

class V4l2Camera final : public Camera {
 public:
  explicit V4l2Camera(V4l2CameraOptions options, V4l2Paths paths = {});
  ~V4l2Camera() override;
  static Result<std::unique_ptr<Camera>> create(std::string_view args);

  Status open() override;
  Status start() override;
  Status acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) override;
  void stop() override;
  Status setCalibration(const CameraCalibration& calibration) override;
  // A USB port reset of the camera's device (hal/usb), found by the port seen
  // at the last open(); call after stop(). kUnavailable when the node is not
  // on USB or fovea has no USB support.
  Status resetDevice() override;

  const CameraInfo& info() const override { return info_; }
  CameraCounters counters() const override { return counters_.snapshot(); }

  // After open(): the nodes in use.
  const std::string& depthNodePath() const { return depth_.path(); }
  const V4l2Node& colourNode() const { return colour_; }
  bool hasColour() const { return options_.colour.kind != NodeSelector::Kind::kNone; }
  // Pairing of depth with colour since open() (zero without colour).
  PairingCounts pairingCounts() const;

 private:
  Status negotiateDepth();
  Status negotiateColour();
  Status prepareCalibration();
  Result<std::string> resolveDepthPath();
  Result<std::string> resolveColourPath();
  // Takes every colour frame ready now into the pairer; 0 or an errno.
  int drainColour();
  // acquire()'s steps; ok means go on, anything else is what acquire() returns.
  Status takeReadyFrames(bool colour);
  Status pairPendingDepth(std::optional<int>& colour_slot, int64_t& wait_for_colour_ns, bool& dropped);
  Status deliverPendingDepth(RgbdFrame& slot, const std::optional<int>& colour_slot);
  Status waitForNodes(std::chrono::steady_clock::time_point deadline, int64_t wait_for_colour_ns, bool colour);
  Status gone();
  void closeNodes();

  V4l2CameraOptions options_;
  V4l2Paths paths_;
  CameraInfo info_;
  CameraCalibration calibration_;
  V4l2Node depth_{V4l2Node::Io::kRaw};
  V4l2Node colour_{V4l2Node::Io::kLibv4l2};
  UsbIdentity usb_;
  // What the first open found, to find the device again after it re-enumerates.
  SeenNode seen_depth_;
  SeenNode seen_colour_;

  MjpegDecoder mjpeg_;
  std::optional<TimestampPairer> pairer_;
  std::unique_ptr<hal::DepthToColourRegistration> registration_;
  std::vector<std::vector<uint8_t>> colour_rgb_;  // kColourSlots converted colour images
  int64_t colour_period_ns_ = 0;
  bool have_colour_ = false;
  int64_t latest_colour_stamp_ns_ = 0;

  bool opened_ = false;
  bool started_ = false;
  bool pending_ = false;  // a depth buffer dequeued and waiting for its colour
  V4l2Node::Frame pending_depth_;
  int consecutive_unpaired_ = 0;
  bool stalled_ = false;
  uint64_t sequence_ = 0;

  CameraCounterSet counters_;
};

}  // namespace fovea::hal::v4l2
