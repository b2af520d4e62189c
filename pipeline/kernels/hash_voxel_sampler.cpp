#include "pipeline/kernels/hash_voxel_sampler.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <string>

#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/partition.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::pipeline {

namespace {

// As the reference: |index| below 2^52 converts to int64 exactly.
constexpr double kMaxAbsIndex = 4503599627370496.0;
constexpr std::size_t kInitialTableEntries = std::size_t{1} << 14;  // 128 KiB of keys
constexpr uint64_t kAxisMask = (uint64_t{1} << kVoxelAxisBits) - 1;
// Points done by the scalar code after the SIMD kernel stops (any vector width divides it).
constexpr std::size_t kScalarRun = 64;
// How many points ahead accumulate() prefetches table entries.
constexpr std::size_t kPrefetchAhead = 32;

const char* axisName(int axis) { return axis == 0 ? "x" : (axis == 1 ? "y" : "z"); }

// copyFovea() without representatives (slotsToRepresentatives() gives the
// fovea's), its pointers in locals, skipping 8 points at a time where none is in
// the fovea (the usual case outside it). Same output.
void copyFoveaFast(const PointCloud& in, const uint8_t* region, FoveatedCloud& out) {
  const std::size_t n = in.size();
  const float* x = in.x();
  const float* y = in.y();
  const float* z = in.z();
  const uint32_t* rgb = in.rgb();
  float* ox = out.points.x();
  float* oy = out.points.y();
  float* oz = out.points.z();
  uint32_t* orgb = out.points.rgb();
  uint8_t* oregion = out.region.data();
  uint32_t* oweight = out.hasWeights() ? out.weight.data() : nullptr;
  std::size_t o = 0;
  std::size_t i = 0;
  constexpr uint64_t kOnes = 0x0101010101010101ull, kHighs = 0x8080808080808080ull;
  while (i < n) {
    if (i + 8 <= n) {
      uint64_t block;
      std::memcpy(&block, region + i, sizeof block);
      if (((block - kOnes) & ~block & kHighs) == 0) {  // no zero byte: no fovea point
        i += 8;
        continue;
      }
    }
    const std::size_t stop = std::min(n, i + 8);
    for (; i < stop; ++i) {
      if (region[i] != 0) continue;
      ox[o] = x[i];
      oy[o] = y[i];
      oz[o] = z[i];
      orgb[o] = rgb[i];
      oregion[o] = 0;
      if (oweight != nullptr) oweight[o] = 1;
      ++o;
    }
  }
}

}  // namespace

struct HashVoxelSampler::KeyJob {
  const HashVoxelSampler* self;
  const PointCloud* in;
  const uint8_t* region;
  uint64_t* keys;
  std::vector<kernels::VoxelKeyState>* state;
  std::vector<BadPoint>* bad;
};

HashVoxelSampler::HashVoxelSampler(std::size_t max_points, std::size_t max_voxels)
    : max_voxels_(max_voxels),
      voxel_key_(max_voxels),
      voxel_table_pos_(max_voxels),
      acc_(new Acc[max_voxels]),
      rank_(max_voxels),
      max_points_(max_points),
      chunk_key_(kChunk),
      chunk_slot_(kChunk),
      part_state_(1),
      part_bad_(1) {
  table_key_.assign(std::bit_ceil(std::max<std::size_t>(2 * max_voxels, 16)), kEmpty);
  table_slot_.assign(table_key_.size(), 0);
}

void HashVoxelSampler::setWorkerPool(WorkerPool* pool) {
  pool_ = pool;
  const std::size_t parts = pool ? static_cast<std::size_t>(pool->parts()) : 1;
  part_state_.assign(parts, kernels::VoxelKeyState{});
  part_bad_.assign(parts, BadPoint{});
  point_key_.assign(parts > 1 ? max_points_ : 0, kEmpty);
}

void HashVoxelSampler::clearTable(std::size_t voxels) {
  for (std::size_t s = 0; s < voxels; ++s) table_key_[voxel_table_pos_[s]] = kEmpty;
}

void HashVoxelSampler::growTable(std::size_t voxels) {
  clearTable(voxels);
  active_ *= 2;
  --shift_;
  table_mask_ = active_ - 1;
  for (std::size_t s = 0; s < voxels; ++s) {
    std::size_t pos = hashVoxelKey(voxel_key_[s]) >> shift_;
    while (table_key_[pos] != kEmpty) pos = (pos + 1) & table_mask_;
    table_key_[pos] = voxel_key_[s];
    table_slot_[pos] = static_cast<uint32_t>(s);
    voxel_table_pos_[s] = static_cast<uint32_t>(pos);
  }
}

bool HashVoxelSampler::computeKeys(const PointCloud& in, const uint8_t* region, std::size_t begin, std::size_t end,
                                   kernels::VoxelKeyState& st, uint64_t* keys, BadPoint& bad) const {
  const float* coord[3] = {in.x(), in.y(), in.z()};
  std::size_t pos = begin;
  while (pos < end) {
    pos += kernels::voxelKeyRange(coord[0] + pos, coord[1] + pos, coord[2] + pos, region + pos, end - pos, st,
                                  keys + (pos - begin));
    const std::size_t stop = std::min(end, pos + kScalarRun);
    // The points the kernel left: the reference's scalar code, checks included.
    for (; pos < stop; ++pos) {
      const uint8_t r = region[pos];
      ++st.histogram[r];
      keys[pos - begin] = kEmpty;
      if (r < 1 || r >= st.region_count) continue;
      uint64_t key = uint64_t{r} << (3 * kVoxelAxisBits);
      for (int a = 0; a < 3; ++a) {
        const double d = voxelIndex(st.origin[a], coord[a][pos], st.inv_voxel[r]);
        if (!(std::fabs(d) < kMaxAbsIndex)) {
          bad = BadPoint{true, pos, a, d, r};
          return false;
        }
        st.lo[r][a] = std::min(st.lo[r][a], d);
        st.hi[r][a] = std::max(st.hi[r][a], d);
        key |= (static_cast<uint64_t>(static_cast<int64_t>(d)) & kAxisMask) << ((2 - a) * kVoxelAxisBits);
      }
      keys[pos - begin] = key;
    }
  }
  return true;
}

uint32_t HashVoxelSampler::findSlotInTable(uint64_t key, uint64_t hash, std::size_t line, bool& fresh) {
  fresh = false;
  std::size_t pos = hash >> shift_;
  while (table_key_[pos] != key && table_key_[pos] != kEmpty) pos = (pos + 1) & table_mask_;
  uint32_t slot;
  if (table_key_[pos] == key) {
    slot = table_slot_[pos];
  } else {
    if (voxels_ == max_voxels_) return kNoSlot;
    fresh = true;
    slot = static_cast<uint32_t>(voxels_++);
    table_key_[pos] = key;
    table_slot_[pos] = slot;
    voxel_key_[slot] = key;
    voxel_table_pos_[slot] = static_cast<uint32_t>(pos);
    if (2 * voxels_ > active_ && active_ < table_key_.size()) growTable(voxels_);  // load factor <= 1/2
  }
  if (line != kEmptyLine) {  // that line answers kEmpty (fovea and skipped points)
    recent_key_[line] = key;
    recent_slot_[line] = slot;
  }
  return slot;
}

template <bool kRepresentative>
bool HashVoxelSampler::accumulate(const PointCloud& in, std::size_t begin, std::size_t end, const uint64_t* keys,
                                  uint32_t* point_slot) {
  for (std::size_t c0 = begin; c0 < end; c0 += kChunk) {
    const std::size_t c1 = std::min(end, c0 + kChunk);
    if (!accumulateChunk<kRepresentative>(in, c0, c1, keys + (c0 - begin), point_slot)) return false;
  }
  return true;
}

template <bool kRepresentative>
bool HashVoxelSampler::accumulateChunk(const PointCloud& in, std::size_t begin, std::size_t end,
                                       const uint64_t* keys, uint32_t* point_slot) {
  const float* px_in = in.x();
  const float* py_in = in.y();
  const float* pz_in = in.z();
  const uint32_t* rgb_in = in.rgb();
  Acc* acc = acc_.get();
  uint32_t* slot_of = chunk_slot_.data();
  // Pass 1: each point's voxel slot. A look-up in the recent-voxel cache for every
  // point costs less than a branch on "same voxel as the last point", which noisy
  // depth makes unpredictable; the table behind the cache is the rare case. A fresh
  // voxel starts at its first point.
  for (std::size_t i = begin; i < end; ++i) {
    const uint64_t key = keys[i - begin];
    // The table entry a later point will probe: a miss in a table of megabytes
    // costs more than everything else done for a point, and keys are known ahead.
    if (i + kPrefetchAhead < end) {
      __builtin_prefetch(&table_key_[hashVoxelKey(keys[i + kPrefetchAhead - begin]) >> shift_]);
    }
    const uint64_t hash = hashVoxelKey(key);
    const std::size_t line = hash >> (64 - kRecentBits);
    uint32_t slot = recent_slot_[line];  // kNoSlot for kEmpty (fovea or skipped)
    if (recent_key_[line] != key) [[unlikely]] {
      ++lookups_;
      bool fresh;
      slot = findSlotInTable(key, hash, line, fresh);
      if (slot == kNoSlot) return false;
      if (fresh) {
        Acc& a = acc[slot];
        const float px = px_in[i], py = py_in[i], pz = pz_in[i];
        a.sx = a.sy = a.sz = 0.0;
        a.fx = a.lo[0] = a.hi[0] = px;
        a.fy = a.lo[1] = a.hi[1] = py;
        a.fz = a.lo[2] = a.hi[2] = pz;
        a.n = 0;
        a.sr = a.sg = a.sb = 0;
      }
    }
    slot_of[i - begin] = slot;
  }
  // Pass 2: reduceVoxel()'s loop body, point by point in input order, into the slots.
  for (std::size_t i = begin; i < end; ++i) {
    const uint32_t slot = slot_of[i - begin];
    if constexpr (kRepresentative) point_slot[i] = slot;
    if (slot == kNoSlot) continue;
    Acc& a = acc[slot];
    const float px = px_in[i], py = py_in[i], pz = pz_in[i];
    a.sx += static_cast<double>(px) - a.fx;
    a.sy += static_cast<double>(py) - a.fy;
    a.sz += static_cast<double>(pz) - a.fz;
    a.lo[0] = std::min(a.lo[0], px), a.hi[0] = std::max(a.hi[0], px);
    a.lo[1] = std::min(a.lo[1], py), a.hi[1] = std::max(a.hi[1], py);
    a.lo[2] = std::min(a.lo[2], pz), a.hi[2] = std::max(a.hi[2], pz);
    const uint32_t c = rgb_in[i];
    a.sr += rgbRed(c);
    a.sg += rgbGreen(c);
    a.sb += rgbBlue(c);
    ++a.n;
  }
  return true;
}

// What steps 1-2 found.
struct HashVoxelSampler::KeyPass {
  bool fits = true;               // no voxel beyond max_voxels
  const BadPoint* bad = nullptr;  // the first bad point in point order
};

// How step 3's sort key packs a voxel: (region, i - lo, j - lo, k - lo), with the
// voxel's slot below it where both fit one 64-bit word.
struct HashVoxelSampler::VoxelOrder {
  int region_shift = 0;  // of the region within the key
  int key_shift = 0;     // of the key within sortKeys(): the slot's bits when packed, else 0
  bool packed = false;
  uint64_t slot_mask = 0;
};

Status HashVoxelSampler::sample(const PointCloud& in, const uint8_t* region, int region_count,
                                const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out,
                                SampleCounts& counts, uint32_t* representative) {
  counts = {};
  out.clear();
  out.points.origin_m = in.origin_m;
  out.points.has_color = in.has_color;
  const std::size_t n = in.size();
  if (n > max_points_ || n > kMaxPoints) {
    return {ErrorCode::kCapacityExceeded, "voxel sampler: cloud has " + std::to_string(n) + " points, capacity is " +
                                              std::to_string(std::min(max_points_, kMaxPoints)) +
                                              ": raise pipeline.max_points"};
  }
  if (region_count < 1 || region_count > kMaxRegions) {
    return {ErrorCode::kInvalidArgument, "voxel sampler: region count out of range"};
  }
  // 1 / voxel size per region; regions outside [1, region_count) get 0: their
  // indices are computed and ignored. Kept here: the key states point to it while
  // the keys are computed.
  std::array<double, 256> inv_voxel{};
  if (Status s = inverseVoxelSizes(region_count, voxel_size_m, inv_voxel.data()); !s) return s;
  startFrame(in, region_count, inv_voxel);

  // 1-2. Keys and checks, then accumulation in place. The first bad point in point
  //      order wins over everything, then spans, then the voxel count (as the
  //      reference), so a voxel overflow only stops the accumulation.
  const int parts = (pool_ != nullptr && pool_->parts() > 1 && n >= 4 * kChunk) ? pool_->parts() : 1;
  const KeyPass pass = parts > 1 ? keysThreaded(in, region, parts, representative)
                                 : keysInChunks(in, region, region_count, representative);
  const std::size_t voxels = voxels_;
  clearTable(voxels);  // the table is empty again for the next frame
  last_voxels_ = voxels;
  if (const BadPoint* bad = pass.bad; bad != nullptr) {
    return {ErrorCode::kRangeExceeded, "voxel sampler: region " + std::to_string(bad->region) + " point " +
                                           std::to_string(bad->point) + " has voxel index " +
                                           std::to_string(bad->value) + " along " + axisName(bad->axis) +
                                           " (not a finite coordinate within range)"};
  }
  RegionLo lo_index{};
  if (Status s = countAndCheckSpans(region_count, voxel_size_m, counts, lo_index); !s) return s;
  // The capacity errors the foveator coarsens on: no allocation (kVoxelsFull).
  if (!pass.fits) return {ErrorCode::kCapacityExceeded, kVoxelsFull};
  const std::size_t fovea = counts.in[0];
  if (fovea + voxels > out.points.capacity()) return {ErrorCode::kCapacityExceeded, kOutputFull};

  // 3. The occupied voxels in the reference's key order, after the fovea (untouched
  //    and in input order).
  const VoxelOrder order = sortVoxels(region_count, counts, lo_index, voxels);
  copyFoveaFast(in, region, out);
  counts.out[0] = static_cast<uint32_t>(fovea);
  writeVoxels(order, fovea, voxels, out, counts);
  std::fill_n(sortKeys(), voxels, kEmpty);  // the table empty again for the next frame
  std::fill_n(sortKeysScratch(), voxels, kEmpty);
  if (representative != nullptr) slotsToRepresentatives(region, n, representative);
  (void)out.points.resize(fovea + voxels);
  return Status::ok();
}

// Each point's voxel slot (kNoSlot: none), as accumulate() left it in
// `representative`, into its output index: the fovea's points their place in
// input order at the front (copyFovea's), the others their voxel's.
void HashVoxelSampler::slotsToRepresentatives(const uint8_t* region, std::size_t n, uint32_t* representative) const {
  uint32_t fovea = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const uint32_t slot = representative[i];
    if (region[i] == 0) {
      representative[i] = fovea++;
    } else {
      representative[i] = slot != kNoSlot ? rank_[slot] : kNoRepresentative;
    }
  }
}

// Sizes the table for this frame and resets the cache, the counters and the key states.
void HashVoxelSampler::startFrame(const PointCloud& in, int region_count, const std::array<double, 256>& inv_voxel) {
  // Start where the previous frame ended (consecutive frames have similar voxel
  // counts), so the steady state does not rehash; the output does not depend on it.
  active_ = std::min(table_key_.size(), std::max(kInitialTableEntries, std::bit_ceil(2 * last_voxels_ + 1)));
  shift_ = 64 - std::countr_zero(active_);
  table_mask_ = active_ - 1;
  recent_key_.fill(kEmpty - 1);  // no key (keys never set bit 63), and not kEmpty
  recent_key_[kEmptyLine] = kEmpty;
  recent_slot_[kEmptyLine] = kNoSlot;
  voxels_ = 0;
  lookups_ = 0;

  for (kernels::VoxelKeyState& st : part_state_) {
    st.reset();
    st.inv_voxel = inv_voxel.data();
    st.origin[0] = in.origin_m.x();
    st.origin[1] = in.origin_m.y();
    st.origin[2] = in.origin_m.z();
    st.region_count = region_count;
  }
  for (BadPoint& b : part_bad_) b = BadPoint{};
}

// Step 1 on the pool's threads over contiguous ranges (keys kept for every point),
// then step 2 over the whole cloud.
HashVoxelSampler::KeyPass HashVoxelSampler::keysThreaded(const PointCloud& in, const uint8_t* region, int parts,
                                                         uint32_t* point_slot) {
  KeyPass pass;
  KeyJob job{this, &in, region, point_key_.data(), &part_state_, &part_bad_};
  pool_->run(
      [](void* ctx, int part, int count) {
        auto* j = static_cast<KeyJob*>(ctx);
        const std::size_t n_points = j->in->size();
        const std::size_t b = WorkerPool::rangeBegin(n_points, part, count);
        const std::size_t e = WorkerPool::rangeBegin(n_points, part + 1, count);
        const auto p = static_cast<std::size_t>(part);
        j->self->computeKeys(*j->in, j->region, b, e, (*j->state)[p], j->keys + b, (*j->bad)[p]);
      },
      &job);
  for (int part = 0; part < parts && pass.bad == nullptr; ++part) {
    if (part_bad_[static_cast<std::size_t>(part)].bad) pass.bad = &part_bad_[static_cast<std::size_t>(part)];
  }
  if (pass.bad != nullptr) return pass;
  mergePartStates(parts);
  pass.fits = point_slot != nullptr ? accumulate<true>(in, 0, in.size(), point_key_.data(), point_slot)
                                    : accumulate<false>(in, 0, in.size(), point_key_.data(), nullptr);
  return pass;
}

// The parts' region histograms and index ranges, into part_state_[0].
void HashVoxelSampler::mergePartStates(int parts) {
  kernels::VoxelKeyState& st = part_state_[0];
  for (int part = 1; part < parts; ++part) {
    const kernels::VoxelKeyState& other = part_state_[static_cast<std::size_t>(part)];
    for (int r = 0; r < 256; ++r) st.histogram[r] += other.histogram[r];
    for (int r = 0; r < kMaxRegions; ++r) {
      for (int a = 0; a < 3; ++a) {
        st.lo[r][a] = std::min(st.lo[r][a], other.lo[r][a]);
        st.hi[r][a] = std::max(st.hi[r][a], other.hi[r][a]);
      }
    }
  }
}

// Steps 1-2 a chunk of kChunk points at a time, on this thread.
HashVoxelSampler::KeyPass HashVoxelSampler::keysInChunks(const PointCloud& in, const uint8_t* region,
                                                         int region_count, uint32_t* point_slot) {
  KeyPass pass;
  const std::size_t n = in.size();
  const uint32_t* histogram = part_state_[0].histogram;
  const auto sampledSoFar = [&] {
    uint64_t total = 0;
    for (int r = 1; r < region_count; ++r) total += histogram[r];
    return total;
  };
  for (std::size_t c0 = 0; c0 < n; c0 += kChunk) {
    const std::size_t c1 = std::min(n, c0 + kChunk);
    const uint64_t sampled_before = sampledSoFar();
    if (!computeKeys(in, region, c0, c1, part_state_[0], chunk_key_.data(), part_bad_[0])) {
      pass.bad = &part_bad_[0];
      break;
    }
    if (sampledSoFar() == sampled_before) {  // only fovea or skipped points (all of FREF)
      if (point_slot != nullptr) std::fill(point_slot + c0, point_slot + c1, kNoSlot);
      continue;
    }
    if (pass.fits) {
      pass.fits = point_slot != nullptr ? accumulate<true>(in, c0, c1, chunk_key_.data(), point_slot)
                                        : accumulate<false>(in, c0, c1, chunk_key_.data(), nullptr);
    }
  }
  return pass;
}

// The points per region (counts.in), and each sampled region's smallest voxel
// index per axis; an error for a region wider than the reference allows.
Status HashVoxelSampler::countAndCheckSpans(int region_count, const std::array<double, kMaxRegions>& voxel_size_m,
                                            SampleCounts& counts, RegionLo& lo_index) const {
  const kernels::VoxelKeyState& st = part_state_[0];
  for (int r = 0; r < region_count; ++r) counts.in[r] = st.histogram[r];
  for (int r = 1; r < region_count; ++r) {
    if (counts.in[r] == 0) continue;
    for (int a = 0; a < 3; ++a) {
      lo_index[r][a] = static_cast<int64_t>(st.lo[r][a]);
      const int64_t span = static_cast<int64_t>(st.hi[r][a]) - lo_index[r][a] + 1;
      if (span > kMaxVoxelSpan) {
        return {ErrorCode::kRangeExceeded,
                "voxel sampler: region " + std::to_string(r) + " spans " + std::to_string(span) + " voxels of " +
                    std::to_string(voxel_size_m[r]) + " m along " + axisName(a) + ", more than " +
                    std::to_string(kMaxVoxelSpan) + ": crop the cloud or raise fixation.min_m"};
      }
    }
  }
  return Status::ok();
}

// Sorts the occupied voxels into the reference's key order (keys are unique: no ties).
// Within the span, k - lo is (wrapped k - wrapped lo) mod 2^20: no index is recomputed.
// The sort key packs (region, i - lo, j - lo, k - lo) with as many bits per axis as
// the widest region needs, which orders like the reference's 20-bit fields and
// leaves the radix sort fewer bits that vary. Where the key and the slot fit one
// 64-bit word together (camera frames do), the slot rides below the key and
// one array is sorted; otherwise (key, slot) pairs are.
HashVoxelSampler::VoxelOrder HashVoxelSampler::sortVoxels(int region_count, const SampleCounts& counts,
                                                          const RegionLo& lo_index, std::size_t voxels) {
  const kernels::VoxelKeyState& st = part_state_[0];
  int width[3] = {0, 0, 0};
  for (int r = 1; r < region_count; ++r) {
    if (counts.in[r] == 0) continue;
    for (int a = 0; a < 3; ++a) {
      const auto extent = static_cast<uint64_t>(static_cast<int64_t>(st.hi[r][a]) - lo_index[r][a]);
      width[a] = std::max(width[a], static_cast<int>(std::bit_width(extent)));
    }
  }
  const int shift[3] = {width[1] + width[2], width[2], 0};
  VoxelOrder order;
  order.region_shift = width[0] + width[1] + width[2];
  const int key_bits = order.region_shift + static_cast<int>(std::bit_width(static_cast<unsigned>(region_count - 1)));
  const int slot_bits = std::max(1, static_cast<int>(std::bit_width(voxels)));
  order.packed = key_bits + slot_bits <= 64;
  order.key_shift = order.packed ? slot_bits : 0;
  order.slot_mask = (uint64_t{1} << slot_bits) - 1;
  uint64_t* keys = sortKeys();
  for (std::size_t s = 0; s < voxels; ++s) {
    const uint64_t hash_key = voxel_key_[s];
    const auto r = static_cast<uint8_t>(hash_key >> (3 * kVoxelAxisBits));
    uint64_t key = uint64_t{r} << order.region_shift;
    for (int a = 0; a < 3; ++a) {
      const uint64_t wrapped = (hash_key >> ((2 - a) * kVoxelAxisBits)) & kAxisMask;
      key |= ((wrapped - static_cast<uint64_t>(lo_index[r][a])) & kAxisMask) << shift[a];
    }
    if (order.packed) {
      keys[s] = (key << order.key_shift) | s;
    } else {
      keys[s] = key;
      sortSlots()[s] = static_cast<uint32_t>(s);
    }
  }
  if (order.packed) {
    radixSortBits(keys, sortKeysScratch(), voxels, slot_bits, key_bits);
  } else {
    radixSortPairs(keys, sortSlots(), sortKeysScratch(), sortSlotsScratch(),
                   voxels);
  }
  return order;
}

// One point per voxel, in the sorted order after the fovea's, with reduceVoxel()'s
// final expressions; rank_ keeps each slot's place for the representatives.
void HashVoxelSampler::writeVoxels(const VoxelOrder& order, std::size_t fovea, std::size_t voxels,
                                   FoveatedCloud& out, SampleCounts& counts) {
  const uint64_t* keys = sortKeys();
  const uint32_t* slots = sortSlots();
  const auto slotAt = [&](std::size_t q) {
    return order.packed ? static_cast<uint32_t>(keys[q] & order.slot_mask) : slots[q];
  };
  uint32_t* weights = out.hasWeights() ? out.weight.data() : nullptr;
  for (std::size_t q = 0; q < voxels; ++q) {
    const std::size_t o = fovea + q;
    const uint32_t slot = slotAt(q);
    if (q + 16 < voxels) {
      const Acc* ahead = &acc_[slotAt(q + 16)];
      __builtin_prefetch(ahead);
      __builtin_prefetch(reinterpret_cast<const char*>(ahead) + sizeof(Acc) - 1);
    }
    rank_[slot] = static_cast<uint32_t>(o);
    const Acc& a = acc_[slot];
    const auto r = static_cast<uint8_t>(keys[q] >> (order.key_shift + order.region_shift));
    const auto cnt = static_cast<uint64_t>(a.n);
    const double inv_n = 1.0 / static_cast<double>(cnt);
    out.points.x()[o] = std::clamp(static_cast<float>(a.fx + a.sx * inv_n), a.lo[0], a.hi[0]);
    out.points.y()[o] = std::clamp(static_cast<float>(a.fy + a.sy * inv_n), a.lo[1], a.hi[1]);
    out.points.z()[o] = std::clamp(static_cast<float>(a.fz + a.sz * inv_n), a.lo[2], a.hi[2]);
    out.points.rgb()[o] =
        packRgb(roundedMeanColour(a.sr, cnt, inv_n), roundedMeanColour(a.sg, cnt, inv_n),
                roundedMeanColour(a.sb, cnt, inv_n));
    out.region[o] = r;
    if (weights != nullptr) weights[o] = a.n;
    ++counts.out[r];
  }
}

}  // namespace fovea::pipeline
