#include "pipeline/map/mapper.h"

#include <algorithm>
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
  if (mapper.delta_ && config.delta.explain_held_only) mapper.map_->setHeldFrames(mapper.delta_->heldFrames());
  mapper.live_ = std::make_unique<LiveCollector>(config.map.max_width, config.map.max_height);
  if (config.output != MapOutput::kNone) {
    Result<ExplainedView> view =
        ExplainedView::create(config.map.max_width, config.map.max_height, config.map.depth_tolerance_sigmas,
                              config.map.kernels);
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
  mapper.gate_ = std::make_unique<MapGate>();
  mapper.tracker_lock_ = std::make_unique<std::mutex>();
  if (config.fusion_thread) {
    mapper.handoff_ = std::make_unique<HandOff>();
    mapper.handoff_->frame = hal::RgbdFrame(config.map.max_width, config.map.max_height);
    const std::size_t pixels = static_cast<std::size_t>(config.map.max_width) * config.map.max_height;
    if (mapper.poser_) mapper.handoff_->moving.assign(pixels, 0);  // the tracker's moving pixels
    mapper.handoff_->bytes = pixels * (2 + 3) + mapper.handoff_->moving.size();
    mapper.map_->setGate(mapper.gate_.get());
  }
  return mapper;
}

bool Mapper::addFrame(hal::RgbdFrame& frame, bool outside_pose_valid, MapperFrame& out) {
  out = {};
  if (poser_) {
    std::lock_guard<std::mutex> hold(*tracker_lock_);  // the fusion thread builds the tracker's model
    out.pose_usable = poser_->poseFrame(frame, outside_pose_valid, out.track);
  } else {
    out.pose_usable = outside_pose_valid;
  }
  if (!budget_.admit()) {
    out.fusion_skipped = true;
    return false;
  }
  const uint8_t* moving = movingPixels(frame);
  if (!handoff_) {
    MapReadLock hold(*gate_);
    fuse(frame, moving, out);
    budget_.spent(out.fuse.fuse_ns);
    return out.fused();
  }
  HandOff& h = *handoff_;
  if (h.state.load(std::memory_order_acquire) != kIdle) {
    out.fusion_skipped = true;
    ++h.busy;
    return false;
  }
  h.frame = frame;  // the same size as created: the vectors keep their memory
  h.has_moving = moving != nullptr;
  if (moving != nullptr) std::copy_n(moving, frame.pixelCount(), h.moving.begin());
  h.pose_usable = out.pose_usable;
  h.state.store(kSubmitted, std::memory_order_release);
  out.handed_off = true;
  return false;
}

const uint8_t* Mapper::movingPixels(const hal::RgbdFrame& frame) const {
  if (!poser_) return nullptr;
  const MovingPixels& moving = poser_->tracker().moving();
  return moving.width() == frame.width() && moving.height() == frame.height() ? moving.mask() : nullptr;
}

void Mapper::fuse(hal::RgbdFrame& frame, const uint8_t* moving, MapperFrame& out) {
  map_->fuse(frame, out.fuse, out.pose_usable, moving);
  if (view_ && out.fused()) view_->capture(frame, map_->explainedPixels());
  if (poser_ && out.fused()) {
    const int64_t t0 = monotonicNs();
    std::lock_guard<std::mutex> hold(*tracker_lock_);
    poser_->fused(frame, *map_, moving);
    out.track.model_ns = monotonicNs() - t0;
  }
}

bool Mapper::fuseSubmitted() {
  if (!handoff_) return false;
  HandOff& h = *handoff_;
  uint8_t submitted = kSubmitted;
  if (!h.state.compare_exchange_strong(submitted, kFusing, std::memory_order_acq_rel)) return false;
  {
    MapReadLock hold(*gate_);
    MapperFrame out;
    out.pose_usable = h.pose_usable;
    fuse(h.frame, h.has_moving ? h.moving.data() : nullptr, out);
    h.done = out;
    ++h.fused;
    h.untaken_ns += out.fuse.fuse_ns;
  }
  h.state.store(kIdle, std::memory_order_release);
  return true;
}

bool Mapper::takeFused(MapperFrame& out) {
  if (!handoff_) return false;
  MapReadLock hold(*gate_);
  if (handoff_->taken == handoff_->fused) return false;
  handoff_->taken = handoff_->fused;
  out = handoff_->done;
  budget_.spent(handoff_->untaken_ns);
  handoff_->untaken_ns = 0;
  return true;
}

Status Mapper::collectLive(const hal::RgbdFrame& frame, const MapperFrame& figures, const DepthRange& range,
                           const LiveSelection& selection, PointCloud& cloud, LiveFigures& out) {
  out = {};
  cloud.has_color = frame.has_rgb;
  const int w = frame.width(), h = frame.height();
  if (figures.fused()) {
    out.valid = figures.fuse.pixels_valid;
    return live_->collect([&](LivePointSink& sink) { (void)map_->visitUnexplained(frame, cloud.origin_m, sink); },
                          selection, w, h, cloud, out.points);
  }
  if (Status s = validateFrame(frame); !s) return s;
  if (Status s = range.validate(); !s) return s;
  const PixelBackprojection rule(frame, range);
  // The frame's counts are those of the last unfiltered pass, which saw every pixel.
  if (view_ && figures.pose_usable && (figures.fusion_skipped || figures.handed_off)) {
    MapReadLock hold(*gate_);  // the fusion thread captures the view
    return live_->collect(
        [&](LivePointSink& sink) {
          ExplainedView::VisitCounts counts;
          view_->visitUnexplained(frame, rule, sink, counts);
          if (!sink.filtered()) out.valid = counts.valid, out.explained_by_last_view = counts.explained;
        },
        selection, w, h, cloud, out.points);
  }
  return live_->collect(
      [&](LivePointSink& sink) {
        uint32_t valid = 0;
        rule.forEachPoint(frame, [&](int u, int v, std::size_t i, const Eigen::Vector3f& p) {
          ++valid;
          if (sink.skips(u, v)) return true;
          return sink.take(u, v, p, pixelRgb(frame, i));
        });
        if (!sink.filtered()) out.valid = valid;
      },
      selection, w, h, cloud, out.points);
}

MapperStatus Mapper::status() {
  MapperStatus s;
  MapReadLock hold(*gate_);
  s.surfels = map_->size();
  s.counters = map_->counters();
  s.fusion_busy = handoff_ ? handoff_->busy : 0;
  return s;
}

void Mapper::appendVisible(const Eigen::Vector3d& eye_m, PointCloud& cloud, EyeViewStats& stats) {
  if (!eye_) return;
  MapReadLock hold(*gate_);
  eye_->appendVisible(*map_, eye_m, cloud, stats);
}

Status Mapper::planBricks(const Gaze& gaze, double budget_bytes, double live_bytes, const Eigen::Vector3d& origin_m,
                          BrickBatch& batch, MapperPlan& plan) {
  batch.clear(origin_m);
  plan = {};
  if (!delta_) return {ErrorCode::kInvalidArgument, "bricks: the mapper does not stream the map's bricks"};
  MapReadLock hold(*gate_);  // the plan and the sampling read the map
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
  pinHeldBricks();
  return Status::ok();
}

// What the operator may still draw keeps its brick: fusion gives only an
// unpinned empty brick to a new place. Here under the gate, so fusion sees the
// pins whole; forget() between plans only unpins, which waits for the next plan.
void Mapper::pinHeldBricks() {
  const std::size_t bricks = map_->brickCount();
  for (std::size_t b = 0; b < bricks; ++b) {
    const auto brick = static_cast<uint16_t>(b);
    map_->pinBrick(brick, delta_->holds(brick));
  }
}

void Mapper::forgetBrick(uint16_t brick) {
  if (delta_ && brick < map_->config().max_bricks) delta_->forget(brick);
}

void Mapper::brickTooLarge(uint16_t brick) {
  if (delta_ && brick < map_->config().max_bricks) delta_->tooLarge(brick);
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
  m.view = (view_ ? view_->memoryBytes() : 0) + live_->memoryBytes();
  m.handoff = handoff_ ? handoff_->bytes : 0;
  return m;
}

}  // namespace fovea::pipeline::map
