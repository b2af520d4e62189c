#include "pipeline/map/eye_view.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/clock.h"

namespace fovea::pipeline::map {

namespace {

// A footprint's radius is capped at this many cells (surfels seen at grazing
// angles have wide ones, which would hide what lies beside an object's edge);
// 2.5 reaches as far as whole cells two away from the surfel's own.
constexpr float kMaxSplatCells = 2.5f;
// floor() for the cell coordinates here (in [-3, face_cells + 3]) without the
// libm call that x86-64's baseline makes of std::floor (four a surfel cost about
// 4 ms a frame on the mock orbit, when every surfel took the footprint loop).
inline int floorCell(float x) { return static_cast<int>(x + 1024.0f) - 1024; }
constexpr float kMinEyeDistanceM = 1e-3f;  // nearer than this a surfel has no direction: sent, not splatted

}  // namespace

Status EyeViewConfig::validate() const {
  if (face_cells < 8 || face_cells > 2048) {
    return {ErrorCode::kInvalidArgument, "map.eye_face_cells: must be in [8, 2048]"};
  }
  if (!(std::isfinite(occlusion_margin) && occlusion_margin >= 0.0 && occlusion_margin <= 10.0)) {
    return {ErrorCode::kInvalidArgument, "map.occlusion_margin: must be in [0, 10]"};
  }
  return Status::ok();
}

EyeView::EyeView(const EyeViewConfig& config, std::size_t max_bricks)
    : config_(config),
      face_cells_(config.face_cells),
      nearest_(6 * static_cast<std::size_t>(config.face_cells) * static_cast<std::size_t>(config.face_cells)),
      brick_rel_(max_bricks) {}

Result<EyeView> EyeView::create(const EyeViewConfig& config, std::size_t max_bricks) {
  if (Status s = config.validate(); !s) return Result<EyeView>(s.code(), s.message());
  if (max_bricks == 0) return Result<EyeView>(ErrorCode::kInvalidArgument, "eye view: max_bricks is 0");
  return EyeView(config, max_bricks);
}

EyeView::Cell EyeView::cellOf(const Eigen::Vector3f& d) const {
  const float ax = std::abs(d.x()), ay = std::abs(d.y()), az = std::abs(d.z());
  Cell c;
  float a = 0.0f, b = 0.0f;
  if (ax >= ay && ax >= az) {
    c.face = d.x() >= 0.0f ? 0 : 1;
    c.axis = ax;
    a = d.y();
    b = d.z();
  } else if (ay >= az) {
    c.face = d.y() >= 0.0f ? 2 : 3;
    c.axis = ay;
    a = d.x();
    b = d.z();
  } else {
    c.face = d.z() >= 0.0f ? 4 : 5;
    c.axis = az;
    a = d.x();
    b = d.y();
  }
  // Face coordinates in [-1, 1] to cells; the clamp catches the rounding at +1.
  const float half = 0.5f * static_cast<float>(face_cells_);
  c.fu = (a / c.axis + 1.0f) * half;
  c.fv = (b / c.axis + 1.0f) * half;
  c.u = std::clamp(static_cast<int>(c.fu), 0, face_cells_ - 1);
  c.v = std::clamp(static_cast<int>(c.fv), 0, face_cells_ - 1);
  return c;
}

float EyeView::nearestAt(const Eigen::Vector3f& dir) const {
  if (!(dir.squaredNorm() > 0.0f) || !dir.allFinite()) return std::numeric_limits<float>::infinity();
  const Cell c = cellOf(dir);
  return nearest_[indexOf(c, c.u, c.v)];
}

void EyeView::appendVisible(const SurfelMap& map, const Eigen::Vector3d& eye_m, PointCloud& cloud,
                            EyeViewStats& stats) {
  const int64_t start_ns = monotonicNs();
  stats = {};
  std::fill(nearest_.begin(), nearest_.end(), std::numeric_limits<float>::infinity());
  stats.frame_points = static_cast<uint32_t>(cloud.size());
  // Everything relative to the cloud's origin in float: a map spans metres to
  // kilometres around it, and the differences below are taken in double first.
  const Eigen::Vector3f eye = (eye_m - cloud.origin_m).cast<float>();
  const std::size_t bricks = std::min(map.brickCount(), brick_rel_.size());
  for (std::size_t b = 0; b < bricks; ++b) {
    brick_rel_[b] = (map.brickOrigin(static_cast<uint16_t>(b)) - eye_m).cast<float>();
  }
  // Pass one: the nearest distance of every direction, from the frame's points
  // and the map's settled surfels; pass two: the surfels not behind it.
  splatFramePoints(cloud, eye);
  splatSurfels(map, bricks, stats);
  appendUnhidden(map, bricks, eye, cloud, stats);
  stats.ns = monotonicNs() - start_ns;
}

// The frame's points already in the cloud, each in its cell (a moving object
// hides the wall behind it).
void EyeView::splatFramePoints(const PointCloud& cloud, const Eigen::Vector3f& eye) {
  const float* px = cloud.x();
  const float* py = cloud.y();
  const float* pz = cloud.z();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f d(px[i] - eye.x(), py[i] - eye.y(), pz[i] - eye.z());
    const float dist = d.norm();
    if (!(dist >= kMinEyeDistanceM) || !std::isfinite(dist)) continue;
    const Cell c = cellOf(d);
    float& held = nearest_[indexOf(c, c.u, c.v)];
    held = std::min(held, dist);
  }
}

// The map's settled surfels over their footprints (on their own face: a
// footprint that crosses a cube edge leaves the other face's cells as they
// were, which can only show more, never hide).
void EyeView::splatSurfels(const SurfelMap& map, std::size_t bricks, EyeViewStats& stats) {
  const float half = 0.5f * static_cast<float>(face_cells_);
  const std::size_t slots = map.slotCount();
  for (std::size_t slot = 0; slot < slots; ++slot) {
    if (!map.live(slot)) continue;
    const Surfel& s = map.surfel(slot);
    if (!(s.flags & kSurfelSettled) || s.brick >= bricks) continue;
    ++stats.settled;
    const Eigen::Vector3f d = brick_rel_[s.brick] + Eigen::Vector3f(s.x, s.y, s.z);
    const float dist = d.norm();
    if (!(dist >= kMinEyeDistanceM)) continue;
    const Cell c = cellOf(d);
    // The footprint covers its own cell and every cell whose centre lies within
    // its radius of the surfel's exact position. Neighbouring surfels' discs
    // overlap, so their union covers every cell between them. (Rounding the
    // radius down to whole cells around the surfel's cell instead turned 1.8
    // cells into a cross of 5 and left a grid of holes between surfels 1.4 cells
    // apart: from 1.4 m at 160x120, the wall showed through a box.)
    const float radius = std::min(kMaxSplatCells, surfelRadius(s) / c.axis * half);
    float& own = nearest_[indexOf(c, c.u, c.v)];
    own = std::min(own, dist);
    // Fusion gives a surfel sqrt(2) times its pixel's footprint (map_kernels.cpp),
    // so a radius under one cell means surfels at most 0.71 cells apart: every
    // cell of the surface then holds a surfel of its own (a disc of radius 0.5,
    // the lattice's covering radius, fits in a cell). Most surfels take this path.
    if (radius >= 1.0f) splatDisc(c, radius, dist);
  }
}

// The cells of c's face whose centre lies within `radius` cells of the
// surfel's position take `dist` where it is nearer.
void EyeView::splatDisc(const Cell& c, float radius, float dist) {
  // Only the cells whose centre (u + 0.5) can lie within the radius.
  const int u0 = std::max(0, -floorCell(radius + 0.5f - c.fu));
  const int u1 = std::min(face_cells_ - 1, floorCell(c.fu + radius - 0.5f));
  const int v0 = std::max(0, -floorCell(radius + 0.5f - c.fv));
  const int v1 = std::min(face_cells_ - 1, floorCell(c.fv + radius - 0.5f));
  for (int v = v0; v <= v1; ++v) {
    const float dv = static_cast<float>(v) + 0.5f - c.fv;
    for (int u = u0; u <= u1; ++u) {
      const float du = static_cast<float>(u) + 0.5f - c.fu;
      if (du * du + dv * dv > radius * radius) continue;
      float& held = nearest_[indexOf(c, u, v)];
      held = std::min(held, dist);
    }
  }
}

// Pass two: the settled surfels not behind their cell's nearest surface, into the cloud.
void EyeView::appendUnhidden(const SurfelMap& map, std::size_t bricks, const Eigen::Vector3f& eye, PointCloud& cloud,
                             EyeViewStats& stats) const {
  const auto margin = static_cast<float>(config_.occlusion_margin);
  const std::size_t slots = map.slotCount();
  for (std::size_t slot = 0; slot < slots; ++slot) {
    if (!map.live(slot)) continue;
    const Surfel& s = map.surfel(slot);
    if (!(s.flags & kSurfelSettled) || s.brick >= bricks) continue;
    const Eigen::Vector3f d = brick_rel_[s.brick] + Eigen::Vector3f(s.x, s.y, s.z);
    const float dist = d.norm();
    if (dist >= kMinEyeDistanceM) {
      const Cell c = cellOf(d);
      if (dist > nearest_[indexOf(c, c.u, c.v)] + margin * dist + 3.0f * depthSigma(dist)) {
        ++stats.hidden;
        continue;
      }
    }
    const Eigen::Vector3f p = d + eye;
    if (!cloud.push(p.x(), p.y(), p.z(), packRgb(s.red, s.green, s.blue))) {
      ++stats.dropped_full;
      continue;
    }
    ++stats.appended;
  }
}

}  // namespace fovea::pipeline::map
