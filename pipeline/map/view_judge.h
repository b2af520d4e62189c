// The explained view's judgement of a frame's pixels (explained_view.h), a
// row at a time: each valid pixel back-projected as pipeline/backproject.h
// makes it, turned into the captured view's camera, and looked up there at its
// nearest pixel. judgeRowRef() is the specification; judgeRowSimd() (Highway,
// view_judge_simd-inl.h) gives the same codes: the arithmetic below in its
// order, never a fused multiply-add (test_map_equivalence).
//
// The judgement of a point q in the view's camera (ViewLookup::explains):
//   u = fx * q.x / q.z + cx, v likewise; inside when q.z > 0 and u, v lie
//   within (-0.5, size - 0.5); the nearest pixel is lround's (nearestPixel());
//   explained when that pixel's raw depth is not 0 and
//   |q.z - seen| <= sigmas * depthSigma(seen), seen = float(raw) * scale.
// Into the view: q = ((R00 p.x + R01 p.y) + R02 p.z) + t.x, each row alike.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>

#include <Eigen/Core>

#include "core/depth_noise.h"
#include "pipeline/backproject.h"

namespace fovea::pipeline::map {

// std::lround(c) for c > -0.5, without libm's call: c + 0.5 is exact in
// double, and truncating it is flooring it there.
inline std::size_t nearestPixel(float c) { return static_cast<std::size_t>(static_cast<double>(c) + 0.5); }

// The captured view as the judgement reads it. `raw` has one element more
// than its pixels (a SIMD gather reads 4 bytes at a 2-byte element).
struct ViewLookup {
  const uint16_t* raw = nullptr;
  int width = 0, height = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0;
  float scale = 0;   // metres per raw unit
  float sigmas = 0;  // the depth tolerance in the sensor's sigmas

  bool explains(float x, float y, float z) const {
    if (!(z > 0.0f)) return false;
    const float u = fx * x / z + cx, v = fy * y / z + cy;
    // Inside the view (also false for NaN): the nearest pixel's centre.
    if (!(u > -0.5f && u < static_cast<float>(width) - 0.5f && v > -0.5f && v < static_cast<float>(height) - 0.5f)) {
      return false;
    }
    const std::size_t iu = nearestPixel(u), iv = nearestPixel(v);
    const float seen = static_cast<float>(raw[iv * static_cast<std::size_t>(width) + iu]) * scale;
    return seen > 0.0f && std::fabs(z - seen) <= sigmas * depthSigma(seen);
  }
};

// Into the view's camera: R p + t in the order above.
struct IntoView {
  Eigen::Matrix3f R = Eigen::Matrix3f::Identity();
  Eigen::Vector3f t = Eigen::Vector3f::Zero();
  Eigen::Vector3f apply(const Eigen::Vector3f& p) const {
    return {((R(0, 0) * p.x() + R(0, 1) * p.y()) + R(0, 2) * p.z()) + t.x(),
            ((R(1, 0) * p.x() + R(1, 1) * p.y()) + R(1, 2) * p.z()) + t.y(),
            ((R(2, 0) * p.x() + R(2, 1) * p.y()) + R(2, 2) * p.z()) + t.z()};
  }
};

// A pixel's code.
inline constexpr uint8_t kJudgedInvalid = 0;    // no depth, or outside the range
inline constexpr uint8_t kJudgedExplained = 1;  // the view explains it
inline constexpr uint8_t kJudgedUnexplained = 2;

struct ViewJudgeParams {
  ViewLookup view;
  IntoView into;
  PixelBackprojection rule;  // the frame's
  const uint16_t* depth = nullptr;  // the frame's, row-major at `width`
  int width = 0;
};

// Row v's codes into out[0, width).
void judgeRowRef(const ViewJudgeParams& p, int v, uint8_t* out);
void judgeRowSimd(const ViewJudgeParams& p, int v, uint8_t* out);

}  // namespace fovea::pipeline::map
