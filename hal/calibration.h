// Calibration of an RGB-D camera from outside the device: what a board profile
// or a calibration file says when the device does not (V4L2 pairs, a libcamera
// colour camera beside a depth source), or says better. Types only here; the
// parsers (ROS camera_info YAML, OpenCV FileStorage YAML, the board profile's
// keys) validate and return these with messages that name the file and field.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "core/result.h"
#include "hal/frame.h"

namespace fovea::hal {

// Lens distortion of one camera. kPlumbBob is OpenCV's and ROS's five-term
// Brown-Conrady model (k1, k2, p1, p2, k3) applied to normalised coordinates
// (x/z, y/z) before the pinhole; kNone leaves them as they are.
struct Distortion {
  enum class Model : uint8_t { kNone, kPlumbBob };
  Model model = Model::kNone;
  std::array<double, 5> coeffs{};  // k1, k2, p1, p2, k3
  // kNone, or every coefficient zero.
  bool isIdentity() const {
    if (model == Model::kNone) return true;
    for (double c : coeffs) {
      if (c != 0.0) return false;
    }
    return true;
  }
};

// One camera's pinhole model and distortion.
struct StreamCalibration {
  CameraIntrinsics intrinsics;
  Distortion distortion;
};

// What is known about a camera from outside it; every part optional, so a file
// can give the colour camera alone and the device the rest. Depth images are
// taken as undistorted (RealSense and Orbbec rectify depth on the device).
struct CameraCalibration {
  std::optional<StreamCalibration> depth;
  std::optional<StreamCalibration> colour;
  // p_colour = R_colour_depth * p_depth + t_colour_depth (metres).
  std::optional<Pose> T_colour_depth;
  std::optional<double> depth_scale_m;
  std::string source;  // where it came from, for messages ("d435.yaml", "board rpi5-usb-rgbd")

  bool empty() const { return !depth && !colour && !T_colour_depth && !depth_scale_m; }
};

}  // namespace fovea::hal
