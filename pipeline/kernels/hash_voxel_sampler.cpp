#include "pipeline/kernels/hash_voxel_sampler.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <string>

#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/partition.h"

namespace fovea::pipeline {

namespace {

// As the reference: |index| below 2^52 converts to int64 exactly.
constexpr double kMaxAbsIndex = 4503599627370496.0;

const char* axisName(int axis) { return axis == 0 ? "x" : (axis == 1 ? "y" : "z"); }

}  // namespace

HashVoxelSampler::HashVoxelSampler(std::size_t max_points, std::size_t max_voxels)
    : max_points_(max_points),
      max_voxels_(max_voxels),
      voxels_(max_voxels),
      sort_keys_(max_voxels),
      sort_keys_scratch_(max_voxels),
      sort_slot_(max_voxels),
      sort_slot_scratch_(max_voxels),
      out_pos_(max_voxels),
      chunk_index_(3 * kChunk) {
  const std::size_t entries = std::bit_ceil(std::max<std::size_t>(2 * max_voxels, 16));
  table_.assign(entries, Entry{kEmpty, 0});
}

namespace {
constexpr std::size_t kInitialTableEntries = std::size_t{1} << 14;  // 256 KiB
uint64_t hashKey(uint64_t key) { return key * 0x9E3779B97F4A7C15ull; }
}  // namespace

void HashVoxelSampler::clearTable(std::size_t voxels) {
  for (std::size_t s = 0; s < voxels; ++s) table_[voxels_[s].table_pos].key = kEmpty;
}

void HashVoxelSampler::growTable(std::size_t voxels) {
  clearTable(voxels);
  active_ *= 2;
  --shift_;
  const std::size_t mask = active_ - 1;
  for (std::size_t s = 0; s < voxels; ++s) {
    std::size_t pos = hashKey(voxels_[s].key) >> shift_;
    while (table_[pos].key != kEmpty) pos = (pos + 1) & mask;
    table_[pos] = Entry{voxels_[s].key, static_cast<uint32_t>(s)};
    voxels_[s].table_pos = static_cast<uint32_t>(pos);
  }
}

Status HashVoxelSampler::sample(const PointCloud& in, const uint8_t* region, int region_count,
                                const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out,
                                SampleCounts& counts, uint32_t* representative) {
  counts = {};
  out.clear();
  out.points.origin_m = in.origin_m;
  out.points.has_color = in.has_color;
  const std::size_t n = in.size();
  if (n > max_points_) {
    return {ErrorCode::kCapacityExceeded, "voxel sampler: cloud has " + std::to_string(n) + " points, capacity is " +
                                              std::to_string(max_points_) + ": raise pipeline.max_points"};
  }
  if (region_count < 1 || region_count > kMaxRegions) {
    return {ErrorCode::kInvalidArgument, "voxel sampler: region count out of range"};
  }
  // Regions outside [1, region_count) get 0: their (unused) indices stay finite or NaN.
  std::array<double, 256> inv_voxel{};
  for (int r = 1; r < region_count; ++r) {
    const double v = voxel_size_m[r];
    if (!(std::isfinite(v) && v > 0.0) || !std::isfinite(1.0 / v)) {
      return {ErrorCode::kInvalidArgument, "voxel sampler: region " + std::to_string(r) + " voxel size " +
                                               std::to_string(v) + " m is not a positive number"};
    }
    inv_voxel[r] = 1.0 / v;
  }

  const float* coord[3] = {in.x(), in.y(), in.z()};
  const double origin[3] = {in.origin_m.x(), in.origin_m.y(), in.origin_m.z()};
  double* index[3] = {chunk_index_.data(), chunk_index_.data() + kChunk, chunk_index_.data() + 2 * kChunk};

  // One pass: voxel indices (voxelIndexSimd, bit-exact with voxelIndex), the
  // reference's checks (first bad index in point order; then spans; then the voxel
  // count), and accumulation. The hash key wraps each index to its low 20 bits:
  // unique within a region whose span fits 2^20 voxels, and a wider region is
  // refused below anyway. The sort key (relative to the region's smallest index,
  // as the reference packs it) is made per voxel once the ranges are known.
  int64_t lo_index[kMaxRegions][3], hi_index[kMaxRegions][3];
  for (auto& row : lo_index) std::fill(std::begin(row), std::end(row), INT64_MAX);
  for (auto& row : hi_index) std::fill(std::begin(row), std::end(row), INT64_MIN);
  constexpr uint64_t kAxisMask = (uint64_t{1} << kVoxelAxisBits) - 1;
  std::size_t voxels = 0;
  bool too_many_voxels = false;
  uint64_t last_key = kEmpty;
  uint32_t last_slot = 0;
  active_ = std::min(table_.size(), kInitialTableEntries);
  shift_ = 64 - std::countr_zero(active_);
  uint64_t table_mask = active_ - 1;
  recent_key_.fill(kEmpty);
  for (std::size_t c0 = 0; c0 < n; c0 += kChunk) {
    const std::size_t len = std::min(kChunk, n - c0);
    for (int a = 0; a < 3; ++a) voxelIndexSimd(coord[a] + c0, region + c0, len, origin[a], inv_voxel.data(), index[a]);
    for (std::size_t q = 0; q < len; ++q) {
      const std::size_t i = c0 + q;
      const uint8_t r = region[i];
      if (r >= region_count) continue;  // kRegionInvalid: already counted by the partition
      ++counts.in[r];
      if (r == 0) continue;
      int64_t k[3];
      for (int a = 0; a < 3; ++a) {
        const double d = index[a][q];
        if (!(std::fabs(d) < kMaxAbsIndex)) {
          clearTable(voxels);
          return {ErrorCode::kRangeExceeded, "voxel sampler: region " + std::to_string(r) + " point " +
                                                 std::to_string(i) + " has voxel index " + std::to_string(d) +
                                                 " along " + axisName(a) + " (not a finite coordinate within range)"};
        }
        k[a] = static_cast<int64_t>(d);
        lo_index[r][a] = std::min(lo_index[r][a], k[a]);
        hi_index[r][a] = std::max(hi_index[r][a], k[a]);
      }
      if (too_many_voxels) continue;  // still looking for the errors the reference reports first
      const uint64_t key = (uint64_t{r} << (3 * kVoxelAxisBits)) |
                           ((static_cast<uint64_t>(k[0]) & kAxisMask) << (2 * kVoxelAxisBits)) |
                           ((static_cast<uint64_t>(k[1]) & kAxisMask) << kVoxelAxisBits) |
                           (static_cast<uint64_t>(k[2]) & kAxisMask);
      const float px = coord[0][i], py = coord[1][i], pz = coord[2][i];
      uint32_t slot = last_slot;
      if (key != last_key) {
        const uint64_t hash = hashKey(key);
        // A small direct-mapped cache in front of the table: the few voxels a run
        // of rows keeps returning to stay in L1.
        const std::size_t line = hash >> (64 - kRecentBits);
        if (recent_key_[line] == key) {
          slot = recent_slot_[line];
          last_key = key;
          last_slot = slot;
          goto accumulate;
        }
        std::size_t pos = hash >> shift_;
        while (table_[pos].key != key && table_[pos].key != kEmpty) pos = (pos + 1) & table_mask;
        if (table_[pos].key == key) {
          slot = table_[pos].slot;
        } else {
          if (voxels == max_voxels_) {
            too_many_voxels = true;
            continue;
          }
          slot = static_cast<uint32_t>(voxels++);
          table_[pos] = Entry{key, slot};
          Voxel& v = voxels_[slot];
          v = Voxel{};
          v.key = key;
          v.table_pos = static_cast<uint32_t>(pos);
          v.index[0] = k[0], v.index[1] = k[1], v.index[2] = k[2];
          v.first[0] = v.lo[0] = v.hi[0] = px;
          v.first[1] = v.lo[1] = v.hi[1] = py;
          v.first[2] = v.lo[2] = v.hi[2] = pz;
          if (2 * voxels > active_ && active_ < table_.size()) {  // keep the load factor <= 1/2
            growTable(voxels);
            table_mask = active_ - 1;
          }
        }
        last_key = key;
        last_slot = slot;
        recent_key_[line] = key;
        recent_slot_[line] = slot;
      }
    accumulate:
      Voxel& v = voxels_[slot];
      v.sx += static_cast<double>(px) - v.first[0];
      v.sy += static_cast<double>(py) - v.first[1];
      v.sz += static_cast<double>(pz) - v.first[2];
      v.lo[0] = std::min(v.lo[0], px), v.hi[0] = std::max(v.hi[0], px);
      v.lo[1] = std::min(v.lo[1], py), v.hi[1] = std::max(v.hi[1], py);
      v.lo[2] = std::min(v.lo[2], pz), v.hi[2] = std::max(v.hi[2], pz);
      const uint32_t c = in.rgb()[i];
      v.sr += rgbRed(c);
      v.sg += rgbGreen(c);
      v.sb += rgbBlue(c);
      ++v.count;
      if (representative) representative[i] = slot;  // remapped to the output index below
    }
  }
  clearTable(voxels);  // the table is empty again for the next frame
  for (int r = 1; r < region_count; ++r) {
    if (counts.in[r] == 0) continue;
    for (int a = 0; a < 3; ++a) {
      const int64_t span = hi_index[r][a] - lo_index[r][a] + 1;
      if (span > kMaxVoxelSpan) {
        return {ErrorCode::kRangeExceeded,
                "voxel sampler: region " + std::to_string(r) + " spans " + std::to_string(span) + " voxels of " +
                    std::to_string(voxel_size_m[r]) + " m along " + axisName(a) + ", more than " +
                    std::to_string(kMaxVoxelSpan) + ": crop the cloud or raise fixation.min_m"};
      }
    }
  }
  if (too_many_voxels) {
    return {ErrorCode::kCapacityExceeded, "voxel sampler: more than " + std::to_string(max_voxels_) +
                                              " occupied voxels: raise pipeline.max_voxels"};
  }

  const std::size_t fovea = counts.in[0];
  if (fovea + voxels > out.points.capacity()) {
    return {ErrorCode::kCapacityExceeded, "voxel sampler: output needs " + std::to_string(fovea + voxels) +
                                              " points, capacity is " + std::to_string(out.points.capacity())};
  }

  // The fovea, untouched and in input order.
  std::size_t o = 0;
  float* ox = out.points.x();
  float* oy = out.points.y();
  float* oz = out.points.z();
  uint32_t* orgb = out.points.rgb();
  for (std::size_t i = 0; i < n; ++i) {
    const uint8_t r = region[i];
    if (r != 0) {
      if (representative && r >= region_count) representative[i] = kNoRepresentative;
      continue;
    }
    if (representative) representative[i] = static_cast<uint32_t>(o);
    ox[o] = in.x()[i];
    oy[o] = in.y()[i];
    oz[o] = in.z()[i];
    orgb[o] = in.rgb()[i];
    out.region[o] = 0;
    out.weight[o] = 1;
    ++o;
  }
  counts.out[0] = static_cast<uint32_t>(fovea);

  // The occupied voxels in key order (keys are unique: no ties to keep stable).
  for (std::size_t s = 0; s < voxels; ++s) {
    const Voxel& v = voxels_[s];
    const auto r = static_cast<uint8_t>(v.key >> (3 * kVoxelAxisBits));
    uint64_t key = uint64_t{r} << (3 * kVoxelAxisBits);  // packed as the reference packs it
    for (int a = 0; a < 3; ++a) {
      key |= static_cast<uint64_t>(v.index[a] - lo_index[r][a]) << ((2 - a) * kVoxelAxisBits);
    }
    sort_keys_[s] = key;
    sort_slot_[s] = static_cast<uint32_t>(s);
  }
  radixSortPairs(sort_keys_.data(), sort_slot_.data(), sort_keys_scratch_.data(), sort_slot_scratch_.data(), voxels);
  for (std::size_t q = 0; q < voxels; ++q) {
    const uint32_t s = sort_slot_[q];
    if (q + 8 < voxels) __builtin_prefetch(&voxels_[sort_slot_[q + 8]]);
    const Voxel& v = voxels_[s];
    out_pos_[s] = static_cast<uint32_t>(o);
    const uint64_t count = v.count;
    const double inv_count = 1.0 / static_cast<double>(count);
    ox[o] = std::clamp(static_cast<float>(v.first[0] + v.sx * inv_count), v.lo[0], v.hi[0]);
    oy[o] = std::clamp(static_cast<float>(v.first[1] + v.sy * inv_count), v.lo[1], v.hi[1]);
    oz[o] = std::clamp(static_cast<float>(v.first[2] + v.sz * inv_count), v.lo[2], v.hi[2]);
    orgb[o] = packRgb(static_cast<uint8_t>((v.sr + count / 2) / count), static_cast<uint8_t>((v.sg + count / 2) / count),
                      static_cast<uint8_t>((v.sb + count / 2) / count));
    const auto r = static_cast<uint8_t>(v.key >> (3 * kVoxelAxisBits));
    out.region[o] = r;
    out.weight[o] = static_cast<uint32_t>(count);
    ++counts.out[r];
    ++o;
  }
  if (representative) {
    for (std::size_t i = 0; i < n; ++i) {
      const uint8_t r = region[i];
      if (r != 0 && r < region_count) representative[i] = out_pos_[representative[i]];
    }
  }
  (void)out.points.resize(o);
  return Status::ok();
}

}  // namespace fovea::pipeline
