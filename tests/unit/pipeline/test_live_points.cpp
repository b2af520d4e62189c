// A frame's live points within a fixed capacity (pipeline/map/live_points.h):
// against a selection written here by brute force, on random candidates and
// on the mock living room's first frame as the map offers it, and the hard
// cases: a capacity met exactly, none, no cone, a cone holding everything,
// a point at the eye.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/map/live_points.h"
#include "pipeline/map/mapper.h"
#include "pipeline/map/surfel_map.h"
#include "tests/support/cameras.h"
#include "tests/support/test_time.h"

namespace fovea::pipeline::map {
namespace {

struct Candidate {
  int u = 0, v = 0;
  Eigen::Vector3f p;
  uint32_t rgb = 0;
};

// Offers a list, as a source does a frame, skipping what the sink's filter
// skips.
struct ListSource {
  const std::vector<Candidate>* list;
  int calls = 0;
  void operator()(LivePointSink& sink) {
    ++calls;
    for (const Candidate& c : *list) {
      if (sink.skips(c.u, c.v)) continue;
      if (!sink.take(c.u, c.v, c.p, c.rgb)) return;
    }
  }
};

// Records what a source offers.
struct Recorder final : LivePointSink {
  std::vector<Candidate> seen;
  bool take(int u, int v, const Eigen::Vector3f& p, uint32_t rgb) override {
    seen.push_back({u, v, p, rgb});
    return true;
  }
};

// The reference: every candidate when they fit; else the finest stride from
// 2 to 4 whose grid points plus the points within the cone fit, trying each
// stride on every candidate; else the points on the grid of 4 alone, the
// cone's too (cone_thinned), when they fit; else none (stride 0). The cone's
// test is the float arithmetic the header states (a double one would differ
// on points at its edge).
std::vector<Candidate> selectByBruteForce(const std::vector<Candidate>& all, const LiveSelection& s,
                                          std::size_t capacity, int& stride, bool& cone_thinned) {
  stride = 1;
  cone_thinned = false;
  if (all.size() <= capacity) return all;
  auto whole = [&](const Candidate& c) {
    const Eigen::Vector3f d = c.p - s.eye_m;
    return d.dot(s.gaze) >= s.whole_cos * d.norm();
  };
  for (stride = 2; stride <= LiveSelection::kMaxStride; ++stride) {
    std::vector<Candidate> kept;
    for (const Candidate& c : all) {
      if ((c.u % stride == 0 && c.v % stride == 0) || whole(c)) kept.push_back(c);
    }
    if (kept.size() <= capacity) return kept;
  }
  std::vector<Candidate> grid;
  for (const Candidate& c : all) {
    if (c.u % LiveSelection::kMaxStride == 0 && c.v % LiveSelection::kMaxStride == 0) grid.push_back(c);
  }
  stride = grid.size() <= capacity ? LiveSelection::kMaxStride : 0;
  cone_thinned = stride != 0;
  return stride != 0 ? grid : std::vector<Candidate>{};
}

void expectSame(const PointCloud& cloud, const std::vector<Candidate>& expected) {
  ASSERT_EQ(cloud.size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    ASSERT_EQ(cloud.x()[i], expected[i].p.x()) << i;
    ASSERT_EQ(cloud.y()[i], expected[i].p.y()) << i;
    ASSERT_EQ(cloud.z()[i], expected[i].p.z()) << i;
    ASSERT_EQ(cloud.rgb()[i], expected[i].rgb) << i;
  }
}

// Runs a collector and the reference on one list and capacity: `fresh` a new
// collector, else one whose last frame was thinned.
void checkAgainstReference(const std::vector<Candidate>& all, const LiveSelection& selection, std::size_t capacity,
                           int w, int h, bool fresh = true) {
  LiveCollector collector(w, h);
  PointCloud cloud(capacity);
  LivePointStats stats;
  if (!fresh) {  // a frame of one point more than fits: thinned
    std::vector<Candidate> over(capacity + 1, Candidate{0, 0, Eigen::Vector3f(0, 0, 1), 0});
    ListSource before{&over};
    (void)collector.collect(before, selection, w, h, cloud, stats);
    ASSERT_GE(stats.passes, 2) << "the frame before did not fit";
  }
  ListSource source{&all};
  const Status s = collector.collect(source, selection, w, h, cloud, stats);
  int stride = 0;
  bool cone_thinned = false;
  const std::vector<Candidate> expected = selectByBruteForce(all, selection, capacity, stride, cone_thinned);
  if (stride == 0) {
    EXPECT_EQ(s.code(), ErrorCode::kCapacityExceeded);
    EXPECT_EQ(cloud.size(), 0u) << "a refused frame leaves no points";
    return;
  }
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(stats.stride, stride);
  EXPECT_EQ(stats.cone_thinned, cone_thinned);
  EXPECT_EQ(stats.candidates, all.size());
  // Fresh: once when everything fits, else take until full, count, take
  // thinned; after a thinned frame: take and count at once, then thinned.
  const int passes = stride == 1 ? 1 : fresh ? 3 : 2;
  EXPECT_EQ(source.calls, passes);
  EXPECT_EQ(stats.passes, passes);
  expectSame(cloud, expected);
}

std::vector<Candidate> randomCandidates(std::mt19937& rng, int w, int h, double valid_share) {
  std::uniform_real_distribution<float> pos(-3.0f, 3.0f);
  std::bernoulli_distribution valid(valid_share);
  std::vector<Candidate> all;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      if (valid(rng)) all.push_back({u, v, Eigen::Vector3f(pos(rng), pos(rng), pos(rng)), static_cast<uint32_t>(rng())});
    }
  }
  return all;
}

LiveSelection randomSelection(std::mt19937& rng) {
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  std::uniform_real_distribution<float> deg(0.0f, 60.0f);
  LiveSelection s;
  s.eye_m = Eigen::Vector3f(unit(rng), unit(rng), unit(rng));
  s.gaze = Eigen::Vector3f(unit(rng), unit(rng), unit(rng) + 2.0f).normalized();
  s.whole_cos = std::cos(deg(rng) * static_cast<float>(M_PI / 180.0));
  return s;
}

TEST(LivePoints, RandomCandidatesAreSelectedAsTheBruteForceSelectsThem) {
  std::mt19937 rng(41);
  for (int trial = 0; trial < 60; ++trial) {
    const std::vector<Candidate> all = randomCandidates(rng, 48, 36, trial % 3 == 0 ? 1.0 : 0.6);
    const LiveSelection selection = randomSelection(rng);
    std::uniform_int_distribution<std::size_t> capacity(0, all.size() + 10);
    SCOPED_TRACE(trial);
    checkAgainstReference(all, selection, capacity(rng), 48, 36, trial % 2 == 0);
  }
}

TEST(LivePoints, HardCases) {
  constexpr int kW = 40, kH = 30;
  std::mt19937 rng(7);
  const std::vector<Candidate> all = randomCandidates(rng, kW, kH, 1.0);
  LiveSelection selection = randomSelection(rng);
  for (bool fresh : {true, false}) {
    SCOPED_TRACE(fresh ? "fresh" : "after a thinned frame");
    checkAgainstReference(all, selection, all.size(), kW, kH, fresh);      // exactly full: every point
    checkAgainstReference(all, selection, all.size() - 1, kW, kH, fresh);  // one short: thinned
    checkAgainstReference(all, selection, 0, kW, kH, fresh);               // no room at all
    LiveSelection no_cone = selection;
    no_cone.whole_cos = 2.0f;  // the grids alone
    checkAgainstReference(all, no_cone, all.size() / 4, kW, kH, fresh);
    checkAgainstReference(all, no_cone, 80, kW, kH, fresh);  // the 4-grid of 40 x 30 exactly
    checkAgainstReference(all, no_cone, 79, kW, kH, fresh);  // not even that
    // A cone too wide for any grid: the 4-grid alone, the cone's pixels too,
    // rather than no frame (it fits exactly), and no frame when not even that.
    LiveSelection wide = selection;
    wide.whole_cos = -1.0f;
    checkAgainstReference(all, wide, 80, kW, kH, fresh);
    checkAgainstReference(all, wide, 79, kW, kH, fresh);
    LiveSelection everything = selection;
    everything.whole_cos = -1.0f;  // a cone of every direction: nothing thins
    checkAgainstReference(all, everything, all.size() / 2, kW, kH, fresh);
    // A point at the eye is within any cone (its direction is none).
    std::vector<Candidate> at_eye = all;
    LiveSelection narrow = selection;
    narrow.whole_cos = 1.0f;
    for (Candidate& c : at_eye) c.p = narrow.eye_m;
    checkAgainstReference(at_eye, narrow, 10, kW, kH, fresh);
  }
  // A frame larger than the collector's is refused, never written past.
  LiveCollector small(kW, kH);
  PointCloud cloud(16);
  LivePointStats stats;
  ListSource source{&all};
  EXPECT_EQ(small.collect(source, selection, kW + 1, kH, cloud, stats).code(), ErrorCode::kInvalidInput);
  EXPECT_EQ(small.collect(source, selection, kW, kH + 1, cloud, stats).code(), ErrorCode::kInvalidInput);
  EXPECT_EQ(source.calls, 0);
}

// The map's first frame of the mock living room: nothing is explained yet, so
// every valid pixel is a candidate; a cloud of a sixth of the pixels takes the
// cone whole and a grid of the rest, as the reference selects from what the
// map offers.
TEST(LivePoints, TheMapsFirstFrameIsThinnedOutsideTheConeAsTheReferenceThinsIt) {
  constexpr int kW = 160, kH = 120;
  std::unique_ptr<hal::Camera> camera = test::startedCamera("mock:living-room,size=160x120,path=orbit");
  ASSERT_TRUE(camera);
  SurfelMapConfig config;
  config.max_width = kW;
  config.max_height = kH;
  config.max_surfels = 1 << 16;
  config.max_bricks = 1024;
  SurfelMap map = SurfelMap::create(config).value();
  hal::RgbdFrame frame(kW, kH);
  ASSERT_TRUE(camera->acquire(frame, test::scaled(std::chrono::seconds(1))).isOk());
  FuseStats stats;
  ASSERT_EQ(map.fuse(frame, stats), FuseOutcome::kFused);
  const Eigen::Vector3d origin = frame.T_world_cam.t_world_cam;
  Recorder offered;
  ASSERT_TRUE(map.visitUnexplained(frame, origin, offered));
  ASSERT_GT(offered.seen.size(), static_cast<std::size_t>(kW) * kH / 2) << "a new map explains little";
  LiveSelection selection;
  selection.eye_m = Eigen::Vector3f::Zero();
  selection.gaze = frame.T_world_cam.R_world_cam.col(2).cast<float>();
  selection.whole_cos = std::cos(static_cast<float>(10.0 * M_PI / 180.0));
  const std::size_t capacity = static_cast<std::size_t>(kW) * kH / 6;
  PointCloud cloud(capacity);
  cloud.origin_m = origin;
  LivePointStats live;
  LiveCollector collector(kW, kH);
  ASSERT_TRUE(collector
                  .collect([&](LivePointSink& sink) { (void)map.visitUnexplained(frame, origin, sink); }, selection,
                           kW, kH, cloud, live)
                  .isOk());
  int stride = 0;
  bool cone_thinned = false;
  const std::vector<Candidate> expected = selectByBruteForce(offered.seen, selection, capacity, stride, cone_thinned);
  ASSERT_GT(stride, 1);
  ASSERT_FALSE(cone_thinned);
  EXPECT_EQ(live.stride, stride);
  expectSame(cloud, expected);
  // Every point in the cone is there.
  std::size_t in_cone = 0;
  for (const Candidate& c : offered.seen) in_cone += selection.whole(c.p) ? 1 : 0;
  std::size_t kept_in_cone = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    kept_in_cone += selection.whole(Eigen::Vector3f(cloud.x()[i], cloud.y()[i], cloud.z()[i])) ? 1 : 0;
  }
  EXPECT_GT(in_cone, 0u);
  EXPECT_EQ(kept_in_cone, in_cone);
  // The fused frame alone is offered: another stamp gets nothing.
  hal::RgbdFrame other = frame;
  other.stamp_ns += 1;
  Recorder none;
  EXPECT_FALSE(map.visitUnexplained(other, origin, none));
  EXPECT_TRUE(none.seen.empty());
}

// The mapper's three sources through one small cloud: a frame fused now, one
// left unfused (judged by the last fused view) and one refused (every valid
// pixel). Each is thinned, and the two that judge the pixels themselves count
// the frame's valid pixels whole, though their first pass stopped when the
// cloud was full.
TEST(LivePoints, TheMappersSourcesThinIntoASmallCloudAndCountTheWholeFrame) {
  constexpr int kW = 160, kH = 120;
  std::unique_ptr<hal::Camera> camera = test::startedCamera("mock:living-room,size=160x120,path=orbit");
  ASSERT_TRUE(camera);
  MapperConfig config;
  config.map.max_width = kW;
  config.map.max_height = kH;
  config.map.max_surfels = 1 << 16;
  config.map.max_bricks = 1024;
  config.output = MapOutput::kBricks;
  // Every settled surfel explains (no bricks are planned here; explaining by
  // held surfels alone has its own test, test_surfel_map's MapDelta tests).
  config.delta.explain_held_only = false;
  Mapper mapper = Mapper::create(config).value();
  hal::RgbdFrame frame(kW, kH);
  const auto validPixels = [&] {
    const PixelBackprojection rule(frame, config.map.depth);
    uint32_t n = 0;
    rule.forEachPoint(frame, [&](int, int, std::size_t, const Eigen::Vector3f&) { return ++n > 0; });
    return n;
  };
  LiveSelection selection;
  selection.gaze = Eigen::Vector3f::UnitZ();
  selection.whole_cos = std::cos(static_cast<float>(8.0 * M_PI / 180.0));
  PointCloud cloud(static_cast<std::size_t>(kW) * kH / 8);
  for (int i = 0; i < 14; ++i) {  // the map settles, so that its view explains
    ASSERT_TRUE(camera->acquire(frame, test::scaled(std::chrono::seconds(1))).isOk());
    MapperFrame fused;
    ASSERT_TRUE(mapper.addFrame(frame, true, fused));
    if (i == 0) {
      cloud.origin_m = frame.T_world_cam.t_world_cam;
      LiveFigures live;
      ASSERT_TRUE(mapper.collectLive(frame, fused, config.map.depth, selection, cloud, live).isOk());
      EXPECT_GT(live.points.stride, 1) << "the first frame is all unexplained";
      EXPECT_GT(live.points.candidates, cloud.capacity());
      EXPECT_GT(cloud.size(), 0u);
      EXPECT_EQ(live.valid, fused.fuse.pixels_valid) << "fused now: the map's count";
    }
  }
  ASSERT_TRUE(camera->acquire(frame, test::scaled(std::chrono::seconds(1))).isOk());
  cloud.origin_m = frame.T_world_cam.t_world_cam;
  MapperFrame unfused;
  unfused.pose_usable = true;
  unfused.fusion_skipped = true;
  PointCloud roomy(static_cast<std::size_t>(kW) * kH);
  roomy.origin_m = cloud.origin_m;
  LiveFigures all;  // fits: not thinned, so the next frame's first pass stops when full
  ASSERT_TRUE(mapper.collectLive(frame, unfused, config.map.depth, selection, roomy, all).isOk());
  EXPECT_EQ(all.points.stride, 1);
  EXPECT_EQ(all.valid, validPixels());
  EXPECT_EQ(all.explained_by_last_view + roomy.size(), all.valid);
  LiveFigures live;
  PointCloud tiny(200);
  tiny.origin_m = cloud.origin_m;
  ASSERT_TRUE(mapper.collectLive(frame, unfused, config.map.depth, selection, tiny, live).isOk());
  EXPECT_GT(live.points.stride, 1);
  EXPECT_EQ(live.points.passes, 3) << "take until full, count, take thinned";
  EXPECT_EQ(live.valid, validPixels());
  EXPECT_GT(live.explained_by_last_view, live.valid / 3) << "the settled map explains much of a nearby view";
  EXPECT_EQ(live.explained_by_last_view + live.points.candidates, live.valid);
  MapperFrame refused;  // no pose: every valid pixel
  refused.fuse.outcome = FuseOutcome::kRefusedNoPose;
  LiveFigures whole;
  ASSERT_TRUE(mapper.collectLive(frame, refused, config.map.depth, selection, cloud, whole).isOk());
  EXPECT_EQ(whole.valid, validPixels());
  EXPECT_EQ(whole.explained_by_last_view, 0u);
  EXPECT_EQ(whole.points.candidates, whole.valid);
  EXPECT_GT(whole.points.stride, 1);
}

}  // namespace
}  // namespace fovea::pipeline::map
