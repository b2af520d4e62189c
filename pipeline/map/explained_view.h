// What the last fused frame's settled surfels explained, kept so that a later
// frame the map did not fuse (fusion's time budget left it, or fusion is busy
// with another frame) can still be thinned to what the map does not explain:
// its points are reprojected into that fused frame's camera and a point the
// map explained there, at the same depth within the sensor's noise, is
// dropped. Without it such a frame went to the operator whole, though the
// operator holds the map's bricks of most of it.
//
// The fused frame's own points judged against its own view are exactly what
// SurfelMap::appendUnexplained() leaves (test_explained_view.cpp). Judging a
// later frame is an approximation: a pixel of the fused frame stands for its
// measured depth, not the surfel's, so the depth tolerance is the map's
// association tolerance widened by sqrt(2) for the two measurements' noise,
// and a point outside the fused frame's view is never explained (new to the
// map as far as the operator can tell).
//
// Memory: the raw depth, two bytes a pixel of the largest frame, and a byte a
// column, allocated by create(); nothing else allocates.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/kernel_set.h"
#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/backproject.h"
#include "pipeline/map/live_points.h"
#include "pipeline/map/view_judge.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline::map {

class ExplainedView {
 public:
  // depth_tolerance_sigmas: the map's association tolerance (SurfelMapConfig);
  // kernels: visitUnexplained()'s judgement of a row (view_judge.h).
  static Result<ExplainedView> create(int max_width, int max_height, double depth_tolerance_sigmas,
                                      KernelSet kernels = defaultKernelSet());

  // Keeps `frame`'s view (its pose and intrinsics) and, per pixel, the
  // measured depth where `explained` is set (which the map sets only on a
  // valid depth), for the frame the map just fused: its raw value, which
  // makes the depth in metres as the map's vertices do (float(raw) * scale,
  // map_kernels.h), the same bits. A frame larger than create()'s size
  // empties the view.
  void capture(const hal::RgbdFrame& frame, const uint8_t* explained);

  // Removes from `cloud` (world positions relative to cloud.origin_m) the
  // points the captured view explains, keeping the others in their order;
  // returns how many it removed. An empty view removes none. The judgement
  // on a cloud already made: the tests' reference for visitUnexplained().
  std::size_t removeExplained(PointCloud& cloud) const;

  // The same judgement on `frame`'s valid pixels as `rule` back-projects them
  // (relative to the frame's camera position), a row at a time (view_judge.h):
  // offers `sink` those the view does not explain, in pixel order, until it
  // says stop, and counts the valid pixels and the explained ones it passed
  // (of those the sink does not skip). The service's way (Mapper::collectLive):
  // no cloud of the whole frame.
  struct VisitCounts {
    uint32_t valid = 0, explained = 0;
  };
  void visitUnexplained(const hal::RgbdFrame& frame, const PixelBackprojection& rule, LivePointSink& sink,
                        VisitCounts& counts) const;

  bool empty() const { return width_ == 0; }
  const hal::Pose& pose() const { return pose_; }
  std::size_t memoryBytes() const { return raw_.capacity() * sizeof(uint16_t) + codes_.capacity(); }

 private:
  ViewLookup lookup() const { return {raw_.data(), width_, height_, fx_, fy_, cx_, cy_, scale_, sigmas_}; }
  // Into the view's camera from world positions relative to origin_m:
  // R^T (origin + p - t), the translation in double (the cloud and the camera
  // may be far from the world origin).
  IntoView intoView(const Eigen::Vector3d& origin_m) const {
    return {pose_.R_world_cam.transpose().cast<float>(),
            (pose_.R_world_cam.transpose() * (origin_m - pose_.t_world_cam)).cast<float>()};
  }

  std::size_t max_pixels_ = 0;
  float sigmas_ = 0.0f;
  int width_ = 0, height_ = 0;
  float fx_ = 0, fy_ = 0, cx_ = 0, cy_ = 0;
  hal::Pose pose_;
  float scale_ = 0;             // the captured frame's metres per raw unit, as a float
  std::vector<uint16_t> raw_;  // explained pixels' raw depth, 0 elsewhere; one more (ViewLookup)
  KernelSet kernels_ = KernelSet::kRef;
  mutable std::vector<uint8_t> codes_;  // a row's (visitUnexplained; one thread at a time)
};

}  // namespace fovea::pipeline::map
