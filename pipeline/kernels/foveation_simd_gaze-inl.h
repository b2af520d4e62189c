// The SIMD kernels of the gaze's cones, in double: the point seen from the eye
// (also used by ACUITY's kernels, foveation_simd_acuity-inl.h), the partition into
// cones with the region driver it shares with ACUITY's levels, and the fixation's
// hit cone.
// Per-target bodies, compiled once per Highway target by foveation_simd.cpp, which
// gives the rules every -inl header of these kernels follows (the namespace
// brackets, bit-exactness).

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_GAZE_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_GAZE_INL_H_
#undef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_GAZE_INL_H_
#else
#define FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_GAZE_INL_H_
#endif

#include <algorithm>
#include <cstring>

#include "hwy/highway.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/kernels/store_first_lanes-inl.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// ---- the point seen from the eye ------------------------------------------------

// With v = P - H (vx, vy, vz) and the unit gaze L: t = v.L, the part of v along the
// gaze, and d = |v - t L|, its distance from the gaze axis, with axialRadial()'s
// expressions in that order (partition.h): t = vx lx + vy ly + vz lz, left to right;
// r = v - t L; d = sqrt(rx^2 + ry^2 + rz^2). In the vectors' precision (double for
// the partition and the hit cone, float for ACUITY's levels). Two functions, not a
// struct: SVE's vectors are sizeless and cannot be members.
template <class D, typename T>
HWY_INLINE hn::Vec<D> AlongGaze(D d, const T* l, hn::Vec<D> vx, hn::Vec<D> vy, hn::Vec<D> vz) {
  return hn::Add(hn::Add(hn::Mul(vx, hn::Set(d, l[0])), hn::Mul(vy, hn::Set(d, l[1]))), hn::Mul(vz, hn::Set(d, l[2])));
}
template <class D, typename T>
HWY_INLINE hn::Vec<D> FromGazeAxis(D d, const T* l, hn::Vec<D> vx, hn::Vec<D> vy, hn::Vec<D> vz, hn::Vec<D> t) {
  const auto rx = hn::Sub(vx, hn::Mul(t, hn::Set(d, l[0])));
  const auto ry = hn::Sub(vy, hn::Mul(t, hn::Set(d, l[1])));
  const auto rz = hn::Sub(vz, hn::Mul(t, hn::Set(d, l[2])));
  return hn::Sqrt(hn::Add(hn::Add(hn::Mul(rx, rx), hn::Mul(ry, ry)), hn::Mul(rz, rz)));
}

// ---- partition ----------------------------------------------------------------

// Regions of one vector of points (x, y, z: float arrays of at least Lanes(dd)).
template <class DD>
HWY_INLINE hn::Vec<DD> PartitionVector(DD dd, const PartitionParams& p, const float* xs, const float* ys,
                                       const float* zs) {
  const hn::Rebind<float, DD> df;
  const auto px = hn::PromoteTo(dd, hn::LoadU(df, xs));
  const auto py = hn::PromoteTo(dd, hn::LoadU(df, ys));
  const auto pz = hn::PromoteTo(dd, hn::LoadU(df, zs));
  const auto finite = hn::And(hn::And(hn::IsFinite(px), hn::IsFinite(py)), hn::IsFinite(pz));
  const auto vx = hn::Add(hn::Set(dd, p.origin_minus_eye[0]), px);
  const auto vy = hn::Add(hn::Set(dd, p.origin_minus_eye[1]), py);
  const auto vz = hn::Add(hn::Set(dd, p.origin_minus_eye[2]), pz);
  const auto t = AlongGaze(dd, p.l, vx, vy, vz);
  const auto d = FromGazeAxis(dd, p.l, vx, vy, vz, t);
  const auto zero = hn::Zero(dd);
  const auto ahead = hn::Ge(t, zero);
  // The first bound that holds wins: walk them from the outermost inwards.
  auto region = hn::Set(dd, static_cast<double>(p.bounds.count));
  for (int j = p.bounds.count - 1; j >= 0; --j) {
    const auto tan_e = hn::Set(dd, p.bounds.tan_e[j]);
    const ConeBounds::Kind kind = p.bounds.kind[j];
    const auto inside = kind == ConeBounds::Kind::kBelow90 ? hn::Le(d, hn::Mul(tan_e, t))
                        : kind == ConeBounds::Kind::kAt90  ? ahead
                                                           : hn::Or(ahead, hn::Ge(d, hn::Mul(tan_e, hn::Neg(t))));
    region = hn::IfThenElse(inside, hn::Set(dd, static_cast<double>(j)), region);
  }
  return hn::IfThenElse(finite, region, hn::Set(dd, static_cast<double>(kRegionInvalid)));
}

// Runs vector(d, xs, ys, zs) (a vector of T, one region per lane: double for the
// partition, float for ACUITY's levels) over points [begin, end), one vector at a time
// (the tail on a zero-padded copy), writes each result as the point's region byte and
// counts them in histogram. The bytes are narrowed in registers: reading the lanes
// back from a vector store would stall on store forwarding at every point.
template <typename T, class VectorFn>
HWY_INLINE void RegionRange(const float* x, const float* y, const float* z, std::size_t begin, std::size_t end,
                            uint8_t* region_out, uint32_t* histogram, const VectorFn& vector) {
  const hn::ScalableTag<T> d;
  const hn::Rebind<int32_t, decltype(d)> di;
  const hn::Rebind<uint8_t, decltype(d)> du8;
  const auto bytes = [&](auto v) {
    if constexpr (sizeof(T) == sizeof(int32_t)) {
      return hn::DemoteTo(du8, hn::ConvertTo(di, v));
    } else {
      return hn::DemoteTo(du8, hn::DemoteTo(di, v));
    }
  };
  const std::size_t lanes = hn::Lanes(d);
  constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(T);
  std::size_t i = begin;
  for (; i + lanes <= end; i += lanes) hn::StoreU(bytes(vector(d, x + i, y + i, z + i)), du8, region_out + i);
  if (i < end) {
    HWY_ALIGN float tx[kMax] = {}, ty[kMax] = {}, tz[kMax] = {};
    HWY_ALIGN uint8_t tail[kMax];
    const std::size_t rest = end - i;
    std::memcpy(tx, x + i, rest * sizeof(float));
    std::memcpy(ty, y + i, rest * sizeof(float));
    std::memcpy(tz, z + i, rest * sizeof(float));
    hn::Store(bytes(vector(d, tx, ty, tz)), du8, tail);
    std::memcpy(region_out + i, tail, rest);
  }
  // Four histograms, byte k counted in part k % 4: neighbouring points mostly share a
  // region, and one counter would make each increment wait for the previous one.
  uint32_t part[4][256] = {};
  std::size_t k = begin;
  for (; k + 4 <= end; k += 4) {
    ++part[0][region_out[k]];
    ++part[1][region_out[k + 1]];
    ++part[2][region_out[k + 2]];
    ++part[3][region_out[k + 3]];
  }
  for (; k < end; ++k) ++part[0][region_out[k]];
  for (int r = 0; r < 256; ++r) histogram[r] += part[0][r] + part[1][r] + part[2][r] + part[3][r];
}

inline void PartitionRangeT(const float* x, const float* y, const float* z, const PartitionParams& p,
                            std::size_t begin, std::size_t end, uint8_t* region_out, uint32_t* histogram) {
  RegionRange<double>(x, y, z, begin, end, region_out, histogram,
              [&p](auto dd, const float* xs, const float* ys, const float* zs) {
                return PartitionVector(dd, p, xs, ys, zs);
              });
}

// ---- fixation: the hit cone --------------------------------------------------

// t of the fovea's points inside the hit cone (t > 0 and d <= tan_cone t, with
// axialRadial()'s expressions), appended in input order; returns how many.
inline std::size_t HitConeRangeT(const float* x, const float* y, const float* z, const uint8_t* region,
                                 std::size_t n, const double* origin_minus_eye, const double* l, double tan_cone,
                                 double* t_out) {
  const hn::ScalableTag<double> dd;
  const hn::Rebind<float, decltype(dd)> df;
  const std::size_t lanes = hn::Lanes(dd);
  constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(double);
  constexpr std::size_t kBlock = 64;  // a multiple of any vector's lane count
  constexpr uint64_t kOnes = 0x0101010101010101ull, kHighs = 0x8080808080808080ull;
  HWY_ALIGN double reg[kMax];
  HWY_ALIGN float tx[kMax], ty[kMax], tz[kMax];
  const auto zero = hn::Zero(dd);
  std::size_t m = 0;
  for (std::size_t b = 0; b < n; b += kBlock) {
    const std::size_t block_end = std::min(n, b + kBlock);
    if (block_end - b == kBlock) {  // 64 points without a fovea byte: skipped (most, except with FREF)
      uint64_t zero_bytes = 0;
      for (std::size_t w = 0; w < kBlock; w += 8) {
        uint64_t word;
        std::memcpy(&word, region + b + w, sizeof word);
        zero_bytes |= (word - kOnes) & ~word & kHighs;
      }
      if (zero_bytes == 0) continue;
    }
    for (std::size_t i = b; i < block_end; i += lanes) {
      const std::size_t valid = std::min(lanes, block_end - i);
      bool any = false;
      for (std::size_t k = 0; k < lanes; ++k) {
        const bool fovea = k < valid && region[i + k] == 0;
        reg[k] = fovea ? 1.0 : 0.0;
        any |= fovea;
      }
      if (!any) continue;
      const float* xs = x + i;
      const float* ys = y + i;
      const float* zs = z + i;
      if (valid < lanes) {  // the cloud's tail, zero-padded (padding is not in the fovea)
        std::fill(tx, tx + kMax, 0.0f), std::fill(ty, ty + kMax, 0.0f), std::fill(tz, tz + kMax, 0.0f);
        std::memcpy(tx, xs, valid * sizeof(float));
        std::memcpy(ty, ys, valid * sizeof(float));
        std::memcpy(tz, zs, valid * sizeof(float));
        xs = tx, ys = ty, zs = tz;
      }
      const auto vx = hn::Add(hn::Set(dd, origin_minus_eye[0]), hn::PromoteTo(dd, hn::LoadU(df, xs)));
      const auto vy = hn::Add(hn::Set(dd, origin_minus_eye[1]), hn::PromoteTo(dd, hn::LoadU(df, ys)));
      const auto vz = hn::Add(hn::Set(dd, origin_minus_eye[2]), hn::PromoteTo(dd, hn::LoadU(df, zs)));
      const auto t = AlongGaze(dd, l, vx, vy, vz);
      const auto d = FromGazeAxis(dd, l, vx, vy, vz, t);
      const auto inside = hn::And(hn::And(hn::Gt(hn::Load(dd, reg), zero), hn::Gt(t, zero)),
                                  hn::Le(d, hn::Mul(hn::Set(dd, tan_cone), t)));
      // Not CompressBlendedStore: t_out may end within this vector (StoreFirstLanes).
      const std::size_t inside_count = hn::CountTrue(dd, inside);
      StoreFirstLanes(hn::Compress(t, inside), dd, inside_count, t_out + m);
      m += inside_count;
    }
  }
  return m;
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::kernels
HWY_AFTER_NAMESPACE();

#endif  // include guard
