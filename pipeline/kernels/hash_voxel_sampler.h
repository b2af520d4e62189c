// The fast voxel sampler: same contract and the same output as VoxelSampler (the
// reference), without radix-sorting the points.
//
// 1. A pass over the points (split across the worker pool's threads, if any)
//    computes their voxel indices (voxelIndexSimd, 2048 points at a time, bit-exact
//    with voxelIndex()), makes the reference's checks and a hash key per point: the
//    region and the indices wrapped to 20 bits, unique within the span the reference
//    allows (a wider region is refused anyway). A second, sequential pass gives each
//    sampled point the slot of its voxel, found through the previous point's voxel
//    (image coherence), a small direct-mapped cache of recent voxels, then a
//    preallocated open-addressing hash table (power of two >= 2 max_voxels, linear
//    probing; a frame starts on a prefix sized from the previous frame's voxel
//    count, at least 16 Ki entries, and doubles it when half full).
// 2. A counting sort groups the points by slot, keeping input order within a voxel.
// 3. Only the occupied voxels (far fewer than points) are radix-sorted, by the
//    reference's packed key (region, i, j, k relative to the region's smallest index).
// 4. Each voxel's points are reduced with the reference's code in the reference's
//    order, so centroids, colours and weights are bit-identical (split across a
//    WorkerPool's threads when one is set: every voxel's output place is fixed).
// Per point it keeps 16 bytes (key, slot, grouped index) where the reference keeps 24.
// All memory is allocated by the constructor; sample() never allocates.
//
// A difference by design: with more than max_voxels occupied voxels it stops
// counting at the first voxel too many (the error says "more than").
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "hal/result.h"
#include "pipeline/acuity.h"
#include "pipeline/kernels/worker_pool.h"
#include "pipeline/point_cloud.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::pipeline {

class HashVoxelSampler {
 public:
  HashVoxelSampler() = default;
  HashVoxelSampler(std::size_t max_points, std::size_t max_voxels);

  // Same contract as VoxelSampler::sample.
  Status sample(const PointCloud& in, const uint8_t* region, int region_count,
                const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out, SampleCounts& counts,
                uint32_t* representative = nullptr);

  // Lets step 4 (one centroid per voxel) share the pool's threads; the output is
  // the same. The pool must outlive the sampler's use of it; null: one thread.
  void setWorkerPool(WorkerPool* pool);

  std::size_t maxPoints() const { return point_slot_.size(); }
  std::size_t maxVoxels() const { return max_voxels_; }
  std::size_t tableSize() const { return table_.size(); }

  static constexpr std::size_t kChunk = 2048;  // points per voxel-index batch

 private:
  struct Entry {
    uint64_t key;
    uint32_t slot;
  };
  static constexpr uint64_t kEmpty = UINT64_MAX;  // keys never set bit 63
  static constexpr int kRecentBits = 10;

  struct ReduceJob;
  struct KeyJob;
  // Per pool part: what step 1a found in its range of points.
  struct PartKeys {
    std::array<uint32_t, kMaxRegions> in{};
    int64_t lo[kMaxRegions][3];
    int64_t hi[kMaxRegions][3];
    bool bad = false;  // a voxel index out of range: the first such point of the part
    std::size_t bad_point = 0;
    int bad_axis = 0;
    double bad_value = 0.0;
    uint8_t bad_region = 0;
  };
  void computeKeys(const KeyJob& job, int part, int parts);
  void reduceVoxels(const PointCloud& in, FoveatedCloud& out, std::size_t q_begin, std::size_t q_end, std::size_t fovea,
                    uint32_t* representative, uint32_t* region_counts) const;
  void clearTable(std::size_t voxels);
  // Doubles the table's active prefix and reinserts the voxels found so far.
  void growTable(std::size_t voxels);

  std::size_t max_voxels_ = 0;
  std::size_t active_ = 0;  // entries of table_ in use this frame (a power of two)
  std::size_t last_voxels_ = 0;
  int shift_ = 64;
  std::vector<Entry> table_;
  // Per voxel slot (max_voxels).
  std::vector<uint64_t> voxel_key_;         // the hash key
  std::vector<uint32_t> voxel_table_pos_;   // where it sits in table_
  std::vector<uint32_t> voxel_start_;       // count, then start of its points in order_ (max_voxels + 1)
  std::vector<uint32_t> voxel_cursor_;
  std::vector<uint64_t> sort_keys_, sort_keys_scratch_;
  std::vector<uint32_t> sort_slot_, sort_slot_scratch_;
  // Per point (max_points).
  std::vector<uint32_t> point_slot_;  // voxel slot, or kNoSlot
  std::vector<uint64_t> point_key_;   // hash key, or kEmpty (fovea, skipped)
  std::vector<uint32_t> order_;       // point indices grouped by slot, input order within
  std::vector<double> chunk_index_;   // 3 * kChunk voxel indices per pool part
  std::vector<PartKeys> part_keys_;
  std::array<uint64_t, std::size_t{1} << kRecentBits> recent_key_{};
  std::array<uint32_t, std::size_t{1} << kRecentBits> recent_slot_{};
  WorkerPool* pool_ = nullptr;
  std::vector<uint32_t> part_counts_;  // kMaxRegions per pool part
};

}  // namespace fovea::pipeline
