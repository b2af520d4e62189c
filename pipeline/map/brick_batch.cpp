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
      sampler_(max_brick_surfels, max_brick_surfels),
      sampled_(max_brick_surfels) {}

std::size_t BrickSampler::memoryBytes() const {
  // Per point: the surfel copy (16), its region (1), the sampler's keys and
  // indices with their scratch (24) and the sampled copy (21).
  return surfels_.capacity() * (16 + 1 + 24 + 21);
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
  SampleCounts counts;
  if (!sampler_.sample(surfels_, region_.data(), level + 1, level_step_m_, sampled_, counts)) return false;
  PointCloud& out = batch.points.points;
  const std::size_t first = out.size();
  if (first + sampled_.size() > out.capacity()) return false;
  // The batch's points share one origin: the brick's offset from it, in float,
  // is exact to well under a millimetre within kilometres.
  const Eigen::Vector3f shift = (surfels_.origin_m - out.origin_m).cast<float>();
  const PointCloud& in = sampled_.points;
  for (std::size_t i = 0; i < sampled_.size(); ++i) {
    (void)out.push(in.x()[i] + shift.x(), in.y()[i] + shift.y(), in.z()[i] + shift.z(), in.rgb()[i]);
    batch.points.region[first + i] = level;
    if (batch.points.hasWeights()) batch.points.weight[first + i] = sampled_.weight[i];
  }
  BrickBatchEntry& e = batch.add();
  e.brick = brick;
  e.key = map.brickKey(brick);
  e.version = version;
  e.level = level;
  e.fovea = fovea;
  e.first = static_cast<uint32_t>(first);
  e.count = static_cast<uint32_t>(sampled_.size());
  batch.level_step_m = level_step_m_;
  ++counters_.bricks;
  counters_.surfels_in += surfels_.size();
  counters_.points_out += sampled_.size();
  counters_.truncated += truncated ? 1 : 0;
  return true;
}

}  // namespace fovea::pipeline::map
