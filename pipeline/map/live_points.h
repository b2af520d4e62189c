// A frame's live points within a fixed capacity (issue 41, part 5: memory).
//
// With bricks the operator keeps the map, so a frame carries only its points
// the map does not explain: a few tens of thousands once the map has settled
// (the mock orbit: 34 863 a frame median, 46 202 at p90, before foveation),
// and the whole frame only while the map is new (its first half second) or
// after a turn into unmapped space. The cloud that holds them, and the
// foveator's per-point scratch after it, are sized for the common case, not
// for every pixel; a frame with more candidates than fit is thinned here, by a
// rule that keeps the eye's detail:
//  - the points within `whole_deg` of the gaze (the fovea and a margin for the
//    gaze's movement since it was last known) are all kept;
//  - of the others, only the pixels on a grid of `stride` (u and v multiples of
//    it), the finest stride from 2 to kMaxStride whose points fit. The foveator
//    then samples them into voxels larger than a few pixels anyway.
// A frame whose points do not fit even so is refused (kCapacityExceeded).
//
// The candidates come from a source that calls a LivePointSink for each point
// in pixel order (SurfelMap, ExplainedView, or every valid pixel:
// pipeline/backproject.h); collectLivePoints() runs it once when everything
// fits, else three times (take until full, count per stride, take thinned).
// Nothing allocates.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include <Eigen/Core>

#include "core/result.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline::map {

// Which points a thinned frame keeps. Positions are relative to the cloud's origin.
struct LiveSelection {
  static constexpr int kMaxStride = 4;
  int stride = 1;                                     // 1: every point
  Eigen::Vector3f eye_m = Eigen::Vector3f::Zero();    // the gaze's origin
  Eigen::Vector3f gaze = Eigen::Vector3f::UnitZ();    // unit
  float whole_cos = 1.0f;                             // cos(whole_deg); > 1 keeps none whole

  static bool onGrid(int u, int v, int stride) { return u % stride == 0 && v % stride == 0; }
  bool whole(const Eigen::Vector3f& p) const {
    const Eigen::Vector3f d = p - eye_m;
    return d.dot(gaze) >= whole_cos * d.norm();
  }
  bool keeps(int u, int v, const Eigen::Vector3f& p) const {
    return stride == 1 || onGrid(u, v, stride) || whole(p);
  }
};

// Takes a candidate point (relative to the cloud's origin) at pixel (u, v);
// false stops the source.
class LivePointSink {
 public:
  virtual bool take(int u, int v, const Eigen::Vector3f& p, uint32_t rgb) = 0;

 protected:
  ~LivePointSink() = default;
};

// Pushes the points the selection keeps; stops at the first that does not fit.
class LivePointPush final : public LivePointSink {
 public:
  LivePointPush(const LiveSelection& selection, PointCloud& out) : selection_(selection), out_(out) {}
  bool take(int u, int v, const Eigen::Vector3f& p, uint32_t rgb) override {
    if (!selection_.keeps(u, v, p)) return true;
    if (out_.push(p.x(), p.y(), p.z(), rgb)) return true;
    overflowed_ = true;
    return false;
  }
  bool overflowed() const { return overflowed_; }

 private:
  const LiveSelection& selection_;
  PointCloud& out_;
  bool overflowed_ = false;
};

// Counts what each stride would keep.
class LivePointTally final : public LivePointSink {
 public:
  explicit LivePointTally(const LiveSelection& selection) : selection_(selection) {}
  bool take(int u, int v, const Eigen::Vector3f& p, uint32_t) override;
  // The points stride s keeps (1 <= s <= kMaxStride).
  std::size_t kept(int stride) const { return kept_[static_cast<std::size_t>(stride)]; }
  // The finest stride whose points fit `capacity`; 0 when none does.
  int finestStrideWithin(std::size_t capacity) const;

 private:
  const LiveSelection& selection_;
  std::array<std::size_t, LiveSelection::kMaxStride + 1> kept_{};  // [s]: on stride s's grid or in the cone
};

struct LivePointStats {
  uint32_t candidates = 0;  // the source's points (counted only when thinned; else the points kept)
  uint8_t stride = 1;       // the grid outside the gaze's cone: 1 when not thinned
};

// Fills `out` (cleared first; its origin kept) from `visit_all(sink)`, which
// must offer the same points in the same order on every call.
template <typename VisitAll>
Status collectLivePoints(VisitAll&& visit_all, LiveSelection selection, PointCloud& out, LivePointStats& stats) {
  stats = {};
  out.clear();
  selection.stride = 1;
  LivePointPush all(selection, out);
  visit_all(static_cast<LivePointSink&>(all));
  stats.candidates = static_cast<uint32_t>(out.size());
  if (!all.overflowed()) return Status::ok();
  out.clear();
  LivePointTally tally(selection);
  visit_all(static_cast<LivePointSink&>(tally));
  stats.candidates = static_cast<uint32_t>(tally.kept(1));
  selection.stride = tally.finestStrideWithin(out.capacity());
  if (selection.stride == 0) {
    return {ErrorCode::kCapacityExceeded,
            "live points: " + std::to_string(tally.kept(LiveSelection::kMaxStride)) +
                " even on every " + std::to_string(LiveSelection::kMaxStride) +
                "th pixel outside the gaze's cone, capacity " + std::to_string(out.capacity())};
  }
  stats.stride = static_cast<uint8_t>(selection.stride);
  LivePointPush thinned(selection, out);
  visit_all(static_cast<LivePointSink&>(thinned));
  return Status::ok();
}

}  // namespace fovea::pipeline::map
