// The V4L2 camera's spec, "v4l2:DEPTH[,key=value...]": which node gives depth,
// which gives colour, and the modes to ask them for. Pure parsing, no I/O.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "core/result.h"

namespace fovea::hal::v4l2 {

// How a node is named: a path that may change when the device re-enumerates,
// or something that does not (the USB serial, the bus path V4L2 reports).
struct NodeSelector {
  enum class Kind : uint8_t {
    kNone,    // colour only: no colour node (depth alone, has_rgb false)
    kAuto,    // depth: the first node offering depth (Z16 first); colour: the depth node's USB sibling
    kPath,    // "/dev/video2"
    kSerial,  // "serial=123": the USB device's serial (sysfs)
    kBus,     // "bus=usb-0000:01:00.0-1": VIDIOC_QUERYCAP's bus_info
  };
  Kind kind = Kind::kNone;
  std::string value;  // the path, serial or bus_info
};

// "/dev/video2", "serial=123", "bus=usb-...", "auto", and for colour also "none".
std::string selectorText(const NodeSelector& selector);

// A V4L2 fourcc as its characters without the padding ("Z16", "YUYV").
std::string fourccText(uint32_t fourcc);

struct V4l2CameraOptions {
  NodeSelector depth;
  NodeSelector colour;        // kNone by default
  int width = 0;              // 0: 640x480 when offered, else the node's first size
  int height = 0;
  int fps = 0;                // 0: 30 when offered, else the node's current rate
  uint32_t depth_format = 0;  // V4L2_PIX_FMT_Z16 or _Y16; 0: Z16 when offered, else Y16
  int colour_width = 0;       // 0: as for depth
  int colour_height = 0;
  uint32_t colour_format = 0;  // YUYV, UYVY, MJPG, RGB3 (libv4l2 converts to it), BGR3; 0: the first offered
  double depth_scale_m = 0.001;
  bool depth_scale_given = false;  // depth_scale= overrides a calibration's
  std::string calib_path;          // calib=FILE
  int buffers = 4;                 // mmap streaming buffers per node
  int64_t pair_tolerance_ns = 0;   // 0: half the depth frame period
  // Explicit approximations for a camera without calibration (see v4l2_camera.h).
  double hfov_deg = 0.0;          // depth intrinsics from a horizontal field of view
  double colour_hfov_deg = 0.0;   // colour intrinsics likewise
  bool extrinsics_identity = false;  // extrinsics=identity: colour and depth centres taken as one
};

// Parses the spec after "v4l2:". kInvalidArgument naming the option and the
// accepted forms.
Result<V4l2CameraOptions> parseV4l2CameraOptions(std::string_view args);

}  // namespace fovea::hal::v4l2
