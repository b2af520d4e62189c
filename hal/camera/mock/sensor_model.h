// The numbers of the mock camera's sensor model (described in mock_camera.h):
// Kinect v1 intrinsics and depth units, which the camera reports, and the
// noise and dropout model, which its renderer (render.cpp) applies. One
// header so that the camera and the renderer agree on them.
#pragma once

#include <numbers>

namespace fovea::hal::mock {

// Kinect v1 nominal focal length at 640 pixels wide.
inline constexpr double kFocalAt640 = 525.0;
inline constexpr double kDepthScaleM = 0.001;
inline constexpr double kMinRangeM = 0.4;
inline constexpr double kMaxRangeM = 8.0;
// Nguyen, Izadi, Lovell 2012, axial noise: depthSigma() (core/depth_noise.h),
// plus a term that grows with the angle of incidence.
inline constexpr double kSigmaAngleM = 0.0001;
inline constexpr double kSigmaAngleCapRad = 80.0 * std::numbers::pi / 180.0;
// Dropout: incidence ramp, random speckle, discontinuity bands.
inline constexpr double kGrazingStartDeg = 75.0;
inline constexpr double kGrazingFullDeg = 85.0;
inline constexpr double kRandomDropout = 0.003;
inline constexpr double kEdgeJumpM = 0.03;     // a neighbour nearer by more than this
inline constexpr double kEdgeJumpPerM = 0.02;  // ... plus this per metre of its depth is an occluder
inline constexpr float kShadowDropout = 0.5f;  // second pixel of the projector's shadow
inline constexpr int kEdgeReachPx = 2;
inline constexpr int kRgbNoiseLevels = 4;  // +- per channel

}  // namespace fovea::hal::mock
