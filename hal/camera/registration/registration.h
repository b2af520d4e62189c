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
//
// The arithmetic (float; every line one IEEE operation, in this order):
//   z = float(raw) * scale
//   X = qx * z + tx;  Y = qy * z + ty;  Z = qz * z + tz
//       where (qx, qy, qz) = R * ((u - cx) / fx, (v - cy) / fy, 1) per depth
//       pixel, computed in double at create() and rounded to float
//   behind unless Z > 0 (a NaN is behind too)
//   a = X / Z;  b = Y / Z                          (IEEE division, correctly rounded)
//   plumb-bob (skipped when the colour distortion is the identity):
//     aa = a * a;  bb = b * b;  ab = a * b;  r2 = aa + bb
//     radial = ((k3 * r2 + k2) * r2 + k1) * r2 + 1
//     a' = a * radial + (2p1 * ab + p2 * (r2 + (aa + aa)))
//     b' = b * radial + (p1 * (r2 + (bb + bb)) + 2p2 * ab)    (2p1, 2p2: float(2 * p))
//   hu = (fx * a' + cx) + 0.5;  hv = (fy * b' + cy) + 0.5
//   inside when 0 <= hu < width and 0 <= hv < height (false for NaN); then the
//   colour pixel is (int(hu), int(hv)): truncation of a non-negative value is
//   floor, so this is the nearest pixel with halves rounded up.
// No float-to-int conversion ever sees a value outside the image.
// The plumb-bob polynomial is trusted as the calibration gives it: like OpenCV's
// projectPoints, a point far outside the calibrated field of view can fold back
// into the image under strong distortion.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/kernel_set.h"
#include "core/result.h"
#include "hal/calibration.h"
#include "hal/frame.h"

namespace fovea::hal {

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

  // What registerRef and the SIMD kernel read: the float constants and the
  // per-pixel rotated rays (padded to a multiple of any vector width).
  struct Kernel {
    int depth_width = 0, depth_height = 0, colour_width = 0, colour_height = 0;
    float scale = 0, tx = 0, ty = 0, tz = 0;
    float fx = 0, fy = 0, cx = 0, cy = 0;
    bool distort = false;
    float k1 = 0, k2 = 0, k3 = 0, p1 = 0, p2 = 0, two_p1 = 0, two_p2 = 0;
    const float* qx = nullptr;
    const float* qy = nullptr;
    const float* qz = nullptr;
  };
  Kernel kernel() const;

  // depth: depth.width x depth.height units; colour_rgb: colour.width x
  // colour.height RGB8, row-major; out_rgb: depth.width x depth.height RGB8.
  RegistrationCounts registerRef(const uint16_t* depth, const uint8_t* colour_rgb, uint8_t* out_rgb) const;
  RegistrationCounts registerSimd(const uint16_t* depth, const uint8_t* colour_rgb, uint8_t* out_rgb) const;
  // The kernel set's choice (FOVEA_FORCE_KERNEL=ref forces the reference).
  RegistrationCounts apply(const uint16_t* depth, const uint8_t* colour_rgb, uint8_t* out_rgb,
                           KernelSet kernels = defaultKernelSet()) const;

 private:
  RegistrationParams params_;
  // Per depth pixel, what does not change from frame to frame: the ray through
  // the pixel rotated into the colour camera, (qx, qy, qz) = R * (x/z, y/z, 1),
  // precomputed at create() (12 bytes a pixel: 3.7 MB at 640x480).
  std::vector<float> ray_x_;
  std::vector<float> ray_y_;
  std::vector<float> ray_z_;
  Kernel constants_;  // without the table pointers (kernel() adds them), so copies stay right
};

namespace kernels {
// The SIMD body (registration_simd.cpp); the counts as registerRef's.
RegistrationCounts registerSimdDispatch(const DepthToColourRegistration::Kernel& k, const uint16_t* depth,
                                        const uint8_t* colour_rgb, uint8_t* out_rgb);
}  // namespace kernels

}  // namespace fovea::hal
