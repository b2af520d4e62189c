// Per-target body of gatherIndexSimd (index_map.h); compiled once per Highway
// target by index_map_simd.cpp. Bit for bit gatherIndexRef: a vector of
// neighbouring pixels of one row at a time, each lane running the reference's
// offsets in its order with its arithmetic (Add, Mul, Div and comparisons, never
// MulAdd). The centres a vector needs at an offset are one unaligned load of
// the grid's row, which the grid's border and slack (empty cells) keep in
// bounds; a row's tail is computed whole and stored through a copy.

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_MAP_INDEX_MAP_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_MAP_INDEX_MAP_SIMD_INL_H_
#undef FOVEA_PIPELINE_MAP_INDEX_MAP_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_MAP_INDEX_MAP_SIMD_INL_H_
#endif

#include <cstring>
#include <limits>

#include "hwy/highway.h"
#include "pipeline/map/depth_sigma_simd-inl.h"
#include "pipeline/map/index_map.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::map {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// The pixels x .. x + lanes - 1 of row y: their slots and depths.
template <class DF>
HWY_INLINE void GatherVector(DF df, const CentreGrid& g, float sigmas, int x, int y, uint32_t* slot_out,
                             float* depth_out) {
  const hn::RebindToUnsigned<DF> du;
  const hn::RebindToSigned<DF> di;
  auto held = hn::Set(df, std::numeric_limits<float>::infinity());
  auto cell = hn::Set(du, CentreGrid::kEmptyCell);
  const auto slot_bits = hn::Set(di, static_cast<int32_t>(CentreGrid::kSlotBits));
  auto held_slot = slot_bits;
  auto held_rsq = hn::Set(di, -1);
  const auto zero = hn::Zero(df);
  const auto one = hn::Set(df, 1.0f);
  for (const GatherOffset& o : kGatherOffsets) {
    const std::size_t k = g.at(x - o.du, y - o.dv);
    const auto c = hn::LoadU(du, g.cell + k);
    const auto iz = hn::Add(hn::Add(hn::LoadU(df, g.inv_depth + k),
                                    hn::Mul(hn::LoadU(df, g.grad_u + k), hn::Set(df, static_cast<float>(o.du)))),
                            hn::Mul(hn::LoadU(df, g.grad_v + k), hn::Set(df, static_cast<float>(o.dv))));
    const auto reach = hn::BitCast(di, hn::ShiftRight<24>(c));
    const auto reaches = hn::RebindMask(df, hn::Gt(reach, hn::Set(di, static_cast<int32_t>(o.reach) - 1)));
    const auto z = hn::Div(one, iz);
    const auto same = hn::Mul(hn::Set(df, sigmas), DepthSigma(df, z));
    const auto nearer = hn::Lt(z, hn::Sub(held, same));
    // Slots are below 2^24: signed comparisons order them.
    const int32_t rsq = o.du * o.du + o.dv * o.dv;
    const auto slot = hn::And(hn::BitCast(di, c), slot_bits);
    const auto older = hn::And(hn::Eq(held_rsq, hn::Set(di, rsq)), hn::Lt(slot, held_slot));
    const auto tie = hn::And(hn::Le(z, hn::Add(held, same)), hn::RebindMask(df, older));
    const auto take = hn::And(hn::And(hn::Gt(iz, zero), reaches), hn::Or(nearer, tie));
    const auto take_i = hn::RebindMask(di, take);
    held = hn::IfThenElse(take, z, held);
    cell = hn::IfThenElse(hn::RebindMask(du, take), c, cell);
    held_slot = hn::IfThenElse(take_i, slot, held_slot);
    held_rsq = hn::IfThenElse(take_i, hn::Set(di, rsq), held_rsq);
  }
  const auto slot = hn::And(cell, hn::Set(du, CentreGrid::kSlotBits));
  const auto none = hn::Eq(slot, hn::Set(du, CentreGrid::kSlotBits));
  hn::StoreU(hn::IfThenElse(none, hn::Set(du, IndexMap::kNoSurfel), slot), du, slot_out);
  hn::StoreU(held, df, depth_out);
}

HWY_NOINLINE void GatherIndexT(const CentreGrid& grid, float sigmas, int y0, int y1, const IndexOut& out) {
  const hn::ScalableTag<float> df;
  const auto lanes = static_cast<int>(hn::Lanes(df));
  constexpr std::size_t kMaxLanes = HWY_MAX_BYTES / sizeof(float);
  HWY_ALIGN uint32_t tail_slot[kMaxLanes];
  HWY_ALIGN float tail_depth[kMaxLanes];
  const int w = grid.width;
  for (int y = y0; y < y1; ++y) {
    const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    int x = 0;
    for (; x + lanes <= w; x += lanes) {
      GatherVector(df, grid, sigmas, x, y, out.slot + row + x, out.depth + row + x);
    }
    if (x < w) {
      GatherVector(df, grid, sigmas, x, y, tail_slot, tail_depth);
      const auto n = static_cast<std::size_t>(w - x);
      std::memcpy(out.slot + row + x, tail_slot, n * sizeof(uint32_t));
      std::memcpy(out.depth + row + x, tail_depth, n * sizeof(float));
    }
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::map
HWY_AFTER_NAMESPACE();

#endif  // include guard
