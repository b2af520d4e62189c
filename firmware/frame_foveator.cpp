#include "firmware/frame_foveator.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace fovea::firmware {

std::string_view foveationSourceName(FoveationSource source) {
  switch (source) {
    case FoveationSource::kFrame: return "frame";
    case FoveationSource::kMap: return "map";
    case FoveationSource::kPyramid: return "pyramid";
  }
  return "?";
}

std::optional<FoveationSource> parseFoveationSource(std::string_view name) {
  if (name == "frame") return FoveationSource::kFrame;
  if (name == "map") return FoveationSource::kMap;
  if (name == "pyramid") return FoveationSource::kPyramid;
  return std::nullopt;
}

std::size_t frameBrickPoints(double max_budget_bytes_per_s, double fps, std::size_t max_brick_surfels) {
  const double points = std::ceil(max_budget_bytes_per_s / std::max(fps, 1.0) / kWireBytesPerPointEstimate);
  return std::max(max_brick_surfels, static_cast<std::size_t>(std::min(points, 1e9)));
}

Result<FrameFoveator> FrameFoveator::create(const pipeline::PipelineCapacity& capacity,
                                            const pipeline::FoveationConfig& config,
                                            const pipeline::DepthRange& range, const MapSettings& map, int width,
                                            int height) {
  if (Status s = range.validate(); !s) return s;
  pipeline::PipelineCapacity sized = capacity;
  sized.max_points = cloudCapacity(capacity.max_points, map);
  if (appendsMapToCloud(map)) {
    sized.max_voxels = std::min(sized.max_points, capacity.max_voxels + map.map.max_surfels);
  }
  Result<pipeline::Foveator> foveator = pipeline::Foveator::create(sized, config);
  if (!foveator) return foveator.status();
  FrameFoveator stage(std::move(foveator.value()), sized, range);
  stage.source_ = map.source;
  if (map.source == FoveationSource::kPyramid) {
    Result<pipeline::PyramidSampler> pyramid = pipeline::PyramidSampler::create(width, height, 5, capacity.kernels);
    if (!pyramid) return pyramid.status();
    stage.pyramid_ = std::make_unique<pipeline::PyramidSampler>(std::move(pyramid.value()));
    stage.pyramid_rule_ = pipeline::PyramidRule::fromAcuity(config.acuity);
    if (Status s = stage.pyramid_rule_.validate(); !s) return s;
  }
  if (map.source == FoveationSource::kMap) {
    pipeline::map::SurfelMapConfig map_config = map.map;
    map_config.depth = range;
    map_config.max_width = width;
    map_config.max_height = height;
    Result<pipeline::map::SurfelMap> fused = pipeline::map::SurfelMap::create(map_config);
    if (!fused) return fused.status();
    stage.map_ = std::make_unique<pipeline::map::SurfelMap>(std::move(fused.value()));
    if (!(map.fuse_budget_ms >= 0.0 && map.fuse_budget_ms <= 1e4)) {
      return Result<FrameFoveator>(ErrorCode::kInvalidArgument, "map.fuse_budget_ms: must be in [0, 10000]");
    }
    stage.budget_ = pipeline::map::FusionBudget(std::llround(map.fuse_budget_ms * 1e6));
    if (appendsMapToCloud(map)) {
      Result<pipeline::map::EyeView> eye = pipeline::map::EyeView::create(map.eye, map_config.max_bricks);
      if (!eye) return eye.status();
      stage.eye_ = std::make_unique<pipeline::map::EyeView>(std::move(eye.value()));
    } else {
      if (map.max_frame_brick_points == 0 || map.max_frame_bricks == 0) {
        return Result<FrameFoveator>(ErrorCode::kInvalidArgument, "map: a frame's bricks need room (max_frame_brick_points, max_frame_bricks; 0 points is the service's to resolve)");
      }
      Result<pipeline::map::MapDelta> delta = pipeline::map::MapDelta::create(map.delta_config, map_config.max_bricks);
      if (!delta) return delta.status();
      Result<pipeline::map::BrickSampler> sampler =
          pipeline::map::BrickSampler::create(map.delta_config.acuity, map.max_brick_surfels);
      if (!sampler) return sampler.status();
      stage.delta_ = std::make_unique<pipeline::map::MapDelta>(std::move(delta.value()));
      stage.bricks_ = std::make_unique<pipeline::map::BrickSampler>(std::move(sampler.value()));
      stage.max_frame_brick_points_ = map.max_frame_brick_points;
      stage.max_frame_bricks_ = map.max_frame_bricks;
    }
    if (map.tracking != pipeline::map::PoseTracking::kOff) {
      pipeline::map::TrackerConfig tracker_config = map.tracker;
      tracker_config.max_width = width;
      tracker_config.max_height = height;
      Result<pipeline::map::PoseEstimator> poser = pipeline::map::PoseEstimator::create(map.tracking, tracker_config);
      if (!poser) return Result<FrameFoveator>(poser.status().code(), "tracking: " + poser.status().message());
      stage.poser_ = std::make_unique<pipeline::map::PoseEstimator>(std::move(poser.value()));
    }
  } else if (map.tracking != pipeline::map::PoseTracking::kOff) {
    return Result<FrameFoveator>(ErrorCode::kInvalidArgument, "tracking the camera needs the map source");
  }
  return stage;
}

bool FrameFoveator::trackPose(hal::RgbdFrame& frame, bool outside_pose_valid) {
  map_figures_.track = {};
  if (!poser_) return outside_pose_valid;
  return poser_->poseFrame(frame, outside_pose_valid, map_figures_.track);
}

Status FrameFoveator::backproject(const hal::RgbdFrame& frame, pipeline::BackprojectCounts& counts, bool pose_valid) {
  if (source_ == FoveationSource::kFrame) return backprojector_.run(frame, range_, cloud_, counts);
  if (source_ == FoveationSource::kPyramid) {
    frame_ = &frame;
    counts = {};
    counts.pixels = frame.pixelCount();
    return Status::ok();
  }
  const pipeline::map::TrackStats track = map_figures_.track;  // trackPose()'s, for this frame
  map_figures_ = {};
  map_figures_.track = track;
  bool fused = false;
  if (budget_.admit()) {
    fused = map_->fuse(frame, map_figures_.fuse, pose_valid) == pipeline::map::FuseOutcome::kFused;
    budget_.spent(map_figures_.fuse.fuse_ns);
  } else {
    map_figures_.fusion_skipped = true;
  }
  if (poser_ && fused) poser_->fused(frame, *map_);
  if (!fused) {
    // Not in the map (refused, or over the time budget): the operator still
    // sees the frame as it is, beside the map.
    if (Status s = backprojector_.run(frame, range_, cloud_, counts); !s) {
      cloud_.clear();
      return s;
    }
    map_figures_.frame_points = static_cast<uint32_t>(cloud_.size());
    return Status::ok();
  }
  cloud_.clear();
  cloud_.origin_m = frame.T_world_cam.t_world_cam;
  counts = {};
  counts.pixels = frame.pixelCount();
  counts.valid = map_figures_.fuse.pixels_valid;
  map_figures_.frame_points = static_cast<uint32_t>(map_->appendUnexplained(frame, cloud_));
  return Status::ok();
}

Status FrameFoveator::foveate(const pipeline::Gaze& gaze, pipeline::FoveatedCloud& out,
                              pipeline::FoveationStats& stats) {
  if (source_ == FoveationSource::kPyramid) return foveatePyramid(gaze, out, stats);
  if (source_ == FoveationSource::kMap) {
    if (!gaze.origin_m.allFinite()) return {ErrorCode::kInvalidInput, "gaze origin is not finite"};
    if (!cloud_.resize(map_figures_.frame_points)) return {ErrorCode::kCapacityExceeded, "map: frame points beyond the cloud"};
    // With bricks the operator holds the map: only the live points go as a frame.
    if (!delta_) eye_->appendVisible(*map_, gaze.origin_m, cloud_, map_figures_.eye);
  }
  return foveator_.foveate(cloud_, gaze, out, stats);
}

Status FrameFoveator::foveatePyramid(const pipeline::Gaze& gaze, pipeline::FoveatedCloud& out,
                                     pipeline::FoveationStats& stats) {
  if (frame_ == nullptr) return {ErrorCode::kInvalidArgument, "pyramid: no frame taken in"};
  const hal::RgbdFrame& frame = *frame_;
  frame_ = nullptr;
  if (foveator_.model().preset() != pipeline::Preset::kAcuity) {
    // The pyramid is ACUITY's rule; another preset (a fallback) takes the exact path.
    pipeline::BackprojectCounts counts;
    if (Status s = backprojector_.run(frame, range_, cloud_, counts); !s) return s;
    return foveator_.foveate(cloud_, gaze, out, stats);
  }
  stats = {};
  const auto t0 = std::chrono::steady_clock::now();
  Result<pipeline::Gaze> unit = pipeline::normalizeGaze(gaze);
  if (!unit) return unit.status();
  pipeline::PyramidStats pyramid;
  if (Status s = pyramid_->sample(frame, range_, unit.value(), pyramid_rule_, out, pyramid); !s) return s;
  stats.region_count = pyramid_->levels() + 1;
  for (int k = 0; k < stats.region_count; ++k) stats.regions[k].points_out = pyramid.out_by_level[k];
  stats.points_in = pyramid.points_in;
  stats.points_out = pyramid.points_out;
  stats.sample_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count();
  return Status::ok();
}

pipeline::map::BrickBatch FrameFoveator::makeBrickBatch() const {
  if (!delta_) return {};
  return pipeline::map::BrickBatch(max_frame_brick_points_, max_frame_bricks_);
}

Status FrameFoveator::planBricks(const pipeline::Gaze& gaze, double budget_bytes, double live_bytes,
                                 pipeline::map::BrickBatch& batch) {
  batch.clear(cloud_.origin_m);
  map_figures_.bricks_planned = 0;
  map_figures_.brick_points = 0;
  map_figures_.bricks_waiting = 0;
  map_figures_.fovea_bricks_waiting = 0;
  if (!delta_) return {ErrorCode::kInvalidArgument, "bricks: the stage does not stream the map's bricks"};
  Result<std::span<const pipeline::map::BrickDue>> plan = delta_->plan(*map_, gaze, map_figures_.delta);
  if (!plan) return plan.status();
  double left = budget_bytes;
  bool live_charged = false;
  const std::span<const pipeline::map::BrickDue> due_bricks = plan.value();
  std::size_t next = 0;
  for (; next < due_bricks.size(); ++next) {
    const pipeline::map::BrickDue& due = due_bricks[next];
    if (!due.fovea && !live_charged) {
      left -= live_bytes;
      live_charged = true;
    }
    if (left <= 0.0) break;  // the rest stays due, oldest first next frame
    const std::size_t before = batch.points.size();
    uint32_t version = delta_->version(due.brick) + 1;  // what markSent will make it (0 is skipped)
    if (version == 0) version = 1;
    if (!bricks_->append(*map_, due.brick, due.level, version, due.fovea, batch)) break;
    delta_->markSent(*map_, due.brick, due.level);
    const std::size_t points = batch.points.size() - before;
    left -= static_cast<double>(points) * kWireBytesPerPointEstimate;
    ++map_figures_.bricks_planned;
    map_figures_.brick_points += static_cast<uint32_t>(points);
  }
  for (std::size_t i = next; i < due_bricks.size(); ++i) {
    ++map_figures_.bricks_waiting;
    map_figures_.fovea_bricks_waiting += due_bricks[i].fovea ? 1 : 0;
  }
  return Status::ok();
}

void FrameFoveator::forgetBrick(uint16_t brick) {
  if (delta_ && map_ && brick < map_->config().max_bricks) delta_->forget(brick);
}

void FrameFoveator::forgetBatch(const pipeline::map::BrickBatch& batch) {
  for (const pipeline::map::BrickBatchEntry& e : batch.entries()) forgetBrick(e.brick);
}

void FrameFoveator::forgetAllBricks() {
  if (delta_) delta_->forgetAll();
}

}  // namespace fovea::firmware
