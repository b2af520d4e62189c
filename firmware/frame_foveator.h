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
#include "pipeline/map/brick_batch.h"
#include "pipeline/map/eye_view.h"
#include "pipeline/map/fusion_budget.h"
#include "pipeline/map/map_delta.h"
#include "pipeline/map/pose_tracking.h"
#include "pipeline/map/surfel_map.h"
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
  // Fusion's average time a frame at most (pipeline/map/fusion_budget.h); the
  // frames it does not fuse go whole, counted. 0: every frame is fused.
  double fuse_budget_ms = 0.0;
  // The map tracks the camera (camera.pose.source = track, track+X; map source
  // only): pipeline/map/pose_tracking.h, docs/tracking.md.
  pipeline::map::PoseTracking tracking = pipeline::map::PoseTracking::kOff;
  pipeline::map::TrackerConfig tracker;
};

// Bytes a point is estimated to take on the wire, chunk headers included
// (docs/protocol-chunks.md: about 4), for planning a frame's bricks within
// the budget before they are encoded; the pacing holds the real budget.
inline constexpr double kWireBytesPerPointEstimate = 4.5;

// The points a frame's bricks can carry at most: what the link's largest
// budget pays for in one frame period at kWireBytesPerPointEstimate (92 593
// at 12.5 MB/s and 30 fps), and at least one brick whole.
std::size_t frameBrickPoints(double max_budget_bytes_per_s, double fps, std::size_t max_brick_surfels);

// What the map did with the last frame (map source only).
struct MapFrameFigures {
  pipeline::map::TrackStats track;  // with tracking (trackPose())
  pipeline::map::FuseStats fuse;
  pipeline::map::EyeViewStats eye;
  bool fusion_skipped = false;  // the time budget left the frame unfused (fuse is then not filled)
  bool fused() const { return !fusion_skipped && fuse.outcome == pipeline::map::FuseOutcome::kFused; }
  uint32_t frame_points = 0;  // the frame's points in the cloud: unexplained (fused) or all (refused, skipped)
  pipeline::map::MapDeltaStats delta;  // planBricks()'s
  uint32_t bricks_planned = 0;         // into the batch
  uint32_t brick_points = 0;
  uint32_t bricks_waiting = 0;         // due but not in the batch (the budget): they wait
  uint32_t fovea_bricks_waiting = 0;   // ... of them the fovea's
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

  // With tracking (MapSettings::tracking), before backproject(): sets
  // frame.T_world_cam to the tracker's pose (outside_pose_valid: whether the
  // frame's own pose, from the pose source, is usable, as the prior with
  // track+X). Returns whether the frame may be fused: false when the tracker
  // is lost (the frame then carries the last good or the outside pose, to be
  // shown beside the map). Without tracking: outside_pose_valid, frame untouched.
  bool trackPose(hal::RgbdFrame& frame, bool outside_pose_valid);
  const pipeline::map::PoseEstimator* poseEstimator() const { return poser_.get(); }

  // Takes a frame in. pyramid source: only keeps `frame`, which must stay valid
  // until foveate(). frame source: back-projects it into cloud()
  // (kCapacityExceeded for a frame larger than the capacity). map source: fuses
  // it (a refused frame is counted in the map's counters; pose_valid false is
  // the pose source's "no pose for this stamp") and puts the points the map does
  // not explain into cloud(); a frame the map refused is back-projected whole.
  Status backproject(const hal::RgbdFrame& frame, pipeline::BackprojectCounts& counts, bool pose_valid = true);
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

  // Bricks (streamsBricks() only). Fills `batch` (cleared first) with the
  // bricks due for the eye at `gaze`, in the plan's order, while the estimated
  // bytes fit `budget_bytes`; `live_bytes` (the frame's live points) are
  // charged after the fovea's bricks, so those go first. Each brick put in the
  // batch is taken as sent (MapDelta::markSent): a brick that then never
  // reaches the operator must be forgotten (forgetBrick, forgetBatch).
  Status planBricks(const pipeline::Gaze& gaze, double budget_bytes, double live_bytes,
                    pipeline::map::BrickBatch& batch);
  bool streamsBricks() const { return delta_ != nullptr; }
  // The operator does not hold `brick` (lost, evicted): due again.
  void forgetBrick(uint16_t brick);
  // A batch whose bricks never went out (a dropped frame): all due again.
  void forgetBatch(const pipeline::map::BrickBatch& batch);
  // The operator holds nothing (a new session).
  void forgetAllBricks();
  // A batch sized for this stage (empty when it does not stream bricks).
  pipeline::map::BrickBatch makeBrickBatch() const;

  FoveationSource source() const { return source_; }
  const pipeline::PointCloud& cloud() const { return cloud_; }
  pipeline::Foveator& foveator() { return foveator_; }
  const pipeline::DepthRange& range() const { return range_; }
  // The map source's map and its figures for the last frame (null / zero otherwise).
  const pipeline::map::SurfelMap* map() const { return map_.get(); }
  // The last frame's (trackPose() sets .track, backproject() the rest).
  const MapFrameFigures& mapFigures() const { return map_figures_; }
  // Frames the time budget left unfused so far (map source).
  uint64_t fusionSkipped() const { return budget_.skipped(); }
  bool hasFusionBudget() const { return budget_.budgetNs() > 0; }
  // Bytes the map source allocated, by part (all 0 for the other sources).
  struct MapMemory {
    pipeline::map::SurfelMapMemory map;
    std::size_t eye = 0;      // the eye's depth buffer (without bricks)
    std::size_t delta = 0;    // with bricks: what the operator holds, the plan, the brick sampler
    std::size_t tracker = 0;  // with tracking: the pyramids
    std::size_t total() const { return map.total() + eye + delta + tracker; }
  };
  MapMemory mapMemory() const {
    MapMemory m;
    if (!map_) return m;
    m.map = map_->memoryParts();
    m.eye = eye_ ? eye_->memoryBytes() : 0;
    m.delta = delta_ ? delta_->memoryBytes() + bricks_->memoryBytes() : 0;
    m.tracker = poser_ ? poser_->memoryBytes() : 0;
    return m;
  }
  std::size_t mapMemoryBytes() const { return mapMemory().total(); }
  const pipeline::map::MapDelta* mapDelta() const { return delta_.get(); }
  // Bytes the pyramid source allocated (0 for the others).
  std::size_t pyramidMemoryBytes() const { return pyramid_ ? pyramid_->memoryBytes() : 0; }

 private:
  Status foveatePyramid(const pipeline::Gaze& gaze, pipeline::FoveatedCloud& out, pipeline::FoveationStats& stats);

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
  std::unique_ptr<pipeline::map::SurfelMap> map_;
  std::unique_ptr<pipeline::map::EyeView> eye_;          // map source without bricks
  std::unique_ptr<pipeline::map::MapDelta> delta_;        // map source with bricks
  std::unique_ptr<pipeline::map::BrickSampler> bricks_;
  std::unique_ptr<pipeline::map::PoseEstimator> poser_;  // map source with tracking
  std::size_t max_frame_brick_points_ = 0, max_frame_bricks_ = 0;
  MapFrameFigures map_figures_;
  pipeline::map::FusionBudget budget_;
  std::unique_ptr<pipeline::PyramidSampler> pyramid_;  // pyramid source
  pipeline::PyramidRule pyramid_rule_;
  const hal::RgbdFrame* frame_ = nullptr;  // pyramid source: the last backproject()'s
};

}  // namespace fovea::firmware
