#include "firmware/frame_foveator.h"

#include <algorithm>

namespace fovea::firmware {

std::string_view foveationSourceName(FoveationSource source) {
  switch (source) {
    case FoveationSource::kFrame: return "frame";
    case FoveationSource::kMap: return "map";
  }
  return "?";
}

std::optional<FoveationSource> parseFoveationSource(std::string_view name) {
  if (name == "frame") return FoveationSource::kFrame;
  if (name == "map") return FoveationSource::kMap;
  return std::nullopt;
}

Result<FrameFoveator> FrameFoveator::create(const pipeline::PipelineCapacity& capacity,
                                            const pipeline::FoveationConfig& config,
                                            const pipeline::DepthRange& range, const MapSettings& map, int width,
                                            int height) {
  if (Status s = range.validate(); !s) return s;
  pipeline::PipelineCapacity sized = capacity;
  sized.max_points = cloudCapacity(capacity.max_points, map);
  if (map.source == FoveationSource::kMap) {
    sized.max_voxels = std::min(sized.max_points, capacity.max_voxels + map.map.max_surfels);
  }
  Result<pipeline::Foveator> foveator = pipeline::Foveator::create(sized, config);
  if (!foveator) return foveator.status();
  FrameFoveator stage(std::move(foveator.value()), sized, range);
  stage.source_ = map.source;
  if (map.source == FoveationSource::kMap) {
    pipeline::map::SurfelMapConfig map_config = map.map;
    map_config.depth = range;
    map_config.max_width = width;
    map_config.max_height = height;
    Result<pipeline::map::SurfelMap> fused = pipeline::map::SurfelMap::create(map_config);
    if (!fused) return fused.status();
    Result<pipeline::map::EyeView> eye = pipeline::map::EyeView::create(map.eye, map_config.max_bricks);
    if (!eye) return eye.status();
    stage.map_ = std::make_unique<pipeline::map::SurfelMap>(std::move(fused.value()));
    stage.eye_ = std::make_unique<pipeline::map::EyeView>(std::move(eye.value()));
  }
  return stage;
}

Status FrameFoveator::backproject(const hal::RgbdFrame& frame, pipeline::BackprojectCounts& counts, bool pose_valid) {
  if (source_ == FoveationSource::kFrame) return backprojector_.run(frame, range_, cloud_, counts);
  map_figures_ = {};
  const pipeline::map::FuseOutcome outcome = map_->fuse(frame, map_figures_.fuse, pose_valid);
  if (outcome != pipeline::map::FuseOutcome::kFused) {
    // Not in the map: the operator still sees the frame as it is, beside the map.
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
  if (source_ == FoveationSource::kMap) {
    if (!gaze.origin_m.allFinite()) return {ErrorCode::kInvalidInput, "gaze origin is not finite"};
    if (!cloud_.resize(map_figures_.frame_points)) return {ErrorCode::kCapacityExceeded, "map: frame points beyond the cloud"};
    eye_->appendVisible(*map_, gaze.origin_m, cloud_, map_figures_.eye);
  }
  return foveator_.foveate(cloud_, gaze, out, stats);
}

}  // namespace fovea::firmware
