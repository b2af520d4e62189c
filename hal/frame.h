// An RGB-D frame slot: buffers sized once at construction, refilled by a camera
// every frame without allocating.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace fovea::hal {

// Pinhole model, OpenCV/TUM convention: x right, y down, z forward (metres).
struct CameraIntrinsics {
  int width = 0;
  int height = 0;
  double fx = 0.0;
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
};

// Rigid transform taking camera coordinates to world coordinates:
// p_world = R_world_cam * p_cam + t_world_cam. Double, because the world origin
// may be kilometres away (see docs/precision.md).
struct Pose {
  Eigen::Matrix3d R_world_cam = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_world_cam = Eigen::Vector3d::Zero();
};

class RgbdFrame {
 public:
  RgbdFrame() = default;
  // Allocates room for frames up to max_width x max_height.
  RgbdFrame(int max_width, int max_height);

  // Sets the current size; false (and nothing changes) when it exceeds the capacity.
  [[nodiscard]] bool setSize(int width, int height);

  int width() const { return width_; }
  int height() const { return height_; }
  std::size_t pixelCount() const { return static_cast<std::size_t>(width_) * height_; }

  // Row-major, width() x height(); 0 means "no measurement".
  uint16_t* depth() { return depth_.data(); }
  const uint16_t* depth() const { return depth_.data(); }
  // Row-major RGB8 registered to the depth image, 3 bytes per pixel.
  uint8_t* rgb() { return rgb_.data(); }
  const uint8_t* rgb() const { return rgb_.data(); }

  CameraIntrinsics intrinsics;
  double depth_scale_m = 0.001;  // metres per depth unit: 0.001 (mm) or 1/5000 (TUM)
  Pose T_world_cam;
  bool has_rgb = true;
  int64_t stamp_ns = 0;      // capture time, CLOCK_MONOTONIC or the recording's clock
  uint64_t sequence = 0;     // frame counter of the camera

 private:
  int width_ = 0;
  int height_ = 0;
  std::vector<uint16_t> depth_;
  std::vector<uint8_t> rgb_;
};

}  // namespace fovea::hal
