// A 3-vector of floats and the two products the map's scalar references
// (splat_plan.cpp, association_plan.cpp) share with their Highway kernels
// (surfel_simd-inl.h's Dot3 and RotateRow): each written out in one order,
// a0 b0 + (a1 b1 + a2 b2), Eigen's for the fixed-size products these passes
// used before, so that the maps are those they made, bit for bit.
#pragma once

namespace fovea::pipeline::map {

struct Float3 {
  float x, y, z;
};

inline float dot(Float3 a, Float3 b) { return a.x * b.x + (a.y * b.y + a.z * b.z); }

// r * v, r row-major.
inline Float3 rotate(const float* r, Float3 v) {
  return {r[0] * v.x + (r[1] * v.y + r[2] * v.z), r[3] * v.x + (r[4] * v.y + r[5] * v.z),
          r[6] * v.x + (r[7] * v.y + r[8] * v.z)};
}

}  // namespace fovea::pipeline::map
