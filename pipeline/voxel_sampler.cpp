#include "pipeline/voxel_sampler.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "pipeline/partition.h"

namespace fovea::pipeline {

namespace {

// |index| below 2^52 converts to int64 exactly, far beyond any usable span.
constexpr double kMaxAbsIndex = 4503599627370496.0;

struct AxisRange {
  int64_t lo = INT64_MAX;
  int64_t hi = INT64_MIN;
  void add(int64_t v) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
};

const char* axisName(int axis) { return axis == 0 ? "x" : (axis == 1 ? "y" : "z"); }

// Voxel index ranges per region and axis.
using RegionIndexRanges = std::array<std::array<AxisRange, 3>, kMaxRegions>;

// Pass 1: counts.in per region, index ranges per region and axis, and the range
// check of every index.
Status measureIndexRanges(const PointCloud& in, const uint8_t* region, int region_count,
                          const std::array<double, kMaxRegions>& inv_voxel, SampleCounts& counts,
                          RegionIndexRanges& range) {
  const std::size_t n = in.size();
  const float* coord[3] = {in.x(), in.y(), in.z()};
  const double origin[3] = {in.origin_m.x(), in.origin_m.y(), in.origin_m.z()};
  for (std::size_t i = 0; i < n; ++i) {
    const uint8_t r = region[i];
    if (r >= region_count) continue;  // kRegionInvalid: already counted by the partition
    ++counts.in[r];
    if (r == 0) continue;
    for (int a = 0; a < 3; ++a) {
      const double k = voxelIndex(origin[a], coord[a][i], inv_voxel[r]);
      if (!(std::fabs(k) < kMaxAbsIndex)) {
        return {ErrorCode::kRangeExceeded,
                "voxel sampler: region " + std::to_string(r) + " point " + std::to_string(i) + " has voxel index " +
                    std::to_string(k) + " along " + axisName(a) + " (not a finite coordinate within range)"};
      }
      range[r][a].add(static_cast<int64_t>(k));
    }
  }
  return Status::ok();
}

// Every occupied region's span along every axis fits the packed key.
Status checkVoxelSpans(const RegionIndexRanges& range, const SampleCounts& counts, int region_count,
                       const std::array<double, kMaxRegions>& voxel_size_m) {
  for (int r = 1; r < region_count; ++r) {
    if (counts.in[r] == 0) continue;
    for (int a = 0; a < 3; ++a) {
      const int64_t span = range[r][a].hi - range[r][a].lo + 1;
      if (span > kMaxVoxelSpan) {
        return {ErrorCode::kRangeExceeded,
                "voxel sampler: region " + std::to_string(r) + " spans " + std::to_string(span) +
                    " voxels of " + std::to_string(voxel_size_m[r]) + " m along " + axisName(a) + ", more than " +
                    std::to_string(kMaxVoxelSpan) + ": crop the cloud or raise fixation.min_m"};
      }
    }
  }
  return Status::ok();
}

// Pass 2: packed keys (region, i, j, k) of the non-fovea points, with their
// indexes; returns how many.
std::size_t packVoxelKeys(const PointCloud& in, const uint8_t* region, int region_count,
                          const std::array<double, kMaxRegions>& inv_voxel, const RegionIndexRanges& range,
                          uint64_t* keys, uint32_t* index) {
  const std::size_t n = in.size();
  const float* coord[3] = {in.x(), in.y(), in.z()};
  const double origin[3] = {in.origin_m.x(), in.origin_m.y(), in.origin_m.z()};
  std::size_t m = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const uint8_t r = region[i];
    if (r == 0 || r >= region_count) continue;
    uint64_t key = uint64_t{r} << (3 * kVoxelAxisBits);
    for (int a = 0; a < 3; ++a) {
      const auto k = static_cast<int64_t>(voxelIndex(origin[a], coord[a][i], inv_voxel[r]));
      key |= static_cast<uint64_t>(k - range[r][a].lo) << ((2 - a) * kVoxelAxisBits);
    }
    keys[m] = key;
    index[m] = static_cast<uint32_t>(i);
    ++m;
  }
  return m;
}

// One centroid per run of equal keys of the m sorted ones, written from out index o
// on; returns the index after the last.
std::size_t reduceVoxelRuns(const PointCloud& in, const uint64_t* keys, const uint32_t* index, std::size_t m,
                            std::size_t o, FoveatedCloud& out, SampleCounts& counts, uint32_t* representative) {
  for (std::size_t s = 0; s < m;) {
    std::size_t e = s + 1;
    while (e < m && keys[e] == keys[s]) ++e;
    const auto r = static_cast<uint8_t>(keys[s] >> (3 * kVoxelAxisBits));
    reduceVoxel(in, index + s, e - s, r, o, out, representative);
    ++counts.out[r];
    ++o;
    s = e;
  }
  return o;
}

}  // namespace

Status inverseVoxelSizes(int region_count, const std::array<double, kMaxRegions>& voxel_size_m, double* inv_voxel) {
  for (int r = 1; r < region_count; ++r) {
    const double v = voxel_size_m[r];
    if (!(std::isfinite(v) && v > 0.0) || !std::isfinite(1.0 / v)) {
      return {ErrorCode::kInvalidArgument, "voxel sampler: region " + std::to_string(r) +
                                               " voxel size " + std::to_string(v) + " m is not a positive number"};
    }
    inv_voxel[r] = 1.0 / v;
  }
  return Status::ok();
}

VoxelSampler::VoxelSampler(std::size_t max_points, std::size_t max_voxels)
    : max_voxels_(max_voxels),
      keys_(max_points),
      keys_scratch_(max_points),
      index_(max_points),
      index_scratch_(max_points) {}

void radixSortPairs(uint64_t* keys, uint32_t* index, uint64_t* keys_scratch, uint32_t* index_scratch,
                    std::size_t n) {
  if (n < 2) return;
  uint32_t histogram[8][256];
  std::memset(histogram, 0, sizeof histogram);
  for (std::size_t i = 0; i < n; ++i) {
    const uint64_t k = keys[i];
    for (int b = 0; b < 8; ++b) ++histogram[b][(k >> (8 * b)) & 0xFF];
  }
  uint64_t* src_k = keys;
  uint32_t* src_i = index;
  uint64_t* dst_k = keys_scratch;
  uint32_t* dst_i = index_scratch;
  for (int b = 0; b < 8; ++b) {
    uint32_t* h = histogram[b];
    // A byte that is the same in every key does not reorder anything.
    if (h[(src_k[0] >> (8 * b)) & 0xFF] == n) continue;
    uint32_t offset = 0;
    for (int v = 0; v < 256; ++v) {
      const uint32_t c = h[v];
      h[v] = offset;
      offset += c;
    }
    for (std::size_t i = 0; i < n; ++i) {
      const uint32_t slot = h[(src_k[i] >> (8 * b)) & 0xFF]++;
      dst_k[slot] = src_k[i];
      dst_i[slot] = src_i[i];
    }
    std::swap(src_k, dst_k);
    std::swap(src_i, dst_i);
  }
  if (src_k != keys) {
    std::memcpy(keys, src_k, n * sizeof *keys);
    std::memcpy(index, src_i, n * sizeof *index);
  }
}

void radixSortBits(uint64_t* values, uint64_t* scratch, std::size_t n, int lo_bit, int bits) {
  if (n < 2 || bits <= 0) return;
  constexpr int kMaxDigitBits = 11;
  constexpr int kMaxPasses = (64 + kMaxDigitBits - 1) / kMaxDigitBits;
  // Digits of equal width: 40 bits take four passes of 10, not three of 11 and one of 7.
  const int passes = (bits + kMaxDigitBits - 1) / kMaxDigitBits;
  const int digit_bits = (bits + passes - 1) / passes;
  const uint64_t digit_mask = (uint64_t{1} << digit_bits) - 1;
  static_assert(kMaxPasses * (std::size_t{1} << kMaxDigitBits) * sizeof(uint32_t) <= 48 * 1024);
  uint32_t histogram[kMaxPasses][std::size_t{1} << kMaxDigitBits];
  const std::size_t buckets = std::size_t{1} << digit_bits;
  for (int p = 0; p < passes; ++p) std::memset(histogram[p], 0, buckets * sizeof(uint32_t));
  // The last digit may reach past lo_bit + bits: those bits are masked off, not sorted.
  const uint64_t field_mask = bits >= 64 ? ~uint64_t{0} : ((uint64_t{1} << bits) - 1);
  for (std::size_t i = 0; i < n; ++i) {
    const uint64_t field = (values[i] >> lo_bit) & field_mask;
    for (int p = 0; p < passes; ++p) ++histogram[p][(field >> (p * digit_bits)) & digit_mask];
  }
  uint64_t* src = values;
  uint64_t* dst = scratch;
  for (int p = 0; p < passes; ++p) {
    uint32_t* h = histogram[p];
    const int shift = lo_bit + p * digit_bits;
    const uint64_t mask = p == passes - 1 ? (field_mask >> (p * digit_bits)) : digit_mask;
    // A digit that is the same in every value does not reorder anything.
    if (h[(src[0] >> shift) & mask] == n) continue;
    uint32_t offset = 0;
    for (std::size_t v = 0; v < buckets; ++v) {
      const uint32_t c = h[v];
      h[v] = offset;
      offset += c;
    }
    for (std::size_t i = 0; i < n; ++i) dst[h[(src[i] >> shift) & mask]++] = src[i];
    std::swap(src, dst);
  }
  if (src != values) std::memcpy(values, src, n * sizeof *values);
}

Status VoxelSampler::sample(const PointCloud& in, const uint8_t* region, int region_count,
                            const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out,
                            SampleCounts& counts, uint32_t* representative) {
  out.clear();
  out.points.origin_m = in.origin_m;
  out.points.has_color = in.has_color;
  return sampleAt(in, region, region_count, voxel_size_m, out, 0, counts, representative);
}

Status VoxelSampler::sampleAt(const PointCloud& in, const uint8_t* region, int region_count,
                              const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out,
                              std::size_t first, SampleCounts& counts, uint32_t* representative) {
  counts = {};
  const std::size_t n = in.size();
  if (n > keys_.size()) {
    return {ErrorCode::kCapacityExceeded,
            "voxel sampler: cloud has " + std::to_string(n) + " points, capacity is " +
                std::to_string(keys_.size()) + ": raise pipeline.max_points"};
  }
  if (region_count < 1 || region_count > kMaxRegions) {
    return {ErrorCode::kInvalidArgument, "voxel sampler: region count out of range"};
  }

  std::array<double, kMaxRegions> inv_voxel{};
  if (Status s = inverseVoxelSizes(region_count, voxel_size_m, inv_voxel.data()); !s) return s;

  // Pass 1: index ranges per region and axis, and the range check.
  RegionIndexRanges range{};
  if (Status s = measureIndexRanges(in, region, region_count, inv_voxel, counts, range); !s) return s;
  if (Status s = checkVoxelSpans(range, counts, region_count, voxel_size_m); !s) return s;

  // Pass 2: packed keys (region, i, j, k) of the non-fovea points.
  const std::size_t m = packVoxelKeys(in, region, region_count, inv_voxel, range, keys_.data(), index_.data());
  radixSortPairs(keys_.data(), index_.data(), keys_scratch_.data(), index_scratch_.data(), m);

  std::size_t voxels = 0;
  for (std::size_t s = 0; s < m; ++s) voxels += (s == 0 || keys_[s] != keys_[s - 1]);
  // The capacity errors the foveator coarsens on: no allocation (kVoxelsFull).
  if (voxels > max_voxels_) return {ErrorCode::kCapacityExceeded, kVoxelsFull};
  const std::size_t fovea = counts.in[0];
  if (first > out.size() || first + fovea + voxels > out.points.capacity()) {
    return {ErrorCode::kCapacityExceeded, kOutputFull};
  }

  // The fovea, untouched and in input order.
  std::size_t o = copyFovea(in, region, out, representative, first);
  counts.out[0] = static_cast<uint32_t>(fovea);

  // One centroid per run of equal keys.
  o = reduceVoxelRuns(in, keys_.data(), index_.data(), m, o, out, counts, representative);
  (void)out.points.resize(o);
  return Status::ok();
}

}  // namespace fovea::pipeline
