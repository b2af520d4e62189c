// What of the map an operator who keeps it needs next: the robot's side of the
// stream of changes (issue 26, docs/map-delta.md).
//
// The operator holds the map's bricks, each at a level of detail. Every frame
// plan() gives each brick the level the operator's eye needs now, ACUITY's rule
// (acuity_levels.h: level n when k v_n <= r sin(MAR(E))) taken at the brick's
// most demanding point: r the distance from the eye to the nearest point of the
// brick's cube, E the smallest eccentricity over the sphere around it. Both
// bound the per-point values from below, so the brick's level is never coarser
// than any of its surfels' (a test checks it against every point). A brick is
// then due when:
//  - the operator lacks it (kMissing), or needs it finer than it holds it
//    (kRefine; coarsening is never sent: the operator draws what it has);
//  - its settled set changed since it was sent at level h (kChanged): it
//    gained more than growth_fraction of the settled surfels held then, or
//    (a coarse level hides more, so these bounds are times 2^h) lost more
//    than change_fraction of them, or, with their number about the same,
//    surfels settled or went (SurfelMap::brickChanges) more than
//    churn_fraction times (surface replaced where it was: a real sensor's
//    noise does it all the time, docs/map-delta.md). A gain is not scaled by
//    the level: with explain_held_only the surfels the operator lacks go as
//    live points every frame, however coarse the brick it holds.
// The plan lists the due bricks in budget order: the fovea's first (the brick
// comes within fovea_ecc_deg of the gaze), then changes, then the periphery's;
// in each, the longest waiting first, then the nearest to the gaze. The caller
// sends from the front while its budget lasts and calls markSent() for what
// went; the rest stays due and ages.
//
// A brick sent empty (its settled surfels all went) is held for
// kEmptyHoldPlans plans, long enough for its one empty chunk to be delivered
// or reported lost, and then no longer: holds() turns false, and the map may
// give the brick's slot to a new place (SurfelMap::pinBrick). An emptied brick
// whose empty version was lost (forget()) while the operator may still draw an
// earlier one is due again (kChanged) until one is delivered.
//
// Memory: the per-brick state and the plan, allocated by create(); plan()
// allocates nothing.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "core/result.h"
#include "pipeline/acuity.h"
#include "pipeline/acuity_levels.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/partition.h"

namespace fovea::pipeline::map {

struct MapDeltaConfig {
  // The level rule: ACUITY's (preset kAcuity: level_voxel_m, level_margin,
  // slope, the floors). The refinement passes and the view cull do not apply.
  AcuityConfig acuity = [] {
    AcuityConfig c;
    c.preset = Preset::kAcuity;
    return c;
  }();
  // A brick that comes within this of the gaze is the fovea's: sent first.
  double fovea_ecc_deg = 5.0;
  // Changes to a brick's settled set that make it due again, as a fraction of
  // its settled surfels when sent: surfels lost, times 2^level (what the
  // operator would still draw in space now free), surfels gained (surface it
  // lacks; with explain_held_only it gets their pixels as live points
  // meanwhile, so the bound may be loose), and surfels settled or gone counted
  // each, times 2^level (the churn: surface replaced where it was).
  double change_fraction = 0.01;
  double growth_fraction = 0.2;
  double churn_fraction = 0.2;
  // A pixel is explained (no live point) only by a settled surfel the operator
  // holds: one its brick's version in hand had settled (heldFrames()). Off:
  // by any settled surfel, whether or not its brick went yet.
  bool explain_held_only = true;

  Status validate() const;
};

enum class BrickNeed : uint8_t { kMissing, kRefine, kChanged };
inline constexpr std::size_t kBrickNeedCount = 3;  // the needs above, for tables indexed by them

struct BrickDue {
  uint16_t brick = 0;
  uint8_t level = 0;  // to send it at
  BrickNeed need = BrickNeed::kMissing;
  bool fovea = false;
};

struct MapDeltaStats {
  uint32_t bricks = 0;  // with settled surfels
  uint32_t missing = 0, refine = 0, changed = 0;
  uint32_t fovea = 0;  // of the due, the fovea's
  int64_t ns = 0;      // plan()'s time
};

class MapDelta {
 public:
  // max_bricks: the map's (SurfelMapConfig::max_bricks).
  static Result<MapDelta> create(const MapDeltaConfig& config, std::size_t max_bricks);

  // The level the eye (gaze.origin_m, looking along gaze.direction) needs for
  // the cube [origin, origin + size]^3, and its smallest eccentricity (degrees).
  // gaze from normalizeGaze().
  struct Need {
    uint8_t level = 0;
    float ecc_deg = 0.0f;
  };
  Need need(const Eigen::Vector3d& origin_m, double size_m, const Gaze& gaze) const;
  // Whether a brick held at `level` with `held_settled` settled surfels, which
  // now has `settled` after `changes` settlings and removals, is due again.
  bool changedEnough(uint32_t changes, uint32_t settled, uint32_t held_settled, uint8_t level) const;

  // The bricks due for an eye at `gaze`, in budget order (valid until the next
  // call). kInvalidInput for a bad gaze. Never allocates.
  Result<std::span<const BrickDue>> plan(const SurfelMap& map, const Gaze& gaze, MapDeltaStats& stats);

  // The caller sent `brick` at `level`: the operator now holds it so (until
  // forget() says otherwise: the sender resends lost parts, and tells when a
  // version cannot be delivered). Returns the brick's new version (from 1).
  uint32_t markSent(const SurfelMap& map, uint16_t brick, uint8_t level);
  // The operator does not hold `brick` (it evicted it, or its version was lost
  // on the way: net/brick_sender.h): it is due again.
  void forget(uint16_t brick) {
    held_level_[brick] = kNotHeld;
    held_frame_[brick].store(0, std::memory_order_relaxed);
  }
  // The operator holds nothing (a new session, or an operator that restarted).
  void forgetAll();
  // The version of `brick` last sent could not go: more parts than a version
  // may have (the link's sender keeps BrickSenderConfig::max_parts), which only
  // a dense brick close to the camera reaches at level 0. From now on it is
  // planned at least a level coarser than that version, until it empties (a
  // slot given to a new place starts empty): the operator gets the finest
  // version that fits, not the same one refused every frame.
  void tooLarge(uint16_t brick);
  uint8_t levelFloor(uint16_t brick) const { return level_floor_[brick]; }
  uint64_t tooLargeCount() const { return too_large_; }  // tooLarge() calls, since start

  static constexpr uint8_t kNotHeld = 0xff;
  static constexpr uint32_t kEmptyHoldPlans = 64;  // about 2 s at 30 plans a second
  uint8_t heldLevel(uint16_t brick) const { return held_level_[brick]; }
  // Whether the operator may draw something of `brick` as this side sent it.
  bool holds(uint16_t brick) const { return held_level_[brick] != kNotHeld || may_draw_[brick] != 0; }
  uint32_t version(uint16_t brick) const { return version_[brick]; }
  // Per brick, the map's last finished frame (SurfelMap::settledThroughFrame)
  // when the version the operator holds was sampled, 0 when it holds none: the
  // surfels settled by then are the operator's (SurfelMap::setHeldFrames). Written
  // by the planner's thread, read by fusion's, hence atomic.
  const std::atomic<uint32_t>* heldFrames() const { return held_frame_.get(); }
  const MapDeltaConfig& config() const { return config_; }
  std::size_t memoryBytes() const;

 private:
  MapDelta(const MapDeltaConfig& config, const LevelBounds& bounds, std::size_t max_bricks);

  MapDeltaConfig config_;
  LevelBounds bounds_;
  uint32_t plan_number_ = 0;
  std::vector<uint8_t> held_level_;        // kNotHeld: the operator lacks it
  std::vector<uint8_t> sent_level_;        // the level of the version last sent (held or not)
  std::vector<uint8_t> level_floor_;       // tooLarge()'s: planned at this level or coarser
  uint64_t too_large_ = 0;
  std::vector<uint32_t> held_changes_;     // the map's change counter when sent
  std::vector<uint32_t> held_settled_;      // ... and the settled surfels then
  std::unique_ptr<std::atomic<uint32_t>[]> held_frame_;  // ... and the map's frame number then (0: not held)
  std::vector<uint32_t> version_;
  std::vector<uint32_t> sent_plan_;        // plan number when last sent
  std::vector<uint8_t> may_draw_;          // 1: a version with surfels went, and no empty one is known delivered since
  std::vector<uint32_t> due_since_;        // plan number the brick became due (0: not due)
  std::vector<uint64_t> order_;            // plan scratch: sort keys
  std::vector<BrickDue> due_;              // by brick, then in plan order
  std::vector<BrickDue> plan_;
};

}  // namespace fovea::pipeline::map
