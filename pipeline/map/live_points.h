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
// A frame whose points do not fit even so keeps the grid of kMaxStride
// alone, the cone's pixels too (LivePointStats::cone_thinned): the operator
// then holds little of what the camera sees (a new session, or one that lost
// its bricks, since only held surface explains a pixel), and a frame dropped
// for it would send no bricks either, so that the next frames would not fit
// again. Only when even that grid's points do not fit is the frame refused
// (kCapacityExceeded).
//
// The candidates come from a source that calls a LivePointSink for each point
// in pixel order (SurfelMap, ExplainedView, or every valid pixel:
// pipeline/backproject.h). LiveCollector runs it once when everything fits;
// else it counts what each stride would keep (marking the pixels within the
// cone), then takes the thinned points, the source skipping every other pixel
// before its work (LivePointSink::skips). A frame after a thinned one is
// counted as it is taken, since it likely needs thinning too. Memory: a bit a
// pixel of the largest frame, allocated by the constructor.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

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

// Which pixels a pass wants at all: those on the stride's grid or marked
// within the cone (a bit a pixel, row-major at `width`). Sources ask before
// their work, so the thinned pass costs what it keeps.
struct LivePixelFilter {
  int stride = 1;
  int width = 0;
  const uint64_t* cone_bits = nullptr;
  bool keeps(int u, int v) const {
    if (LiveSelection::onGrid(u, v, stride)) return true;
    const std::size_t i = static_cast<std::size_t>(v) * static_cast<std::size_t>(width) + static_cast<std::size_t>(u);
    return (cone_bits[i >> 6] >> (i & 63u)) & 1u;
  }
};

// Takes a candidate point (relative to the cloud's origin) at pixel (u, v);
// false stops the source. A source skips the pixels skips() names before it
// works on them (a filter is an optimisation: take() still selects).
class LivePointSink {
 public:
  virtual bool take(int u, int v, const Eigen::Vector3f& p, uint32_t rgb) = 0;
  bool skips(int u, int v) const { return filter_ != nullptr && !filter_->keeps(u, v); }
  bool filtered() const { return filter_ != nullptr; }
  void setFilter(const LivePixelFilter* filter) { filter_ = filter; }

 protected:
  ~LivePointSink() = default;

 private:
  const LivePixelFilter* filter_ = nullptr;
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

// Counts what each stride would keep and marks the candidates within the cone
// (cone_bits, cleared by the caller).
class LivePointTally final : public LivePointSink {
 public:
  LivePointTally(const LiveSelection& selection, int width, uint64_t* cone_bits)
      : selection_(selection), width_(width), cone_bits_(cone_bits) {}
  bool take(int u, int v, const Eigen::Vector3f& p, uint32_t) override;
  // The points stride s keeps (1 <= s <= kMaxStride).
  std::size_t kept(int stride) const { return kept_[static_cast<std::size_t>(stride)]; }
  // The finest stride whose points fit `capacity`; 0 when none does.
  int finestStrideWithin(std::size_t capacity) const;
  // The points on kMaxStride's grid, the cone's or not.
  std::size_t onCoarsestGrid() const { return on_coarsest_grid_; }

 private:
  const LiveSelection& selection_;
  int width_;
  uint64_t* cone_bits_;
  std::array<std::size_t, LiveSelection::kMaxStride + 1> kept_{};  // [s]: on stride s's grid or in the cone
  std::size_t on_coarsest_grid_ = 0;
};

// Both at once: takes the points while they fit and counts all of them.
class LivePointPushAndTally final : public LivePointSink {
 public:
  LivePointPushAndTally(LivePointPush& push, LivePointTally& tally) : push_(push), tally_(tally) {}
  bool take(int u, int v, const Eigen::Vector3f& p, uint32_t rgb) override {
    (void)tally_.take(u, v, p, rgb);
    if (!push_.overflowed()) (void)push_.take(u, v, p, rgb);
    return true;
  }

 private:
  LivePointPush& push_;
  LivePointTally& tally_;
};

struct LivePointStats {
  uint32_t candidates = 0;  // the source's points (when not thinned: those taken)
  uint8_t stride = 1;       // the grid outside the gaze's cone: 1 when not thinned
  bool cone_thinned = false;  // ... and inside it too (the grid of kMaxStride alone)
  uint8_t passes = 0;       // the source's runs
};

class LiveCollector {
 public:
  LiveCollector(int max_width, int max_height);

  // Fills `out` (cleared first; its origin kept) with the points of a frame
  // of width x height pixels from `visit_all(sink)`, which offers the same
  // points in the same order on every call (skipping those sink.skips()
  // names). The last call whose sink is not filtered() has seen every point
  // (a source counting the frame's pixels keeps that call's counts).
  // kCapacityExceeded (`out` empty) when even the grid of kMaxStride alone
  // does not fit; kInvalidInput for a frame larger than the constructor's.
  template <typename VisitAll>
  Status collect(VisitAll&& visit_all, LiveSelection selection, int width, int height, PointCloud& out,
                 LivePointStats& stats);

  std::size_t memoryBytes() const { return cone_bits_.capacity() * sizeof(uint64_t); }

 private:
  static Status overCapacity(std::size_t kept, std::size_t capacity);
  bool fits(int width, int height) const;
  std::vector<uint64_t> cone_bits_;
  bool last_thinned_ = false;
};

template <typename VisitAll>
Status LiveCollector::collect(VisitAll&& visit_all, LiveSelection selection, int width, int height, PointCloud& out,
                              LivePointStats& stats) {
  stats = {};
  out.clear();
  if (!fits(width, height)) return {ErrorCode::kInvalidInput, "live points: the frame is larger than the collector's"};
  selection.stride = 1;
  LivePointPush all(selection, out);
  LivePointTally tally(selection, width, cone_bits_.data());
  std::fill(cone_bits_.begin(), cone_bits_.end(), 0);
  if (last_thinned_) {
    LivePointPushAndTally both(all, tally);
    visit_all(static_cast<LivePointSink&>(both));
  } else {
    visit_all(static_cast<LivePointSink&>(all));
    if (all.overflowed()) visit_all(static_cast<LivePointSink&>(tally));
  }
  stats.passes = static_cast<uint8_t>(last_thinned_ || !all.overflowed() ? 1 : 2);
  last_thinned_ = all.overflowed();
  stats.candidates = static_cast<uint32_t>(all.overflowed() ? tally.kept(1) : out.size());
  if (!all.overflowed()) return Status::ok();
  out.clear();
  selection.stride = tally.finestStrideWithin(out.capacity());
  if (selection.stride == 0) {
    if (tally.onCoarsestGrid() > out.capacity()) return overCapacity(tally.onCoarsestGrid(), out.capacity());
    selection.stride = LiveSelection::kMaxStride;
    selection.whole_cos = 2.0f;  // no point is within the cone
    std::fill(cone_bits_.begin(), cone_bits_.end(), 0);
    stats.cone_thinned = true;
  }
  stats.stride = static_cast<uint8_t>(selection.stride);
  const LivePixelFilter filter{selection.stride, width, cone_bits_.data()};
  LivePointPush kept(selection, out);
  kept.setFilter(&filter);
  visit_all(static_cast<LivePointSink&>(kept));
  ++stats.passes;
  return Status::ok();
}

}  // namespace fovea::pipeline::map
