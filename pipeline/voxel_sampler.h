// Foveated voxel sampling (Eq. 7): every region but the fovea is reduced to one
// point per occupied voxel of its own size, at the centroid of the voxel's points,
// with their mean colour. The fovea passes untouched.
//
// - The lattice is anchored at the world origin: voxel (i, j, k) of size v covers
//   [i v, (i+1) v) x [j v, (j+1) v) x [k v, (k+1) v) in world coordinates, with
//   i = floor((origin_m.x + x) * (1 / v)) evaluated in double. A static scene
//   therefore gives the same voxels whatever the cloud's extent or origin.
// - Output order: the fovea's points in input order, then each region's voxels in
//   increasing (i, j, k). Deterministic, and independent of the input order.
// - Centroids are accumulated in double relative to the voxel's first point, so a
//   million points in one voxel or a cloud 10 km from the world origin stay exact
//   to float rounding; each output coordinate is clamped to the range of its
//   voxel's points, which keeps it inside the voxel.
// - Voxel indices are packed per region relative to the frame's smallest index,
//   20 bits per axis. A region spanning more than 2^20 voxels along an axis is
//   refused with kRangeExceeded; nothing wraps silently.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/result.h"
#include "pipeline/acuity.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline {

inline constexpr int kVoxelAxisBits = 20;
inline constexpr uint32_t kNoRepresentative = UINT32_MAX;
inline constexpr int64_t kMaxVoxelSpan = int64_t{1} << kVoxelAxisBits;
// The voxel samplers' two capacity errors (kCapacityExceeded), on which the
// foveator coarsens and tries again, a frame at a time: short enough for
// std::string's own buffer (15 bytes in libstdc++), so that a retry allocates
// nothing; Foveator::sampleWithinCapacity words the error when it gives up.
inline constexpr const char* kVoxelsFull = "max_voxels full";
inline constexpr const char* kOutputFull = "output full";

struct SampleCounts {
  std::array<uint32_t, kMaxRegions> in{};   // input points per region
  std::array<uint32_t, kMaxRegions> out{};  // output points per region
};

// 1 / voxel size of regions 1 .. region_count - 1 into inv_voxel[1 .. region_count)
// (the other entries untouched); kInvalidArgument naming the region when a size is
// not a positive number with a finite inverse. Shared by the voxel samplers.
Status inverseVoxelSizes(int region_count, const std::array<double, kMaxRegions>& voxel_size_m, double* inv_voxel);

// World voxel index along one axis; the specification shared by every kernel.
inline double voxelIndex(double origin_m, float coord, double inv_voxel_m) {
  return std::floor((origin_m + static_cast<double>(coord)) * inv_voxel_m);
}

// Copies the fovea (region 0) untouched, in input order, to `out` from index
// `o` on (the front, for a sampler's own output), sets representative[] for
// every input point (kNoRepresentative for the others, which the voxel
// reduction fills in later) and returns the index after the last copied.
inline std::size_t copyFovea(const PointCloud& in, const uint8_t* region, FoveatedCloud& out,
                             uint32_t* representative, std::size_t o = 0) {
  for (std::size_t i = 0; i < in.size(); ++i) {
    if (region[i] != 0) {
      if (representative) representative[i] = kNoRepresentative;
      continue;
    }
    if (representative) representative[i] = static_cast<uint32_t>(o);
    out.points.x()[o] = in.x()[i];
    out.points.y()[o] = in.y()[i];
    out.points.z()[o] = in.z()[i];
    out.points.rgb()[o] = in.rgb()[i];
    out.region[o] = 0;
    if (out.hasWeights()) out.weight[o] = 1;
    ++o;
  }
  return o;
}

// Reduces one voxel to output point o: the centroid of its members' positions,
// summed in double relative to the first member and clamped to the members' range
// (so it stays inside the voxel), the rounded mean colour, and the weight. Every
// sampler calls this with the members in input order, which is what makes their
// outputs bit-identical to the reference's.
inline void reduceVoxel(const PointCloud& in, const uint32_t* members, std::size_t count, uint8_t region,
                        std::size_t o, FoveatedCloud& out, uint32_t* representative) {
  const uint32_t first = members[0];
  const float fx = in.x()[first], fy = in.y()[first], fz = in.z()[first];
  double sx = 0.0, sy = 0.0, sz = 0.0;
  uint64_t sr = 0, sg = 0, sb = 0;
  float lo[3] = {fx, fy, fz}, hi[3] = {fx, fy, fz};
  for (std::size_t q = 0; q < count; ++q) {
    const uint32_t i = members[q];
    if (representative) representative[i] = static_cast<uint32_t>(o);
    const float px = in.x()[i], py = in.y()[i], pz = in.z()[i];
    sx += static_cast<double>(px) - fx;
    sy += static_cast<double>(py) - fy;
    sz += static_cast<double>(pz) - fz;
    lo[0] = std::min(lo[0], px), hi[0] = std::max(hi[0], px);
    lo[1] = std::min(lo[1], py), hi[1] = std::max(hi[1], py);
    lo[2] = std::min(lo[2], pz), hi[2] = std::max(hi[2], pz);
    const uint32_t c = in.rgb()[i];
    sr += rgbRed(c);
    sg += rgbGreen(c);
    sb += rgbBlue(c);
  }
  const auto n = static_cast<uint64_t>(count);
  const double inv_n = 1.0 / static_cast<double>(n);
  out.points.x()[o] = std::clamp(static_cast<float>(fx + sx * inv_n), lo[0], hi[0]);
  out.points.y()[o] = std::clamp(static_cast<float>(fy + sy * inv_n), lo[1], hi[1]);
  out.points.z()[o] = std::clamp(static_cast<float>(fz + sz * inv_n), lo[2], hi[2]);
  out.points.rgb()[o] = packRgb(static_cast<uint8_t>((sr + n / 2) / n), static_cast<uint8_t>((sg + n / 2) / n),
                                static_cast<uint8_t>((sb + n / 2) / n));
  out.region[o] = region;
  if (out.hasWeights()) out.weight[o] = static_cast<uint32_t>(n);
}

class VoxelSampler {
 public:
  VoxelSampler() = default;
  // Allocates all scratch memory for clouds of up to max_points points and
  // outputs of up to max_voxels voxels.
  VoxelSampler(std::size_t max_points, std::size_t max_voxels);

  // region[i] is point i's region (0 = fovea, kRegionInvalid = skip);
  // voxel_size_m[n] is region n's voxel edge (n >= 1). If representative is not
  // null, representative[i] receives the index in `out` of the point that stands
  // for input point i (kNoRepresentative for skipped points): what error metrics
  // need. Never allocates.
  Status sample(const PointCloud& in, const uint8_t* region, int region_count,
                const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out,
                SampleCounts& counts, uint32_t* representative = nullptr);
  // sample()'s points appended to `out` after its `first` points, which stay,
  // as do its origin and colour flag: the points written are relative to
  // in.origin_m all the same (the caller moves them if the origins differ).
  // Nothing is written when an error is returned.
  Status sampleAt(const PointCloud& in, const uint8_t* region, int region_count,
                  const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out, std::size_t first,
                  SampleCounts& counts, uint32_t* representative = nullptr);

  std::size_t maxPoints() const { return keys_.size(); }
  std::size_t maxVoxels() const { return max_voxels_; }

 private:
  std::size_t max_voxels_ = 0;
  std::vector<uint64_t> keys_, keys_scratch_;
  std::vector<uint32_t> index_, index_scratch_;
};

// Sorts (key, index) pairs by key, stably, with LSD radix passes over the bytes
// that vary. Uses the scratch arrays (each n long); never allocates.
void radixSortPairs(uint64_t* keys, uint32_t* index, uint64_t* keys_scratch, uint32_t* index_scratch,
                    std::size_t n);

// Sorts values by their bits [lo_bit, lo_bit + bits), stably, with LSD radix passes of
// at most 11 bits (fewer passes than bytes, and one array moved instead of two: a
// payload packed below lo_bit, such as an index, rides along). Uses the scratch array
// (n long); never allocates. 0 <= lo_bit, 0 <= bits, lo_bit + bits <= 64.
void radixSortBits(uint64_t* values, uint64_t* scratch, std::size_t n, int lo_bit, int bits);

}  // namespace fovea::pipeline
