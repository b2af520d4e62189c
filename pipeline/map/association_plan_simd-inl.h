// Per-target body of planAssociationSimd (association_plan.h); compiled once
// per Highway target by association_plan_simd.cpp. Bit for bit
// planAssociationRef: a vector of pixels at a time, the per-pixel maps loaded,
// the surfels the index map names there copied and transposed into a vector a
// field (LoadSurfelsAt: the pool read as structure of arrays), the bricks'
// origins and the codecs' tables gathered by index, and every lane computed in
// the reference's order of operations (Add, Sub, Mul, Div, Sqrt, never
// MulAdd). A vector none of whose pixels has a surfel at its depth and a
// normal skips the merge. The pixels past the last whole vector are the
// reference's.

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_MAP_ASSOCIATION_PLAN_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_MAP_ASSOCIATION_PLAN_SIMD_INL_H_
#undef FOVEA_PIPELINE_MAP_ASSOCIATION_PLAN_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_MAP_ASSOCIATION_PLAN_SIMD_INL_H_
#endif

#include <cstddef>

#include "hwy/highway.h"
#include "pipeline/map/association_plan.h"
#include "pipeline/map/depth_sigma_simd-inl.h"
#include "pipeline/map/index_map.h"
#include "pipeline/map/surfel_simd-inl.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::map {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// One colour channel merged: a * surfel + b * pixel + 0.5, truncated (the
// reference's conversion to a byte).
template <class DF, class V, class VU>
HWY_INLINE VU MergedChannel(DF df, VU surfel, VU pixel, V a, V b) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du;
  const V mixed = hn::Add(hn::Add(hn::Mul(a, hn::ConvertTo(df, hn::BitCast(di, surfel))),
                                  hn::Mul(b, hn::ConvertTo(df, hn::BitCast(di, pixel)))),
                          hn::Set(df, 0.5f));
  return hn::BitCast(du, hn::ConvertTo(di, mixed));
}

// mergedColour (association_plan.cpp) of the surfels' colour words (red, green,
// blue, flags) and the pixels at j0 (grey without a colour image).
template <class DF, class V, class VU>
HWY_INLINE VU MergedColour(DF df, const AssociationFrame& f, VU surfel_rgb, std::size_t j0, V a, V b) {
  const hn::RebindToUnsigned<DF> du;
  const hn::Rebind<uint8_t, DF> d8;
  VU red = hn::Set(du, kGreyRgb[0]), green = hn::Set(du, kGreyRgb[1]), blue = hn::Set(du, kGreyRgb[2]);
  if (f.rgb != nullptr) {
    hn::Vec<decltype(d8)> r8, g8, b8;
    hn::LoadInterleaved3(d8, f.rgb + 3 * j0, r8, g8, b8);
    red = hn::PromoteTo(du, r8), green = hn::PromoteTo(du, g8), blue = hn::PromoteTo(du, b8);
  }
  const auto byte = hn::Set(du, 0xffu);
  const VU r = MergedChannel(df, hn::And(surfel_rgb, byte), red, a, b);
  const VU g = MergedChannel(df, hn::And(hn::ShiftRight<8>(surfel_rgb), byte), green, a, b);
  const VU bl = MergedChannel(df, hn::And(hn::ShiftRight<16>(surfel_rgb), byte), blue, a, b);
  return hn::Or(r, hn::Or(hn::ShiftLeft<8>(g), hn::ShiftLeft<16>(bl)));
}

// planMergeRef for the lanes of `merging` at j0 (the others' merge arrays and
// bits are left as the reference leaves a lane it does not merge: no bits).
// n*: the pixels' camera-frame normals; slot: their surfels.
template <class DF, class V, class VU, class M>
HWY_NOINLINE void MergeVector(DF df, const AssociationFrame& f, const Surfel* surfels, std::size_t j0, M merging, VU slot,
                              V nx, V ny, V nz, VU& bits, AssociationPlan& plan) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du;
  V sx, sy, sz;
  VU normal_radius, colour, confidence_brick, first_seen;
  LoadSurfelsAt(df, surfels, hn::IfThenElseZero(hn::RebindMask(du, merging), slot), sx, sy, sz, normal_radius, colour,
                confidence_brick, first_seen);
  const V weight = hn::LoadU(df, f.weight + j0), z = hn::LoadU(df, f.z + j0);
  // The normal test on the surfel's direction as decoded.
  const V wx = RotateRow(df, f.r, nx, ny, nz), wy = RotateRow(df, f.r + 3, nx, ny, nz),
          wz = RotateRow(df, f.r + 6, nx, ny, nz);
  V dx, dy, dz;
  DecodeDirection(df, normal_radius, dx, dy, dz);
  const V d_norm = hn::Sqrt(Dot3(dx, dy, dz, dx, dy, dz));
  const auto bucket = hn::ConvertTo(
      di, hn::Max(hn::Zero(df), hn::Mul(hn::Sub(z, hn::Set(df, f.normal_cos_z_min)), hn::Set(df, f.normal_cos_per_m))));
  const V cos_tolerance =
      hn::GatherIndex(df, f.normal_cos, hn::Min(bucket, hn::Set(di, static_cast<int32_t>(f.normal_cos_size - 1))));
  const auto merges = hn::And(merging, hn::Not(hn::Lt(Dot3(dx, dy, dz, wx, wy, wz), hn::Mul(cos_tolerance, d_norm))));
  if (hn::AllFalse(df, merges)) return;
  // The position, relative to the surfel's brick.
  const auto b3 = hn::BitCast(di, hn::Mul(hn::ShiftRight<16>(confidence_brick), hn::Set(du, 3u)));
  const V vx = hn::Sub(hn::Mul(hn::LoadU(df, f.ray_u + j0), z), hn::GatherIndex(df, f.brick_cam, b3));
  const V vy = hn::Sub(hn::Mul(hn::Set(df, f.ray_v), z), hn::GatherIndex(df, f.brick_cam + 1, b3));
  const V vz = hn::Sub(z, hn::GatherIndex(df, f.brick_cam + 2, b3));
  const V c = DecodeConfidence(df, hn::And(confidence_brick, hn::Set(du, 0xffffu)));
  const V sum = hn::Add(c, weight);
  const V inv_sum = hn::Div(hn::Set(df, 1.0f), sum);
  const V a = hn::Mul(c, inv_sum), b = hn::Mul(weight, inv_sum);
  hn::StoreU(MergedColour(df, f, colour, j0, a, b), du, plan.rgb + j0);
  hn::StoreU(hn::Add(hn::Mul(a, sx), hn::Mul(b, RotateRow(df, f.r, vx, vy, vz))), df, plan.x + j0);
  hn::StoreU(hn::Add(hn::Mul(a, sy), hn::Mul(b, RotateRow(df, f.r + 3, vx, vy, vz))), df, plan.y + j0);
  hn::StoreU(hn::Add(hn::Mul(a, sz), hn::Mul(b, RotateRow(df, f.r + 6, vx, vy, vz))), df, plan.z + j0);
  // The normal: the confidence-weighted directions; the radius; the confidence.
  const V wd = hn::Mul(weight, d_norm);
  V mx = hn::Add(hn::Mul(c, dx), hn::Mul(wd, wx)), my = hn::Add(hn::Mul(c, dy), hn::Mul(wd, wy)),
    mz = hn::Add(hn::Mul(c, dz), hn::Mul(wd, wz));
  const auto some = hn::Gt(Dot3(mx, my, mz, mx, my, mz), hn::Zero(df));
  mx = hn::IfThenElse(some, mx, wx);
  my = hn::IfThenElse(some, my, wy);
  mz = hn::IfThenElse(some, mz, wz);
  const V old_radius = hn::GatherIndex(df, kRadiusTable.data(), hn::BitCast(di, hn::And(normal_radius, hn::Set(du, 0xffu))));
  const V radius = hn::Add(hn::Mul(a, old_radius), hn::Mul(b, hn::LoadU(df, f.radius + j0)));
  hn::StoreU(hn::Or(hn::ShiftLeft<8>(EncodeNormal(df, mx, my, mz)), EncodeRadius(df, radius)), du, plan.normal_radius + j0);
  const V capped = hn::Min(sum, hn::Set(df, f.confidence_cap));
  hn::StoreU(EncodeConfidence(df, capped), du, plan.confidence + j0);
  const auto stable = hn::And(merges, hn::Ge(capped, hn::Set(df, f.stable_confidence)));
  bits = hn::Or(bits, hn::IfThenElseZero(hn::RebindMask(du, merges), hn::Set(du, AssociationPlan::kMerges)));
  bits = hn::Or(bits, hn::IfThenElseZero(hn::RebindMask(du, stable), hn::Set(du, AssociationPlan::kStable)));
}

// The pixels at j0: their kinds and bits, and the merges of those at depth.
template <class DF>
HWY_NOINLINE void PlanPixels(DF df, const AssociationFrame& f, const Surfel* surfels, std::size_t j0, AssociationPlan& plan) {
  using V = hn::Vec<DF>;
  const hn::RebindToUnsigned<DF> du;
  const V weight = hn::LoadU(df, f.weight + j0), z = hn::LoadU(df, f.z + j0);
  const V nx = hn::LoadU(df, f.nx + j0), ny = hn::LoadU(df, f.ny + j0), nz = hn::LoadU(df, f.nz + j0);
  const auto slot = hn::LoadU(du, f.slot + j0);
  const auto measured = hn::RebindMask(du, hn::Ne(weight, hn::Zero(df)));
  const auto has_normal = hn::RebindMask(du, hn::Gt(Dot3(nx, ny, nz, nx, ny, nz), hn::Zero(df)));
  const auto empty = hn::Eq(slot, hn::Set(du, IndexMap::kNoSurfel));
  const V tolerance = hn::Mul(hn::Set(df, f.sigmas), DepthSigma(df, z));
  const V seen = hn::LoadU(df, f.seen + j0);
  const auto carve = hn::RebindMask(du, hn::Lt(seen, hn::Sub(z, tolerance)));
  const auto at_depth = hn::RebindMask(du, hn::Le(seen, hn::Add(z, tolerance)));
  auto kind = hn::IfThenElse(at_depth, hn::Set(du, AssociationPlan::kAtDepth), hn::Set(du, AssociationPlan::kInFront));
  kind = hn::IfThenElse(carve, hn::Set(du, AssociationPlan::kCarve), kind);
  kind = hn::IfThenElse(empty, hn::Set(du, AssociationPlan::kEmpty), kind);
  kind = hn::IfThenElseZero(measured, kind);  // kNothing
  auto bits = hn::IfThenElseZero(hn::And(measured, has_normal), hn::Set(du, AssociationPlan::kHasNormal));
  const auto merging = hn::AndNot(empty, hn::AndNot(carve, hn::And(at_depth, hn::And(measured, has_normal))));
  if (!hn::AllFalse(du, merging)) MergeVector(df, f, surfels, j0, hn::RebindMask(df, merging), slot, nx, ny, nz, bits, plan);
  hn::StoreU(kind, du, plan.kind + j0);
  hn::StoreU(bits, du, plan.bits + j0);
  hn::StoreU(slot, du, plan.slot + j0);
}

// The whole vectors of the batch; the rest is the reference's (the same plans).
HWY_NOINLINE std::size_t PlanAssociationT(const AssociationFrame& frame, const Surfel* surfels, std::size_t count,
                                          AssociationPlan& plan) {
  const hn::ScalableTag<float> df;
  const std::size_t lanes = hn::Lanes(df);
  std::size_t j0 = 0;
  for (; j0 + lanes <= count; j0 += lanes) PlanPixels(df, frame, surfels, j0, plan);
  return j0;
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::map
HWY_AFTER_NAMESPACE();

#endif  // include guard
