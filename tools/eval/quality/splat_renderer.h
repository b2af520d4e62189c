// A deterministic software renderer for point clouds: fovea-eval renders the
// full-resolution reference (FREF) and a foveated cloud from the same VR eye and
// compares the images (image_quality.h), an objective stand-in for a user study.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace fovea::tools::eval {

// Points at or nearer than this along the forward axis are not drawn.
inline constexpr double kNearPlaneM = 0.01;

// A view of the points (not owned).
struct SplatCloud {
  const float* x = nullptr;  // metres, relative to origin_m
  const float* y = nullptr;
  const float* z = nullptr;
  const uint32_t* rgb = nullptr;  // 0x00RRGGBB (pipeline::packRgb)
  const float* size_m = nullptr;  // splat edge length in world metres, > 0
  std::size_t count = 0;
  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();  // added to x, y, z in double
};

// A pinhole eye: square pixels, principal point at the image centre. Pixel
// coordinates are continuous: pixel (i, j) spans [i, i+1) x [j, j+1), so its
// centre is (i + 0.5, j + 0.5) and the principal point (width/2, height/2).
struct EyeCamera {
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();  // the eye, world
  // Columns: right, down, forward (OpenCV: x right, y down, z forward); a rotation.
  Eigen::Matrix3d world_from_eye = Eigen::Matrix3d::Identity();
  int width = 1440, height = 1600;  // one eye of a VR headset
  double horizontal_fov_deg = 100.0;

  double focalPx() const;
  // x right, y down, z = depth along the forward axis.
  Eigen::Vector3d toEye(const Eigen::Vector3d& world) const;
  // The pixel of a point in eye coordinates (eye.z > 0).
  Eigen::Vector2d pixelOfEye(const Eigen::Vector3d& eye) const;
  // The pixel of a world point; false when it is at or behind the near plane.
  bool project(const Eigen::Vector3d& world, Eigen::Vector2d& pixel) const;
  // The unit world direction from the eye through the centre of pixel (x, y).
  Eigen::Vector3d rayThroughPixel(int x, int y) const;
};

// RGB8 and depth (metres along the forward axis; +inf where nothing was drawn).
struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // 3 bytes per pixel, row-major
  std::vector<float> depth;
};

// drawn: splats that reach at least one pixel (whether or not nearer ones hide
// them); skipped_invalid: a non-finite coordinate or a size that is not finite
// and > 0; behind: at or behind the near plane; outside: in front, off the image.
struct RenderCounts {
  std::size_t drawn = 0, skipped_invalid = 0, behind = 0, outside = 0;
};

// Draws every point as a z-buffered, axis-aligned square splat centred on its
// pixel, max(1, round(focalPx * size_m / depth)) pixels a side (at most the
// image's larger side), covering the pixels whose centres are nearest. The
// nearest depth (as float) wins; equal depths go to the lower point index, so the
// image depends on the inputs only. Uncovered pixels get `background`. `out` is
// resized to the camera's image.
RenderCounts renderSplats(const SplatCloud& cloud, const EyeCamera& camera, const std::array<uint8_t, 3>& background,
                          Image& out);

}  // namespace fovea::tools::eval
