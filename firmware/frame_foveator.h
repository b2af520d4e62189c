// One frame's way through the pipeline, shared by `fovead run` (one thread) and
// the service's foveation stage. Three sources (foveation.source, FoveationSource):
//  - frame: back-projection into the stage's own cloud, foveated as it is;
//  - map (docs/map.md): the frame is fused into the surfel map; the cloud is
//    then the frame's points the map does not explain yet (a moving object, new
//    surface) and, once the gaze is known, the map's stable surfels the
//    operator's eye can see (pipeline/map/eye_view.h), all foveated together.
//    With bricks (MapSettings::delta, the service's default for the map
//    source) the operator keeps the map, so the cloud is only the frame's
//    points the map does not explain (the live points), and planBricks() fills
//    a batch with the map's bricks the operator's eye needs and lacks
//    (pipeline/map/map_delta.h, docs/map-delta.md), which the streamer sends;
//  - pyramid: the frame's image pyramid sampled by ACUITY's rule on pixel cells
//    (pipeline/pyramid_sampler.h), without back-projecting it; another preset
//    (the gaze policy's fallback, say) back-projects the frame as frame does.
// The foveation configuration the gaze policy chose is applied only when it
// changes. Everything is allocated by create(); a frame allocates nothing.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>

#include "core/clock.h"
#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/pyramid_sampler.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/map/mapper.h"
#include "pipeline/point_cloud.h"

namespace fovea::firmware {

// What is foveated: each frame's back-projected points (the exact methods), the
// fused map, or each frame's image pyramid (ACUITY's rule on pixel cells,
// approximate: pipeline/pyramid_sampler.h; a preset other than ACUITY, such as the
// gaze policy's fallback, back-projects the frame as kFrame does).
enum class FoveationSource : uint8_t { kFrame, kMap, kPyramid };
std::string_view foveationSourceName(FoveationSource source);
std::optional<FoveationSource> parseFoveationSource(std::string_view name);

// The map's settings ([map] in the configuration file, foveation.source).
// The map's depth range and largest frame are the camera's (create() sets them).
struct MapSettings {
  FoveationSource source = FoveationSource::kFrame;
  pipeline::map::SurfelMapConfig map;
  pipeline::map::EyeViewConfig eye;
  // Stream the map as bricks the operator keeps (map source only): the eye view
  // is then not appended to the frame. Off here; the service's configuration
  // turns it on (map.delta).
  bool delta = false;
  pipeline::map::MapDeltaConfig delta_config;
  // A brick's settled surfels sampled at most (the rest are left out, counted).
  std::size_t max_brick_surfels = 1u << 16;
  // The points one frame's bricks may carry (BrickBatch's capacity); 0: what
  // the link's largest budget pays for in a frame (frameBrickPoints(), which
  // the service applies; 2^18 before, three times that at 30 fps).
  std::size_t max_frame_brick_points = 0;
  std::size_t max_frame_bricks = 1024;
  // With bricks, a foveated frame's live points at most (the fovea whole and a
  // point per voxel; the sampler's voxels too), within pipeline.max_voxels and
  // pipeline.max_output_points: the operator keeps the map, so a frame carries
  // what the map does not explain yet, a few thousand points once it has
  // settled (the mock orbit: 4 443 a frame median, 6 730 at p90), and all of
  // the frame only while the map is new or a frame is not fused. 0: what
  // liveFramePoints() makes of the pixels (the service applies it). A frame
  // that needs more is foveated coarser, as any (pipeline.max_coarsenings).
  std::size_t max_live_points = 0;
  // Fusion's average time a frame at most (pipeline/map/fusion_budget.h); the
  // frames it does not fuse go without what the last fused frame explained,
  // counted. 0: every frame is fused.
  double fuse_budget_ms = 0.0;
  // Fusion on a thread of its own, which calls fuseSubmitted() (Mapper's
  // fusion_thread): each frame goes out at once, and fusion takes the newest
  // frame whenever it is free. Off here (`fovead run`: one thread); the
  // service's configuration turns it on (map.fusion_thread).
  bool fusion_thread = false;
  // The map tracks the camera (camera.pose.source = track, track+X; map source
  // only): pipeline/map/pose_tracking.h, docs/tracking.md.
  pipeline::map::PoseTracking tracking = pipeline::map::PoseTracking::kOff;
  pipeline::map::TrackerConfig tracker;
};

using pipeline::map::kWireBytesPerPointEstimate;

// The points a frame's bricks can carry at most: what the link's largest
// budget pays for in one frame period at kWireBytesPerPointEstimate (92 593
// at 12.5 MB/s and 30 fps), and at least one brick whole.
std::size_t frameBrickPoints(double max_budget_bytes_per_s, double fps, std::size_t max_brick_surfels);

// MapSettings::max_live_points when 0: an eighth of the pixels (38 400 at
// 640x480), which holds F1's foveation of a whole frame of the mock living room
// (37 300 points, the map's first frames), where the frame source's capacity
// (pipeline.max_output_points, 0.35 of the pixels) is sized for F2 and F3 on a
// whole TUM frame.
std::size_t liveFramePoints(std::size_t max_live_points, std::size_t pixels);

// With bricks, the cloud of a frame's live points before foveation holds this
// many times liveFramePoints() (a preset that keeps every point, FREF, the
// pixels): the foveator samples the periphery to fewer points than it gets
// (the mock orbit: 34 863 a frame median and 46 202 at p90 in, 4 443 and 6 730
// out), and a frame with more is thinned outside the eye's cone
// (pipeline/map/live_points.h): only the map's first half second and turns
// into unmapped space are.
inline constexpr std::size_t kLiveCandidatesPerOutput = 2;
// The thinning's cone around the gaze: ACUITY's fovea (its levels have no
// bound of their own; the paper's 5 degrees), and the margin for where the eye
// may be one frame period after the last gaze known (smooth pursuit; a
// saccade may leave it, for a frame that was thinned).
inline constexpr double kAcuityFoveaDeg = 5.0;
inline constexpr double kLiveGazeMarginDeg = 5.0;

// What the map did with the last frame (map source only): the mapper's
// frame (track, fuse, fusion_skipped, fused()), the eye's view, and the plan.
struct MapFrameFigures : pipeline::map::MapperFrame {
  pipeline::map::EyeViewStats eye;
  // The frame's points in the cloud: unexplained (fused), those the last fused
  // view does not explain (posed, not fused now), or all (refused, lost);
  // Mapper::collectLive, thinned when they did not fit (live.stride > 1).
  uint32_t frame_points = 0;
  uint32_t explained_by_last_view = 0;  // not fused now: the points the last fused view explained, left out
  pipeline::map::LivePointStats live;
  pipeline::map::MapperPlan plan;  // planBricks()'s
};

class FrameFoveator {
 public:
  // capacity.max_points: the frame's pixels; the map source without bricks
  // adds the map's max_surfels to the cloud's capacity itself (cloudCapacity()).
  static Result<FrameFoveator> create(const pipeline::PipelineCapacity& capacity,
                                      const pipeline::FoveationConfig& config, const pipeline::DepthRange& range,
                                      const MapSettings& map = {}, int width = 640, int height = 480);
  // The points a cloud may hold for this source: the pixels, plus the map's
  // surfels for the map source without bricks, whose cloud carries the eye's
  // view of the map (what the foveated output must hold too). With bricks the
  // cloud is only the frame's points, as for the frame source.
  static std::size_t cloudCapacity(std::size_t pixels, const MapSettings& map) {
    return appendsMapToCloud(map) ? pixels + map.map.max_surfels : pixels;
  }
  static bool appendsMapToCloud(const MapSettings& map) { return map.source == FoveationSource::kMap && !map.delta; }
  // The map source with bricks: the cloud carries the frame's live points only.
  static bool streamsLiveOnly(const MapSettings& map) { return map.source == FoveationSource::kMap && map.delta; }
  // ... and map.max_live_points caps them, unless the preset keeps every point (FREF).
  static bool capsLivePoints(const MapSettings& map, pipeline::Preset preset) {
    return streamsLiveOnly(map) && preset != pipeline::Preset::kFRef;
  }

  const pipeline::map::PoseEstimator* poseEstimator() const { return mapper_ ? mapper_->poseEstimator() : nullptr; }

  // Takes a frame in. pyramid source: only keeps `frame`, which must stay valid
  // until foveate(). frame source: back-projects it into cloud()
  // (kCapacityExceeded for a frame larger than the capacity). map source: the
  // mapper poses it (with tracking: frame.T_world_cam becomes the tracker's) and
  // fuses it (a refused frame is counted in the map's counters; pose_valid
  // false is the pose source's "no pose for this stamp"), and puts the points
  // the map does not explain into cloud(); a frame not fused (refused, lost,
  // over the time budget) is back-projected whole.
  Status backproject(hal::RgbdFrame& frame, pipeline::BackprojectCounts& counts, bool pose_valid = true);
  // Makes `config` the foveation in use. The gaze policy hands out pointers to
  // its own configurations, so a pointer equal to the one in use means no change
  // (invalidate() forces the next call to apply, e.g. after the policy's
  // configuration was replaced in place). On error the previous one stays.
  Status use(const pipeline::FoveationConfig* config) {
    if (config == in_use_) return Status::ok();
    const pipeline::PyramidRule rule = pipeline::PyramidRule::fromAcuity(config->acuity);
    if (pyramid_) {
      if (Status s = rule.validate(); !s) return s;  // before anything changes
    }
    if (Status s = foveator_.setConfig(*config); !s) return s;
    if (pyramid_) pyramid_rule_ = rule;
    in_use_ = config;
    return Status::ok();
  }
  void invalidate() { in_use_ = nullptr; }
  // Foveates the cloud of the last backproject() (map source: with the map's
  // surfels the eye at gaze.origin_m sees appended first, afresh at each call).
  // Pyramid source: samples the frame of the last backproject() (stats' regions
  // are the pyramid's levels, 0 = pixels; sample_ns its time).
  Status foveate(const pipeline::Gaze& gaze, pipeline::FoveatedCloud& out, pipeline::FoveationStats& stats);

  // Bricks (streamsBricks() only): Mapper::planBricks for the eye at `gaze`,
  // the batch's points relative to the cloud's origin; mapFigures().plan says
  // what went in. A brick put in the batch is taken as sent: one that then
  // never reaches the operator must be forgotten (forgetBrick, forgetBatch).
  Status planBricks(const pipeline::Gaze& gaze, double budget_bytes, double live_bytes,
                    pipeline::map::BrickBatch& batch);
  bool streamsBricks() const { return mapper_ && mapper_->output() == pipeline::map::MapOutput::kBricks; }
  // The operator does not hold `brick` (lost, evicted): due again.
  void forgetBrick(uint16_t brick) {
    if (mapper_) mapper_->forgetBrick(brick);
  }
  // A version of `brick` with more parts than a version may have: planned a
  // level coarser from now on.
  void brickTooLarge(uint16_t brick) {
    if (mapper_) mapper_->brickTooLarge(brick);
  }
  // A batch whose bricks never went out (a dropped frame): all due again.
  void forgetBatch(const pipeline::map::BrickBatch& batch) {
    if (mapper_) mapper_->forgetBatch(batch);
  }
  // The operator holds nothing (a new session).
  void forgetAllBricks() {
    if (mapper_) mapper_->forgetAll();
  }
  // A batch sized for this stage (empty when it does not stream bricks).
  pipeline::map::BrickBatch makeBrickBatch() const;

  FoveationSource source() const { return source_; }
  const pipeline::PointCloud& cloud() const { return cloud_; }
  pipeline::Foveator& foveator() { return foveator_; }
  const pipeline::DepthRange& range() const { return range_; }
  // The map source's mapper, map and figures for the last frame (null / zero otherwise).
  const pipeline::map::Mapper* mapper() const { return mapper_.get(); }
  // The map itself: with a fusion thread, only on it or after it stopped
  // (mapStatus() from the others).
  const pipeline::map::SurfelMap* map() const { return mapper_ ? &mapper_->map() : nullptr; }
  pipeline::map::MapperStatus mapStatus() { return mapper_ ? mapper_->status() : pipeline::map::MapperStatus{}; }
  bool fusionThread() const { return mapper_ && mapper_->fusionThread(); }
  // The fusion thread's step (Mapper::fuseSubmitted) and, on the foveation
  // thread, the figures of the fusion it finished last (Mapper::takeFused).
  bool fuseSubmitted() { return mapper_ && mapper_->fuseSubmitted(); }
  bool takeFused(pipeline::map::MapperFrame& out) { return mapper_ && mapper_->takeFused(out); }
  // The last frame's (backproject() the frame's, foveate() the eye's, planBricks() the plan).
  const MapFrameFigures& mapFigures() const { return map_figures_; }
  // Frames the time budget left unfused so far (map source).
  uint64_t fusionSkipped() const { return mapper_ ? mapper_->fusionSkipped() : 0; }
  bool hasFusionBudget() const { return mapper_ && mapper_->hasFusionBudget(); }
  // Bytes the map source allocated, by part (all 0 for the other sources).
  pipeline::map::MapperMemory mapMemory() const { return mapper_ ? mapper_->memory() : pipeline::map::MapperMemory{}; }
  std::size_t mapMemoryBytes() const { return mapMemory().total(); }
  const pipeline::map::MapDelta* mapDelta() const { return mapper_ ? mapper_->delta() : nullptr; }
  // Bytes the pyramid source allocated (0 for the others).
  std::size_t pyramidMemoryBytes() const { return pyramid_ ? pyramid_->memoryBytes() : 0; }

 private:
  Status foveatePyramid(const pipeline::Gaze& gaze, pipeline::FoveatedCloud& out, pipeline::FoveationStats& stats);
  pipeline::map::LiveSelection liveSelection(const hal::RgbdFrame& frame) const;

  FrameFoveator(pipeline::Foveator foveator, const pipeline::PipelineCapacity& capacity,
                const pipeline::DepthRange& range)
      : foveator_(std::move(foveator)),
        backprojector_(capacity.threads, capacity.kernels),
        cloud_(capacity.max_points),
        range_(range) {}

  pipeline::Foveator foveator_;
  pipeline::Backprojector backprojector_;
  pipeline::PointCloud cloud_;
  pipeline::DepthRange range_;
  const pipeline::FoveationConfig* in_use_ = nullptr;
  FoveationSource source_ = FoveationSource::kFrame;
  std::unique_ptr<pipeline::map::Mapper> mapper_;  // map source
  std::size_t max_frame_brick_points_ = 0, max_frame_bricks_ = 0;
  MapFrameFigures map_figures_;
  pipeline::Gaze last_gaze_;  // map source: the last foveate()'s, unit (has_gaze_)
  bool has_gaze_ = false;
  std::unique_ptr<pipeline::PyramidSampler> pyramid_;  // pyramid source
  pipeline::PyramidRule pyramid_rule_;
  const hal::RgbdFrame* frame_ = nullptr;  // pyramid source: the last backproject()'s
};

}  // namespace fovea::firmware
