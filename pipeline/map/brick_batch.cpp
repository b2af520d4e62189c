#include "pipeline/map/brick_batch.h"

#include <algorithm>

namespace fovea::pipeline::map {

Result<BrickSampler> BrickSampler::create(const AcuityConfig& levels, std::size_t max_brick_surfels) {
  if (max_brick_surfels == 0 || max_brick_surfels > (std::size_t{1} << 24)) {
    return Result<BrickSampler>(ErrorCode::kInvalidArgument, "brick sampler: max_brick_surfels must be in [1, 2^24]");
  }
  Result<RegionModel> model = RegionModel::create(levels);
  if (!model) return model.status();
  if (!model->levels()) {
    return Result<BrickSampler>(ErrorCode::kInvalidArgument, "brick sampler: the levels must be ACUITY's (preset acuity)");
  }
  std::array<double, kMaxRegions> steps{};
  for (int n = 1; n < kMaxRegions; ++n) steps[static_cast<std::size_t>(n)] = model->voxelSizeM(n, 0.0);
  return BrickSampler(steps, max_brick_surfels);
}

BrickSampler::BrickSampler(const std::array<double, kMaxRegions>& steps, std::size_t max_brick_surfels)
    : level_step_m_(steps),
      surfels_(max_brick_surfels),
      region_(max_brick_surfels),
      sampler_(max_brick_surfels, max_brick_surfels) {}

std::size_t BrickSampler::memoryBytes() const {
  // Per point: the surfel copy (16), its region (1), the sampler's keys and
  // indices with their scratch (24).
  return surfels_.capacity() * (16 + 1 + 24);
}

bool BrickSampler::append(const SurfelMap& map, uint16_t brick, uint8_t level, uint32_t version, bool fovea,
                          BrickBatch& batch) {
  if (batch.full() || level >= kMaxRegions) return false;
  surfels_.clear();
  surfels_.origin_m = map.brickOrigin(brick);
  bool truncated = false;
  for (uint32_t slot = map.firstInBrick(brick); slot != SurfelMap::kNoSurfel; slot = map.nextInBrick(slot)) {
    const Surfel& s = map.surfel(slot);
    if (!(s.flags & kSurfelSettled)) continue;
    if (!surfels_.push(s.x, s.y, s.z, packRgb(s.red, s.green, s.blue))) {
      truncated = true;
      break;
    }
  }
  std::fill_n(region_.begin(), surfels_.size(), level);
  // Sampled straight into the batch (its regions are the level, its weights
  // the sampler's), relative to the brick's origin, then moved to the batch's:
  // the batch's points share one origin, and the brick's offset from it, in
  // float, is exact to well under a millimetre within kilometres.
  PointCloud& out = batch.points.points;
  const std::size_t first = out.size();
  SampleCounts counts;
  if (!sampler_.sampleAt(surfels_, region_.data(), level + 1, level_step_m_, batch.points, first, counts)) return false;
  const Eigen::Vector3f shift = (surfels_.origin_m - out.origin_m).cast<float>();
  for (std::size_t i = first; i < out.size(); ++i) {
    out.x()[i] = out.x()[i] + shift.x();
    out.y()[i] = out.y()[i] + shift.y();
    out.z()[i] = out.z()[i] + shift.z();
  }
  const std::size_t sampled = out.size() - first;
  BrickBatchEntry& e = batch.add();
  e.brick = brick;
  e.key = map.brickKey(brick);
  e.version = version;
  e.level = level;
  e.fovea = fovea;
  e.first = static_cast<uint32_t>(first);
  e.count = static_cast<uint32_t>(sampled);
  batch.level_step_m = level_step_m_;
  ++counters_.bricks;
  counters_.surfels_in += surfels_.size();
  counters_.points_out += sampled;
  counters_.truncated += truncated ? 1 : 0;
  return true;
}

}  // namespace fovea::pipeline::map
