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
constexpr std::size_t kInitialTableEntries = std::size_t{1} << 14;  // 256 KiB
constexpr uint32_t kNoSlot = UINT32_MAX;

const char* axisName(int axis) { return axis == 0 ? "x" : (axis == 1 ? "y" : "z"); }
uint64_t hashKey(uint64_t key) { return key * 0x9E3779B97F4A7C15ull; }

}  // namespace

struct HashVoxelSampler::KeyJob {
  HashVoxelSampler* self;
  const PointCloud* in;
  const uint8_t* region;
  int region_count;
  const double* inv_voxel;
};

struct HashVoxelSampler::ReduceJob {
  HashVoxelSampler* self;
  const PointCloud* in;
  FoveatedCloud* out;
  std::size_t voxels;
  std::size_t fovea;
  uint32_t* representative;
};

namespace {

}  // namespace

HashVoxelSampler::HashVoxelSampler(std::size_t max_points, std::size_t max_voxels)
    : max_voxels_(max_voxels),
      voxel_key_(max_voxels),
      voxel_table_pos_(max_voxels),
      voxel_start_(max_voxels + 1),
      voxel_cursor_(max_voxels),
      sort_keys_(max_voxels),
      sort_keys_scratch_(max_voxels),
      sort_slot_(max_voxels),
      sort_slot_scratch_(max_voxels),
      point_slot_(max_points),
      point_key_(max_points),
      order_(max_points),
      chunk_index_(3 * kChunk),
      part_keys_(1) {
  table_.assign(std::bit_ceil(std::max<std::size_t>(2 * max_voxels, 16)), Entry{kEmpty, 0});
}

void HashVoxelSampler::setWorkerPool(WorkerPool* pool) {
  pool_ = pool;
  const std::size_t parts = pool ? static_cast<std::size_t>(pool->parts()) : 1;
  part_counts_.assign(kMaxRegions * parts, 0);
  part_keys_.assign(parts, PartKeys{});
  chunk_index_.assign(3 * kChunk * parts, 0.0);
}

void HashVoxelSampler::clearTable(std::size_t voxels) {
  for (std::size_t s = 0; s < voxels; ++s) table_[voxel_table_pos_[s]].key = kEmpty;
}

void HashVoxelSampler::growTable(std::size_t voxels) {
  clearTable(voxels);
  active_ *= 2;
  --shift_;
  const std::size_t mask = active_ - 1;
  for (std::size_t s = 0; s < voxels; ++s) {
    std::size_t pos = hashKey(voxel_key_[s]) >> shift_;
    while (table_[pos].key != kEmpty) pos = (pos + 1) & mask;
    table_[pos] = Entry{voxel_key_[s], static_cast<uint32_t>(s)};
    voxel_table_pos_[s] = static_cast<uint32_t>(pos);
  }
}

void HashVoxelSampler::reduceVoxels(const PointCloud& in, FoveatedCloud& out, std::size_t q_begin, std::size_t q_end,
                                    std::size_t fovea, uint32_t* representative, uint32_t* region_counts) const {
  for (std::size_t q = q_begin; q < q_end; ++q) {
    const std::size_t o = fovea + q;
    const uint32_t slot = sort_slot_[q];
    const std::size_t s = voxel_start_[slot];
    const std::size_t e = voxel_start_[slot + 1];
    const auto r = static_cast<uint8_t>(sort_keys_[q] >> (3 * kVoxelAxisBits));
    reduceVoxel(in, order_.data() + s, e - s, r, o, out, representative);
    ++region_counts[r];
  }
}

void HashVoxelSampler::computeKeys(const KeyJob& job, int part, int parts) {
  const PointCloud& in = *job.in;
  const std::size_t n = in.size();
  const std::size_t begin = WorkerPool::rangeBegin(n, part, parts);
  const std::size_t end = WorkerPool::rangeBegin(n, part + 1, parts);
  PartKeys& pk = part_keys_[static_cast<std::size_t>(part)];
  pk = PartKeys{};
  for (auto& row : pk.lo) std::fill(std::begin(row), std::end(row), INT64_MAX);
  for (auto& row : pk.hi) std::fill(std::begin(row), std::end(row), INT64_MIN);
  const float* coord[3] = {in.x(), in.y(), in.z()};
  const double origin[3] = {in.origin_m.x(), in.origin_m.y(), in.origin_m.z()};
  double* chunk = chunk_index_.data() + 3 * kChunk * static_cast<std::size_t>(part);
  double* index[3] = {chunk, chunk + kChunk, chunk + 2 * kChunk};
  constexpr uint64_t kAxisMask = (uint64_t{1} << kVoxelAxisBits) - 1;
  uint64_t* point_key = point_key_.data();
  for (std::size_t c0 = begin; c0 < end; c0 += kChunk) {
    const std::size_t len = std::min(kChunk, end - c0);
    for (int a = 0; a < 3; ++a) {
      voxelIndexSimd(coord[a] + c0, job.region + c0, len, origin[a], job.inv_voxel, index[a]);
    }
    for (std::size_t q = 0; q < len; ++q) {
      const std::size_t i = c0 + q;
      const uint8_t r = job.region[i];
      point_key[i] = kEmpty;
      if (r >= job.region_count) continue;  // kRegionInvalid: already counted by the partition
      ++pk.in[r];
      if (r == 0) continue;
      int64_t k[3];
      for (int a = 0; a < 3; ++a) {
        const double d = index[a][q];
        if (!(std::fabs(d) < kMaxAbsIndex)) {
          pk.bad = true;
          pk.bad_point = i;
          pk.bad_axis = a;
          pk.bad_value = d;
          pk.bad_region = r;
          return;
        }
        k[a] = static_cast<int64_t>(d);
        pk.lo[r][a] = std::min(pk.lo[r][a], k[a]);
        pk.hi[r][a] = std::max(pk.hi[r][a], k[a]);
      }
      point_key[i] = (uint64_t{r} << (3 * kVoxelAxisBits)) |
                     ((static_cast<uint64_t>(k[0]) & kAxisMask) << (2 * kVoxelAxisBits)) |
                     ((static_cast<uint64_t>(k[1]) & kAxisMask) << kVoxelAxisBits) |
                     (static_cast<uint64_t>(k[2]) & kAxisMask);
    }
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
  if (n > point_slot_.size()) {
    return {ErrorCode::kCapacityExceeded, "voxel sampler: cloud has " + std::to_string(n) + " points, capacity is " +
                                              std::to_string(point_slot_.size()) + ": raise pipeline.max_points"};
  }
  if (region_count < 1 || region_count > kMaxRegions) {
    return {ErrorCode::kInvalidArgument, "voxel sampler: region count out of range"};
  }
  // Regions outside [1, region_count) get 0: their indices are computed and ignored.
  std::array<double, 256> inv_voxel{};
  for (int r = 1; r < region_count; ++r) {
    const double v = voxel_size_m[r];
    if (!(std::isfinite(v) && v > 0.0) || !std::isfinite(1.0 / v)) {
      return {ErrorCode::kInvalidArgument, "voxel sampler: region " + std::to_string(r) + " voxel size " +
                                               std::to_string(v) + " m is not a positive number"};
    }
    inv_voxel[r] = 1.0 / v;
  }

  // 1a. Each point's voxel indices (voxelIndexSimd), the index check, the ranges
  //     and the hash key: the region and the indices wrapped to 20 bits. Contiguous
  //     ranges of points on the pool's threads, each with its own ranges and first
  //     bad point; merged in point order, so the outcome is the single-threaded one.
  KeyJob job{this, &in, region, region_count, inv_voxel.data()};
  const int parts = (pool_ != nullptr && n >= 4 * kChunk) ? pool_->parts() : 1;
  if (parts > 1) {
    pool_->run([](void* ctx, int part, int count) { static_cast<KeyJob*>(ctx)->self->computeKeys(
                                                        *static_cast<KeyJob*>(ctx), part, count); },
               &job);
  } else {
    computeKeys(job, 0, 1);
  }
  int64_t lo_index[kMaxRegions][3], hi_index[kMaxRegions][3];
  for (auto& row : lo_index) std::fill(std::begin(row), std::end(row), INT64_MAX);
  for (auto& row : hi_index) std::fill(std::begin(row), std::end(row), INT64_MIN);
  for (int part = 0; part < parts; ++part) {
    const PartKeys& pk = part_keys_[static_cast<std::size_t>(part)];
    if (pk.bad) {  // the first part with a bad index holds the first bad point
      return {ErrorCode::kRangeExceeded, "voxel sampler: region " + std::to_string(pk.bad_region) + " point " +
                                             std::to_string(pk.bad_point) + " has voxel index " +
                                             std::to_string(pk.bad_value) + " along " + axisName(pk.bad_axis) +
                                             " (not a finite coordinate within range)"};
    }
    for (int r = 0; r < kMaxRegions; ++r) {
      counts.in[r] += pk.in[r];
      for (int a = 0; a < 3; ++a) {
        lo_index[r][a] = std::min(lo_index[r][a], pk.lo[r][a]);
        hi_index[r][a] = std::max(hi_index[r][a], pk.hi[r][a]);
      }
    }
  }
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

  // 1b. Each point's voxel slot, through the previous point's voxel, the recent
  //     cache and the table (wrapped keys are unique now that the spans fit).
  constexpr uint64_t kAxisMask = (uint64_t{1} << kVoxelAxisBits) - 1;
  std::size_t voxels = 0;
  uint64_t last_key = kEmpty;
  uint32_t last_slot = 0;
  // Start where the previous frame ended (consecutive frames have similar voxel
  // counts), so the steady state does not rehash; the output does not depend on it.
  active_ = std::min(table_.size(), std::max(kInitialTableEntries, std::bit_ceil(2 * last_voxels_ + 1)));
  shift_ = 64 - std::countr_zero(active_);
  std::size_t table_mask = active_ - 1;
  recent_key_.fill(kEmpty);
  uint32_t* point_slot = point_slot_.data();
  const uint64_t* point_key = point_key_.data();
  for (std::size_t i = 0; i < n; ++i) {
    const uint64_t key = point_key[i];
    if (key == kEmpty) {  // fovea or skipped
      point_slot[i] = kNoSlot;
      continue;
    }
    if (key != last_key) {
      const uint64_t hash = hashKey(key);
      const std::size_t line = hash >> (64 - kRecentBits);
      if (recent_key_[line] == key) {
        last_slot = recent_slot_[line];
      } else {
        std::size_t pos = hash >> shift_;
        while (table_[pos].key != key && table_[pos].key != kEmpty) pos = (pos + 1) & table_mask;
        if (table_[pos].key == key) {
          last_slot = table_[pos].slot;
        } else {
          if (voxels == max_voxels_) {
            clearTable(voxels);
            last_voxels_ = voxels;
            return {ErrorCode::kCapacityExceeded, "voxel sampler: more than " + std::to_string(max_voxels_) +
                                                      " occupied voxels: raise pipeline.max_voxels"};
          }
          last_slot = static_cast<uint32_t>(voxels++);
          table_[pos] = Entry{key, last_slot};
          voxel_key_[last_slot] = key;
          voxel_table_pos_[last_slot] = static_cast<uint32_t>(pos);
          voxel_start_[last_slot] = 0;
          if (2 * voxels > active_ && active_ < table_.size()) {  // keep the load factor <= 1/2
            growTable(voxels);
            table_mask = active_ - 1;
          }
        }
        recent_key_[line] = key;
        recent_slot_[line] = last_slot;
      }
      last_key = key;
    }
    point_slot[i] = last_slot;
    ++voxel_start_[last_slot];
  }
  clearTable(voxels);  // the table is empty again for the next frame
  last_voxels_ = voxels;
  const std::size_t fovea = counts.in[0];
  if (fovea + voxels > out.points.capacity()) {
    return {ErrorCode::kCapacityExceeded, "voxel sampler: output needs " + std::to_string(fovea + voxels) +
                                              " points, capacity is " + std::to_string(out.points.capacity())};
  }

  // 2. Group the points by voxel (counting sort; input order within a voxel).
  uint32_t start = 0;
  for (std::size_t s = 0; s < voxels; ++s) {
    const uint32_t count = voxel_start_[s];
    voxel_start_[s] = start;
    voxel_cursor_[s] = start;
    start += count;
  }
  voxel_start_[voxels] = start;
  for (std::size_t i = 0; i < n; ++i) {
    const uint32_t s = point_slot[i];
    if (s != kNoSlot) order_[voxel_cursor_[s]++] = static_cast<uint32_t>(i);
  }

  // 3. The occupied voxels in the reference's key order (keys are unique: no ties).
  //    Within the span, k - lo is (wrapped k - wrapped lo) mod 2^20: no index is recomputed.
  for (std::size_t s = 0; s < voxels; ++s) {
    const uint64_t hash_key = voxel_key_[s];
    const auto r = static_cast<uint8_t>(hash_key >> (3 * kVoxelAxisBits));
    uint64_t key = uint64_t{r} << (3 * kVoxelAxisBits);
    for (int a = 0; a < 3; ++a) {
      const int shift = (2 - a) * kVoxelAxisBits;
      const uint64_t wrapped = (hash_key >> shift) & kAxisMask;
      key |= ((wrapped - static_cast<uint64_t>(lo_index[r][a])) & kAxisMask) << shift;
    }
    sort_keys_[s] = key;
    sort_slot_[s] = static_cast<uint32_t>(s);
  }
  radixSortPairs(sort_keys_.data(), sort_slot_.data(), sort_keys_scratch_.data(), sort_slot_scratch_.data(), voxels);

  // The fovea, untouched and in input order.
  std::size_t o = copyFovea(in, region, out, representative);
  counts.out[0] = static_cast<uint32_t>(fovea);

  // 4. One centroid per voxel: the reference's reduction over the same points in
  //    the same order. Voxels are independent and their output places fixed
  //    (fovea + rank), so threads can share them without changing a bit.
  if (pool_ != nullptr && pool_->parts() > 1 && voxels >= 1024) {
    ReduceJob job{this, &in, &out, voxels, fovea, representative};
    pool_->run(
        [](void* ctx, int part, int parts) {
          auto* j = static_cast<ReduceJob*>(ctx);
          uint32_t* region_counts = j->self->part_counts_.data() + kMaxRegions * static_cast<std::size_t>(part);
          std::fill(region_counts, region_counts + kMaxRegions, 0u);
          j->self->reduceVoxels(*j->in, *j->out, WorkerPool::rangeBegin(j->voxels, part, parts),
                                WorkerPool::rangeBegin(j->voxels, part + 1, parts), j->fovea, j->representative,
                                region_counts);
        },
        &job);
    for (int part = 0; part < pool_->parts(); ++part) {
      for (int r = 1; r < kMaxRegions; ++r) counts.out[r] += part_counts_[kMaxRegions * static_cast<std::size_t>(part) + r];
    }
  } else {
    reduceVoxels(in, out, 0, voxels, fovea, representative, counts.out.data());
  }
  o += voxels;
  (void)out.points.resize(o);
  return Status::ok();
}

}  // namespace fovea::pipeline
