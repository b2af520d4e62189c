#include "pipeline/foveator.h"

#include <algorithm>

#include "core/clock.h"
#include "pipeline/acuity_levels.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::pipeline {

Result<Foveator> Foveator::create(const PipelineCapacity& capacity, const FoveationConfig& config) {
  if (capacity.max_points == 0 || capacity.max_points > HashVoxelSampler::kMaxPoints) {
    return Result<Foveator>(ErrorCode::kInvalidArgument, "pipeline.max_points: must be in [1, " +
                                                              std::to_string(HashVoxelSampler::kMaxPoints) +
                                                              "] (the voxels' 32-bit colour sums)");
  }
  if (capacity.threads < 1 || capacity.threads > 64) {
    return Result<Foveator>(ErrorCode::kInvalidArgument, "pipeline.threads: must be in [1, 64]");
  }
  if (capacity.max_voxels == 0) {
    return Result<Foveator>(ErrorCode::kInvalidArgument, "pipeline.max_voxels: must be at least 1");
  }
  if (capacity.max_coarsenings < 0 || capacity.max_coarsenings > 16) {
    return Result<Foveator>(ErrorCode::kInvalidArgument, "pipeline.max_coarsenings: must be in [0, 16]");
  }
  if (Status s = config.fixation.validate(); !s) return s;
  Result<RegionModel> model = RegionModel::create(config.acuity);
  if (!model) return model.status();
  return Foveator(capacity, config, model.value());
}

Foveator::Foveator(const PipelineCapacity& capacity, const FoveationConfig& config, RegionModel model)
    : capacity_(capacity),
      config_(config),
      model_(model),
      bounds_(ConeBounds::fromModel(model)),
      levels_(LevelBounds::fromModel(model)),
      region_(capacity.max_points),
      point_scratch_(new std::byte[capacity.max_points * sizeof(double)]),
      sampler_(capacity.kernels == KernelSet::kRef ? VoxelSampler(capacity.max_points, capacity.max_voxels)
                                                   : VoxelSampler()),
      hash_sampler_(capacity.kernels == KernelSet::kSimd ? HashVoxelSampler(capacity.max_points, capacity.max_voxels)
                                                         : HashVoxelSampler()) {
  // setConfig copies a configuration into config_ on the frame path (the gaze
  // policy switching between the operator's and the fallback's): with room for
  // the most bounds a model may have, that copy never allocates.
  config_.acuity.custom_bounds_deg.reserve(kMaxRegions - 1);
  if (capacity.kernels == KernelSet::kSimd && capacity.threads > 1) {
    pool_ = std::make_unique<WorkerPool>(capacity.threads);
    part_histograms_.assign(static_cast<std::size_t>(capacity.threads) * 256, 0);
    hash_sampler_.setWorkerPool(pool_.get());
  }
  table_ = chooseKernels(capacity.kernels, pool_ != nullptr);
}

Foveator::KernelTable Foveator::chooseKernels(KernelSet set, bool pooled) {
  // The reference is the specification and always runs on the calling thread.
  if (set == KernelSet::kRef) {
    return {
        [](Foveator& f, const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) {
          partitionRef(in, gaze, f.bounds_, f.region_.data(), counts);
        },
        [](Foveator& f, const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) {
          assignLevelsRef(in, gaze, f.levels_, f.region_.data(), counts);
        },
        computeFixation,
        [](Foveator& f, const PointCloud& in, const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out,
           SampleCounts& counts, uint32_t* rep) {
          return f.sampler_.sample(in, f.region_.data(), f.model_.regionCount(), voxel_size_m, out, counts, rep);
        },
        [](Foveator& f, const PointCloud& in, const Gaze& gaze, const PointCloud& out, const uint32_t* rep) {
          return refineTestRef(in, gaze, f.levels_, out, rep, f.region_.data(), f.refineState());
        },
        {"partitionRef", "assignLevelsRef", "computeFixation", "VoxelSampler", "refineTestRef"}};
  }
  // The hash sampler shares the pool through setWorkerPool(); the fixation has no
  // threaded form (one percentile over the fovea's points).
  const auto hash_sample = [](Foveator& f, const PointCloud& in, const std::array<double, kMaxRegions>& voxel_size_m,
                              FoveatedCloud& out, SampleCounts& counts, uint32_t* rep) {
    return f.hash_sampler_.sample(in, f.region_.data(), f.model_.regionCount(), voxel_size_m, out, counts, rep);
  };
  if (pooled) {
    return {
        [](Foveator& f, const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) {
          f.partitionParallel(in, gaze, counts);
        },
        [](Foveator& f, const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) {
          f.levelsParallel(in, gaze, counts);
        },
        computeFixationSimd,
        hash_sample,
        [](Foveator& f, const PointCloud& in, const Gaze& gaze, const PointCloud& out, const uint32_t* rep) {
          return f.refineTestParallel(in, gaze, out, rep);
        },
        {"partitionRange/pool", "levelRange/pool", "computeFixationSimd", "HashVoxelSampler/pool",
         "refineTestRange/pool"}};
  }
  return {
      [](Foveator& f, const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) {
        partitionSimd(in, gaze, f.bounds_, f.region_.data(), counts);
      },
      [](Foveator& f, const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) {
        assignLevelsSimd(in, gaze, f.levels_, f.region_.data(), counts);
      },
      computeFixationSimd,
      hash_sample,
      [](Foveator& f, const PointCloud& in, const Gaze& gaze, const PointCloud& out, const uint32_t* rep) {
        return refineTestSimd(in, gaze, f.levels_, out, rep, f.region_.data(), f.refineState());
      },
      {"partitionSimd", "assignLevelsSimd", "computeFixationSimd", "HashVoxelSampler", "refineTestSimd"}};
}

namespace {

struct PartitionJob {
  const PointCloud* cloud;
  const kernels::PartitionParams* params;
  uint8_t* region;
  uint32_t* histograms;  // 256 per part
};

void partitionPart(void* ctx, int part, int parts) {
  auto* job = static_cast<PartitionJob*>(ctx);
  const std::size_t n = job->cloud->size();
  uint32_t* histogram = job->histograms + 256 * static_cast<std::size_t>(part);
  std::fill(histogram, histogram + 256, 0u);
  kernels::partitionRange(*job->cloud, *job->params, WorkerPool::rangeBegin(n, part, parts),
                          WorkerPool::rangeBegin(n, part + 1, parts), job->region, histogram);
}

struct LevelJob {
  const PointCloud* cloud;
  const kernels::LevelParams* params;
  uint8_t* region;
  uint32_t* histograms;  // 256 per part
};

void levelPart(void* ctx, int part, int parts) {
  auto* job = static_cast<LevelJob*>(ctx);
  const std::size_t n = job->cloud->size();
  uint32_t* histogram = job->histograms + 256 * static_cast<std::size_t>(part);
  std::fill(histogram, histogram + 256, 0u);
  kernels::levelRange(*job->cloud, *job->params, WorkerPool::rangeBegin(n, part, parts),
                      WorkerPool::rangeBegin(n, part + 1, parts), job->region, histogram);
}

struct RefineJob {
  const PointCloud* cloud;
  const kernels::LevelParams* params;
  const kernels::RefineInputs* inputs;
  const uint8_t* region;
  uint8_t* state;
  uint32_t* histograms;  // per part (256 each): [0] gets the points beyond
};

void refinePart(void* ctx, int part, int parts) {
  auto* job = static_cast<RefineJob*>(ctx);
  const std::size_t n = job->cloud->size();
  job->histograms[256 * static_cast<std::size_t>(part)] = static_cast<uint32_t>(
      kernels::refineTestRange(*job->cloud, *job->params, *job->inputs, job->region,
                               WorkerPool::rangeBegin(n, part, parts), WorkerPool::rangeBegin(n, part + 1, parts),
                               job->state));
}

}  // namespace

std::size_t Foveator::refineTestParallel(const PointCloud& in, const Gaze& gaze, const PointCloud& out,
                                         const uint32_t* representative) {
  const kernels::LevelParams params = kernels::prepareLevels(in, gaze, levels_);
  const kernels::RefineInputs inputs = kernels::prepareRefine(in, out, representative);
  RefineJob job{&in, &params, &inputs, region_.data(), refineState(), part_histograms_.data()};
  pool_->run(refinePart, &job);
  std::size_t beyond = 0;
  for (int part = 0; part < pool_->parts(); ++part) beyond += part_histograms_[256 * static_cast<std::size_t>(part)];
  return beyond;
}

void Foveator::sumHistograms(PartitionCounts& counts) const {
  counts = {};
  for (int part = 0; part < pool_->parts(); ++part) {
    const uint32_t* histogram = part_histograms_.data() + 256 * static_cast<std::size_t>(part);
    for (int r = 0; r < kMaxRegions; ++r) counts.per_region[r] += histogram[r];
    counts.invalid += histogram[kRegionInvalid];
    counts.culled += histogram[kRegionCulled];
  }
}

void Foveator::levelsParallel(const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) {
  const kernels::LevelParams params = kernels::prepareLevels(in, gaze, levels_);
  LevelJob job{&in, &params, region_.data(), part_histograms_.data()};
  pool_->run(levelPart, &job);
  sumHistograms(counts);
}

void Foveator::partitionParallel(const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) {
  const kernels::PartitionParams params = kernels::preparePartition(in, gaze, bounds_);
  PartitionJob job{&in, &params, region_.data(), part_histograms_.data()};
  pool_->run(partitionPart, &job);
  sumHistograms(counts);
}

Status Foveator::setConfig(const FoveationConfig& config) {
  if (Status s = config.fixation.validate(); !s) return s;
  Result<RegionModel> model = RegionModel::create(config.acuity);
  if (!model) return model.status();
  model_ = model.value();
  bounds_ = ConeBounds::fromModel(model_);
  levels_ = LevelBounds::fromModel(model_);
  config_ = config;
  return Status::ok();
}

// Doubling every region's edge leaves the regions and the fovea as they were
// and merges neighbouring voxels: on a surface about a quarter as many. The
// fovea alone over the output's capacity stays an error.
Status Foveator::sampleWithinCapacity(const PointCloud& in, std::array<double, kMaxRegions>& voxel_size_m,
                                      FoveatedCloud& out, SampleCounts& counts, uint32_t* representative,
                                      FoveationStats& stats) {
  Status s = table_.sample(*this, in, voxel_size_m, out, counts, representative);
  while (s.code() == ErrorCode::kCapacityExceeded && stats.coarsened < capacity_.max_coarsenings) {
    for (int r = 1; r < model_.regionCount(); ++r) voxel_size_m[r] *= 2.0;
    ++stats.coarsened;
    counts = {};
    s = table_.sample(*this, in, voxel_size_m, out, counts, representative);
  }
  if (s.code() != ErrorCode::kCapacityExceeded) return s;
  const bool voxels = s.message() == kVoxelsFull;
  return {ErrorCode::kCapacityExceeded,
          "voxel sampler: " +
              (voxels ? "more than " + std::to_string(capacity_.max_voxels) + " occupied voxels"
                      : "more points than the output's " + std::to_string(out.points.capacity())) +
              " after " + std::to_string(stats.coarsened) + " coarsenings" +
              (voxels ? ": raise pipeline.max_voxels" : "")};
}

Status Foveator::foveate(const PointCloud& in, const Gaze& gaze, FoveatedCloud& out, FoveationStats& stats,
                         uint32_t* representative) {
  stats = {};
  stats.region_count = model_.regionCount();
  out.clear();
  if (in.size() > capacity_.max_points) {
    return {ErrorCode::kCapacityExceeded, "foveator: cloud has " + std::to_string(in.size()) +
                                              " points, capacity is " + std::to_string(capacity_.max_points) +
                                              ": raise pipeline.max_points"};
  }
  Result<Gaze> unit_gaze = normalizeGaze(gaze);
  if (!unit_gaze) return unit_gaze.status();

  const int64_t t0 = monotonicNs();
  PartitionCounts partition_counts;
  // The acuity mode's levels in place of the cones; the samplers below are shared.
  (model_.levels() ? table_.levels : table_.partition)(*this, in, unit_gaze.value(), partition_counts);
  const int64_t t1 = monotonicNs();
  // The levels need no fixation distance: each point's own distance sizes its voxel.
  if (model_.levels()) {
    stats.fixation.source = FixationSource::kNone;
  } else {
    stats.fixation = table_.fixation(in, region_.data(), unit_gaze.value(), config_.fixation, fixationScratch());
  }
  std::array<double, kMaxRegions> voxel_size_m{};
  for (int r = 1; r < model_.regionCount(); ++r) voxel_size_m[r] = model_.voxelSizeM(r, stats.fixation.d0_m);
  const int64_t t2 = monotonicNs();
  SampleCounts sample_counts;
  // ACUITY's refinement needs every point's representative, asked for or not.
  const bool refine = model_.levels() && model_.refinePasses() > 0;
  uint32_t* rep = representative != nullptr || !refine ? representative : representativeScratch();
  Status sampled = sampleWithinCapacity(in, voxel_size_m, out, sample_counts, rep, stats);
  // Move the points the eye would see displaced one level down and sample again,
  // until none moves or the passes are spent.
  for (int pass = 0; refine && sampled && pass < model_.refinePasses(); ++pass) {
    const std::size_t beyond = table_.refine_test(*this, in, unit_gaze.value(), out.points, rep);
    if (beyond == 0) break;
    const std::size_t moved = moveRefinedVoxels(refineState(), rep, in.size(), out.size(), voxelBeyond(),
                                                region_.data(), partition_counts);
    stats.refined += static_cast<uint32_t>(moved);
    ++stats.refine_passes;
    sampled = sampleWithinCapacity(in, voxel_size_m, out, sample_counts, rep, stats);
  }
  const int64_t t3 = monotonicNs();

  stats.partition_ns = t1 - t0;
  stats.fixation_ns = t2 - t1;
  stats.sample_ns = t3 - t2;
  stats.dropped_nonfinite = partition_counts.invalid;
  stats.culled = partition_counts.culled;
  stats.points_in = static_cast<uint32_t>(in.size()) - partition_counts.invalid;
  for (int r = 0; r < model_.regionCount(); ++r) {
    stats.regions[r].points_in = partition_counts.per_region[r];
    stats.regions[r].points_out = sample_counts.out[r];
    stats.regions[r].voxel_size_m = voxel_size_m[r];
  }
  stats.points_out = static_cast<uint32_t>(out.size());
  return sampled;
}

}  // namespace fovea::pipeline
