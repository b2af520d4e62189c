// The map's work in one object (issue 41, part 6; docs/map.md, "The mapper"):
// the surfel map, the camera's tracking against it, fusion's time budget and
// what the operator gets of it. One call a frame (addFrame: pose, then fuse)
// and, for an operator who keeps the map, one plan a gaze (planBricks). The
// service's foveation stage and `fovead run` (firmware/frame_foveator.h),
// `fovead map` and the tracking bench each drive one.
//
// What the operator gets (MapperConfig::output):
//  - kNone: nothing (`fovead map`, the benches: the map is the product);
//  - kEyeView: the map's settled surfels the eye can see, appended to the
//    frame's cloud every frame (pipeline/map/eye_view.h);
//  - kBricks: the operator keeps the map; planBricks() lists the bricks its eye
//    needs and lacks (pipeline/map/map_delta.h) and samples them into a batch
//    (pipeline/map/brick_batch.h).
//
// Fusion on a thread of its own (MapperConfig::fusion_thread; issue 41, part
// 3): addFrame() poses the frame and hands it to fuseSubmitted(), which
// another thread calls, when that thread is idle (else the frame is left
// unfused, counted); either way the frame goes out at once, thinned by the
// last fused view (collectLive). The map is shared through a MapGate
// (map_gate.h): fusion holds it and lets the planner and the view through at
// its safe points, so a new gaze is planned without waiting for the fusion in
// flight; the tracker's model, which fusion rebuilds after each frame, has a
// lock of its own, so that tracking a frame does not hold fusion up. map() is
// then for the fusion thread alone, or for after it stopped; addFrame()'s
// thread reads status().
//
// Memory: everything is sized by create() from the configuration; addFrame(),
// fuseSubmitted(), appendVisible() and planBricks() allocate nothing.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/partition.h"
#include "pipeline/map/brick_batch.h"
#include "pipeline/map/explained_view.h"
#include "pipeline/map/eye_view.h"
#include "pipeline/map/fusion_budget.h"
#include "pipeline/map/map_delta.h"
#include "pipeline/map/map_gate.h"
#include "pipeline/map/pose_tracking.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline::map {

enum class MapOutput : uint8_t { kNone, kEyeView, kBricks };

struct MapperConfig {
  // Its max_width x max_height size the tracker too.
  SurfelMapConfig map;
  PoseTracking tracking = PoseTracking::kOff;
  TrackerConfig tracker;
  // Fusion's average time a frame at most (fusion_budget.h); 0: every frame.
  double fuse_budget_ms = 0.0;
  MapOutput output = MapOutput::kNone;
  EyeViewConfig eye;               // kEyeView
  MapDeltaConfig delta;            // kBricks
  std::size_t max_brick_surfels = 1u << 16;  // kBricks: a brick's settled surfels sampled at most
  // Fuse on another thread, which calls fuseSubmitted() (the service's map
  // thread); off: addFrame() fuses on the caller's.
  bool fusion_thread = false;
};

// What addFrame() did with a frame.
struct MapperFrame {
  TrackStats track;             // with tracking
  FuseStats fuse;               // unless fusion_skipped
  bool pose_usable = false;     // the pose source's or the tracker's pose may be fused
  bool fusion_skipped = false;  // the time budget, or a busy fusion thread, left the frame unfused
  bool handed_off = false;      // fusion_thread: given to the fusion thread, fused later
  bool fused() const { return !fusion_skipped && !handed_off && fuse.outcome == FuseOutcome::kFused; }
};

// What collectLive() did with a frame.
struct LiveFigures {
  LivePointStats points;
  uint32_t valid = 0;                   // the frame's valid pixels
  uint32_t explained_by_last_view = 0;  // not fused now: the valid pixels the last fused view explained, left out
};

// What planBricks() put in the batch.
struct MapperPlan {
  MapDeltaStats delta;
  uint32_t bricks_planned = 0;        // into the batch
  std::array<uint32_t, kBrickNeedCount> planned_by_need = {};  // ... of them by why they were due (BrickNeed)
  uint32_t brick_points = 0;
  uint32_t bricks_waiting = 0;        // due but not in the batch (the budget): they wait
  uint32_t fovea_bricks_waiting = 0;  // ... of them the fovea's
};

// The map's size and counters, as of the reader's look (status()).
struct MapperStatus {
  std::size_t surfels = 0;
  SurfelMapCounters counters;
  uint64_t fusion_busy = 0;  // fusion_thread: frames left unfused because it was busy
};

// What create() allocated, by part.
struct MapperMemory {
  SurfelMapMemory map;
  std::size_t eye = 0;      // kEyeView: the eye's depth buffer
  std::size_t delta = 0;    // kBricks: what the operator holds, the plan, the brick sampler
  std::size_t view = 0;     // the last fused frame's explained depths (output other than kNone), the live points' cone bits
  std::size_t tracker = 0;  // with tracking: the pyramids
  std::size_t handoff = 0;  // fusion_thread: the frame handed to it
  std::size_t total() const { return map.total() + eye + delta + view + tracker + handoff; }
};

// Bytes a point is estimated to take on the wire, chunk headers included
// (docs/protocol-chunks.md: about 4), for planning a frame's bricks within
// the budget before they are encoded; the pacing holds the real budget.
inline constexpr double kWireBytesPerPointEstimate = 4.5;

class Mapper {
 public:
  static Result<Mapper> create(const MapperConfig& config);

  // Poses `frame` (frame.T_world_cam: with tracking, the tracker's pose, or
  // when it is lost the outside or last good pose, to be shown by) and fuses
  // it when the pose may be fused and the time budget allows. outside_pose_valid:
  // the pose source had a pose for the frame's stamp. Returns out.fused().
  // fusion_thread: hands the frame to it instead when it is idle (out.handed_off)
  // and returns false.
  bool addFrame(hal::RgbdFrame& frame, bool outside_pose_valid, MapperFrame& out);

  // fusion_thread, on that thread: fuses the frame addFrame() handed off, if
  // any (false: none waited). Never allocates.
  bool fuseSubmitted();
  // fusion_thread: the figures of the newest fusion finished since the last
  // call (false: none finished). The time budget is charged here, with every
  // fusion finished since.
  bool takeFused(MapperFrame& out);

  // The frame's live points (live_points.h), the frame addFrame() just took
  // (`frame` its figures), into `cloud` (cleared; its origin must be the
  // frame's camera position): fused now, the pixels no settled surfel
  // explains (with bricks and MapDeltaConfig::explain_held_only, no surfel
  // the operator holds); posed and left unfused by the time budget, a busy fusion thread
  // or the hand-off, the valid pixels the last fused view does not explain
  // (ExplainedView), which the operator has from the map; refused or lost,
  // every valid pixel. Output kNone keeps no view: every valid pixel.
  Status collectLive(const hal::RgbdFrame& frame, const MapperFrame& figures, const DepthRange& range,
                     const LiveSelection& selection, PointCloud& cloud, LiveFigures& out);
  // kEyeView: appends the settled surfels an eye at `eye_m` sees (EyeView::appendVisible).
  void appendVisible(const Eigen::Vector3d& eye_m, PointCloud& cloud, EyeViewStats& stats);

  // kBricks. Fills `batch` (cleared first, origin `origin_m`) with the bricks
  // due for the eye at `gaze`, in the plan's order, while the estimated bytes
  // fit `budget_bytes`; `live_bytes` (the frame's live points) are charged after
  // the fovea's bricks, so those go first. A brick put in the batch is taken as
  // sent: one that never reaches the operator must be forgotten.
  Status planBricks(const Gaze& gaze, double budget_bytes, double live_bytes, const Eigen::Vector3d& origin_m,
                    BrickBatch& batch, MapperPlan& plan);
  // The operator does not hold `brick` (lost, evicted), the batch's bricks
  // (never sent), or anything (a new session): due again.
  void forgetBrick(uint16_t brick);
  // The version of `brick` last planned had more parts than a version may
  // have: planned a level coarser from now on (MapDelta::tooLarge).
  void brickTooLarge(uint16_t brick);
  void forgetBatch(const BrickBatch& batch);
  void forgetAll();

  MapOutput output() const { return output_; }
  const SurfelMap& map() const { return *map_; }
  MapperStatus status();  // addFrame()'s thread
  bool fusionThread() const { return handoff_ != nullptr; }
  const PoseEstimator* poseEstimator() const { return poser_.get(); }
  const MapDelta* delta() const { return delta_.get(); }
  const BrickSampler* sampler() const { return sampler_.get(); }
  uint64_t fusionSkipped() const { return budget_.skipped(); }  // by the time budget
  bool hasFusionBudget() const { return budget_.budgetNs() > 0; }
  MapperMemory memory() const;

 private:
  Mapper() = default;
  // Fuses `frame` here (addFrame(), or the fusion thread's fuseSubmitted()),
  // without its moving pixels (null: none).
  void fuse(hal::RgbdFrame& frame, const uint8_t* moving, MapperFrame& out);
  // The tracker's moving pixels of `frame`, the frame it just posed (null:
  // no tracking, or none for a frame of that size).
  const uint8_t* movingPixels(const hal::RgbdFrame& frame) const;
  void pinHeldBricks();  // planBricks()'s, under the gate: the map keeps what the operator may draw

  // fusion_thread's hand-off: the frame and the state, which addFrame() moves
  // from idle to submitted and fuseSubmitted() to fusing and back to idle.
  enum : uint8_t { kIdle, kSubmitted, kFusing };
  struct HandOff {
    hal::RgbdFrame frame;
    std::vector<uint8_t> moving;  // its moving pixels, when has_moving
    bool has_moving = false;
    bool pose_usable = false;
    std::atomic<uint8_t> state{kIdle};
    MapperFrame done;          // the last fusion's figures (under the gate)
    uint64_t fused = 0;        // ... how many finished (under the gate)
    uint64_t taken = 0;        // ... of them seen by takeFused()
    int64_t untaken_ns = 0;    // ... the time of those not yet seen (under the gate)
    uint64_t busy = 0;         // frames it was busy for (addFrame's thread)
    std::size_t bytes = 0;     // the frame's depth and colour, and the moving pixels
  };

  MapOutput output_ = MapOutput::kNone;
  std::unique_ptr<SurfelMap> map_;
  std::unique_ptr<PoseEstimator> poser_;    // with tracking
  std::unique_ptr<EyeView> eye_;            // kEyeView
  std::unique_ptr<MapDelta> delta_;         // kBricks
  std::unique_ptr<BrickSampler> sampler_;   // kBricks
  std::unique_ptr<ExplainedView> view_;     // output other than kNone
  std::unique_ptr<LiveCollector> live_;     // collectLive()'s (a bit a pixel)
  FusionBudget budget_;
  std::unique_ptr<MapGate> gate_;    // always (uncontended without a fusion thread)
  // The tracker: posing a frame (addFrame's thread) against building its model
  // after a fusion (the fusion thread, which holds the gate then: gate first).
  std::unique_ptr<std::mutex> tracker_lock_;
  std::unique_ptr<HandOff> handoff_;  // fusion_thread
};

}  // namespace fovea::pipeline::map
