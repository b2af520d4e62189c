#include "pipeline/map/map_kernels.h"

#include <algorithm>
#include <cmath>

#include "pipeline/map/surfel.h"

namespace fovea::pipeline::map {

VertexTables::VertexTables(int max_width, int max_height)
    : weight_u(static_cast<std::size_t>(max_width)),
      weight_v(static_cast<std::size_t>(max_height)),
      ray_u(static_cast<std::size_t>(max_width) + kNormalReach + kRaySlack, 0.0f),
      ray_v(static_cast<std::size_t>(max_height)) {}

std::size_t VertexTables::memoryBytes() const {
  return (weight_u.capacity() + weight_v.capacity() + ray_u.capacity() + ray_v.capacity()) * sizeof(float);
}

VertexParams prepareVertices(const hal::RgbdFrame& frame, const RawDepthRange& raw, VertexTables& tables) {
  const hal::CameraIntrinsics& k = frame.intrinsics;
  VertexParams p;
  p.depth = frame.depth();
  p.width = frame.width();
  p.height = frame.height();
  p.raw_min = static_cast<int32_t>(raw.min);  // in [1, 65536]
  p.raw_max = static_cast<int32_t>(raw.max);  // in [0, 65535]
  p.scale = static_cast<float>(frame.depth_scale_m);
  p.fx = static_cast<float>(k.fx);
  p.fy = static_cast<float>(k.fy);
  p.cx = static_cast<float>(k.cx);
  p.cy = static_cast<float>(k.cy);
  p.f = 0.5f * (p.fx + p.fy);
  // Keller's weight, exp(-gamma^2 / (2 sigma^2)) with gamma the distance from the
  // image centre over the half-diagonal and sigma 0.6, as the product of its
  // column and row factors: one exp() per column and per row instead of per pixel,
  // and a product that the SIMD kernel reproduces bit for bit.
  const float half_diagonal = std::sqrt(p.cx * p.cx + p.cy * p.cy);
  const float two_sigma_sq = 2.0f * 0.6f * 0.6f;
  auto factor = [&](float d) { return std::exp(-(d * d) / (half_diagonal * half_diagonal) / two_sigma_sq); };
  float* const ray_u = tables.ray_u.data() + kNormalReach;
  for (int u = 0; u < p.width; ++u) {
    tables.weight_u[u] = factor(static_cast<float>(u) - p.cx);
    ray_u[u] = (static_cast<float>(u) - p.cx) / p.fx;
  }
  for (int v = 0; v < p.height; ++v) {
    tables.weight_v[v] = factor(static_cast<float>(v) - p.cy);
    tables.ray_v[v] = (static_cast<float>(v) - p.cy) / p.fy;
  }
  p.weight_u = tables.weight_u.data();
  p.weight_v = tables.weight_v.data();
  p.ray_u = ray_u;
  p.ray_v = tables.ray_v.data();
  return p;
}

uint32_t computeDepthsRef(const VertexParams& p, float* z, float* weight) {
  uint32_t measured = 0;
  for (int v = 0; v < p.height; ++v) {
    for (int u = 0; u < p.width; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * p.width + u;
      const int32_t d = p.depth[i];
      z[i] = d < p.raw_min || d > p.raw_max ? 0.0f : static_cast<float>(d) * p.scale;
      weight[i] = z[i] == 0.0f ? 0.0f : p.weight_u[u] * p.weight_v[v];
      if (z[i] != 0.0f) ++measured;
    }
  }
  return measured;
}

uint32_t computeNormalsRef(const VertexParams& p, const PixelMaps& out) {
  const int w = p.width, h = p.height;
  // Normals from central differences over kNormalReach pixels each side; none near
  // the border, next to a missing measurement or across a depth step (more than 5 %
  // of the depth a pixel: a surface seen at up to about 87 degrees keeps its normal,
  // an occluding edge does not).
  const std::size_t row = static_cast<std::size_t>(w) * kNormalReach;
  uint32_t valid = 0;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      out.nx[i] = out.ny[i] = out.nz[i] = 0.0f;  // none: the pixel can still carve, not merge or add
      out.radius[i] = 0.0f;
      const float z = out.z[i];
      if (z == 0.0f) continue;
      if (u < kNormalReach || v < kNormalReach || u >= w - kNormalReach || v >= h - kNormalReach) continue;
      const std::size_t l = i - kNormalReach, r = i + kNormalReach, up = i - row, down = i + row;
      const float step = (0.05f * kNormalReach) * z;
      if (out.z[l] == 0.0f || out.z[r] == 0.0f || out.z[up] == 0.0f || out.z[down] == 0.0f ||
          std::abs(out.z[l] - z) > step || std::abs(out.z[r] - z) > step || std::abs(out.z[up] - z) > step ||
          std::abs(out.z[down] - z) > step) {
        continue;
      }
      // The neighbours' vertices from their depths and rays.
      const float ray_l = p.ray_u[u - kNormalReach], ray_r = p.ray_u[u + kNormalReach], ray_c = p.ray_u[u];
      const float ray_up = p.ray_v[v - kNormalReach], ray_down = p.ray_v[v + kNormalReach], ray_v = p.ray_v[v];
      const float ax = ray_r * out.z[r] - ray_l * out.z[l], ay = ray_v * out.z[r] - ray_v * out.z[l];
      const float az = out.z[r] - out.z[l];
      const float bx = ray_c * out.z[down] - ray_c * out.z[up], by = ray_down * out.z[down] - ray_up * out.z[up];
      const float bz = out.z[down] - out.z[up];
      float nx = ay * bz - az * by, ny = az * bx - ax * bz, nz = ax * by - ay * bx;
      const float norm = std::sqrt((nx * nx + ny * ny) + nz * nz);
      if (!(norm > 0.0f)) continue;
      nx = nx / norm, ny = ny / norm, nz = nz / norm;
      const float x = ray_c * z, y = ray_v * z;
      const float length = std::sqrt((x * x + y * y) + z * z);
      const float rx = x / length, ry = y / length, rz = z / length;
      float facing = -((nx * rx + ny * ry) + nz * rz);
      if (facing < 0.0f) {
        nx = -nx, ny = -ny, nz = -nz;
        facing = -facing;
      }
      out.nx[i] = nx, out.ny[i] = ny, out.nz[i] = nz;
      // The pixel's footprint: sqrt(2) z / f, larger when the surface is slanted
      // (the cosine held at 0.2 or more, so a grazing pixel stays a few pixels wide).
      out.radius[i] = std::clamp(1.41421356f * z / p.f / std::max(facing, 0.2f), kMinRadiusM, kMaxRadiusM);
      ++valid;
    }
  }
  return valid;
}

}  // namespace fovea::pipeline::map
