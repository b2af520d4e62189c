// The depth sensor's axial noise, one model for the whole house: the mock
// camera simulates it (hal/camera/mock/render.cpp), the map associates and
// carves within a few of its sigmas (pipeline/map/surfel_map.cpp,
// surfel_map_render.cpp, eye_view.cpp) and the tracker weighs ICP's residuals
// by it (pipeline/map/tracker*).
//
// sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2 metres: Nguyen, Izadi and Lovell
// 2012, measured on a Kinect (2 mm at 1 m, 26 mm at 4 m); structured-light and
// ToF cameras of that class are within a factor of two.
#pragma once

namespace fovea {

inline constexpr double kDepthNoiseBaseM = 0.0012;
inline constexpr double kDepthNoiseQuadraticPerM = 0.0019;
inline constexpr double kDepthNoiseOffsetM = 0.4;  // the distance the quadratic term grows from

// In double (the mock camera's renderer).
constexpr double depthSigma(double z) {
  const double d = z - kDepthNoiseOffsetM;
  return kDepthNoiseBaseM + kDepthNoiseQuadraticPerM * d * d;
}

// In float, as the map's and the tracker's kernels compute it (each constant
// the float nearest its decimal value, in this order of operations).
inline constexpr float kDepthNoiseBaseF = static_cast<float>(kDepthNoiseBaseM);
inline constexpr float kDepthNoiseQuadraticF = static_cast<float>(kDepthNoiseQuadraticPerM);
inline constexpr float kDepthNoiseOffsetF = static_cast<float>(kDepthNoiseOffsetM);
constexpr float depthSigma(float z) {
  const float d = z - kDepthNoiseOffsetF;
  return kDepthNoiseBaseF + kDepthNoiseQuadraticF * d * d;
}

}  // namespace fovea
