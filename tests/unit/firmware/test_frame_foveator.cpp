// The service's foveation stage (firmware/frame_foveator.h) with each source:
// the frame source is exactly back-projection and foveation; the map source
// fuses, gathers what the eye sees of the map and the frame's unexplained
// points, and foveates them with every preset; a frame without a pose or a bad
// gaze is a counted refusal or an error, never a crash.
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "firmware/frame_foveator.h"
#include "hal/camera.h"
#include "pipeline/kernels/backprojector.h"
#include "tests/support/test_time.h"

namespace fovea::firmware {
namespace {

constexpr const char* kCamera = "mock:living-room,path=orbit,size=160x120";

struct Rig {
  std::unique_ptr<hal::Camera> camera;
  hal::RgbdFrame frame;
  std::size_t pixels = 0;
  int width = 0, height = 0;
};

Rig openRig() {
  Rig rig;
  Result<std::unique_ptr<hal::Camera>> camera = hal::createCamera(kCamera);
  EXPECT_TRUE(camera.isOk()) << camera.status().toString();
  if (!camera.isOk()) return rig;
  rig.camera = std::move(camera.value());
  EXPECT_TRUE(rig.camera->open().isOk());
  EXPECT_TRUE(rig.camera->start().isOk());
  const hal::CameraIntrinsics& k = rig.camera->info().intrinsics;
  rig.width = k.width;
  rig.height = k.height;
  rig.pixels = static_cast<std::size_t>(k.width) * k.height;
  rig.frame = hal::RgbdFrame(k.width, k.height);
  return rig;
}

MapSettings mapSource(std::size_t max_surfels = 1 << 16) {
  MapSettings settings;
  settings.source = FoveationSource::kMap;
  settings.map.max_surfels = max_surfels;
  return settings;
}

pipeline::Gaze gazeFor(const hal::RgbdFrame& frame) {
  pipeline::Gaze gaze;
  gaze.origin_m = frame.T_world_cam.t_world_cam;
  gaze.direction = frame.T_world_cam.R_world_cam.col(2);
  return gaze;
}

TEST(FrameFoveator, SourceNamesParse) {
  EXPECT_EQ(parseFoveationSource("frame"), FoveationSource::kFrame);
  EXPECT_EQ(parseFoveationSource("map"), FoveationSource::kMap);
  EXPECT_EQ(parseFoveationSource("pyramid"), FoveationSource::kPyramid);
  EXPECT_EQ(foveationSourceName(FoveationSource::kPyramid), "pyramid");
  EXPECT_FALSE(parseFoveationSource("Map").has_value());
  EXPECT_FALSE(parseFoveationSource("").has_value());
  EXPECT_EQ(foveationSourceName(FoveationSource::kMap), "map");
  EXPECT_EQ(FrameFoveator::cloudCapacity(100, MapSettings{}), 100u);
  EXPECT_EQ(FrameFoveator::cloudCapacity(100, mapSource(50)), 150u);
  // With bricks the operator keeps the map: the cloud is the frame's live points.
  MapSettings bricks = mapSource(50);
  bricks.delta = true;
  EXPECT_EQ(FrameFoveator::cloudCapacity(100, bricks), 100u);
  // A frame's bricks: what the largest budget pays for in a frame, at least one brick.
  EXPECT_EQ(frameBrickPoints(12.5e6, 30.0, 1 << 16), 92593u);
  EXPECT_EQ(frameBrickPoints(12.5e6, 30.0, 1 << 17), std::size_t{1} << 17);
  EXPECT_EQ(frameBrickPoints(12.5e6, 0.0, 1), 2777778u);  // no rate: as at 1 fps
}

// The frame source is the plain pipeline: the same points out as a
// Backprojector and a Foveator of its own.
TEST(FrameFoveator, TheFrameSourceIsBackProjectionAndFoveation) {
  Rig rig = openRig();
  ASSERT_TRUE(rig.camera);
  const pipeline::PipelineCapacity capacity{rig.pixels, rig.pixels, fovea::defaultKernelSet(), 1};
  Result<FrameFoveator> stage = FrameFoveator::create(capacity, {}, {}, {}, rig.width, rig.height);
  ASSERT_TRUE(stage.isOk()) << stage.status().toString();
  EXPECT_EQ(stage->map(), nullptr);
  EXPECT_EQ(stage->mapMemoryBytes(), 0u);
  pipeline::Backprojector backprojector(1, capacity.kernels);
  pipeline::PointCloud cloud(rig.pixels);
  pipeline::Foveator foveator = pipeline::Foveator::create(capacity, {}).value();
  pipeline::FoveatedCloud a(rig.pixels), b(rig.pixels);
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(rig.camera->acquire(rig.frame, test::scaled(std::chrono::seconds(1))).isOk());
    pipeline::BackprojectCounts counts;
    pipeline::FoveationStats sa, sb;
    ASSERT_TRUE(stage->backproject(rig.frame, counts).isOk());
    ASSERT_TRUE(stage->foveate(gazeFor(rig.frame), a, sa).isOk());
    ASSERT_TRUE(backprojector.run(rig.frame, {}, cloud, counts).isOk());
    ASSERT_TRUE(foveator.foveate(cloud, gazeFor(rig.frame), b, sb).isOk());
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t p = 0; p < a.size(); ++p) {
      ASSERT_EQ(a.points.world(p), b.points.world(p)) << "point " << p;
    }
  }
}

// The pyramid source: ACUITY is the image pyramid's sampling (the same points as a
// PyramidSampler of its own, the regions its levels); another preset, as the gaze
// policy's fallback sets, is the frame source's exact path; foveate() without a
// frame taken in is an error.
TEST(FrameFoveator, ThePyramidSourceSamplesTheImageAndFallsBackToTheFrame) {
  Rig rig = openRig();
  ASSERT_TRUE(rig.camera);
  const pipeline::PipelineCapacity capacity{rig.pixels, rig.pixels, fovea::defaultKernelSet(), 1};
  MapSettings pyramid_source;
  pyramid_source.source = FoveationSource::kPyramid;
  pipeline::FoveationConfig acuity;
  acuity.acuity.preset = pipeline::Preset::kAcuity;
  acuity.acuity.floor_per_m2 = 0.001;
  const pipeline::FoveationConfig f1;
  Result<FrameFoveator> stage = FrameFoveator::create(capacity, acuity, {}, pyramid_source, rig.width, rig.height);
  ASSERT_TRUE(stage.isOk()) << stage.status().toString();
  EXPECT_GT(stage->pyramidMemoryBytes(), rig.pixels * sizeof(float));
  pipeline::PyramidSampler sampler = pipeline::PyramidSampler::create(rig.width, rig.height).value();
  pipeline::Backprojector backprojector(1, capacity.kernels);
  pipeline::PointCloud cloud(rig.pixels);
  pipeline::Foveator foveator = pipeline::Foveator::create(capacity, f1).value();
  pipeline::FoveatedCloud a(rig.pixels), b(rig.pixels);
  pipeline::BackprojectCounts counts;
  pipeline::FoveationStats sa, sb;
  EXPECT_EQ(stage->foveate(gazeFor(rig.frame), a, sa).code(), ErrorCode::kInvalidArgument);  // no frame yet
  for (int i = 0; i < 4; ++i) {
    ASSERT_TRUE(rig.camera->acquire(rig.frame, test::scaled(std::chrono::seconds(1))).isOk());
    const bool fallback = i % 2 == 1;
    ASSERT_TRUE(stage->use(fallback ? &f1 : &acuity).isOk());
    ASSERT_TRUE(stage->backproject(rig.frame, counts).isOk());
    ASSERT_TRUE(stage->foveate(gazeFor(rig.frame), a, sa).isOk());
    if (fallback) {
      ASSERT_TRUE(backprojector.run(rig.frame, {}, cloud, counts).isOk());
      ASSERT_TRUE(foveator.foveate(cloud, gazeFor(rig.frame), b, sb).isOk());
    } else {
      pipeline::PyramidStats ps;
      const pipeline::Gaze gaze = pipeline::normalizeGaze(gazeFor(rig.frame)).value();
      ASSERT_TRUE(sampler.sample(rig.frame, {}, gaze, pipeline::PyramidRule::fromAcuity(acuity.acuity), b, ps).isOk());
      EXPECT_EQ(sa.points_in, ps.points_in);
      EXPECT_EQ(sa.region_count, sampler.levels() + 1);
      EXPECT_EQ(sa.regions[0].points_out, ps.out_by_level[0]);
    }
    ASSERT_EQ(a.size(), b.size()) << (fallback ? "F1 fallback" : "ACUITY");
    EXPECT_EQ(sa.points_out, a.size());
    for (std::size_t p = 0; p < a.size(); ++p) {
      ASSERT_EQ(a.points.world(p), b.points.world(p)) << "point " << p;
      ASSERT_EQ(a.region[p], b.region[p]) << "point " << p;
    }
    // One foveate() per frame taken in.
    EXPECT_EQ(stage->foveate(gazeFor(rig.frame), a, sa).code(), ErrorCode::kInvalidArgument);
  }
}

// Every preset foveates the map: the map's surfels reach the output, and the
// cloud is the frame's unexplained points followed by them.
TEST(FrameFoveator, EveryPresetFoveatesTheMap) {
  for (pipeline::Preset preset : {pipeline::Preset::kF1, pipeline::Preset::kF2, pipeline::Preset::kF3,
                                  pipeline::Preset::kFRef, pipeline::Preset::kAcuity}) {
    SCOPED_TRACE(std::string(pipeline::presetName(preset)));
    Rig rig = openRig();
    ASSERT_TRUE(rig.camera);
    const MapSettings settings = mapSource();
    pipeline::FoveationConfig config;
    config.acuity.preset = preset;
    Result<FrameFoveator> stage = FrameFoveator::create({rig.pixels, rig.pixels, fovea::defaultKernelSet(), 1},
                                                        config, {}, settings, rig.width, rig.height);
    ASSERT_TRUE(stage.isOk()) << stage.status().toString();
    ASSERT_NE(stage->map(), nullptr);
    EXPECT_GT(stage->mapMemoryBytes(), settings.map.max_surfels * sizeof(pipeline::map::Surfel));
    pipeline::FoveatedCloud out(FrameFoveator::cloudCapacity(rig.pixels, settings));
    // Past map.settle_frames (10): the map's surfels are the operator's.
    const int frames = static_cast<int>(settings.map.settle_frames) + 3;
    for (int i = 0; i < frames; ++i) {
      ASSERT_TRUE(rig.camera->acquire(rig.frame, test::scaled(std::chrono::seconds(1))).isOk());
      pipeline::BackprojectCounts counts;
      pipeline::FoveationStats stats;
      ASSERT_TRUE(stage->backproject(rig.frame, counts).isOk());
      ASSERT_TRUE(stage->foveate(gazeFor(rig.frame), out, stats).isOk());
      const MapFrameFigures& figures = stage->mapFigures();
      EXPECT_EQ(figures.fuse.outcome, pipeline::map::FuseOutcome::kFused);
      EXPECT_EQ(stage->cloud().size(), figures.frame_points + figures.eye.appended);
      EXPECT_LE(figures.frame_points, rig.pixels);
      EXPECT_GT(out.size(), 0u);
      if (i == frames - 1) {
        EXPECT_GT(figures.eye.appended, rig.pixels / 2) << "the map's surfels reached the foveator";
        EXPECT_LT(figures.frame_points, rig.pixels / 2) << "the map explains most of the frame by now";
      }
    }
    // foveate() again (another gaze) gathers afresh: the cloud does not grow.
    const std::size_t size = stage->cloud().size();
    pipeline::Gaze other = gazeFor(rig.frame);
    other.origin_m += Eigen::Vector3d(0.3, 0.0, 0.0);
    pipeline::FoveationStats stats;
    ASSERT_TRUE(stage->foveate(other, out, stats).isOk());
    EXPECT_NEAR(static_cast<double>(stage->cloud().size()), static_cast<double>(size), 0.2 * size);
    EXPECT_EQ(stage->cloud().size(), stage->mapFigures().frame_points + stage->mapFigures().eye.appended);
  }
}

// A frame the pose source had no pose for: refused by the map and counted, and
// back-projected whole so the operator keeps the live view; a gaze without a
// finite origin is an error.
TEST(FrameFoveator, AFrameWithoutAPoseIsCountedAndStillShown) {
  Rig rig = openRig();
  ASSERT_TRUE(rig.camera);
  const MapSettings settings = mapSource();
  Result<FrameFoveator> stage = FrameFoveator::create({rig.pixels, rig.pixels, fovea::defaultKernelSet(), 1}, {}, {},
                                                      settings, rig.width, rig.height);
  ASSERT_TRUE(stage.isOk());
  pipeline::FoveatedCloud out(FrameFoveator::cloudCapacity(rig.pixels, settings));
  pipeline::BackprojectCounts counts;
  pipeline::FoveationStats stats;
  ASSERT_TRUE(rig.camera->acquire(rig.frame, test::scaled(std::chrono::seconds(1))).isOk());
  ASSERT_TRUE(stage->backproject(rig.frame, counts, /*pose_valid=*/false).isOk());
  EXPECT_EQ(stage->mapFigures().fuse.outcome, pipeline::map::FuseOutcome::kRefusedNoPose);
  EXPECT_EQ(stage->map()->counters().refused_no_pose, 1u);
  EXPECT_EQ(stage->map()->size(), 0u);
  EXPECT_EQ(stage->mapFigures().frame_points, counts.valid);
  EXPECT_GT(counts.valid, rig.pixels / 2);
  ASSERT_TRUE(stage->foveate(gazeFor(rig.frame), out, stats).isOk());
  EXPECT_GT(out.size(), 0u);

  pipeline::Gaze bad = gazeFor(rig.frame);
  bad.origin_m.x() = std::numeric_limits<double>::quiet_NaN();
  const Status s = stage->foveate(bad, out, stats);
  EXPECT_FALSE(s.isOk());
  EXPECT_EQ(s.code(), ErrorCode::kInvalidInput);

  // A frame with a NaN pose: refused (bad pose), and not back-projectable either: an error.
  ASSERT_TRUE(rig.camera->acquire(rig.frame, test::scaled(std::chrono::seconds(1))).isOk());
  rig.frame.T_world_cam.t_world_cam.y() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(stage->backproject(rig.frame, counts).isOk());
  EXPECT_EQ(stage->map()->counters().refused_bad_pose, 1u);
  EXPECT_EQ(stage->cloud().size(), 0u);
}

// Fusion slowed on purpose against its budget (a budget of a microsecond, far
// below any fusion): the first frame is fused, the next ones are not, each
// counted and back-projected whole, and the map does not change for them.
TEST(FrameFoveator, FramesOverTheFusionBudgetAreCountedAndSentWhole) {
  Rig rig = openRig();
  ASSERT_TRUE(rig.camera);
  MapSettings settings = mapSource();
  settings.fuse_budget_ms = 0.001;
  Result<FrameFoveator> stage = FrameFoveator::create({rig.pixels, rig.pixels, fovea::defaultKernelSet(), 1}, {}, {},
                                                      settings, rig.width, rig.height);
  ASSERT_TRUE(stage.isOk()) << stage.status().toString();
  EXPECT_TRUE(stage->hasFusionBudget());
  pipeline::FoveatedCloud out(FrameFoveator::cloudCapacity(rig.pixels, settings));
  std::size_t surfels_after_first = 0;
  for (int i = 0; i < 5; ++i) {
    ASSERT_TRUE(rig.camera->acquire(rig.frame, test::scaled(std::chrono::seconds(1))).isOk());
    pipeline::BackprojectCounts counts;
    pipeline::FoveationStats stats;
    ASSERT_TRUE(stage->backproject(rig.frame, counts).isOk());
    ASSERT_TRUE(stage->foveate(gazeFor(rig.frame), out, stats).isOk());
    const MapFrameFigures& figures = stage->mapFigures();
    if (i == 0) {
      EXPECT_TRUE(figures.fused());
      surfels_after_first = stage->map()->size();
      EXPECT_GT(surfels_after_first, 0u);
      continue;
    }
    EXPECT_TRUE(figures.fusion_skipped);
    EXPECT_FALSE(figures.fused());
    // One fused frame settles nothing, so its view explains nothing and the
    // whole frame goes (test_explained_view.cpp thins frames against a settled map).
    EXPECT_EQ(figures.explained_by_last_view, 0u);
    EXPECT_EQ(figures.frame_points, counts.valid) << "the whole frame goes";
    EXPECT_GT(counts.valid, rig.pixels / 2);
    EXPECT_EQ(stage->map()->size(), surfels_after_first);
    EXPECT_EQ(stage->fusionSkipped(), static_cast<uint64_t>(i));
  }
  EXPECT_EQ(stage->map()->counters().frames_fused, 1u);
  settings.fuse_budget_ms = -1.0;
  EXPECT_FALSE(FrameFoveator::create({rig.pixels, rig.pixels, fovea::defaultKernelSet(), 1}, {}, {}, settings,
                                     rig.width, rig.height)
                   .isOk());
}

// With bricks (map.delta) the frame carries only the live points, and
// planBricks fills the batch with what the operator lacks: everything due at
// first, nothing once it holds it all, a forgotten brick again, everything
// after forgetAllBricks, and within a small budget the fovea's bricks first
// while the rest wait (counted).
TEST(FrameFoveator, PlanBricksSendsWhatTheOperatorLacksWithinTheBudget) {
  Rig rig = openRig();
  ASSERT_TRUE(rig.camera);
  MapSettings settings = mapSource();
  settings.delta = true;
  settings.max_frame_brick_points = std::size_t{1} << 18;  // the service derives it from the link's budget
  settings.map.settle_frames = 2;
  Result<FrameFoveator> stage = FrameFoveator::create({rig.pixels, rig.pixels, fovea::defaultKernelSet(), 1}, {}, {},
                                                      settings, rig.width, rig.height);
  ASSERT_TRUE(stage.isOk()) << stage.status().toString();
  ASSERT_TRUE(stage->streamsBricks());
  pipeline::FoveatedCloud out(FrameFoveator::cloudCapacity(rig.pixels, settings));
  pipeline::map::BrickBatch batch = stage->makeBrickBatch();
  pipeline::BackprojectCounts counts;
  pipeline::FoveationStats stats;
  for (int i = 0; i < 8; ++i) {
    ASSERT_TRUE(rig.camera->acquire(rig.frame, test::scaled(std::chrono::seconds(1))).isOk());
    ASSERT_TRUE(stage->backproject(rig.frame, counts).isOk());
  }
  const pipeline::Gaze gaze = gazeFor(rig.frame);
  ASSERT_TRUE(stage->foveate(gaze, out, stats).isOk());
  // No eye view appended: the cloud is the frame's live points alone.
  EXPECT_EQ(stage->cloud().size(), stage->mapFigures().frame_points);
  EXPECT_EQ(stage->mapFigures().eye.appended, 0u);

  constexpr double kAll = 1e12;
  ASSERT_TRUE(stage->planBricks(gaze, kAll, 0.0, batch).isOk());
  const std::size_t bricks = batch.entries().size();
  ASSERT_GT(bricks, 2u);
  EXPECT_EQ(stage->mapFigures().plan.bricks_waiting, 0u);
  uint64_t settled = 0;
  for (std::size_t b = 0; b < stage->map()->brickCount(); ++b) settled += stage->map()->brickSettledCount(static_cast<uint16_t>(b));
  for (const pipeline::map::BrickBatchEntry& e : batch.entries()) EXPECT_EQ(e.version, 1u);
  // Each counted by why it was due: the operator lacked them all.
  const auto& by_need = stage->mapFigures().plan.planned_by_need;
  EXPECT_EQ(by_need[static_cast<std::size_t>(pipeline::map::BrickNeed::kMissing)], bricks);
  EXPECT_EQ(by_need[static_cast<std::size_t>(pipeline::map::BrickNeed::kRefine)] +
                by_need[static_cast<std::size_t>(pipeline::map::BrickNeed::kChanged)],
            0u);
  EXPECT_LE(batch.points.size(), settled);
  EXPECT_GT(batch.points.size(), 0u);

  ASSERT_TRUE(stage->planBricks(gaze, kAll, 0.0, batch).isOk());
  EXPECT_EQ(batch.entries().size(), 0u) << "the operator holds every brick it was sent";
  const uint16_t forgotten = 1;
  stage->forgetBrick(forgotten);
  stage->forgetBrick(60000);  // beyond the map: ignored
  ASSERT_TRUE(stage->planBricks(gaze, kAll, 0.0, batch).isOk());
  ASSERT_EQ(batch.entries().size(), 1u);
  EXPECT_EQ(batch.entries()[0].brick, forgotten);
  EXPECT_EQ(batch.entries()[0].version, 2u);
  stage->forgetAllBricks();
  ASSERT_TRUE(stage->planBricks(gaze, kAll, 0.0, batch).isOk());
  EXPECT_EQ(batch.entries().size(), bricks);
  // A frame's bricks that never went (forgetBatch): due again.
  stage->forgetBatch(batch);
  // A budget of one byte: the first brick of the plan (the fovea's) goes, the rest wait.
  ASSERT_TRUE(stage->planBricks(gaze, 1.0, 0.0, batch).isOk());
  ASSERT_EQ(batch.entries().size(), 1u);
  EXPECT_TRUE(batch.entries()[0].fovea);
  EXPECT_EQ(stage->mapFigures().plan.bricks_waiting, bricks - 1);
  // Live points costing more than the budget: only the fovea's bricks go before them.
  stage->forgetAllBricks();
  ASSERT_TRUE(stage->planBricks(gaze, 1e6, 2e6, batch).isOk());
  for (const pipeline::map::BrickBatchEntry& e : batch.entries()) EXPECT_TRUE(e.fovea);
  EXPECT_GT(stage->mapFigures().plan.bricks_waiting, 0u);
  // No budget: nothing.
  stage->forgetAllBricks();
  ASSERT_TRUE(stage->planBricks(gaze, 0.0, 0.0, batch).isOk());
  EXPECT_EQ(batch.entries().size(), 0u);
  EXPECT_EQ(stage->mapFigures().plan.bricks_waiting, bricks);
  // A bad gaze is an error, and nothing is taken as sent.
  pipeline::Gaze bad = gaze;
  bad.direction = Eigen::Vector3d::Zero();
  EXPECT_FALSE(stage->planBricks(bad, kAll, 0.0, batch).isOk());
  ASSERT_TRUE(stage->planBricks(gaze, kAll, 0.0, batch).isOk());
  EXPECT_EQ(batch.entries().size(), bricks);
}

}  // namespace
}  // namespace fovea::firmware
