// Per-target body of computeDepthsSimd and computeNormalsSimd (map_kernels.h); compiled once per
// Highway target by vertices_simd.cpp (through hwy/foreach_target.h). Every
// function that calls a Highway op sits between HWY_BEFORE_NAMESPACE and
// HWY_AFTER_NAMESPACE (GCC 12 on aarch64 refuses to inline the ops otherwise).
//
// Bit for bit the reference (map_kernels.cpp): only Add, Sub, Mul, Div, Sqrt,
// Neg, Abs, comparisons and selects, in the reference's order; never MulAdd (an
// FMA on AVX2/NEON); std::max and std::clamp as the selects they are. Lanes a
// reference would skip are computed too and masked to the reference's zeros.
// Tails shorter than a vector run through the same vector code on a zero-padded
// copy (0 is never a valid depth); the rays' table has room for the loads.

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_MAP_VERTICES_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_MAP_VERTICES_SIMD_INL_H_
#undef FOVEA_PIPELINE_MAP_VERTICES_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_MAP_VERTICES_SIMD_INL_H_
#endif

#include <algorithm>
#include <cstring>

#include "hwy/highway.h"
#include "pipeline/map/map_kernels.h"
#include "pipeline/map/surfel.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::map {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

inline constexpr std::size_t kMaxFloatLanes = HWY_MAX_BYTES / sizeof(float);

// One vector of depths and weights from column u (computeDepthsRef's lanes).
template <class DF>
HWY_INLINE std::size_t DepthVector(DF df, const VertexParams& p, const uint16_t* src, const float* wu,
                                   hn::Vec<DF> wv, float* oz, float* ow) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du32;
  const hn::Rebind<uint16_t, DF> du16;
  const auto raw = hn::BitCast(di, hn::PromoteTo(du32, hn::LoadU(du16, src)));
  const auto valid = hn::RebindMask(
      df, hn::And(hn::Gt(raw, hn::Set(di, p.raw_min - 1)), hn::Lt(raw, hn::Set(di, p.raw_max + 1))));
  const auto z = hn::IfThenElseZero(valid, hn::Mul(hn::ConvertTo(df, raw), hn::Set(df, p.scale)));
  const auto seen = hn::Ne(z, hn::Zero(df));
  hn::StoreU(z, df, oz);
  hn::StoreU(hn::IfThenElseZero(seen, hn::Mul(hn::LoadU(df, wu), wv)), df, ow);
  return hn::CountTrue(df, seen);
}

inline uint32_t ComputeDepthsT(const VertexParams& p, float* z, float* weight) {
  const hn::ScalableTag<float> df;
  const std::size_t lanes = hn::Lanes(df);
  const auto w = static_cast<std::size_t>(p.width);
  HWY_ALIGN uint16_t tail_depth[kMaxFloatLanes];
  HWY_ALIGN float tail_wu[kMaxFloatLanes];
  HWY_ALIGN float tail[2][kMaxFloatLanes];
  std::size_t measured = 0;
  for (std::size_t v = 0; v < static_cast<std::size_t>(p.height); ++v) {
    const auto wv = hn::Set(df, p.weight_v[v]);
    const std::size_t i0 = v * w;
    std::size_t u = 0;
    for (; u + lanes <= w; u += lanes) {
      measured += DepthVector(df, p, p.depth + i0 + u, p.weight_u + u, wv, z + i0 + u, weight + i0 + u);
    }
    if (u < w) {
      std::memset(tail_depth, 0, sizeof tail_depth);
      std::memcpy(tail_depth, p.depth + i0 + u, (w - u) * sizeof(uint16_t));
      std::fill(tail_wu, tail_wu + kMaxFloatLanes, 0.0f);
      std::memcpy(tail_wu, p.weight_u + u, (w - u) * sizeof(float));
      // raw 0 is never valid (raw_min >= 1): the padding's lanes count nothing.
      measured += DepthVector(df, p, tail_depth, tail_wu, wv, tail[0], tail[1]);
      std::memcpy(z + i0 + u, tail[0], (w - u) * sizeof(float));
      std::memcpy(weight + i0 + u, tail[1], (w - u) * sizeof(float));
    }
  }
  return static_cast<uint32_t>(measured);
}

// A row's rays: ray_v of the row and of the rows kNormalReach above and below.
struct RowRays {
  float up = 0, centre = 0, down = 0;
};

// One vector of normals and radii from column u of a row. z points at the
// vector's first depth; its neighbours are kNormalReach lanes to either side
// and `rows` floats above and below (rows = 0 and normals false in a row where
// no pixel can have a normal); ray_u at column u's ray (readable kNormalReach
// lanes before and after the vector). Returns the pixels given a normal.
template <class DF>
HWY_INLINE std::size_t NormalVector(DF df, const VertexParams& p, const float* z, std::ptrdiff_t rows, bool normals,
                                    int u, const float* ray_u, const RowRays& ray_v, float* onx, float* ony,
                                    float* onz, float* orad) {
  const hn::RebindToSigned<DF> di;
  const auto zero = hn::Zero(df);
  const auto zc = hn::LoadU(df, z);
  const auto ui = hn::Iota(di, u);
  const auto inside = hn::RebindMask(df, hn::And(hn::Gt(ui, hn::Set(di, kNormalReach - 1)),
                                                 hn::Lt(ui, hn::Set(di, p.width - kNormalReach))));
  auto keep = hn::And(hn::Ne(zc, zero), inside);
  if (!normals || hn::AllFalse(df, keep)) {
    hn::StoreU(zero, df, onx);
    hn::StoreU(zero, df, ony);
    hn::StoreU(zero, df, onz);
    hn::StoreU(zero, df, orad);
    return 0;
  }
  const std::ptrdiff_t l = -kNormalReach, r = kNormalReach, up = -rows, down = rows;
  const auto zl = hn::LoadU(df, z + l), zr = hn::LoadU(df, z + r);
  const auto zu = hn::LoadU(df, z + up), zd = hn::LoadU(df, z + down);
  const auto step = hn::Mul(hn::Set(df, 0.05f * kNormalReach), zc);
  keep = hn::And(keep, hn::And(hn::And(hn::Ne(zl, zero), hn::Ne(zr, zero)), hn::And(hn::Ne(zu, zero), hn::Ne(zd, zero))));
  const auto steep = hn::Or(hn::Or(hn::Gt(hn::Abs(hn::Sub(zl, zc)), step), hn::Gt(hn::Abs(hn::Sub(zr, zc)), step)),
                            hn::Or(hn::Gt(hn::Abs(hn::Sub(zu, zc)), step), hn::Gt(hn::Abs(hn::Sub(zd, zc)), step)));
  keep = hn::AndNot(steep, keep);
  // The neighbours' vertices from their depths and rays, as the reference.
  const auto ray_c = hn::LoadU(df, ray_u);
  const auto ray_row = hn::Set(df, ray_v.centre);
  const auto ax = hn::Sub(hn::Mul(hn::LoadU(df, ray_u + r), zr), hn::Mul(hn::LoadU(df, ray_u + l), zl));
  const auto ay = hn::Sub(hn::Mul(ray_row, zr), hn::Mul(ray_row, zl));
  const auto az = hn::Sub(zr, zl);
  const auto bx = hn::Sub(hn::Mul(ray_c, zd), hn::Mul(ray_c, zu));
  const auto by = hn::Sub(hn::Mul(hn::Set(df, ray_v.down), zd), hn::Mul(hn::Set(df, ray_v.up), zu));
  const auto bz = hn::Sub(zd, zu);
  auto nx = hn::Sub(hn::Mul(ay, bz), hn::Mul(az, by));
  auto ny = hn::Sub(hn::Mul(az, bx), hn::Mul(ax, bz));
  auto nz = hn::Sub(hn::Mul(ax, by), hn::Mul(ay, bx));
  const auto norm = hn::Sqrt(hn::Add(hn::Add(hn::Mul(nx, nx), hn::Mul(ny, ny)), hn::Mul(nz, nz)));
  keep = hn::And(keep, hn::Gt(norm, zero));
  nx = hn::Div(nx, norm), ny = hn::Div(ny, norm), nz = hn::Div(nz, norm);
  const auto xc = hn::Mul(ray_c, zc), yc = hn::Mul(ray_row, zc);
  const auto length = hn::Sqrt(hn::Add(hn::Add(hn::Mul(xc, xc), hn::Mul(yc, yc)), hn::Mul(zc, zc)));
  const auto rx = hn::Div(xc, length), ry = hn::Div(yc, length), rz = hn::Div(zc, length);
  auto facing = hn::Neg(hn::Add(hn::Add(hn::Mul(nx, rx), hn::Mul(ny, ry)), hn::Mul(nz, rz)));
  const auto flip = hn::Lt(facing, zero);
  nx = hn::IfThenElse(flip, hn::Neg(nx), nx);
  ny = hn::IfThenElse(flip, hn::Neg(ny), ny);
  nz = hn::IfThenElse(flip, hn::Neg(nz), nz);
  facing = hn::IfThenElse(flip, hn::Neg(facing), facing);
  // std::max(facing, 0.2f) is facing < 0.2f ? 0.2f : facing; std::clamp(v, lo, hi)
  // is v < lo ? lo : (hi < v ? hi : v).
  const auto floor = hn::Set(df, 0.2f);
  const auto cosine = hn::IfThenElse(hn::Lt(facing, floor), floor, facing);
  auto radius = hn::Div(hn::Div(hn::Mul(hn::Set(df, 1.41421356f), zc), hn::Set(df, p.f)), cosine);
  const auto lo = hn::Set(df, kMinRadiusM), hi = hn::Set(df, kMaxRadiusM);
  radius = hn::IfThenElse(hn::Lt(radius, lo), lo, hn::IfThenElse(hn::Lt(hi, radius), hi, radius));
  hn::StoreU(hn::IfThenElseZero(keep, nx), df, onx);
  hn::StoreU(hn::IfThenElseZero(keep, ny), df, ony);
  hn::StoreU(hn::IfThenElseZero(keep, nz), df, onz);
  hn::StoreU(hn::IfThenElseZero(keep, radius), df, orad);
  return hn::CountTrue(df, keep);
}

inline uint32_t ComputeNormalsT(const VertexParams& p, const PixelMaps& out) {
  const hn::ScalableTag<float> df;
  const std::size_t lanes = hn::Lanes(df);
  const auto w = static_cast<std::size_t>(p.width);
  const auto h = static_cast<std::size_t>(p.height);
  // The tail's neighbourhood, zero-padded: rows v - kNormalReach, v, v + kNormalReach
  // of kNormalReach + lanes + kNormalReach columns of z.
  constexpr std::size_t kStride = kMaxFloatLanes + 2 * kNormalReach;
  HWY_ALIGN float tile[3 * kStride];
  HWY_ALIGN float tail_out[4][kMaxFloatLanes];
  const std::size_t reach = kNormalReach;
  const auto rows = static_cast<std::ptrdiff_t>(w * reach);
  std::size_t valid = 0;
  for (std::size_t v = 0; v < h; ++v) {
    const bool normals = v >= reach && v + reach < h;
    RowRays ray_v;
    ray_v.centre = p.ray_v[v];
    if (normals) ray_v.up = p.ray_v[v - reach], ray_v.down = p.ray_v[v + reach];
    const std::size_t i0 = v * w;
    std::size_t u = 0;
    for (; u + lanes <= w; u += lanes) {
      const std::size_t i = i0 + u;
      valid += NormalVector(df, p, out.z + i, normals ? rows : 0, normals, static_cast<int>(u), p.ray_u + u, ray_v,
                            out.nx + i, out.ny + i, out.nz + i, out.radius + i);
    }
    if (u < w) {
      const std::size_t n = w - u;
      std::fill(tile, tile + 3 * kStride, 0.0f);
      for (int k = 0; k < 3; ++k) {
        if (k != 1 && !normals) continue;
        // Columns u - reach .. w - 1 of row v + (k - 1) reach (u >= reach when
        // the row has a full vector before the tail; otherwise from column 0).
        const std::size_t first = u >= reach ? u - reach : 0;
        const std::size_t row_start = (v + k * reach - reach) * w;
        std::memcpy(tile + k * kStride + (first + reach - u), out.z + row_start + first, (w - first) * sizeof(float));
      }
      const std::size_t centre = kStride + reach;
      valid += NormalVector(df, p, tile + centre, normals ? static_cast<std::ptrdiff_t>(kStride) : 0, normals,
                            static_cast<int>(u), p.ray_u + u, ray_v, tail_out[0], tail_out[1], tail_out[2],
                            tail_out[3]);
      const std::size_t i = i0 + u;
      std::memcpy(out.nx + i, tail_out[0], n * sizeof(float));
      std::memcpy(out.ny + i, tail_out[1], n * sizeof(float));
      std::memcpy(out.nz + i, tail_out[2], n * sizeof(float));
      std::memcpy(out.radius + i, tail_out[3], n * sizeof(float));
    }
  }
  return static_cast<uint32_t>(valid);
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::map
HWY_AFTER_NAMESPACE();

#endif  // include guard
