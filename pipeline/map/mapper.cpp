#include "pipeline/map/mapper.h"

#include <cmath>
#include <utility>

#include "core/clock.h"

namespace fovea::pipeline::map {

namespace {

// What the operator gets of the map, made as config.output says.
Status makeOutput(const MapperConfig& config, std::unique_ptr<EyeView>& eye, std::unique_ptr<MapDelta>& delta,
                  std::unique_ptr<BrickSampler>& sampler) {
  if (config.output == MapOutput::kEyeView) {
    Result<EyeView> made = EyeView::create(config.eye, config.map.max_bricks);
    if (!made) return made.status();
    eye = std::make_unique<EyeView>(std::move(made.value()));
  } else if (config.output == MapOutput::kBricks) {
    Result<MapDelta> made_delta = MapDelta::create(config.delta, config.map.max_bricks);
    if (!made_delta) return made_delta.status();
    Result<BrickSampler> made_sampler = BrickSampler::create(config.delta.acuity, config.max_brick_surfels);
    if (!made_sampler) return made_sampler.status();
    delta = std::make_unique<MapDelta>(std::move(made_delta.value()));
    sampler = std::make_unique<BrickSampler>(std::move(made_sampler.value()));
  }
  return Status::ok();
}

}  // namespace

Result<Mapper> Mapper::create(const MapperConfig& config) {
  if (!(config.fuse_budget_ms >= 0.0 && config.fuse_budget_ms <= 1e4)) {
    return Result<Mapper>(ErrorCode::kInvalidArgument, "map.fuse_budget_ms: must be in [0, 10000]");
  }
  Result<SurfelMap> map = SurfelMap::create(config.map);
  if (!map) return map.status();
  Mapper mapper;
  mapper.output_ = config.output;
  mapper.map_ = std::make_unique<SurfelMap>(std::move(map.value()));
  if (Status s = makeOutput(config, mapper.eye_, mapper.delta_, mapper.sampler_); !s) return s;
  if (config.output != MapOutput::kNone) {
    Result<ExplainedView> view =
        ExplainedView::create(config.map.max_width, config.map.max_height, config.map.depth_tolerance_sigmas);
    if (!view) return view.status();
    mapper.view_ = std::make_unique<ExplainedView>(std::move(view.value()));
  }
  if (config.tracking != PoseTracking::kOff) {
    TrackerConfig tracker = config.tracker;
    tracker.max_width = config.map.max_width;
    tracker.max_height = config.map.max_height;
    Result<PoseEstimator> poser = PoseEstimator::create(config.tracking, tracker);
    if (!poser) return Result<Mapper>(poser.status().code(), "tracking: " + poser.status().message());
    mapper.poser_ = std::make_unique<PoseEstimator>(std::move(poser.value()));
  }
  mapper.budget_ = FusionBudget(std::llround(config.fuse_budget_ms * 1e6));
  return mapper;
}

bool Mapper::addFrame(hal::RgbdFrame& frame, bool outside_pose_valid, MapperFrame& out) {
  out = {};
  out.pose_usable = poser_ ? poser_->poseFrame(frame, outside_pose_valid, out.track) : outside_pose_valid;
  if (!budget_.admit()) {
    out.fusion_skipped = true;
    return false;
  }
  map_->fuse(frame, out.fuse, out.pose_usable);
  budget_.spent(out.fuse.fuse_ns);
  if (view_ && out.fused()) view_->capture(frame, map_->explainedPixels(), map_->measuredDepth());
  if (poser_ && out.fused()) {
    const int64_t t0 = monotonicNs();
    poser_->fused(frame, *map_);
    out.track.model_ns = monotonicNs() - t0;
  }
  return out.fused();
}

void Mapper::appendVisible(const Eigen::Vector3d& eye_m, PointCloud& cloud, EyeViewStats& stats) {
  if (eye_) eye_->appendVisible(*map_, eye_m, cloud, stats);
}

Status Mapper::planBricks(const Gaze& gaze, double budget_bytes, double live_bytes, const Eigen::Vector3d& origin_m,
                          BrickBatch& batch, MapperPlan& plan) {
  batch.clear(origin_m);
  plan = {};
  if (!delta_) return {ErrorCode::kInvalidArgument, "bricks: the mapper does not stream the map's bricks"};
  Result<std::span<const BrickDue>> due = delta_->plan(*map_, gaze, plan.delta);
  if (!due) return due.status();
  double left = budget_bytes;
  bool live_charged = false;
  std::size_t next = 0;
  for (; next < due->size(); ++next) {
    const BrickDue& brick = (*due)[next];
    if (!brick.fovea && !live_charged) {
      left -= live_bytes;
      live_charged = true;
    }
    if (left <= 0.0) break;  // the rest stays due, oldest first next frame
    const std::size_t before = batch.points.size();
    uint32_t version = delta_->version(brick.brick) + 1;  // what markSent will make it (0 is skipped)
    if (version == 0) version = 1;
    if (!sampler_->append(*map_, brick.brick, brick.level, version, brick.fovea, batch)) break;
    delta_->markSent(*map_, brick.brick, brick.level);
    const std::size_t points = batch.points.size() - before;
    left -= static_cast<double>(points) * kWireBytesPerPointEstimate;
    ++plan.bricks_planned;
    ++plan.planned_by_need[static_cast<std::size_t>(brick.need)];
    plan.brick_points += static_cast<uint32_t>(points);
  }
  for (std::size_t i = next; i < due->size(); ++i) {
    ++plan.bricks_waiting;
    plan.fovea_bricks_waiting += (*due)[i].fovea ? 1 : 0;
  }
  return Status::ok();
}

void Mapper::forgetBrick(uint16_t brick) {
  if (delta_ && brick < map_->config().max_bricks) delta_->forget(brick);
}

void Mapper::forgetBatch(const BrickBatch& batch) {
  for (const BrickBatchEntry& e : batch.entries()) forgetBrick(e.brick);
}

void Mapper::forgetAll() {
  if (delta_) delta_->forgetAll();
}

MapperMemory Mapper::memory() const {
  MapperMemory m;
  m.map = map_->memoryParts();
  m.eye = eye_ ? eye_->memoryBytes() : 0;
  m.delta = delta_ ? delta_->memoryBytes() + sampler_->memoryBytes() : 0;
  m.tracker = poser_ ? poser_->memoryBytes() : 0;
  m.view = view_ ? view_->memoryBytes() : 0;
  return m;
}

}  // namespace fovea::pipeline::map
