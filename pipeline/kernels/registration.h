// Colour registered to depth, for cameras whose device does not do it (two V4L2
// nodes, a libcamera colour camera beside a depth source): hal::RgbdFrame
// promises an RGB8 image the size of the depth image, pixel for pixel.
//
// For each depth pixel with a measurement: the 3D point through the depth
// intrinsics, moved into the colour camera by T_colour_depth, projected through
// the colour intrinsics (and the colour camera's plumb-bob distortion), and the
// nearest colour pixel copied. Pixels without depth, or whose point lands behind
// the colour camera or outside its image, get black and are counted.
//
// registerRef is the specification, in float with a fixed operation order and no
// fused multiply-add; registerSimd (Highway, dynamic dispatch) reproduces it bit
// for bit. Both write every output pixel and never allocate.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "hal/calibration.h"
#include "hal/frame.h"
#include "hal/result.h"
#include "pipeline/kernels/kernel_set.h"

namespace fovea::pipeline {

struct RegistrationParams {
  hal::StreamCalibration depth;   // depth images are taken as undistorted
  hal::StreamCalibration colour;
  hal::Pose T_colour_depth;       // p_colour = R * p_depth + t (metres)
  double depth_scale_m = 0.001;   // metres per depth unit
};

struct RegistrationCounts {
  std::size_t with_depth = 0;      // depth pixels with a measurement
  std::size_t coloured = 0;        // of those, given a colour pixel
  std::size_t outside_colour = 0;  // of those, behind the colour camera or outside its image
};

class DepthToColourRegistration {
 public:
  // Validates the parameters (sizes, focal lengths, a rotation that is one,
  // finite values) with a message naming the field, and allocates the per-pixel
  // tables for the depth image.
  static Result<DepthToColourRegistration> create(const RegistrationParams& params);

  const RegistrationParams& params() const { return params_; }

  // depth: depth.width x depth.height units; colour_rgb: colour.width x
  // colour.height RGB8, row-major; out_rgb: depth.width x depth.height RGB8.
  RegistrationCounts registerRef(const uint16_t* depth, const uint8_t* colour_rgb, uint8_t* out_rgb) const;
  RegistrationCounts registerSimd(const uint16_t* depth, const uint8_t* colour_rgb, uint8_t* out_rgb) const;
  // The kernel set's choice (FOVEA_FORCE_KERNEL=ref forces the reference).
  RegistrationCounts apply(const uint16_t* depth, const uint8_t* colour_rgb, uint8_t* out_rgb,
                           KernelSet kernels = defaultKernelSet()) const;

 private:
  RegistrationParams params_;
  // Per depth pixel, what does not change from frame to frame (the ray through
  // the pixel, in float), precomputed at create().
  std::vector<float> ray_x_;
  std::vector<float> ray_y_;
};

}  // namespace fovea::pipeline
