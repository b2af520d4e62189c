#include "pipeline/map/map_delta.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "core/clock.h"

namespace fovea::pipeline::map {

namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;
// The brick's eccentricity is taken this much smaller than computed: the
// per-point rule's atan is a polynomial (acuity_levels.h, under 1e-5 rad off),
// and the brick must never come out coarser than any of its points.
constexpr double kEccSafetyDeg = 0.01;

}  // namespace

Status MapDeltaConfig::validate() const {
  if (acuity.preset != Preset::kAcuity) {
    return {ErrorCode::kInvalidArgument, "map_delta.acuity: the levels need preset acuity"};
  }
  if (Result<RegionModel> model = RegionModel::create(acuity); !model) return model.status();
  if (!(fovea_ecc_deg >= 0.0 && fovea_ecc_deg <= 180.0)) {
    return {ErrorCode::kInvalidArgument, "map_delta.fovea_ecc_deg: must be in [0, 180]"};
  }
  if (!(change_fraction >= 0.0 && change_fraction <= 1.0)) {
    return {ErrorCode::kInvalidArgument, "map_delta.change_fraction: must be in [0, 1]"};
  }
  if (!(growth_fraction >= 0.0 && growth_fraction <= 1.0)) {
    return {ErrorCode::kInvalidArgument, "map_delta.growth_fraction: must be in [0, 1]"};
  }
  if (!(churn_fraction >= 0.0 && churn_fraction <= 1.0)) {
    return {ErrorCode::kInvalidArgument, "map_delta.churn_fraction: must be in [0, 1]"};
  }
  return Status::ok();
}

Result<MapDelta> MapDelta::create(const MapDeltaConfig& config, std::size_t max_bricks) {
  if (Status s = config.validate(); !s) return Result<MapDelta>(s.code(), s.message());
  if (max_bricks == 0 || max_bricks > 65535) {
    return Result<MapDelta>(ErrorCode::kInvalidArgument, "map_delta: max_bricks must be in [1, 65535]");
  }
  const RegionModel model = RegionModel::create(config.acuity).value();
  return MapDelta(config, LevelBounds::fromModel(model), max_bricks);
}

MapDelta::MapDelta(const MapDeltaConfig& config, const LevelBounds& bounds, std::size_t max_bricks)
    : config_(config), bounds_(bounds) {
  held_level_.assign(max_bricks, kNotHeld);
  sent_level_.assign(max_bricks, 0);
  level_floor_.assign(max_bricks, 0);
  held_changes_.assign(max_bricks, 0);
  held_settled_.assign(max_bricks, 0);
  held_frame_ = std::make_unique<std::atomic<uint32_t>[]>(max_bricks);
  for (std::size_t b = 0; b < max_bricks; ++b) held_frame_[b].store(0, std::memory_order_relaxed);
  version_.assign(max_bricks, 0);
  sent_plan_.assign(max_bricks, 0);
  may_draw_.assign(max_bricks, 0);
  due_since_.assign(max_bricks, 0);
  order_.resize(max_bricks);
  due_.resize(max_bricks);
  plan_.resize(max_bricks);
}

std::size_t MapDelta::memoryBytes() const {
  return held_level_.capacity() + sent_level_.capacity() + level_floor_.capacity() + may_draw_.capacity() +
         (held_changes_.capacity() + held_settled_.capacity() + version_.capacity() + sent_plan_.capacity() +
          due_since_.capacity() + held_level_.size()) *
             sizeof(uint32_t) +
         order_.capacity() * sizeof(uint64_t) + (due_.capacity() + plan_.capacity()) * sizeof(BrickDue);
}

MapDelta::Need MapDelta::need(const Eigen::Vector3d& origin_m, double size_m, const Gaze& gaze) const {
  const Eigen::Vector3d& eye = gaze.origin_m;
  // The nearest point of the cube to the eye.
  const Eigen::Vector3d below = (origin_m - eye).cwiseMax(0.0);
  const Eigen::Vector3d above = (eye - (origin_m + Eigen::Vector3d::Constant(size_m))).cwiseMax(0.0);
  const double r_min = (below + above).norm();
  const Eigen::Vector3d a = origin_m + Eigen::Vector3d::Constant(0.5 * size_m) - eye;
  const double dist = a.norm();
  const double sphere = 0.5 * std::sqrt(3.0) * size_m;
  double ecc = 0.0;
  if (dist > sphere) {
    const double theta = std::atan2(a.cross(gaze.direction).norm(), a.dot(gaze.direction)) * kRadToDeg;
    ecc = std::max(0.0, theta - std::asin(sphere / dist) * kRadToDeg - gaze.fovea_growth_deg - kEccSafetyDeg);
  }
  Need n;
  n.ecc_deg = static_cast<float>(ecc);
  // r is rounded down to float so that it never exceeds a point's r.
  n.level = bounds_.classify(std::nextafter(static_cast<float>(r_min), 0.0f), n.ecc_deg);
  return n;
}

Result<std::span<const BrickDue>> MapDelta::plan(const SurfelMap& map, const Gaze& raw_gaze, MapDeltaStats& stats) {
  const int64_t start = monotonicNs();
  stats = {};
  Result<Gaze> normal = normalizeGaze(raw_gaze);
  if (!normal) return Result<std::span<const BrickDue>>(normal.status().code(), normal.status().message());
  const Gaze& gaze = normal.value();
  ++plan_number_;
  if (plan_number_ == 0) plan_number_ = 1;  // 0 means "not due"
  const double size = map.config().brick_size_m;
  const std::size_t bricks = std::min(map.brickCount(), held_level_.size());
  std::size_t n_due = 0;
  for (std::size_t b = 0; b < bricks; ++b) {
    const auto brick = static_cast<uint16_t>(b);
    const uint32_t settled = map.brickSettledCount(brick);
    if (settled == 0 && held_level_[b] != kNotHeld && held_settled_[b] == 0 &&
        plan_number_ - sent_plan_[b] >= kEmptyHoldPlans) {
      held_level_[b] = kNotHeld;  // sent empty long enough ago, and not reported lost: delivered
      held_frame_[b].store(0, std::memory_order_relaxed);
      may_draw_[b] = 0;
    }
    if (settled == 0) level_floor_[b] = 0;  // emptied, or a new place's: dense no more
    const uint8_t held = held_level_[b];
    stats.bricks += settled > 0 ? 1 : 0;
    if (held == kNotHeld && settled == 0 && may_draw_[b] == 0) {
      due_since_[b] = 0;
      continue;
    }
    Need need = this->need(map.brickOrigin(brick), size, gaze);
    need.level = std::max(need.level, level_floor_[b]);
    BrickDue due{brick, need.level, BrickNeed::kMissing, need.ecc_deg <= config_.fovea_ecc_deg};
    bool is_due = false;
    if (held == kNotHeld && settled == 0) {
      // Emptied, and the version that says so was lost (or never went): the
      // operator may still draw what it had.
      due.need = BrickNeed::kChanged;
      is_due = true;
      ++stats.changed;
    } else if (held == kNotHeld) {
      is_due = true;
      ++stats.missing;
    } else if (need.level < held) {
      due.need = BrickNeed::kRefine;
      is_due = true;
      ++stats.refine;
    } else {
      if (changedEnough(map.brickChanges(brick) - held_changes_[b], settled, held_settled_[b], held)) {
        due.need = BrickNeed::kChanged;
        is_due = true;
        ++stats.changed;
      }
    }
    if (!is_due) {
      due_since_[b] = 0;
      continue;
    }
    if (due_since_[b] == 0) due_since_[b] = plan_number_;
    stats.fovea += due.fovea ? 1 : 0;
    const uint64_t rank = due.fovea ? 0 : due.need == BrickNeed::kChanged ? 1 : 2;
    const uint64_t waited = std::min<uint64_t>(plan_number_ - due_since_[b], (uint64_t{1} << 30) - 1);
    const auto ecc = static_cast<uint64_t>(std::min(need.ecc_deg, 180.0f) * (65535.0f / 180.0f));
    // Ascending: the rank, then the longest waiting, then the nearest to the gaze, then the brick.
    order_[n_due++] = rank << 62 | (((uint64_t{1} << 30) - 1 - waited) << 32) | ecc << 16 | b;
    due_[b] = due;
  }
  std::sort(order_.begin(), order_.begin() + static_cast<std::ptrdiff_t>(n_due));
  for (std::size_t i = 0; i < n_due; ++i) plan_[i] = due_[order_[i] & 0xffffu];
  stats.ns = monotonicNs() - start;
  return std::span<const BrickDue>(plan_.data(), n_due);
}

bool MapDelta::changedEnough(uint32_t changes, uint32_t settled, uint32_t held_settled, uint8_t level) const {
  if (changes == 0) return false;
  const double scale = std::ldexp(static_cast<double>(held_settled), level);
  const double gained = static_cast<double>(settled) - static_cast<double>(held_settled);
  // Growth is not scaled by the level: the surfels the operator lacks go as
  // live points each frame, however coarse the brick it holds.
  if (gained > config_.growth_fraction * static_cast<double>(held_settled)) return true;
  return -gained > config_.change_fraction * scale || static_cast<double>(changes) > config_.churn_fraction * scale;
}

uint32_t MapDelta::markSent(const SurfelMap& map, uint16_t brick, uint8_t level) {
  held_level_[brick] = level;
  sent_level_[brick] = level;
  held_changes_[brick] = map.brickChanges(brick);
  held_settled_[brick] = map.brickSettledCount(brick);
  held_frame_[brick].store(map.settledThroughFrame(), std::memory_order_relaxed);
  if (held_settled_[brick] > 0) may_draw_[brick] = 1;
  sent_plan_[brick] = plan_number_;
  due_since_[brick] = 0;
  if (++version_[brick] == 0) version_[brick] = 1;
  return version_[brick];
}

void MapDelta::tooLarge(uint16_t brick) {
  const auto coarser = static_cast<uint8_t>(std::min<int>(sent_level_[brick] + 1, kMaxRegions - 1));
  level_floor_[brick] = std::max(level_floor_[brick], coarser);
  ++too_large_;
}

void MapDelta::forgetAll() {
  std::fill(held_level_.begin(), held_level_.end(), kNotHeld);
  for (std::size_t b = 0; b < held_level_.size(); ++b) held_frame_[b].store(0, std::memory_order_relaxed);
  std::fill(may_draw_.begin(), may_draw_.end(), uint8_t{0});
  std::fill(due_since_.begin(), due_since_.end(), 0);
}

}  // namespace fovea::pipeline::map
