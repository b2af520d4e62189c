// The tracker's per-pixel kernel (FrameToModelTracker::track(), one Gauss-Newton
// iteration at one pyramid level; docs/tracking.md): each pixel's residuals and
// Jacobians against the model, summed into one 6x6 normal system.
//   trackLevelRef   the scalar reference, the specification (tracker_kernels.cpp);
//   trackLevelSimd  Highway, dynamically dispatched (tracker_simd-inl.h,
//                   tracker_simd.cpp).
// Beside it, the pyramids' kernels: the normals of a vertex map and the 2x2
// downsampling, each a scalar reference and a Highway kernel with the same bits.
//
// Per pixel of the frame's level with a vertex p (camera frame of the new frame):
//   q = R p + t (R, t: the estimate, new camera -> model camera), projected into
//   the model's level, u' = round(fx qx / qz + cx), v' = round(fy qy / qz + cy);
//   the model's vertex m, normal n at (u', v') associate when both exist,
//   |q - m| <= max_distance and (R n_p) . n >= min_normal_cos (n_p: the frame's
//   normal; a frame pixel without a normal does not associate).
//   ICP:          r = n' . (q - m),  J = [n', q x n']   (twist [v, w], left perturbation
//                 of the estimate: q -> q + w x q + v), n' = s n with s = 0.003 /
//                 (0.0012 + 0.0019 (qz - 0.4)^2) when noise_weighting (the sensor's
//                 noise at 1 m over its noise at qz, depthSigma() in surfel_map.h), else 1.
//   photometric:  when use_photometric, r = I_model(u', v') - I_frame(p) if
//                 |r| <= max_photometric_residual, J = g' [I, -[q]x] = [g', q x g'] with
//                 g' = (gx fx / qz, gy fy / qz, -(gx fx qx + gy fy qy) / qz^2) (gx, gy:
//                 the model's intensity gradient per pixel at (u', v')); both
//                 scaled by sqrt(photometric_weight).
// Robust weights (iteratively reweighted least squares with Cauchy's kernel,
// issue 42): each term's w = 1 / (1 + (r0 / c)^2), r0 its residual before the
// photometric weight (ICP: r, noise-weighted; photometric: the intensity
// difference), c its scale (icp_robust_scale, photometric_robust_scale; 0: w = 1,
// least squares). A pixel of something moving, whose residual is many c, pulls
// the pose little.
// Every per-pixel quantity is float. The sums (TrackSums): the 21 entries of the
// upper triangle of w J^T J, the 6 of w J^T r, and the squared residuals
// (unweighted), over every associated pixel.
//
// Stable reduction: the reference promotes each product to double (exact: a
// product of two floats fits a double), sums a row in double and adds the row's
// sum to the total in double: 640 x 480 terms lose about 1e-13 relative, where a
// float running sum loses 1e-3 or more (test_tracker.cpp:
// TrackerReduction). The Highway kernel sums each vector lane of a row in
// float (a lane sees at most width / lanes terms: 80 at 640 columns and 8
// lanes) and adds the row's lanes to the total in double.
//
// kTrackSimdTolerance (test_tracker_equivalence.cpp holds the Highway kernel to
// it): trackLevelSimd matches trackLevelRef to within this relative
// bound on each of the 27 sums, relative to the Cauchy-Schwarz scale of the sum
// (|sum a b| <= sqrt(sum a^2 sum b^2)): for H(i, j), sqrt(H(i, i) H(j, j)); for
// b(i), sqrt(H(i, i) * residual_sq). The inliers are the same pixels.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "core/depth_noise.h"
#include "core/kernel_set.h"

namespace fovea::pipeline::map {

inline constexpr double kTrackSimdTolerance = 1e-4;
// depthSigma(1 m) (core/depth_noise.h): the noise-weighted ICP residual's unit.
inline constexpr float kTrackSigmaAt1m = depthSigma(1.0f);

// One pyramid level of the new frame (structure of arrays, width x height).
struct TrackFrameLevel {
  int width = 0, height = 0;
  const float* x = nullptr;  // camera-frame vertex; z = 0: none
  const float* y = nullptr;
  const float* z = nullptr;
  const float* nx = nullptr;  // unit normal towards the camera; zero: none
  const float* ny = nullptr;
  const float* nz = nullptr;
  const float* intensity = nullptr;  // [0, 1]
};

// One pyramid level of the model, in the model camera's frame.
struct TrackModelLevel {
  int width = 0, height = 0;
  float fx = 0.0f, fy = 0.0f, cx = 0.0f, cy = 0.0f;
  const float* x = nullptr;  // vertex; z = 0: none
  const float* y = nullptr;
  const float* z = nullptr;
  const float* nx = nullptr;  // unit normal; zero: none
  const float* ny = nullptr;
  const float* nz = nullptr;
  const float* intensity = nullptr;  // [0, 1]
  const float* gx = nullptr;         // its gradient per pixel (central differences / 2)
  const float* gy = nullptr;
};

struct TrackParams {
  std::array<float, 9> R{};  // row-major, new camera -> model camera
  std::array<float, 3> t{};
  float max_distance = 0.1f;
  float min_normal_cos = 0.866f;
  bool noise_weighting = true;  // ICP residual and Jacobian times depthSigma(1 m) / depthSigma(qz)
  bool use_photometric = true;
  float photometric_sqrt_weight = 0.316f;
  float max_photometric_residual = 0.3f;
  float icp_robust_scale = 0.0f;          // Cauchy's c for ICP's residual (metres at 1 m's noise); 0: none
  float photometric_robust_scale = 0.0f;  // ... for the intensity difference; 0: none
};

// Cauchy's weight 1 / (1 + (r / c)^2); 1 when c is 0. The Highway kernel
// computes it with the same operations in the same order.
inline float cauchyWeight(float r, float c) {
  if (c == 0.0f) return 1.0f;
  const float q = r / c;
  return 1.0f / (1.0f + q * q);
}

struct TrackSums {
  std::array<double, 21> h{};  // J^T J upper triangle, row by row: (0,0) (0,1) .. (0,5) (1,1) .. (5,5)
  std::array<double, 6> b{};   // J^T r
  double icp_sq = 0.0;         // sum of squared ICP residuals
  double photometric_sq = 0.0; // ... photometric (weighted)
  uint32_t inliers = 0;        // pixels with an ICP residual
  uint32_t photometric_inliers = 0;
  void clear() { *this = TrackSums{}; }
};

// One pixel's terms (the specification, shared by the reference and tests).
struct TrackPixel {
  bool icp = false;
  bool photometric = false;
  float j_icp[6] = {0, 0, 0, 0, 0, 0};
  float r_icp = 0.0f;
  float j_photo[6] = {0, 0, 0, 0, 0, 0};
  float r_photo = 0.0f;
  float w_icp = 1.0f;    // the terms' robust weights (cauchyWeight)
  float w_photo = 1.0f;
};
// The normals of a vertex map (a level of the tracker's pyramids): central
// differences over `reach` pixels each side, none at the border, next to a
// missing pixel (z <= 0) or across a depth step (a neighbour's depth off by
// more than step_share * 2 reach of the pixel's), unit length, facing the
// camera; zero where there is none. `skip` (may be null): pixels whose normal
// is kept as it is. The scalar reference and Highway's kernel give the same
// bits: IEEE-exact operations only (no fused multiply-add), in one order.
struct NormalMapIn {
  int width = 0, height = 0, reach = 1;
  float step_share = 0.05f;
  const float* x = nullptr;
  const float* y = nullptr;
  const float* z = nullptr;
  const uint8_t* skip = nullptr;
};
void computeNormalsRef(const NormalMapIn& in, float* nx, float* ny, float* nz);
// Its pixel i, one not skipped and not on the border (step: step_share * 2 reach).
inline void normalAtRef(const NormalMapIn& in, std::size_t i, float step, float* nx, float* ny, float* nz) {
  const float* x = in.x;
  const float* y = in.y;
  const float* z = in.z;
  nx[i] = ny[i] = nz[i] = 0.0f;
  if (!(z[i] > 0.0f)) return;
  const std::size_t rs = static_cast<std::size_t>(in.reach), rw = rs * static_cast<std::size_t>(in.width);
  const std::size_t l = i - rs, r = i + rs, up = i - rw, dn = i + rw;
  const float zi = z[i];
  bool ok = true;
  for (std::size_t j : {l, r, up, dn}) ok = ok && z[j] > 0.0f && std::abs(z[j] - zi) <= step * zi;
  if (!ok) return;
  const float ax = x[r] - x[l], ay = y[r] - y[l], az = z[r] - z[l];
  const float bx = x[dn] - x[up], by = y[dn] - y[up], bz = z[dn] - z[up];
  float cx = ay * bz - az * by, cy = az * bx - ax * bz, cz = ax * by - ay * bx;
  const float n = std::sqrt(cx * cx + cy * cy + cz * cz);
  if (!(n > 0.0f) || !std::isfinite(n)) return;
  cx /= n, cy /= n, cz /= n;
  if (cx * x[i] + cy * y[i] + cz * zi > 0.0f) cx = -cx, cy = -cy, cz = -cz;
  nx[i] = cx, ny[i] = cy, nz[i] = cz;
}
void computeNormalsSimd(const NormalMapIn& in, float* nx, float* ny, float* nz);
inline void computeNormals(const NormalMapIn& in, float* nx, float* ny, float* nz, KernelSet kernels) {
  if (kernels == KernelSet::kSimd) {
    computeNormalsSimd(in, nx, ny, nz);
  } else {
    computeNormalsRef(in, nx, ny, nz);
  }
}

// One level of the tracker's pyramids, structure of arrays: vertices (camera
// frame; z <= 0: none), normals (zero: none) and intensity.
struct PyramidLevelIn {
  int width = 0, height = 0;
  const float *x = nullptr, *y = nullptr, *z = nullptr;
  const float *nx = nullptr, *ny = nullptr, *nz = nullptr;
  const float* intensity = nullptr;
};
struct PyramidLevelOut {
  float *x = nullptr, *y = nullptr, *z = nullptr;
  float *nx = nullptr, *ny = nullptr, *nz = nullptr;
  float* intensity = nullptr;
};
// The next level down (width / 2 x height / 2) by 2x2 blocks that never mix
// across a depth step: a block's vertices averaged over its pixels (in row
// order) within step_share of its first valid depth, its intensity over all
// four; with `normals`, its normals averaged and renormalised where they
// roughly agree (their sum longer than half their count), else zero; without,
// a block with no vertex gets zero normals and the others keep what `to` holds
// (the caller computes them). The reference and Highway's kernel give the same
// bits (IEEE-exact operations only, in one order).
void downsampleRef(const PyramidLevelIn& from, const PyramidLevelOut& to, float step_share, bool normals);
// Its block (u, v) of `to`.
inline void downsampleBlockRef(const PyramidLevelIn& from, const PyramidLevelOut& to, int u, int v, float step_share,
                               bool normals) {
  const std::size_t fw = static_cast<std::size_t>(from.width);
  const std::size_t o = static_cast<std::size_t>(v) * static_cast<std::size_t>(from.width / 2) + u;
  const std::size_t top = 2 * static_cast<std::size_t>(v) * fw + 2 * static_cast<std::size_t>(u);
  const std::size_t block[4] = {top, top + 1, top + fw, top + fw + 1};
  float zref = 0.0f;
  for (std::size_t j : block) {
    if (from.z[j] > 0.0f) {
      zref = from.z[j];
      break;
    }
  }
  float sx = 0, sy = 0, sz = 0, snx = 0, sny = 0, snz = 0, si = 0;
  int n = 0;
  for (std::size_t j : block) {
    si += from.intensity[j];
    if (zref > 0.0f && from.z[j] > 0.0f && std::abs(from.z[j] - zref) <= step_share * zref) {
      sx += from.x[j], sy += from.y[j], sz += from.z[j];
      snx += from.nx[j], sny += from.ny[j], snz += from.nz[j];
      ++n;
    }
  }
  to.intensity[o] = 0.25f * si;
  if (n == 0) {
    to.x[o] = to.y[o] = to.z[o] = 0.0f;
    to.nx[o] = to.ny[o] = to.nz[o] = 0.0f;
    return;
  }
  const float inv = 1.0f / static_cast<float>(n);
  to.x[o] = sx * inv, to.y[o] = sy * inv, to.z[o] = sz * inv;
  if (!normals) return;
  const float len = std::sqrt(snx * snx + sny * sny + snz * snz);
  if (len > 0.5f * static_cast<float>(n)) {
    to.nx[o] = snx / len, to.ny[o] = sny / len, to.nz[o] = snz / len;
  } else {
    to.nx[o] = to.ny[o] = to.nz[o] = 0.0f;
  }
}
void downsampleSimd(const PyramidLevelIn& from, const PyramidLevelOut& to, float step_share, bool normals);
inline void downsample(const PyramidLevelIn& from, const PyramidLevelOut& to, float step_share, bool normals,
                       KernelSet kernels) {
  if (kernels == KernelSet::kSimd) {
    downsampleSimd(from, to, step_share, normals);
  } else {
    downsampleRef(from, to, step_share, normals);
  }
}

TrackPixel trackPixelRef(const TrackFrameLevel& frame, const TrackModelLevel& model, const TrackParams& params,
                         std::size_t pixel);

void trackLevelRef(const TrackFrameLevel& frame, const TrackModelLevel& model, const TrackParams& params,
                   TrackSums& sums);
void trackLevelSimd(const TrackFrameLevel& frame, const TrackModelLevel& model, const TrackParams& params,
                    TrackSums& sums);
inline void trackLevel(const TrackFrameLevel& frame, const TrackModelLevel& model, const TrackParams& params,
                       TrackSums& sums, KernelSet kernels) {
  if (kernels == KernelSet::kSimd) {
    trackLevelSimd(frame, model, params, sums);
  } else {
    trackLevelRef(frame, model, params, sums);
  }
}

}  // namespace fovea::pipeline::map
