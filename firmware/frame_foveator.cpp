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

std::size_t liveFramePoints(std::size_t max_live_points, std::size_t pixels) {
  return max_live_points > 0 ? max_live_points : std::max<std::size_t>(pixels / 8, 1);
}

namespace {

// The map source's mapper, from the [map] settings and the camera.
pipeline::map::MapperConfig mapperConfig(const MapSettings& map, const pipeline::DepthRange& range, int width,
                                         int height) {
  pipeline::map::MapperConfig config;
  config.map = map.map;
  config.map.depth = range;
  config.map.max_width = width;
  config.map.max_height = height;
  config.tracking = map.tracking;
  config.tracker = map.tracker;
  config.fuse_budget_ms = map.fuse_budget_ms;
  config.fusion_thread = map.fusion_thread;
  config.output = map.delta ? pipeline::map::MapOutput::kBricks : pipeline::map::MapOutput::kEyeView;
  config.eye = map.eye;
  config.delta = map.delta_config;
  config.max_brick_surfels = map.max_brick_surfels;
  return config;
}

}  // namespace

Result<FrameFoveator> FrameFoveator::create(const pipeline::PipelineCapacity& capacity,
                                            const pipeline::FoveationConfig& config,
                                            const pipeline::DepthRange& range, const MapSettings& map, int width,
                                            int height) {
  if (Status s = range.validate(); !s) return s;
  if (map.source != FoveationSource::kMap && map.tracking != pipeline::map::PoseTracking::kOff) {
    return Result<FrameFoveator>(ErrorCode::kInvalidArgument, "tracking the camera needs the map source");
  }
  if (streamsLiveOnly(map) && (map.max_frame_brick_points == 0 || map.max_frame_bricks == 0)) {
    return Result<FrameFoveator>(ErrorCode::kInvalidArgument, "map: a frame's bricks need room (max_frame_brick_points, max_frame_bricks; 0 points is the service's to resolve)");
  }
  pipeline::PipelineCapacity sized = capacity;
  sized.max_points = cloudCapacity(capacity.max_points, map);
  if (capsLivePoints(map, config.acuity.preset)) {
    const std::size_t live = liveFramePoints(map.max_live_points, capacity.max_points);
    sized.max_points = std::min(sized.max_points, kLiveCandidatesPerOutput * live);
  }
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
    Result<pipeline::map::Mapper> mapper = pipeline::map::Mapper::create(mapperConfig(map, range, width, height));
    if (!mapper) return mapper.status();
    stage.mapper_ = std::make_unique<pipeline::map::Mapper>(std::move(mapper.value()));
    stage.max_frame_brick_points_ = map.max_frame_brick_points;
    stage.max_frame_bricks_ = map.max_frame_bricks;
  }
  return stage;
}

Status FrameFoveator::backproject(hal::RgbdFrame& frame, pipeline::BackprojectCounts& counts, bool pose_valid) {
  if (source_ == FoveationSource::kFrame) return backprojector_.run(frame, range_, cloud_, counts);
  if (source_ == FoveationSource::kPyramid) {
    frame_ = &frame;
    counts = {};
    counts.pixels = frame.pixelCount();
    return Status::ok();
  }
  map_figures_ = {};
  // Fused now or not (refused, lost, over the time budget, or handed to the
  // fusion thread), the operator gets the frame's points the map does not
  // explain beside the map; a posed frame not fused now without what the last
  // fused frame explained, which the operator has from the map.
  (void)mapper_->addFrame(frame, pose_valid, map_figures_);
  cloud_.origin_m = frame.T_world_cam.t_world_cam;
  pipeline::map::LiveFigures live;
  Status s = mapper_->collectLive(frame, map_figures_, range_, liveSelection(frame), cloud_, live);
  counts = {};
  counts.pixels = frame.pixelCount();
  counts.valid = live.valid;
  map_figures_.explained_by_last_view = live.explained_by_last_view;
  map_figures_.live = live.points;
  if (!s) cloud_.clear();
  map_figures_.frame_points = static_cast<uint32_t>(cloud_.size());
  return s;
}

// The eye's cone for thinning a frame whose live points do not fit
// (pipeline/map/live_points.h): the gaze of the last frame foveated (this
// frame's is decided after it is taken in) or, before any, the camera's axis;
// as wide as the fovea (the cone presets' first bound, the paper's 5 degrees
// for ACUITY, whose levels have none), the gaze policy's growth for the gaze's
// age, and kLiveGazeMarginDeg for the eye's movement in a frame period.
pipeline::map::LiveSelection FrameFoveator::liveSelection(const hal::RgbdFrame& frame) const {
  const pipeline::RegionModel& model = foveator_.model();
  double whole_deg = model.levels() || model.boundCount() == 0 ? kAcuityFoveaDeg : model.boundDeg(0);
  pipeline::Gaze gaze = last_gaze_;
  if (!has_gaze_) {
    gaze.origin_m = frame.T_world_cam.t_world_cam;
    gaze.direction = frame.T_world_cam.R_world_cam.col(2);
    gaze.fovea_growth_deg = 0.0;
  }
  whole_deg = std::min(whole_deg + gaze.fovea_growth_deg + kLiveGazeMarginDeg, 180.0);
  pipeline::map::LiveSelection selection;
  selection.eye_m = (gaze.origin_m - frame.T_world_cam.t_world_cam).cast<float>();
  selection.gaze = gaze.direction.normalized().cast<float>();
  selection.whole_cos = static_cast<float>(std::cos(whole_deg * (M_PI / 180.0)));
  return selection;
}

Status FrameFoveator::foveate(const pipeline::Gaze& gaze, pipeline::FoveatedCloud& out,
                              pipeline::FoveationStats& stats) {
  if (source_ == FoveationSource::kPyramid) return foveatePyramid(gaze, out, stats);
  if (source_ == FoveationSource::kMap) {
    if (!gaze.origin_m.allFinite()) return {ErrorCode::kInvalidInput, "gaze origin is not finite"};
    if (Result<pipeline::Gaze> unit = pipeline::normalizeGaze(gaze)) {
      last_gaze_ = unit.value();
      has_gaze_ = true;
    }
    if (!cloud_.resize(map_figures_.frame_points)) return {ErrorCode::kCapacityExceeded, "map: frame points beyond the cloud"};
    // With bricks the operator holds the map: only the live points go as a frame.
    if (!streamsBricks()) mapper_->appendVisible(gaze.origin_m, cloud_, map_figures_.eye);
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
  if (!streamsBricks()) return {};
  return pipeline::map::BrickBatch(max_frame_brick_points_, max_frame_bricks_);
}

Status FrameFoveator::planBricks(const pipeline::Gaze& gaze, double budget_bytes, double live_bytes,
                                 pipeline::map::BrickBatch& batch) {
  map_figures_.plan = {};
  if (!mapper_) {
    batch.clear(cloud_.origin_m);
    return {ErrorCode::kInvalidArgument, "bricks: the stage does not stream the map's bricks"};
  }
  return mapper_->planBricks(gaze, budget_bytes, live_bytes, cloud_.origin_m, batch, map_figures_.plan);
}

}  // namespace fovea::firmware
