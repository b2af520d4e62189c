// Per-target body of the registration kernel; compiled once per Highway target
// by registration_simd.cpp (through hwy/foreach_target.h). Every function that
// calls a Highway op sits between HWY_BEFORE_NAMESPACE and HWY_AFTER_NAMESPACE
// (GCC 12 on aarch64 refuses to inline the ops otherwise).
//
// Bit-exactness: the operations of registration.h's arithmetic, one Highway op
// each, in the reference's order (Mul, Add, Div, comparisons); never MulAdd.
// The float-to-int conversion only ever sees lanes already known to be inside
// the colour image (others are zeroed first), so it is defined on every target.
// The tail goes through the same vector code on a zero-padded copy of the depth
// (0 means no measurement) and the padded ray tables.

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_KERNELS_REGISTRATION_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_KERNELS_REGISTRATION_SIMD_INL_H_
#undef FOVEA_PIPELINE_KERNELS_REGISTRATION_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_KERNELS_REGISTRATION_SIMD_INL_H_
#endif

#include <cstring>

#include "hwy/highway.h"
#include "hal/camera/registration/registration.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::hal::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using RegistrationKernel = DepthToColourRegistration::Kernel;

// One vector of depth pixels from `src`, whose rays are at table index i.
// Writes each lane's colour pixel index (v * colour_width + u) or -1 (black)
// to index_out and adds to the counts.
template <bool kDistort, class DF>
HWY_INLINE void RegisterVector(DF df, const RegistrationKernel& k, const uint16_t* src, std::size_t i,
                               int32_t* index_out, std::size_t& with_depth, std::size_t& coloured) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du32;
  const hn::Rebind<uint16_t, DF> du16;
  const auto raw = hn::BitCast(di, hn::PromoteTo(du32, hn::LoadU(du16, src)));
  const auto has_depth = hn::RebindMask(df, hn::Ne(raw, hn::Zero(di)));
  const auto zero = hn::Zero(df);

  const auto z = hn::Mul(hn::ConvertTo(df, raw), hn::Set(df, k.scale));
  const auto X = hn::Add(hn::Mul(hn::LoadU(df, k.qx + i), z), hn::Set(df, k.tx));
  const auto Y = hn::Add(hn::Mul(hn::LoadU(df, k.qy + i), z), hn::Set(df, k.ty));
  const auto Z = hn::Add(hn::Mul(hn::LoadU(df, k.qz + i), z), hn::Set(df, k.tz));
  const auto in_front = hn::Gt(Z, zero);
  // Lanes behind the camera divide too (inf or NaN, never a trap: FP exceptions
  // are masked); they are discarded by in_front.
  auto a = hn::Div(X, Z);
  auto b = hn::Div(Y, Z);
  if constexpr (kDistort) {
    const auto aa = hn::Mul(a, a);
    const auto bb = hn::Mul(b, b);
    const auto ab = hn::Mul(a, b);
    const auto r2 = hn::Add(aa, bb);
    const auto radial = hn::Add(
        hn::Mul(hn::Add(hn::Mul(hn::Add(hn::Mul(hn::Set(df, k.k3), r2), hn::Set(df, k.k2)), r2), hn::Set(df, k.k1)),
                r2),
        hn::Set(df, 1.0f));
    const auto da = hn::Add(hn::Mul(a, radial), hn::Add(hn::Mul(hn::Set(df, k.two_p1), ab),
                                                        hn::Mul(hn::Set(df, k.p2), hn::Add(r2, hn::Add(aa, aa)))));
    const auto db = hn::Add(hn::Mul(b, radial), hn::Add(hn::Mul(hn::Set(df, k.p1), hn::Add(r2, hn::Add(bb, bb))),
                                                        hn::Mul(hn::Set(df, k.two_p2), ab)));
    a = da;
    b = db;
  }
  const auto half = hn::Set(df, 0.5f);
  const auto hu = hn::Add(hn::Add(hn::Mul(hn::Set(df, k.fx), a), hn::Set(df, k.cx)), half);
  const auto hv = hn::Add(hn::Add(hn::Mul(hn::Set(df, k.fy), b), hn::Set(df, k.cy)), half);
  const auto in_u = hn::And(hn::Ge(hu, zero), hn::Lt(hu, hn::Set(df, static_cast<float>(k.colour_width))));
  const auto in_v = hn::And(hn::Ge(hv, zero), hn::Lt(hv, hn::Set(df, static_cast<float>(k.colour_height))));
  const auto inside = hn::And(hn::And(has_depth, in_front), hn::And(in_u, in_v));

  // Truncation of the inside lanes (non-negative, below the image size) is floor.
  const auto cu = hn::ConvertTo(di, hn::IfThenElseZero(inside, hu));
  const auto cv = hn::ConvertTo(di, hn::IfThenElseZero(inside, hv));
  const auto index = hn::Add(hn::Mul(cv, hn::Set(di, k.colour_width)), cu);
  hn::StoreU(hn::IfThenElse(hn::RebindMask(di, inside), index, hn::Set(di, -1)), di, index_out);
  with_depth += hn::CountTrue(df, has_depth);
  coloured += hn::CountTrue(df, inside);
}

// Copies the colour pixel of each lane (or black) to out (3 bytes a pixel).
// Branch-free: black lanes read a black pixel of their own.
HWY_INLINE void CopyColours(const int32_t* index, std::size_t count, const uint8_t* colour_rgb, uint8_t* out) {
  static constexpr uint8_t kBlack[3] = {0, 0, 0};
  for (std::size_t j = 0; j < count; ++j) {
    const int32_t c = index[j];
    const uint8_t* px = c < 0 ? kBlack : colour_rgb + 3 * static_cast<std::size_t>(c);
    std::memcpy(out + 3 * j, px, 3);
  }
}

template <bool kDistort>
HWY_INLINE RegistrationCounts RegisterAll(const RegistrationKernel& k, const uint16_t* depth,
                                          const uint8_t* colour_rgb, uint8_t* out_rgb) {
  const hn::ScalableTag<float> df;
  const std::size_t lanes = hn::Lanes(df);
  constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(float);
  HWY_ALIGN int32_t index[kMax];
  const std::size_t n = static_cast<std::size_t>(k.depth_width) * static_cast<std::size_t>(k.depth_height);
  std::size_t with_depth = 0, coloured = 0;
  std::size_t i = 0;
  for (; i + lanes <= n; i += lanes) {
    RegisterVector<kDistort>(df, k, depth + i, i, index, with_depth, coloured);
    CopyColours(index, lanes, colour_rgb, out_rgb + 3 * i);
  }
  if (i < n) {
    HWY_ALIGN uint16_t tail_depth[kMax] = {};
    std::memcpy(tail_depth, depth + i, (n - i) * sizeof(uint16_t));
    RegisterVector<kDistort>(df, k, tail_depth, i, index, with_depth, coloured);
    CopyColours(index, n - i, colour_rgb, out_rgb + 3 * i);
  }
  RegistrationCounts counts;
  counts.with_depth = with_depth;
  counts.coloured = coloured;
  counts.outside_colour = with_depth - coloured;
  return counts;
}

inline RegistrationCounts RegisterT(const RegistrationKernel& k, const uint16_t* depth, const uint8_t* colour_rgb,
                                    uint8_t* out_rgb) {
  return k.distort ? RegisterAll<true>(k, depth, colour_rgb, out_rgb) : RegisterAll<false>(k, depth, colour_rgb, out_rgb);
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::hal::kernels
HWY_AFTER_NAMESPACE();

#endif  // per-target include guard
