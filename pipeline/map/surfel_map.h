// The fused scene map: surfels fused from posed RGB-D frames on the CPU, in
// memory sized once from the configuration (point-based fusion, Keller et al.
// 2013, the map under ElasticFusion; docs/map.md says what is taken and what
// differs).
//
// Each fuse() call:
//  1. checks the frame's pose (finite, a rotation, not a jump, a later stamp)
//     and refuses the frame, counted, when it fails;
//  2. computes each pixel's camera-frame vertex, normal (central differences,
//     none across a depth step), radius (its footprint, Keller's sqrt(2) z/f
//     over the normal's cosine) and weight (falling off from the image centre);
//     a pixel without a normal (an edge) can carve, not merge or add
//     (map_kernels.h: the scalar reference or the Highway kernel, as
//     SurfelMapConfig::kernels says; the same bits either way);
//  3. renders the map into an index map from the camera (each surfel splatted
//     over its footprint, up to 2 pixels around, z-buffered; of surfels at the
//     same depth the one nearest the pixel wins), dropping on the way surfels
//     that stayed unstable too long and carving every surfel the camera sees
//     through at its centre (free space: a moving object leaves no ghost);
//  4. for each pixel: merges the measurement into the surfel it sees when
//     depth and normal agree (confidence-weighted averages, the confidence
//     capped so that a changed surface still moves), carves the surfel it
//     sees if that lies clearly in front of the measured depth, and marks the
//     pixel as new when nothing explains it;
//  5. evicts the least useful surfels (lowest confidence, longest unseen) when
//     the pool has no room for the new ones, then adds them, unstable.
//
// Memory: the pool of surfels (32 bytes each and 6 for their brick list, the
// free list threaded through the same links: 38 bytes a surfel of capacity),
// the brick table and the per-pixel scratch are allocated by create(); fuse()
// allocates nothing.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "core/depth_noise.h"
#include "core/grid_table.h"
#include "core/kernel_set.h"
#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/backproject.h"
#include "pipeline/map/association_plan.h"
#include "pipeline/map/index_map.h"
#include "pipeline/map/live_points.h"
#include "pipeline/map/map_gate.h"
#include "pipeline/map/map_kernels.h"
#include "pipeline/map/splat_plan.h"
#include "pipeline/map/surfel.h"
#include "pipeline/map/surfel_links.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline::map {

// The depth sensor's noise at depth z (core/depth_noise.h).
using fovea::depthSigma;

struct SurfelMapConfig {
  std::size_t max_surfels = std::size_t{1} << 20;  // at most SurfelLinks::kMaxSlots (16 777 215)
  // Bricks: cubes that hold a surfel's position origin (and will hold the
  // changes the stream sends). 0.5 m: a room needs a few hundred, a float
  // keeps 0.03 micrometres across one, and a brick is a useful unit of change.
  std::size_t max_bricks = 16384;  // at most 65535: a surfel names its brick in 16 bits
  double brick_size_m = 0.5;
  DepthRange depth;
  // Association: depth within depth_tolerance_sigmas times the sensor's noise
  // at that depth (sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2 m, Nguyen et al. 2012:
  // 2 mm at 1 m, 26 mm at 4 m), and normals within normal_tolerance_deg.
  double depth_tolerance_sigmas = 3.0;
  double normal_tolerance_deg = 30.0;
  // Confidence: each observation adds its weight (at most 1); capped so that a
  // surface that changes moves within a few dozen frames.
  double confidence_cap = 20.0;
  // A surfel is stable (written to PLY; shown once settled, below) from here
  // on. 1.5: on the mock living room's orbit (fovea-map-accuracy, docs/map.md)
  // 4 left 34 % of the surface seen without a stable surfel within 1 cm, 1.5
  // left 14 % at 0.42 of a frame's RMS depth error (4: 0.29).
  double stable_confidence = 1.5;
  uint32_t unstable_max_frames = 30;  // an unstable surfel older than this goes
  // A stable surfel is settled (kSurfelSettled: the operator's from then on)
  // once it is this many frames old and seen again: a moving object's surfels
  // reach stability within two frames and go a few frames later, and would
  // otherwise change the map, and every brick it passes, every frame.
  uint32_t settle_frames = 10;
  // A surfel the camera sees through (at its centre's pixel) loses half its
  // confidence and carve_weight times the pixel's weight; one that only a
  // neighbouring pixel of its footprint sees through, that weight alone.
  double carve_weight = 2.0;
  // A frame whose camera moved farther than this from the last frame's is refused.
  double max_pose_jump_m = 1.0;
  // Pixels of the largest frame fused (the scratch is sized for it).
  int max_width = 640;
  int max_height = 480;
  // Step 2's per-pixel kernel (map_kernels.h): the scalar reference or Highway's,
  // the same bits either way.
  KernelSet kernels = defaultKernelSet();

  Status validate() const;
};

// Why fuse() did not fuse a frame (each counted in SurfelMapCounters).
enum class FuseOutcome : uint8_t {
  kFused,
  kRefusedSize,       // larger than max_width x max_height, or bad intrinsics
  kRefusedBadPose,    // NaN/Inf, or R is not a rotation
  kRefusedPoseJump,   // moved more than max_pose_jump_m since the last frame
  kRefusedClock,      // stamp not after the last fused frame's
  kRefusedNoPose,     // the pose source had no pose for the frame (stale, none yet)
};
std::string_view fuseOutcomeName(FuseOutcome outcome);

struct FuseStats {
  FuseOutcome outcome = FuseOutcome::kFused;
  uint32_t pixels_valid = 0;     // depth in range with a normal (those without one only carve)
  uint32_t pixels_moving = 0;    // of them, left out as moving (fuse()'s `moving`)
  uint32_t merged = 0;           // measurements merged into a surfel
  uint32_t added = 0;            // new surfels
  uint32_t carved = 0;           // surfels seen through (confidence lowered)
  uint32_t removed_carved = 0;   // ... and removed for it
  uint32_t removed_unstable = 0; // unstable for longer than unstable_max_frames
  uint32_t evicted = 0;          // removed to make room in a full pool
  uint32_t dropped_full = 0;     // measurements not added: no surfel or brick left
  uint32_t dropped_no_brick = 0; // ... of them for want of a brick (the table full, or beyond its keys)
  int64_t fuse_ns = 0;
  // fuse_ns by step (monotonic clock; the rest of fuse_ns is the frame's checks):
  int64_t vertices_ns = 0;   // 2. vertices, normals, radii, weights
  int64_t index_map_ns = 0;  // 3. the index map (and the unstable surfels' removal, the free-space carving)
  int64_t associate_ns = 0;  // 4. merging and carving
  int64_t add_ns = 0;        // 5. eviction (makeRoom) and the new surfels (addNew)
};

// What create() allocated, by what it grows with.
struct SurfelMapMemory {
  std::size_t pool = 0;      // max_surfels: the surfels (32 bytes) and their brick lists' links (6)
  std::size_t bricks = 0;    // max_bricks: keys, hash table, per-frame culling, lists' heads, counts
  std::size_t pixels = 0;    // max_width x max_height: the per-pixel scratch of a frame's fusion
  std::size_t eviction = 0;  // fixed: makeRoom()'s histogram
  std::size_t total() const { return pool + bricks + pixels + eviction; }
};

struct SurfelMapCounters {
  uint64_t frames_fused = 0;
  uint64_t refused_size = 0, refused_bad_pose = 0, refused_pose_jump = 0, refused_clock = 0, refused_no_pose = 0;
  uint64_t refused() const { return refused_size + refused_bad_pose + refused_pose_jump + refused_clock + refused_no_pose; }
  uint64_t added = 0, evicted = 0, removed_carved = 0, removed_unstable = 0, dropped_full = 0, dropped_no_brick = 0;
  uint64_t bricks_reused = 0;  // empty bricks given a new place when the table was full
};

class SurfelMap {
 public:
  static Result<SurfelMap> create(const SurfelMapConfig& config);

  // Fuses one posed frame (frame.T_world_cam: camera to world). pose_valid
  // false (the pose source had none for the frame's stamp) refuses it.
  // moving (null: none): the frame's pixels found moving (MovingPixels), which
  // neither merge, carve nor add: the map stays static, and they stay
  // unexplained (appendUnexplained() sends them). Never allocates.
  FuseOutcome fuse(const hal::RgbdFrame& frame, FuseStats& stats, bool pose_valid = true,
                   const uint8_t* moving = nullptr);

  // The pixels of the last fused frame (pass that frame) that no settled
  // surfel lies at (within the association's depth tolerance): new surface, a
  // moving object, surface the map has not settled yet. Appends
  // their world positions (relative to out.origin_m) and colours to out until
  // it is full; returns how many it appended (0 when `frame` is not the last
  // fused one: other size or stamp). The map's foveation sends them beside the
  // map, so nothing dynamic is lost while the map learns it.
  std::size_t appendUnexplained(const hal::RgbdFrame& frame, PointCloud& out) const;
  // The same points offered to `sink` in pixel order (relative to origin_m)
  // until it says stop; false, offering none, when `frame` is not the last
  // fused one.
  bool visitUnexplained(const hal::RgbdFrame& frame, const Eigen::Vector3d& origin_m, LivePointSink& sink) const;

  // Live surfels. Slots [0, slotCount()) hold them and free slots (live() false).
  std::size_t size() const { return live_; }
  std::size_t slotCount() const { return high_water_; }
  std::size_t capacity() const { return surfels_.size(); }
  std::size_t brickCount() const { return brick_count_; }
  bool live(std::size_t slot) const { return (surfels_[slot].flags & kSurfelLive) != 0; }
  const Surfel& surfel(std::size_t slot) const { return surfels_[slot]; }
  // World position, in double (the brick's origin plus the surfel's offset).
  Eigen::Vector3d worldPosition(std::size_t slot) const;
  Eigen::Vector3d brickOrigin(uint16_t brick) const;

  // A brick's place on the grid: its origin is key * brick_size_m.
  using BrickKey = GridKey;
  const BrickKey& brickKey(uint16_t brick) const { return brick_keys_[brick]; }

  // Per brick, for the stream of changes (issue 26): the live surfels as a
  // list (firstInBrick, then nextInBrick until kNoSurfel; any order), the
  // settled ones among them, and a counter of changes to the settled set (a
  // surfel settled, or a settled one went) that only grows (wrapping): a
  // reader keeps the value it last saw and compares.
  static constexpr uint32_t kNoSurfel = SurfelLinks::kNoSlot;
  uint32_t firstInBrick(uint16_t brick) const { return brick_head_[brick]; }
  uint32_t nextInBrick(uint32_t slot) const { return links_.next(slot); }
  uint32_t brickSettledCount(uint16_t brick) const { return brick_settled_[brick]; }
  uint32_t brickChanges(uint16_t brick) const { return brick_changes_[brick]; }

  // A brick whose surfels all went (evicted, carved) is given to a new place
  // when the table is full and one is needed, unless it is pinned: the caller
  // that streams bricks pins those the operator may still draw, so that a
  // place is never told to the operator under a brick's slot while its old
  // content is (MapDelta::holds). Bricks start unpinned; pin from the thread
  // that fuses, or under the map's gate. Its brickChanges() keeps counting.
  void pinBrick(uint16_t brick, bool pinned) { brick_pinned_[brick] = pinned ? 1 : 0; }
  bool brickPinned(uint16_t brick) const { return brick_pinned_[brick] != 0; }

  // The index map of the last fused frame (indexMapWidth() x indexMapHeight(),
  // row-major; both 0 before the first fused frame): per pixel the slot of the
  // surfel the frame's pixel saw, rendered at the frame's pose before
  // association (kNoSurfel: none). The slot's surfel is as merged; it may since
  // have been removed (check live()). The tracker's model (tracker.h).
  const uint32_t* indexMap() const { return index_map_.slots(); }
  // The last fused frame's pixels, as fusion left them: 1 where a settled
  // surfel explained the pixel (what appendUnexplained() leaves out), and the
  // measured depth in metres (0: no valid measurement).
  const uint8_t* explainedPixels() const { return explained_.data(); }
  // From now on a settled surfel explains a pixel only when the operator
  // holds it: `held` (per brick slot, max_bricks of them; null: every settled
  // surfel explains) is MapDelta::heldFrames(), and a surfel counts as held
  // when it settled by its brick's frame there. Its settling frame is
  // taken as first_seen + settle_frames, the earliest it can settle: a surfel
  // that became stable later may be counted held when the version did not
  // have it yet (then the operator has a hole there until the brick is due
  // again, as every such surfel had before).
  void setHeldFrames(const std::atomic<uint32_t>* held) { held_frames_ = held; }
  const float* measuredDepth() const { return vertex_z_.data(); }
  int indexMapWidth() const { return index_map_.width(); }
  int indexMapHeight() const { return index_map_.height(); }

  const SurfelMapConfig& config() const { return config_; }
  const SurfelMapCounters& counters() const { return counters_; }
  uint32_t frameNumber() const { return frame_; }
  // The last frame whose fusion finished: every surfel that settled by then
  // has its flag (frameNumber() is the one in flight while fusion runs).
  uint32_t settledThroughFrame() const { return settled_through_; }
  // Bytes allocated by create(), all of it, and by part.
  std::size_t memoryBytes() const;
  SurfelMapMemory memoryParts() const;

  // Empties the map (keeps the memory).
  void clear();

  // With fusion on a thread of its own (Mapper): fuse() runs holding `gate`
  // and lets readers through at its safe points (map_gate.h). Null: none.
  void setGate(MapGate* gate) { gate_ = gate; }

 private:
  explicit SurfelMap(const SurfelMapConfig& config);

  // The brick holding world position p (inserted if new, in an empty unpinned
  // brick when the table is full); -1 when no brick is left for it.
  int findOrAddBrick(const Eigen::Vector3d& p_world);
  int reuseEmptyBrick();  // findOrAddBrick()'s: an empty unpinned brick, out of the table; -1: none
  FuseOutcome checkFrame(const hal::RgbdFrame& frame);
  uint32_t computeDepths(const hal::RgbdFrame& frame);  // step 2's depths and weights, and vertex_params_
  void computeNormals(FuseStats& stats);                 // ... and its normals and radii
  void leaveOutMoving(std::size_t pixels, const uint8_t* moving, FuseStats& stats);
  PixelMaps pixelMaps();  // step 2's output: pointers into the per-pixel scratch
  // Pixel (u, v) = i of the frame prepareVertices() last saw: its vertex from
  // the depth and the rays, the same bits as computeNormals() makes it.
  Eigen::Vector3f vertexAt(std::size_t i, int u, int v) const {
    const float z = vertex_z_[i];
    return {tables_.ray_u[kNormalReach + u] * z, tables_.ray_v[v] * z, z};
  }
  Eigen::Vector3f normalAt(std::size_t pixel) const {
    return {lateMap(kNormalX)[pixel], lateMap(kNormalY)[pixel], lateMap(kNormalZ)[pixel]};
  }
  void makeRoom(std::size_t wanted, FuseStats& stats);
  void renderIndexMap(const hal::RgbdFrame& frame, FuseStats& stats);
  // renderIndexMap()'s steps (surfel_map_render.cpp): the bricks' camera-frame
  // origins and culling, then every surfel to its centre's cell and the gather.
  void cullBricks(const hal::RgbdFrame& frame);
  void splatSurfels(const hal::RgbdFrame& frame, FuseStats& stats);
  SplatFrame splatFrame(const hal::RgbdFrame& frame) const;
  void applySplats(std::size_t b0, std::size_t count, const SplatPlan& plan, FuseStats& stats);
  struct CarvedChain {
    uint32_t head = kNoSurfel, tail = kNoSurfel;
    std::size_t count = 0;
  };
  // Merges and carves; returns the pixels left to add (marked by a negative weight).
  std::size_t associate(const hal::RgbdFrame& frame, FuseStats& stats);
  // associate()'s steps: the normal test's tolerance by depth (for this focal
  // length), the plans' view of the frame, a batch's pixels, its plans applied.
  void updateNormalTolerance(float f_px);
  AssociationFrame associationFrame(const hal::RgbdFrame& frame) const;
  void associationBatch(AssociationFrame& f, const uint8_t* rgb, std::size_t i, int u, int v) const;
  void prefetchSurfels(std::size_t begin, std::size_t end) const;
  struct AssociationRun {
    CarvedChain carved;
    std::size_t to_add = 0;
  };
  void applyAssociation(const AssociationFrame& view, std::size_t i0, std::size_t count, AssociationPlan& plan,
                        AssociationRun& run, FuseStats& stats);
  void applyMerge(Surfel& s, std::size_t i, std::size_t j, const AssociationPlan& plan);
  void carveAway(uint32_t slot, CarvedChain& chain);  // associate()'s: off the brick, onto the chain
  void addNew(const hal::RgbdFrame& frame, FuseStats& stats);
  enum class Added { kYes, kNoSurfel, kNoBrick };
  Added addSurfel(const Eigen::Vector3d& p_world, const Eigen::Vector3f& n_world, float radius, float weight,
                  const uint8_t* rgb);
  void removeSurfel(uint32_t slot);
  void pushFree(uint32_t slot);
  uint32_t popFree();  // free_count_ > 0
  // Takes a surfel out of the map's bookkeeping (flags, brick list, counts) but
  // not into the free list: removeSurfel() does both.
  void detachSurfel(uint32_t slot);
  void markSettled(Surfel& s);
  // Whether `s` explains a pixel at its depth: settled, and held when
  // setHeldFrames() says which are.
  bool explains(const Surfel& s) const {
    if (!(s.flags & kSurfelSettled)) return false;
    if (held_frames_ == nullptr) return true;
    return s.first_seen + config_.settle_frames <= held_frames_[s.brick].load(std::memory_order_relaxed);
  }
  // A surfel the camera saw through keeps `left` confidence; true when that is
  // none and it must go (the caller removes it: at once, or after the frame's
  // association while the index map may still name it). Counts both.
  bool carveTo(uint32_t slot, float left, FuseStats& stats);
  // A safe point of fusion: every surfel, brick list and counter whole.
  void yieldGate() {
    if (gate_ != nullptr) gate_->yield();
  }
  static constexpr std::size_t kYieldEvery = 4096;  // pixels or slots between safe points

  SurfelMapConfig config_;
  std::vector<Surfel> surfels_;
  uint32_t free_head_ = kNoSurfel;    // a stack of free slots below high_water_, through links_.next
  std::size_t free_count_ = 0;
  std::size_t high_water_ = 0;
  std::size_t live_ = 0;

  std::vector<BrickKey> brick_keys_;      // by slot
  GridTable brick_table_;                 // key -> brick
  std::size_t brick_count_ = 0;
  std::vector<Eigen::Vector3f> brick_cam_;   // per frame: brick origin in camera coordinates
  std::vector<uint32_t> brick_visible_;  // 1: in the view (a word: the plan's kernel gathers it)
  std::vector<uint32_t> brick_head_;      // per brick: first surfel of its list (kNoSurfel: none)
  std::vector<uint32_t> brick_settled_;   // ... its settled surfels
  std::vector<uint32_t> brick_changes_;   // ... changes to its settled set (wrapping)
  std::vector<uint8_t> brick_pinned_;     // ... 1: not to be reused while empty (pinBrick)
  std::size_t reuse_cursor_ = 0;          // where reuseEmptyBrick() looks next (round robin)
  uint32_t reuse_failed_frame_ = 0;       // the frame (frame_, from 1) whose look found none: one fruitless look a frame at most
  // Per slot: the brick list's neighbours; a free slot's next is the next free one.
  SurfelLinks links_;

  // Per pixel, sized for max_width x max_height: step 2's maps (PixelMaps,
  // map_kernels.h), structure of arrays; weight is negated by associate() for a
  // pixel to add. The depth and the weight, which the index map's render reads,
  // have maps of their own; the normals and radii (kLateMaps) are made after
  // the render, in the index map's scratch (its planes, free once gathered); a
  // vertex's x and y come from its depth and ray (vertexAt()). 8 bytes a
  // pixel of their own, and the planes grown from 13.4 to 16 a pixel at
  // 640x480, where a map each took 32.
  enum LateMap : std::size_t { kNormalX, kNormalY, kNormalZ, kRadius, kLateMaps };
  float* lateMap(LateMap m) { return index_map_.scratch() + m * pixel_capacity_; }
  const float* lateMap(LateMap m) const { return index_map_.scratch() + m * pixel_capacity_; }
  std::size_t pixel_capacity_ = 0;        // max_width x max_height
  std::vector<float> vertex_z_;           // camera frame; 0: no valid measurement
  std::vector<float> weight_;
  VertexTables tables_;                   // the weight's factors and the rays, by column and by row
  VertexParams vertex_params_;            // the frame being fused's (computeDepths(); until fuse() returns)
  IndexMap index_map_;                    // step 3's, the tracker's model; its scratch: the late maps
  std::vector<uint32_t> key_histogram_;   // makeRoom()'s counts (lowest_keys.h), kKeyHistogramSize
  const std::atomic<uint32_t>* held_frames_ = nullptr;  // setHeldFrames()
  std::vector<uint8_t> explained_;        // the last fused frame: 1 where a settled surfel lies at the pixel's depth
  std::vector<float> normal_cos_;         // the normal test's cosine by depth (associate())
  float normal_cos_f_px_ = 0.0f;          // ... for this focal length (0: not made yet)
  float normal_cos_z_min_ = 0.0f;         // ... its first bucket's depth
  float normal_cos_per_m_ = 0.0f;         // ... and buckets a metre (not a division a pixel)

  uint32_t frame_ = 0;                    // frames fused so far
  uint32_t settled_through_ = 0;          // settledThroughFrame()
  bool have_last_ = false;
  int64_t last_stamp_ns_ = 0;
  Eigen::Vector3d last_position_ = Eigen::Vector3d::Zero();
  MapGate* gate_ = nullptr;  // setGate(): fusion on a thread of its own
  // The last fused frame (appendUnexplained): its pose, size and stamp.
  hal::Pose fused_pose_;
  int fused_width_ = 0, fused_height_ = 0;
  int64_t fused_stamp_ns_ = 0;
  SurfelMapCounters counters_;
};

}  // namespace fovea::pipeline::map
