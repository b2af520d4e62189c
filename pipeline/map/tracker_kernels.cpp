// The tracker's kernels' scalar references (tracker_kernels.h): the
// pyramids' normals and 2x2 downsampling, and the per-pixel Gauss-Newton
// terms summed into one normal system. The Highway kernels (tracker_simd-inl.h)
// match them, the pyramids' bit for bit and the sums within kTrackSimdTolerance;
// test_tracker_equivalence compares them.
#include "pipeline/map/tracker_kernels.h"

#include <algorithm>
#include <cmath>

namespace fovea::pipeline::map {

void downsampleRef(const PyramidLevelIn& from, const PyramidLevelOut& to, float step_share, bool normals) {
  for (int v = 0; v < from.height / 2; ++v) {
    for (int u = 0; u < from.width / 2; ++u) downsampleBlockRef(from, to, u, v, step_share, normals);
  }
}

void computeNormalsRef(const NormalMapIn& in, float* nx, float* ny, float* nz) {
  const int w = in.width, h = in.height, reach = in.reach;
  const float step = static_cast<float>(reach) * 2.0f * in.step_share;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      if (in.skip != nullptr && in.skip[i]) continue;
      if (u < reach || v < reach || u >= w - reach || v >= h - reach) {
        nx[i] = ny[i] = nz[i] = 0.0f;
        continue;
      }
      normalAtRef(in, i, step, nx, ny, nz);
    }
  }
}

// The per-pixel kernel.
TrackPixel trackPixelRef(const TrackFrameLevel& f, const TrackModelLevel& m, const TrackParams& p, std::size_t i) {
  TrackPixel out;
  const float pz = f.z[i];
  if (!(pz > 0.0f)) return out;
  const float nfx = f.nx[i], nfy = f.ny[i], nfz = f.nz[i];
  if (nfx == 0.0f && nfy == 0.0f && nfz == 0.0f) return out;
  const float px = f.x[i], py = f.y[i];
  const auto& R = p.R;
  const float qx = R[0] * px + R[1] * py + R[2] * pz + p.t[0];
  const float qy = R[3] * px + R[4] * py + R[5] * pz + p.t[1];
  const float qz = R[6] * px + R[7] * py + R[8] * pz + p.t[2];
  if (!(qz > 0.0f)) return out;
  const float fu = m.fx * qx / qz + m.cx;
  const float fv = m.fy * qy / qz + m.cy;
  // Inside [-0.5, width - 0.5): also false for NaN and rejects huge values before the cast.
  if (!(fu >= -0.5f && fu < static_cast<float>(m.width) - 0.5f && fv >= -0.5f &&
        fv < static_cast<float>(m.height) - 0.5f)) {
    return out;
  }
  const int u = static_cast<int>(fu + 0.5f), v = static_cast<int>(fv + 0.5f);
  const std::size_t j = static_cast<std::size_t>(v) * m.width + u;
  const float mz = m.z[j];
  const float nx = m.nx[j], ny = m.ny[j], nz = m.nz[j];
  if (!(mz > 0.0f) || (nx == 0.0f && ny == 0.0f && nz == 0.0f)) return out;
  const float dx = qx - m.x[j], dy = qy - m.y[j], dz = qz - mz;
  if (!(dx * dx + dy * dy + dz * dz <= p.max_distance * p.max_distance)) return out;
  const float rnx = R[0] * nfx + R[1] * nfy + R[2] * nfz;
  const float rny = R[3] * nfx + R[4] * nfy + R[5] * nfz;
  const float rnz = R[6] * nfx + R[7] * nfy + R[8] * nfz;
  if (!(rnx * nx + rny * ny + rnz * nz >= p.min_normal_cos)) return out;
  out.icp = true;
  // Weighted by the sensor's noise at the depth against its noise at 1 m
  // (depthSigma(), surfel_map.h): far, coarsely quantised depth counts less.
  const float weight = p.noise_weighting ? kTrackSigmaAt1m / depthSigma(qz) : 1.0f;
  const float wnx = weight * nx, wny = weight * ny, wnz = weight * nz;
  out.r_icp = wnx * dx + wny * dy + wnz * dz;
  out.j_icp[0] = wnx, out.j_icp[1] = wny, out.j_icp[2] = wnz;
  out.j_icp[3] = qy * wnz - qz * wny;
  out.j_icp[4] = qz * wnx - qx * wnz;
  out.j_icp[5] = qx * wny - qy * wnx;
  out.w_icp = cauchyWeight(out.r_icp, p.icp_robust_scale);
  if (p.use_photometric) {
    // The model's intensity interpolated bilinearly at the projection (nearest
    // would leave the photometric term's minimum up to half a pixel off).
    const int u0 = std::clamp(static_cast<int>(std::floor(fu)), 0, m.width - 2);
    const int v0 = std::clamp(static_cast<int>(std::floor(fv)), 0, m.height - 2);
    const float au = std::clamp(fu - static_cast<float>(u0), 0.0f, 1.0f);
    const float av = std::clamp(fv - static_cast<float>(v0), 0.0f, 1.0f);
    const float* I = m.intensity + static_cast<std::size_t>(v0) * m.width + u0;
    const float top = I[0] + au * (I[1] - I[0]);
    const float bottom = I[m.width] + au * (I[m.width + 1] - I[m.width]);
    const float r = top + av * (bottom - top) - f.intensity[i];
    if (std::abs(r) <= p.max_photometric_residual) {
      const float inv_z = 1.0f / qz;
      const float a = m.gx[j] * m.fx * inv_z, b = m.gy[j] * m.fy * inv_z;
      const float gx = a, gy = b, gz = -(a * qx + b * qy) * inv_z;
      const float s = p.photometric_sqrt_weight;
      out.photometric = true;
      out.r_photo = s * r;
      out.w_photo = cauchyWeight(r, p.photometric_robust_scale);
      out.j_photo[0] = s * gx, out.j_photo[1] = s * gy, out.j_photo[2] = s * gz;
      out.j_photo[3] = s * (qy * gz - qz * gy);
      out.j_photo[4] = s * (qz * gx - qx * gz);
      out.j_photo[5] = s * (qx * gy - qy * gx);
    }
  }
  return out;
}

namespace {
// w J^T J and w J^T r, w J[a] rounded to float as the Highway kernel does,
// then each product in double (exact).
void accumulate(const float* J, float r, float w, double* h, double* b) {
  int k = 0;
  for (int a = 0; a < 6; ++a) {
    const double wja = w * J[a];
    for (int c = a; c < 6; ++c) h[k++] += wja * static_cast<double>(J[c]);
    b[a] += wja * static_cast<double>(r);
  }
}
}  // namespace

void trackLevelRef(const TrackFrameLevel& frame, const TrackModelLevel& model, const TrackParams& params,
                   TrackSums& sums) {
  sums.clear();
  for (int v = 0; v < frame.height; ++v) {
    double h[21] = {}, b[6] = {}, icp_sq = 0.0, photo_sq = 0.0;
    for (int u = 0; u < frame.width; ++u) {
      const TrackPixel px = trackPixelRef(frame, model, params, static_cast<std::size_t>(v) * frame.width + u);
      if (!px.icp) continue;
      ++sums.inliers;
      accumulate(px.j_icp, px.r_icp, px.w_icp, h, b);
      icp_sq += static_cast<double>(px.r_icp) * px.r_icp;
      if (px.photometric) {
        ++sums.photometric_inliers;
        accumulate(px.j_photo, px.r_photo, px.w_photo, h, b);
        photo_sq += static_cast<double>(px.r_photo) * px.r_photo;
      }
    }
    for (int k = 0; k < 21; ++k) sums.h[k] += h[k];
    for (int k = 0; k < 6; ++k) sums.b[k] += b[k];
    sums.icp_sq += icp_sq;
    sums.photometric_sq += photo_sq;
  }
}

}  // namespace fovea::pipeline::map
