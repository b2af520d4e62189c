// Which pixels of a frame show something carried with the camera (issue 42;
// docs/tracking.md, "Carried with the camera"): a box in a robot's gripper, a
// tool on its arm, the robot's own body in a corner of the view. Such a thing
// is still in the image while the camera moves, so it agrees exactly with "the
// camera did not move"; near the camera it is measured far more precisely than
// the room (the ICP residuals' noise weighting), and it was in the map from the
// first frame, so it is never in front of what the map knows (moving_pixels.h
// cannot find it). Left in, it takes the pose: the mock `carried` scene's
// orbit, 154 mm ATE with every frame reported tracked.
//
// So it is found before the alignment, without a pose, per pixel i of the
// tracker's second pyramid level (half the frame's width and height). Each
// pixel keeps a reference, its depth and intensity when it last changed, and
// an age, the frames since:
//   still:   it has depth now and in its reference, |z - z_ref| <=
//            still_sigmas depthSigma(z) and |I - I_ref| <= still_intensity
//            (intensity in [0, 1]): the age grows by one;
//   else:    the reference becomes this frame's pixel, the age 0.
// Against its reference, not the frame before: at 30 frames a second a slow
// camera changes most of the room by less than the sensor's noise from one
// frame to the next (the mock orbit: 19 % of the pixels), and the room drifts
// out of its reference over a few frames, where a carried thing never does.
// A pixel is still for long when its age is at least h, the frames compared
// since clear() up to still_frames: from the second frame on, so that a thing
// carried from the first frame is found at once (while h is small, still room
// is found with it: the alignment loses some of the room, not the pose). When
// at least min_changed_share of the pixels with depth are not still for long,
// the camera moved (or much of the view did): the pixels still for long are
// grouped into regions (4-neighbours within region_step_share of each other's
// depth), and a region of at least min_region_share of the level whose mean
// depth is within max_depth_m is carried, widened by margin_pixels. Below that
// share nothing is: at rest every pixel is still, nothing tells them apart.
// The carried pixels are left out of the alignment (the tracker clears their
// depth in its frame pyramid) and join the moving pixels (MovingPixels::update's
// `carried`): not fused, not taken into the next model, sent as live points.
// A static surface within reach can be still too while the camera moves, where
// the motion leaves it unchanged (a plain desk under a camera moving along it
// at a fixed height and pitch, the first frames of a slow start); such a
// region is left out as well, which costs the alignment its constraints and
// the map its fusion there meanwhile (docs/tracking.md: none on the suite's
// static scenes, the orbit's turning points being beyond reach).
//
// Memory: create() sizes everything for max_width x max_height; find()
// allocates nothing.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/result.h"

namespace fovea::pipeline::map {

struct CarriedPixelsConfig {
  bool enabled = true;
  // Still: the depth within this many times the sensor's noise at its depth
  // (depthSigma()), the intensity within this, of its reference's; for long:
  // for this many frames (half a second at 30 fps).
  double still_sigmas = 2.0;
  double still_intensity = 0.03;
  int still_frames = 15;
  // The camera moved: at least this share of the pixels with depth not still
  // for long.
  double min_changed_share = 0.5;
  // A region's neighbouring pixels within this share of each other's depth,
  // and the least share of the level's pixels a carried region covers.
  double region_step_share = 0.02;
  double min_region_share = 0.02;
  // ... and its mean depth at most this (metres): what a robot carries is
  // within its arm's reach, where the room's surfaces that an orbit or a slow
  // start leave still for a while mostly are not.
  double max_depth_m = 1.2;
  // Each carried region widened by this many pixels (of the half level): its
  // edge's pixels, mixed with the room behind or changing with the room's
  // shading, are the thing's too, and near the camera they weigh the most.
  int margin_pixels = 2;

  Status validate() const;
};

class CarriedPixels {
 public:
  // max_width x max_height: the finest level's largest size.
  static Result<CarriedPixels> create(int max_width, int max_height, const CarriedPixelsConfig& config);

  // The frame at half its size (the tracker's level 1): depth (z <= 0: none)
  // and intensity in [0, 1].
  struct FrameIn {
    int width = 0, height = 0;
    const float* z = nullptr;
    const float* intensity = nullptr;
  };
  // Ages the frame's pixels against their references, marks the carried ones,
  // and returns how many of the half level's it marked. A size beyond
  // create()'s, or another size than the frame before's, marks none (and
  // starts again).
  uint32_t find(const FrameIn& half);
  // Forgets the references (the next find() marks none).
  void clear();

  // The half level's pixels: 1 where the last find() marked one carried
  // (width() x height()).
  const uint8_t* mask() const { return mask_.data(); }
  int width() const { return width_; }
  int height() const { return height_; }
  // The last find()'s share of the pixels with depth not still for long.
  double changedShare() const { return changed_share_; }
  std::size_t memoryBytes() const;

 private:
  static constexpr uint8_t kStill = 1, kVisited = 2;

  CarriedPixels() = default;
  // The ages against the references (a reference retaken where the pixel
  // changed), and still for long or not into class_; returns the changed share.
  double age(const FrameIn& half);
  // The regions still for long of at least min_region_share, into mask_; their pixels.
  uint32_t markRegions(const FrameIn& half);
  // One region of pixels still for long from `seed`, kVisited, into queue_[0, returned).
  std::size_t growRegion(const FrameIn& half, std::size_t seed);
  // mask_ widened by margin_pixels; returns its pixels.
  uint32_t widen();

  CarriedPixelsConfig config_;
  std::size_t max_pixels_ = 0;
  int width_ = 0, height_ = 0;
  int compared_ = 0;  // frames aged since clear(), up to still_frames
  bool have_references_ = false;
  double changed_share_ = 0.0;
  std::vector<uint8_t> mask_;       // 1 carried
  std::vector<uint8_t> class_;      // age()'s, with kVisited
  std::vector<uint32_t> queue_;     // growRegion()'s pixels
  std::vector<float> depth_;        // each pixel's reference depth (0: none) ...
  std::vector<uint8_t> intensity_;  // ... and intensity, in 1/255
  std::vector<uint8_t> age_;        // frames still against it, up to 255
};

}  // namespace fovea::pipeline::map
