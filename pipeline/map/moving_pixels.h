// Which pixels of a tracked frame show something moving (issue 42; docs/tracking.md,
// "A world that moves"): a surface well in front of the map's surface at that
// place lies in space the map has seen to be free, so it came there since (a
// person, a carried box, a balloon). Its pixels are not fused: the map stays
// static, and a mover never becomes part of the model the next frame is tracked
// against, so it cannot pull the pose along. They still go to the operator as
// the frame's live points. A pixel found moving for settle_frames frames running,
// at a steady depth and colour, is something that stopped: it is fused again, and
// the map takes it in.
//
// Worked at the tracker's second pyramid level (half the frame's width and
// height: a quarter of the pixels, and a mover is large), per pixel i of that
// level (camera-frame vertex p, after tracking):
//   q = R p + t (the frame's camera into the model's), projected into the
//   model's finest level. In front when the model has surfels there: m_z, the
//   nearest surfel's depth among the 4 x 4 finest pixels around the projection
//   (a pixel at an object's edge lands on the background beside it by a rounding
//   or a small pose error, and is not in front of the object itself), and
//   q_z < m_z - max(min_gap_m, gap_sigmas * depthSigma(m_z)). Unknown when no
//   surfel is there (or the projection leaves the model's view); else explained.
//   The regions: each pixel in front grows through its 4-neighbours that are in
//   front or unknown, within region_step_share of each other's depth (where the
//   map knew nothing behind a mover, as at its edges, the mover is still the
//   mover; an explained pixel, such as the floor a person stands on, stops it).
//   A region is a mover when at least half of it is in front and it covers at
//   least min_region_share of the level: the surface a moving camera uncovers
//   beside the few pixels in front at a static object's edge is unknown, not in
//   front, and speckles are not movers.
//   Steady: in a mover the frame before too, with |z - z_before| <=
//   steady_depth_share z and |I - I_before| <= steady_intensity (intensity in
//   [0, 1]) at the same pixel; the age counts the steady frames (1 when not
//   steady), 0 outside a mover. Moving: in a mover, younger than settle_frames.
//   A finest pixel is moving when its 2 x 2 block is.
// The same pixel, not the pixel the camera's motion moves it to: a slow camera
// moves a static object by a pixel or two a frame, which its edges feel (they
// settle later) and its inside does not.
//
// Memory: create() sizes everything for max_width x max_height; update()
// allocates nothing.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"

namespace fovea::pipeline::map {

struct MovingPixelsConfig {
  bool enabled = true;
  // In front of the map's surface by at least this (metres), and by this many
  // times the sensor's noise at the surface's depth (depthSigma()).
  double min_gap_m = 0.10;
  double gap_sigmas = 5.0;
  // A region's neighbouring pixels within this share of each other's depth,
  // and the least share of the pixels a mover covers.
  double region_step_share = 0.02;
  double min_region_share = 0.003;
  // Frames moving at a steady depth and colour before a pixel counts as static
  // again (fused): half a second at 30 fps.
  int settle_frames = 15;
  double steady_depth_share = 0.02;
  double steady_intensity = 0.08;

  Status validate() const;
};

class MovingPixels {
 public:
  // max_width x max_height: the finest level's largest size.
  static Result<MovingPixels> create(int max_width, int max_height, const MovingPixelsConfig& config);

  // The tracked frame at half its size (the tracker's level 1): vertices in
  // its camera (z <= 0: none) and intensity.
  struct FrameIn {
    int width = 0, height = 0;
    const float *x = nullptr, *y = nullptr, *z = nullptr;
    const float* intensity = nullptr;
  };
  // The model's finest level: its camera, depth, and 1 where a surfel gave the pixel.
  struct ModelIn {
    int width = 0, height = 0;
    float fx = 0, fy = 0, cx = 0, cy = 0;
    const float* z = nullptr;
    const uint8_t* from_surfel = nullptr;
  };
  // Marks the frame's moving pixels (R, t: its camera into the model's) and
  // returns how many of the finest level's. carried (null: none): the half
  // level's pixels carried with the camera (carried_pixels.h), moving
  // whatever their class, with no age. A size beyond create()'s marks none.
  uint32_t update(const FrameIn& half, const ModelIn& model, const Eigen::Matrix3f& R, const Eigen::Vector3f& t,
                  const uint8_t* carried = nullptr);
  // No pixel moving, the ages forgotten (the first frame, a lost one, a reset).
  void clear();

  // The finest level's pixels: 1 where the last update() found one moving
  // (width() x height(), twice the half level's).
  const uint8_t* mask() const { return mask_.data(); }
  int width() const { return 2 * half_width_; }
  int height() const { return 2 * half_height_; }
  std::size_t memoryBytes() const;

 private:
  // classify()'s classes, and the flags growMovers() adds.
  static constexpr uint8_t kExplained = 0, kUnknown = 1, kInFront = 2, kVisited = 0x40, kInMover = 0x80;

  MovingPixels() = default;
  // near_: per half-level pixel, the nearest surfel depth of the model's 4 x 4
  // finest pixels around its block; 0 where none has a surfel.
  void nearestModelDepth(const ModelIn& model);
  // Its pass along finest row v into out (column_near_'s row).
  static void nearestAlongRow(const ModelIn& model, int v, float* out);
  // Half-level pixel i against the model's surface: kExplained (also without depth), kUnknown, kInFront.
  uint8_t classify(const FrameIn& half, const ModelIn& model, const Eigen::Matrix3f& R, const Eigen::Vector3f& t,
                   std::size_t i) const;
  // The regions the pixels in front grow, kInMover where they are movers.
  void growMovers(const FrameIn& half);
  // One region from `seed`, kVisited, into queue_[0, returned).
  std::size_t growRegion(const FrameIn& half, std::size_t seed);
  // The ages and the finest level's mask from the movers and the carried
  // pixels (null: none); returns its moving pixels.
  uint32_t age(const FrameIn& half, const uint8_t* carried);

  MovingPixelsConfig config_;
  std::size_t max_half_pixels_ = 0;
  int half_width_ = 0, half_height_ = 0;
  std::vector<uint8_t> mask_;       // the finest level's: 1 moving
  std::vector<uint8_t> class_;      // the half level's: classify()'s, with the flags
  std::vector<uint32_t> queue_;     // growRegion()'s pixels
  std::vector<float> near_;         // nearestModelDepth()'s
  std::vector<float> column_near_;  // ... its pass down the columns (half width, finest height)
  std::vector<uint8_t> age_;        // frames moving, steady (0: not in a mover)
  std::vector<float> depth_;        // the depth it had the frame before
  std::vector<uint8_t> intensity_;  // ... and its intensity, in 1/255
};

}  // namespace fovea::pipeline::map
