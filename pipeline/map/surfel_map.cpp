#include "pipeline/map/surfel_map.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <string>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include "core/clock.h"
#include "pipeline/map/lowest_keys.h"

namespace fovea::pipeline::map {

namespace {

constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
constexpr std::size_t kNormalCosBuckets = 1024;  // the normal tolerance's table over the depth range

}  // namespace

Status SurfelMapConfig::validate() const {
  auto bad = [](const char* what) { return Status(ErrorCode::kInvalidArgument, std::string("map.") + what); };
  if (max_surfels == 0 || max_surfels > SurfelLinks::kMaxSlots) {
    return bad("max_surfels: must be in [1, 16777215] (the brick lists link slots in 24 bits)");
  }
  if (max_bricks == 0 || max_bricks > 65535) return bad("max_bricks: must be in [1, 65535] (a surfel names its brick in 16 bits)");
  if (!(std::isfinite(brick_size_m) && brick_size_m >= 0.05 && brick_size_m <= 16.0)) {
    return bad("brick_size_m: must be in [0.05, 16] m");
  }
  if (Status s = depth.validate(); !s) return s;
  if (!(std::isfinite(depth_tolerance_sigmas) && depth_tolerance_sigmas > 0.0)) {
    return bad("depth_tolerance_sigmas: must be > 0");
  }
  if (!(normal_tolerance_deg > 0.0 && normal_tolerance_deg <= 180.0)) return bad("normal_tolerance_deg: must be in (0, 180]");
  if (!(confidence_cap >= 1.0 && confidence_cap <= 255.0)) return bad("confidence_cap: must be in [1, 255]");
  if (!(stable_confidence > 0.0 && stable_confidence <= confidence_cap)) {
    return bad("stable_confidence: must be in (0, confidence_cap]");
  }
  if (!(std::isfinite(carve_weight) && carve_weight >= 0.0)) return bad("carve_weight: must be >= 0");
  if (!(max_pose_jump_m > 0.0)) return bad("max_pose_jump_m: must be > 0");
  if (max_width <= 2 || max_height <= 2 || max_width > 8192 || max_height > 8192) {
    return bad("max_width, max_height: must be in [3, 8192]");
  }
  return Status::ok();
}

std::string_view fuseOutcomeName(FuseOutcome outcome) {
  switch (outcome) {
    case FuseOutcome::kFused: return "fused";
    case FuseOutcome::kRefusedSize: return "refused: frame larger than the map's scratch, or bad intrinsics";
    case FuseOutcome::kRefusedBadPose: return "refused: pose not finite or not a rotation";
    case FuseOutcome::kRefusedPoseJump: return "refused: pose jumped farther than max_pose_jump_m";
    case FuseOutcome::kRefusedClock: return "refused: stamp not after the last frame's";
    case FuseOutcome::kRefusedNoPose: return "refused: no pose for the frame";
  }
  return "?";
}

SurfelMap::SurfelMap(const SurfelMapConfig& config) : config_(config) {
  const std::size_t pixels = static_cast<std::size_t>(config.max_width) * config.max_height;
  surfels_.resize(config.max_surfels);
  key_histogram_.resize(kKeyHistogramSize);
  brick_keys_.resize(config.max_bricks);
  brick_table_ = GridTable(config.max_bricks);
  brick_cam_.resize(config.max_bricks);
  brick_visible_.resize(config.max_bricks);
  brick_head_.assign(config.max_bricks, kNoSurfel);
  brick_settled_.assign(config.max_bricks, 0);
  brick_changes_.assign(config.max_bricks, 0);
  brick_pinned_.assign(config.max_bricks, 0);
  links_.resize(config.max_surfels);
  pixel_capacity_ = pixels;
  vertex_z_.resize(pixels);
  weight_.resize(pixels);
  tables_ = VertexTables(config.max_width, config.max_height);
  index_map_ = IndexMap(config.max_width, config.max_height, kLateMaps * pixels);
  explained_.resize(pixels);
  normal_cos_.resize(kNormalCosBuckets);
}

Result<SurfelMap> SurfelMap::create(const SurfelMapConfig& config) {
  if (Status s = config.validate(); !s) return Result<SurfelMap>(s.code(), s.message());
  return SurfelMap(config);
}

std::size_t SurfelMap::memoryBytes() const {
  return memoryParts().total();
}

SurfelMapMemory SurfelMap::memoryParts() const {
  SurfelMapMemory m;
  m.pool = surfels_.capacity() * sizeof(Surfel) + links_.memoryBytes();
  m.bricks = brick_keys_.capacity() * sizeof(BrickKey) + brick_table_.memoryBytes() +
             brick_cam_.capacity() * sizeof(Eigen::Vector3f) +
             (brick_visible_.capacity() + brick_head_.capacity() + brick_settled_.capacity() + brick_changes_.capacity()) * sizeof(uint32_t) +
             brick_pinned_.capacity();
  m.pixels = (vertex_z_.capacity() + weight_.capacity() + normal_cos_.capacity()) * sizeof(float) + tables_.memoryBytes() +
             index_map_.memoryBytes() + explained_.capacity();
  m.eviction = key_histogram_.capacity() * sizeof(uint32_t);
  return m;
}

void SurfelMap::clear() {
  std::fill(surfels_.begin(), surfels_.begin() + static_cast<std::ptrdiff_t>(high_water_), Surfel{});
  brick_table_.clear();
  std::fill(brick_head_.begin(), brick_head_.end(), kNoSurfel);
  std::fill(brick_settled_.begin(), brick_settled_.end(), 0);
  std::fill(brick_changes_.begin(), brick_changes_.end(), 0);
  std::fill(brick_pinned_.begin(), brick_pinned_.end(), uint8_t{0});
  reuse_cursor_ = 0;
  reuse_failed_frame_ = 0;
  free_head_ = kNone;
  free_count_ = high_water_ = live_ = brick_count_ = 0;
  frame_ = settled_through_ = 0;
  have_last_ = false;
  fused_width_ = fused_height_ = 0;
  counters_ = {};
}

Eigen::Vector3d SurfelMap::brickOrigin(uint16_t brick) const {
  const BrickKey& k = brick_keys_[brick];
  return Eigen::Vector3d(k.x, k.y, k.z) * config_.brick_size_m;
}

Eigen::Vector3d SurfelMap::worldPosition(std::size_t slot) const {
  const Surfel& s = surfels_[slot];
  return brickOrigin(s.brick) + Eigen::Vector3d(s.x, s.y, s.z);
}

int SurfelMap::findOrAddBrick(const Eigen::Vector3d& p_world) {
  const Eigen::Vector3d cell = (p_world / config_.brick_size_m).array().floor();
  constexpr double kLimit = 2.0e9;  // inside int32
  if (!(std::abs(cell.x()) < kLimit && std::abs(cell.y()) < kLimit && std::abs(cell.z()) < kLimit)) return -1;
  const BrickKey key{static_cast<int32_t>(cell.x()), static_cast<int32_t>(cell.y()), static_cast<int32_t>(cell.z())};
  auto key_of = [this](uint32_t brick) -> const BrickKey& { return brick_keys_[brick]; };
  std::size_t at = brick_table_.probe(key, key_of);
  if (const int32_t brick = brick_table_.slotAt(at); brick >= 0) return brick;
  int brick = -1;
  if (brick_count_ < config_.max_bricks) {
    brick = static_cast<int>(brick_count_++);
  } else {
    brick = reuseEmptyBrick();
    if (brick < 0) return -1;
    at = brick_table_.probe(key, key_of);  // taking the old key out moved the table's entries
  }
  brick_keys_[brick] = key;
  brick_visible_[brick] = 0;  // not culled for this frame: nothing of it was rendered
  brick_table_.place(at, static_cast<uint32_t>(brick));
  return brick;
}

// Empty means no live surfel in its list (so none settled); a surfel freed
// this frame keeps its old brick number but is no longer live, and nothing
// reads a dead surfel's brick. The brick's per-frame culling is left as it was:
// fusion reads it only for live surfels, and the next frame's culling redoes it.
int SurfelMap::reuseEmptyBrick() {
  if (reuse_failed_frame_ == frame_) return -1;
  auto key_of = [this](uint32_t brick) -> const BrickKey& { return brick_keys_[brick]; };
  for (std::size_t n = 0; n < brick_count_; ++n) {
    const std::size_t b = reuse_cursor_;
    reuse_cursor_ = (reuse_cursor_ + 1) % brick_count_;
    if (brick_head_[b] != kNoSurfel || brick_pinned_[b] != 0) continue;
    brick_table_.erase(brick_keys_[b], key_of);
    ++counters_.bricks_reused;
    return static_cast<int>(b);
  }
  reuse_failed_frame_ = frame_;
  return -1;
}

FuseOutcome SurfelMap::checkFrame(const hal::RgbdFrame& frame) {
  const hal::CameraIntrinsics& k = frame.intrinsics;
  // The per-pixel kernels compute in float: finite and positive as floats too
  // (1e39 is infinite as a float, 1e-300 zero).
  auto positive = [](double x) { return std::isfinite(static_cast<float>(x)) && static_cast<float>(x) > 0.0f; };
  auto finite = [](double x) { return std::isfinite(static_cast<float>(x)); };
  const bool size_ok = frame.width() >= 3 && frame.height() >= 3 && frame.width() <= config_.max_width &&
                       frame.height() <= config_.max_height && k.width == frame.width() &&
                       k.height == frame.height() && positive(k.fx) && positive(k.fy) && finite(k.cx) &&
                       finite(k.cy) && positive(frame.depth_scale_m);
  if (!size_ok) return FuseOutcome::kRefusedSize;
  const Eigen::Matrix3d& R = frame.T_world_cam.R_world_cam;
  const Eigen::Vector3d& t = frame.T_world_cam.t_world_cam;
  if (!R.allFinite() || !t.allFinite() || !((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-3) ||
      !(R.determinant() > 0.0)) {
    return FuseOutcome::kRefusedBadPose;
  }
  if (have_last_ && frame.stamp_ns <= last_stamp_ns_) return FuseOutcome::kRefusedClock;
  const bool jumped = have_last_ && !((t - last_position_).norm() <= config_.max_pose_jump_m);
  // The next frame is measured against this one even when it is refused: a pose
  // source that relocalises loses one frame, not every frame after it.
  have_last_ = true;
  last_stamp_ns_ = frame.stamp_ns;
  last_position_ = t;
  return jumped ? FuseOutcome::kRefusedPoseJump : FuseOutcome::kFused;
}

FuseOutcome SurfelMap::fuse(const hal::RgbdFrame& frame, FuseStats& stats, bool pose_valid, const uint8_t* moving) {
  const int64_t start_ns = monotonicNs();
  stats = {};
  stats.outcome = pose_valid ? checkFrame(frame) : FuseOutcome::kRefusedNoPose;
  switch (stats.outcome) {
    case FuseOutcome::kFused: break;
    case FuseOutcome::kRefusedSize: ++counters_.refused_size; return stats.outcome;
    case FuseOutcome::kRefusedBadPose: ++counters_.refused_bad_pose; return stats.outcome;
    case FuseOutcome::kRefusedPoseJump: ++counters_.refused_pose_jump; return stats.outcome;
    case FuseOutcome::kRefusedClock: ++counters_.refused_clock; return stats.outcome;
    case FuseOutcome::kRefusedNoPose: ++counters_.refused_no_pose; return stats.outcome;
  }
  ++frame_;
  fused_pose_ = frame.T_world_cam;
  fused_width_ = frame.width();
  fused_height_ = frame.height();
  fused_stamp_ns_ = frame.stamp_ns;
  std::fill(explained_.begin(), explained_.begin() + static_cast<std::ptrdiff_t>(frame.pixelCount()), uint8_t{0});
  // The depths and weights first, for the render (a moving pixel weighs
  // nothing); the normals and radii after it, in the index map's scratch.
  int64_t t0 = monotonicNs();
  const uint32_t measured = computeDepths(frame);
  if (moving != nullptr) leaveOutMoving(frame.pixelCount(), moving, stats);
  int64_t t1 = monotonicNs();
  stats.vertices_ns = t1 - t0;
  if (measured > 0) {
    renderIndexMap(frame, stats);
    t0 = monotonicNs();
    stats.index_map_ns = t0 - t1;
    computeNormals(stats);
    t1 = monotonicNs();
    stats.vertices_ns += t1 - t0;
    t0 = t1;
    const std::size_t to_add = associate(frame, stats);
    t1 = monotonicNs();
    stats.associate_ns = t1 - t0;
    makeRoom(to_add, stats);
    addNew(frame, stats);
    stats.add_ns = monotonicNs() - t1;
  }
  settled_through_ = frame_;
  ++counters_.frames_fused;
  counters_.added += stats.added;
  counters_.evicted += stats.evicted;
  counters_.removed_carved += stats.removed_carved;
  counters_.removed_unstable += stats.removed_unstable;
  counters_.dropped_full += stats.dropped_full;
  counters_.dropped_no_brick += stats.dropped_no_brick;
  stats.fuse_ns = monotonicNs() - start_ns;
  return stats.outcome;
}

PixelMaps SurfelMap::pixelMaps() {
  return {vertex_z_.data(), lateMap(kNormalX), lateMap(kNormalY), lateMap(kNormalZ), lateMap(kRadius), weight_.data()};
}

uint32_t SurfelMap::computeDepths(const hal::RgbdFrame& frame) {
  vertex_params_ = prepareVertices(frame, rawDepthRange(config_.depth, frame.depth_scale_m), tables_);
  return pipeline::map::computeDepths(vertex_params_, vertex_z_.data(), weight_.data(), config_.kernels);
}

// After the render, whose planes they take: from computeDepths()'s depths.
void SurfelMap::computeNormals(FuseStats& stats) {
  stats.pixels_valid = pipeline::map::computeNormals(vertex_params_, pixelMaps(), config_.kernels);
}

// A moving pixel keeps its vertex, so that appendUnexplained() sends it and the
// index map's pass still sees through surfels in front of it (the space before
// a mover is free too), but it weighs nothing: the association's merges and
// carving and addNew() take only pixels of positive weight.
void SurfelMap::leaveOutMoving(std::size_t pixels, const uint8_t* moving, FuseStats& stats) {
  uint32_t left_out = 0;
  for (std::size_t i = 0; i < pixels; ++i) {
    if (!moving[i] || weight_[i] == 0.0f) continue;
    weight_[i] = 0.0f;
    ++left_out;
  }
  stats.pixels_moving = left_out;
}

void SurfelMap::detachSurfel(uint32_t slot) {
  Surfel& s = surfels_[slot];
  if (s.flags & kSurfelSettled) {
    --brick_settled_[s.brick];
    ++brick_changes_[s.brick];
  }
  const uint32_t next = links_.next(slot), prev = links_.prev(slot);
  if (prev == kNoSurfel) {
    brick_head_[s.brick] = next;
  } else {
    links_.setNext(prev, next);
  }
  if (next != kNoSurfel) links_.setPrev(next, prev);
  s.flags = 0;
  --live_;
}

void SurfelMap::removeSurfel(uint32_t slot) {
  detachSurfel(slot);
  pushFree(slot);
}

uint32_t SurfelMap::popFree() {
  const uint32_t slot = free_head_;
  free_head_ = links_.next(slot);
  --free_count_;
  return slot;
}

void SurfelMap::pushFree(uint32_t slot) {
  links_.setNext(slot, free_head_);
  free_head_ = slot;
  ++free_count_;
}

void SurfelMap::markSettled(Surfel& s) {
  if (s.flags & kSurfelSettled) return;
  s.flags |= kSurfelSettled;
  ++brick_settled_[s.brick];
  ++brick_changes_[s.brick];
}

bool SurfelMap::carveTo(uint32_t slot, float left, FuseStats& stats) {
  ++stats.carved;
  if (left > 0.0f) {
    surfels_[slot].confidence = encodeConfidence(left);
    return false;
  }
  ++stats.removed_carved;
  return true;
}

void SurfelMap::makeRoom(std::size_t wanted, FuseStats& stats) {
  const std::size_t available = free_count_ + (surfels_.size() - high_water_);
  if (available >= wanted) return;
  // Evict a sixteenth of the pool more than needed, so that a full map sorts
  // its surfels once every several frames rather than every frame.
  const std::size_t target = std::min(live_, wanted - available + surfels_.size() / 16);
  // Usefulness: the confidence, halved for every 30 frames unseen; the score's
  // float bits order like the float (it is >= 0). The `target` least useful go,
  // ties in slot order (lowest_keys.h: no per-surfel scratch).
  auto score_key = [this](std::size_t slot, uint32_t& key) {
    const Surfel& s = surfels_[slot];
    if (!(s.flags & kSurfelLive)) return false;
    const float unseen = static_cast<float>(frame_ - s.last_seen);
    key = std::bit_cast<uint32_t>(decodeConfidence(s.confidence) * std::exp2(-unseen / 30.0f));
    return true;
  };
  const KeyThreshold threshold = kthSmallestKey(high_water_, target, score_key, key_histogram_);
  std::size_t taken_at_key = 0;
  for (std::size_t slot = 0; slot < high_water_; ++slot) {
    uint32_t key = 0;
    if (score_key(slot, key) && threshold.takes(key, taken_at_key)) removeSurfel(static_cast<uint32_t>(slot));
  }
  stats.evicted += static_cast<uint32_t>(target);
}

SurfelMap::Added SurfelMap::addSurfel(const Eigen::Vector3d& p_world, const Eigen::Vector3f& n_world, float radius,
                                      float weight, const uint8_t* rgb) {
  if (free_count_ == 0 && high_water_ == surfels_.size()) return Added::kNoSurfel;
  const int brick = findOrAddBrick(p_world);
  if (brick < 0) return Added::kNoBrick;
  const uint32_t slot = free_count_ > 0 ? popFree() : static_cast<uint32_t>(high_water_++);
  Surfel& s = surfels_[slot];
  const Eigen::Vector3d rel = p_world - brickOrigin(static_cast<uint16_t>(brick));
  s.x = static_cast<float>(rel.x());
  s.y = static_cast<float>(rel.y());
  s.z = static_cast<float>(rel.z());
  setNormalAndRadius(s, n_world, radius);
  s.red = rgb[0];
  s.green = rgb[1];
  s.blue = rgb[2];
  s.confidence = encodeConfidence(weight);
  s.flags = kSurfelLive;
  s.brick = static_cast<uint16_t>(brick);
  s.first_seen = s.last_seen = frame_;
  const uint32_t head = brick_head_[s.brick];
  links_.setNext(slot, head);
  links_.setPrev(slot, kNoSurfel);
  if (head != kNoSurfel) links_.setPrev(head, slot);
  brick_head_[s.brick] = slot;
  if (weight >= config_.stable_confidence) {
    s.flags |= kSurfelStable;
    if (config_.settle_frames == 0) markSettled(s);
  }
  ++live_;
  return Added::kYes;
}

// The pixel's normal is noisy: its two differences span 2 kNormalReach pixels,
// z 2 kNormalReach / f metres, against the sensor's sigma(z) at each end, so its
// direction wanders by about atan(sigma(z) f / (kNormalReach z)) (26 degrees at
// 1 m, 48 at 3 m for f = 525 px). The tolerance is the configured one plus twice
// that, at most 85 degrees: at depth the test only tells a surface's front from
// its back. (With the configured 30 degrees alone, two thirds of the pixels of
// a static mock scene never merged: measured, frames 2 to 12.) A table over the
// depth range, made again only when the focal length changes: no trigonometry
// per pixel, none per frame.
void SurfelMap::updateNormalTolerance(float f_px) {
  if (f_px == normal_cos_f_px_) return;
  normal_cos_f_px_ = f_px;
  normal_cos_z_min_ = static_cast<float>(config_.depth.min_m);
  normal_cos_per_m_ =
      static_cast<float>(normal_cos_.size()) / static_cast<float>(config_.depth.max_m - config_.depth.min_m);
  const auto tolerance_rad = static_cast<float>(config_.normal_tolerance_deg * std::numbers::pi / 180.0);
  const auto z0 = static_cast<float>(config_.depth.min_m), z1 = static_cast<float>(config_.depth.max_m);
  const std::size_t n = normal_cos_.size();
  for (std::size_t b = 0; b < n; ++b) {
    const float z = std::max(z0 + (z1 - z0) * (static_cast<float>(b) + 0.5f) / static_cast<float>(n), 1e-3f);
    const float noise = std::atan(depthSigma(z) * f_px / (static_cast<float>(kNormalReach) * z));
    normal_cos_[b] = std::cos(std::min(tolerance_rad + 2.0f * noise, 85.0f * std::numbers::pi_v<float> / 180.0f));
  }
}

// associate()'s view of the frame and the map, but the batch's per-pixel
// pointers (associationBatch()).
AssociationFrame SurfelMap::associationFrame(const hal::RgbdFrame& frame) const {
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float));
  AssociationFrame f;
  for (int i = 0; i < 9; ++i) f.r[i] = static_cast<float>(frame.T_world_cam.R_world_cam(i / 3, i % 3));
  f.brick_cam = brick_cam_.data()->data();
  f.normal_cos = normal_cos_.data();
  f.normal_cos_size = static_cast<uint32_t>(normal_cos_.size());
  f.normal_cos_z_min = normal_cos_z_min_;
  f.normal_cos_per_m = normal_cos_per_m_;
  f.sigmas = static_cast<float>(config_.depth_tolerance_sigmas);
  f.confidence_cap = static_cast<float>(config_.confidence_cap);
  f.stable_confidence = static_cast<float>(config_.stable_confidence);
  return f;
}

// Points `f` at the batch from pixel i = (u, v) on (rgb: the frame's colour, null: none).
void SurfelMap::associationBatch(AssociationFrame& f, const uint8_t* rgb, std::size_t i, int u, int v) const {
  f.slot = index_map_.slots() + i;
  f.seen = index_map_.depths() + i;
  f.weight = weight_.data() + i;
  f.z = vertex_z_.data() + i;
  f.nx = lateMap(kNormalX) + i;
  f.ny = lateMap(kNormalY) + i;
  f.nz = lateMap(kNormalZ) + i;
  f.radius = lateMap(kRadius) + i;
  f.ray_u = tables_.ray_u.data() + kNormalReach + u;
  f.ray_v = tables_.ray_v[static_cast<std::size_t>(v)];
  f.rgb = rgb == nullptr ? nullptr : rgb + 3 * i;
}

// Pixel i's merge, planned in lane j, into surfel s (a merge's writes; the
// arithmetic is the plan's: association_plan.h).
void SurfelMap::applyMerge(Surfel& s, std::size_t i, std::size_t j, const AssociationPlan& plan) {
  s.x = plan.x[j];
  s.y = plan.y[j];
  s.z = plan.z[j];
  s.normal_radius = plan.normal_radius[j];
  s.red = static_cast<uint8_t>(plan.rgb[j]);
  s.green = static_cast<uint8_t>(plan.rgb[j] >> 8);
  s.blue = static_cast<uint8_t>(plan.rgb[j] >> 16);
  s.confidence = static_cast<uint16_t>(plan.confidence[j]);
  if (plan.bits[j] & AssociationPlan::kStable) {
    s.flags |= kSurfelStable;
    if (frame_ - s.first_seen >= config_.settle_frames) markSettled(s);
  }
  if (explains(s)) explained_[i] = 1;
  s.last_seen = frame_;
}

// A batch of pixels, row by row: planned (association_plan.h), then applied in
// pixel order. A pixel whose surfel an earlier pixel of the batch merged or
// carved is planned again from the surfel as it is then, so the map is a
// pixel-by-pixel pass's. The reference kernel set is that pass (a batch of one
// pixel: nothing planned again), so that the maps fused with either set, which
// the equivalence tests compare, check the replanning too.
std::size_t SurfelMap::associate(const hal::RgbdFrame& frame, FuseStats& stats) {
  const int w = frame.width(), h = frame.height();
  updateNormalTolerance(static_cast<float>(0.5 * (frame.intrinsics.fx + frame.intrinsics.fy)));
  AssociationFrame view = associationFrame(frame);
  AssociationPlan plan;
  AssociationRun run;
  const bool ref = config_.kernels == KernelSet::kRef;
  const int batch = ref ? 1 : static_cast<int>(AssociationPlan::kSize);
  std::size_t yielded_block = 0;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; u += batch) {
      const std::size_t i = static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
      const std::size_t count = std::min<std::size_t>(static_cast<std::size_t>(batch), static_cast<std::size_t>(w - u));
      if (i == 0 || (i + count - 1) / kYieldEvery != yielded_block) {
        yieldGate();
        yielded_block = (i + count - 1) / kYieldEvery;
      }
      associationBatch(view, frame.has_rgb ? frame.rgb() : nullptr, i, u, v);
      prefetchSurfels(i + count, std::min(i + 2 * count, frame.pixelCount()));
      if (ref) {
        planAssociationRef(view, surfels_.data(), count, plan);
      } else {
        planAssociationSimd(view, surfels_.data(), count, plan);
      }
      applyAssociation(view, i, count, plan, run, stats);
    }
  }
  if (run.carved.head != kNone) {
    links_.setNext(run.carved.tail, free_head_);
    free_head_ = run.carved.head;
    free_count_ += run.carved.count;
  }
  return run.to_add;
}

// The surfels the index map names at pixels [begin, end): the next batch's,
// fetched while this one is planned and applied (the index map names surfels
// in no order the cache can guess; with a pool of 920 000 surfels the
// association took as long as before its plans without it). Changes no result.
void SurfelMap::prefetchSurfels(std::size_t begin, std::size_t end) const {
  for (std::size_t i = begin; i < end; ++i) {
    const uint32_t slot = index_map_.slot(i);
    if (slot != kNone) __builtin_prefetch(&surfels_[slot]);
  }
}

// A batch's plans applied in pixel order: carvings, settling, explained
// pixels, merges, and the pixels left to add (marked by a negative weight).
void SurfelMap::applyAssociation(const AssociationFrame& view, std::size_t i0, std::size_t count, AssociationPlan& plan,
                                 AssociationRun& run, FuseStats& stats) {
  const auto carve = static_cast<float>(config_.carve_weight);
  for (std::size_t j = 0; j < count; ++j) {
    const uint32_t kind = plan.kind[j];
    if (kind == AssociationPlan::kNothing) continue;
    const std::size_t i = i0 + j;
    const bool has_normal = (plan.bits[j] & AssociationPlan::kHasNormal) != 0;
    if (kind != AssociationPlan::kEmpty) {
      const uint32_t slot = plan.slot[j];
      Surfel& s = surfels_[slot];
      if (!(s.flags & kSurfelLive)) continue;  // carved away at another pixel this frame
      if (kind == AssociationPlan::kCarve) {
        // The camera sees through the surfel: free space where it is.
        s.flags |= kSurfelTouched;
        if (carveTo(slot, decodeConfidence(s.confidence) - carve * weight_[i], stats)) carveAway(slot, run.carved);
        continue;
      }
      // A settled surfel at the measured depth explains the pixel, whether or
      // not the measurement merges: an edge pixel has no normal, and a far
      // pixel's normal is too noisy for the tolerance (on the mock living
      // room these were 35 000 of the 40 000 pixels a static view left
      // unexplained, and went to the operator every frame). A stable surfel
      // seen at its depth settles once old enough.
      const bool at_depth = kind == AssociationPlan::kAtDepth;
      if (at_depth && (s.flags & kSurfelStable) && frame_ - s.first_seen >= config_.settle_frames) markSettled(s);
      if (at_depth && explains(s)) explained_[i] = 1;
      if (!has_normal) continue;
      if (at_depth) {
        if (s.flags & kSurfelTouched) planMergeRef(view, s, j, plan);
        if (plan.bits[j] & AssociationPlan::kMerges) {
          applyMerge(s, i, j, plan);
          s.flags |= kSurfelTouched;
          ++stats.merged;
        }
        continue;
      }
      // The measurement lies in front of the surfel: a surface the map does not have.
    }
    if (!has_normal) continue;
    weight_[i] = -weight_[i];
    ++run.to_add;
  }
  for (std::size_t j = 0; j < count; ++j) {
    if (plan.kind[j] == AssociationPlan::kCarve || plan.kind[j] == AssociationPlan::kAtDepth) {
      surfels_[plan.slot[j]].flags &= static_cast<uint8_t>(~kSurfelTouched);
    }
  }
}

// Surfels carved away stay out of the free list until every pixel is
// associated (the index map may still name them at other pixels): a chain
// through the links (newest first), which associate() then frees whole.
void SurfelMap::carveAway(uint32_t slot, CarvedChain& chain) {
  detachSurfel(slot);
  links_.setNext(slot, chain.head);
  chain.head = slot;
  if (chain.tail == kNone) chain.tail = slot;
  ++chain.count;
}

void SurfelMap::addNew(const hal::RgbdFrame& frame, FuseStats& stats) {
  const Eigen::Matrix3d& R_wc = frame.T_world_cam.R_world_cam;
  const Eigen::Vector3d& t = frame.T_world_cam.t_world_cam;
  const Eigen::Matrix3f R_wc_f = R_wc.cast<float>();
  const int w = frame.width(), h = frame.height();
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
      if (i % kYieldEvery == 0) yieldGate();
      if (!(weight_[i] < 0.0f)) continue;
      const uint8_t* rgb = frame.has_rgb ? frame.rgb() + 3 * i : kGreyRgb;
      const Eigen::Vector3d p_world = R_wc * vertexAt(i, u, v).cast<double>() + t;
      const Added added = addSurfel(p_world, R_wc_f * normalAt(i), lateMap(kRadius)[i], -weight_[i], rgb);
      if (added == Added::kYes) {
        ++stats.added;
      } else {
        ++stats.dropped_full;
        if (added == Added::kNoBrick) ++stats.dropped_no_brick;
      }
    }
  }
}

std::size_t SurfelMap::appendUnexplained(const hal::RgbdFrame& frame, PointCloud& out) const {
  const std::size_t before = out.size();
  const LiveSelection every;
  LivePointPush push(every, out);
  (void)visitUnexplained(frame, out.origin_m, push);
  return out.size() - before;
}

bool SurfelMap::visitUnexplained(const hal::RgbdFrame& frame, const Eigen::Vector3d& origin_m,
                                 LivePointSink& sink) const {
  if (fused_width_ == 0 || frame.width() != fused_width_ || frame.height() != fused_height_ ||
      frame.stamp_ns != fused_stamp_ns_) {
    return false;
  }
  const Eigen::Matrix3d& R = fused_pose_.R_world_cam;
  // Relative to the cloud's origin in double, then float (the map may be far from the world origin).
  const Eigen::Vector3f t = (fused_pose_.t_world_cam - origin_m).cast<float>();
  const Eigen::Matrix3f R_f = R.cast<float>();
  const int w = frame.width(), h = frame.height();
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
      if (explained_[i] || vertex_z_[i] == 0.0f || sink.skips(u, v)) continue;
      const Eigen::Vector3f p = R_f * vertexAt(i, u, v) + t;
      const uint8_t* rgb = frame.has_rgb ? frame.rgb() + 3 * i : kGreyRgb;
      if (!sink.take(u, v, p, packRgb(rgb[0], rgb[1], rgb[2]))) return true;
    }
  }
  return true;
}

}  // namespace fovea::pipeline::map
