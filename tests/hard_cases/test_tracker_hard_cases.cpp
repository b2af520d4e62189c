// The tracker's hard cases (pipeline/map/tracker.h, docs/tracking.md): a frame
// without depth, a textureless wall, fast motion (frames dropped), a box moving
// through a third of the view, a block carried with the camera, a person walking
// through, a view filled by a mover, the balloon, and the view returning after
// a loss.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "hal/camera.h"
#include "pipeline/map/moving_pixels.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/map/tracker.h"
#include "tests/support/test_time.h"

namespace fovea::pipeline::map {
namespace {

constexpr int kW = 320, kH = 240;

double translationError(const hal::Pose& a, const hal::Pose& b) { return (a.t_world_cam - b.t_world_cam).norm(); }

std::vector<hal::RgbdFrame> mockFrames(const std::string& spec, int n) {
  std::vector<hal::RgbdFrame> frames;
  Result<std::unique_ptr<hal::Camera>> camera = hal::createCamera(spec);
  if (!camera.isOk()) {
    ADD_FAILURE() << camera.status().toString();
    return frames;
  }
  hal::Camera& cam = *camera.value();
  if (!cam.open().isOk() || !cam.start().isOk()) {
    ADD_FAILURE() << "cannot start " << spec;
    return frames;
  }
  for (int i = 0; i < n; ++i) {
    frames.emplace_back(kW, kH);
    if (!cam.acquire(frames.back(), test::scaled(std::chrono::milliseconds(1000))).isOk()) {
      ADD_FAILURE() << "acquire " << i;
      frames.pop_back();
      break;
    }
  }
  return frames;
}

struct Rig {
  SurfelMap map;
  FrameToModelTracker tracker;
  static Rig make() {
    SurfelMapConfig mc;
    mc.max_width = kW;
    mc.max_height = kH;
    mc.max_surfels = 1 << 18;
    mc.max_bricks = 4096;
    TrackerConfig tc;
    tc.max_width = kW;
    tc.max_height = kH;
    return Rig{SurfelMap::create(mc).value(), FrameToModelTracker::create(tc).value(), hal::Pose{}};
  }
  // Tracks (prior: the first frame's truth, else none) and fuses where
  // tracked, without the pixels the tracker found moving (as Mapper does).
  TrackOutcome step(hal::RgbdFrame& frame, TrackStats& stats, const hal::Pose* prior = nullptr) {
    hal::Pose pose;
    const TrackOutcome o = tracker.track(frame, prior, pose, stats);
    if (o != TrackOutcome::kLost) {
      const hal::Pose truth = frame.T_world_cam;
      frame.T_world_cam = pose;
      FuseStats fs;
      const MovingPixels& m = tracker.moving();
      const uint8_t* moving = m.width() == frame.width() && m.height() == frame.height() ? m.mask() : nullptr;
      if (map.fuse(frame, fs, true, moving) == FuseOutcome::kFused) tracker.modelFused(frame, pose, map, moving);
      frame.T_world_cam = truth;
      last_pose = pose;
    }
    return o;
  }
  hal::Pose last_pose;
};

TEST(TrackerHardCases, AFrameWithoutDepthIsLostNotACrash) {
  std::vector<hal::RgbdFrame> frames = mockFrames("mock:living-room,size=320x240,path=orbit", 2);
  ASSERT_EQ(frames.size(), 2u);
  Rig rig = Rig::make();
  TrackStats stats;
  // Before any model: lost too (nothing to start from).
  hal::RgbdFrame empty = frames[1];
  std::fill(empty.depth(), empty.depth() + empty.pixelCount(), uint16_t{0});
  EXPECT_EQ(rig.step(empty, stats), TrackOutcome::kLost);
  EXPECT_EQ(stats.lost_reason, LostReason::kNoValidDepth);
  ASSERT_EQ(rig.step(frames[0], stats, &frames[0].T_world_cam), TrackOutcome::kFirstFrame);
  EXPECT_EQ(rig.step(empty, stats), TrackOutcome::kLost);
  EXPECT_EQ(stats.lost_reason, LostReason::kNoValidDepth);
  EXPECT_TRUE(rig.tracker.lost());
  // Bad intrinsics and a NaN depth scale: lost, counted.
  hal::RgbdFrame bad = frames[1];
  bad.intrinsics.fx = std::nan("");
  EXPECT_EQ(rig.step(bad, stats), TrackOutcome::kLost);
  bad = frames[1];
  bad.depth_scale_m = 0.0;
  EXPECT_EQ(rig.step(bad, stats), TrackOutcome::kLost);
  // A prior of NaN: lost, and the pose reported is the last good one, finite.
  hal::Pose nan_prior;
  nan_prior.t_world_cam.x() = std::nan("");
  hal::Pose pose;
  EXPECT_EQ(rig.tracker.track(frames[1], &nan_prior, pose, stats), TrackOutcome::kLost);
  EXPECT_EQ(stats.lost_reason, LostReason::kImplausibleMotion);
  EXPECT_TRUE(pose.t_world_cam.allFinite());
  EXPECT_EQ(rig.tracker.counters().lost, 5u);
}

// A wall of constant colour square to the camera at 2 m: ICP constrains the
// depth and two rotations, the photometric term nothing.
void renderWall(hal::RgbdFrame& frame, double offset_x) {
  frame.intrinsics = {kW, kH, 262.5, 262.5, (kW - 1) / 2.0, (kH - 1) / 2.0};
  frame.depth_scale_m = 0.001;
  frame.T_world_cam = hal::Pose{};
  frame.T_world_cam.t_world_cam.x() = offset_x;
  for (std::size_t i = 0; i < frame.pixelCount(); ++i) {
    frame.depth()[i] = 2000;
    frame.rgb()[3 * i] = frame.rgb()[3 * i + 1] = frame.rgb()[3 * i + 2] = 200;
  }
}

TEST(TrackerHardCases, ATexturelessWallIsDegenerate) {
  Rig rig = Rig::make();
  hal::RgbdFrame a(kW, kH), b(kW, kH);
  ASSERT_TRUE(a.setSize(kW, kH) && b.setSize(kW, kH));
  renderWall(a, 0.0);
  renderWall(b, 0.02);
  b.stamp_ns = 1;
  TrackStats stats;
  ASSERT_EQ(rig.step(a, stats, &a.T_world_cam), TrackOutcome::kFirstFrame);
  EXPECT_EQ(rig.step(b, stats), TrackOutcome::kLost);
  EXPECT_EQ(stats.lost_reason, LostReason::kDegenerate) << lostReasonName(stats.lost_reason);
  EXPECT_LT(stats.min_eigenvalue, 1e-6);
  EXPECT_GT(stats.inlier_fraction, 0.9);  // every pixel associates: it is the axes that are free
}

// The orbit with every other frame dropped (2.4 cm and 1 degree a step at
// 30 fps, 15 fps effective): measured tracked throughout, within 5 mm RMS.
TEST(TrackerHardCases, FastOrbitWithEveryOtherFrameDropped) {
  FOVEA_SKIP_LONG_SEQUENCE_UNDER_QEMU();
  std::vector<hal::RgbdFrame> frames = mockFrames("mock:living-room,size=320x240,path=orbit", 41);
  ASSERT_EQ(frames.size(), 41u);
  Rig rig = Rig::make();
  TrackStats stats;
  double sq = 0.0, worst = 0.0;
  int n = 0, lost = 0;
  for (std::size_t i = 0; i < frames.size(); i += 2) {
    const TrackOutcome o = rig.step(frames[i], stats, i == 0 ? &frames[0].T_world_cam : nullptr);
    if (o == TrackOutcome::kLost) {
      ++lost;
      continue;
    }
    const double e = translationError(rig.last_pose, frames[i].T_world_cam);
    sq += e * e, worst = std::max(worst, e), ++n;
  }
  const double rmse = std::sqrt(sq / std::max(n, 1));
  std::printf("orbit, every other frame: %d tracked, %d lost, RMSE %.2f mm, max %.2f mm\n", n, lost, rmse * 1e3,
              worst * 1e3);
  EXPECT_EQ(lost, 0);
  EXPECT_LT(rmse, 0.005);
}

// From frame 10 a textured box a third of the view wide, the full height, at
// 0.8 m, moves 3 pixels a frame across the orbiting camera's view (fovea-track's
// `object` case at half its size). The box stands where the map has seen the
// room: its pixels are moving (moving_pixels.h), are not fused, and the track
// holds: issue 42's bound, 10 mm. Fusing them (before) put the box in the model
// and the pose followed it: 186 mm ATE at 640x480 (docs/tracking.md).
TEST(TrackerHardCases, ABoxAThirdOfTheViewMovingThroughIsLeftOutAndTheTrackHolds) {
  FOVEA_SKIP_LONG_SEQUENCE_UNDER_QEMU();
  constexpr int kFrames = 40, kFirst = 10, kBox = kW / 3;
  std::vector<hal::RgbdFrame> frames = mockFrames("mock:living-room,size=320x240,path=orbit", kFrames);
  ASSERT_EQ(frames.size(), static_cast<std::size_t>(kFrames));
  Rig rig = Rig::make();
  TrackStats stats;
  double sq = 0.0, worst = 0.0, least_share = 1.0, most_static_share = 0.0;
  int n = 0, lost = 0;
  for (int i = 0; i < kFrames; ++i) {
    hal::RgbdFrame& f = frames[static_cast<std::size_t>(i)];
    if (i >= kFirst) {
      const int x0 = (i - kFirst) * 3;
      for (int v = 0; v < kH; ++v) {
        for (int u = x0; u < x0 + kBox; ++u) {
          const std::size_t p = static_cast<std::size_t>(v) * kW + u;
          f.depth()[p] = static_cast<uint16_t>(std::lround((0.8 + 0.001 * (u - x0)) / f.depth_scale_m));
          const bool check = ((u - x0) / 8 + v / 8) % 2 == 0;
          f.rgb()[3 * p] = check ? 220 : 40, f.rgb()[3 * p + 1] = 60, f.rgb()[3 * p + 2] = check ? 40 : 200;
        }
      }
    }
    const TrackOutcome o = rig.step(f, stats, i == 0 ? &f.T_world_cam : nullptr);
    if (o == TrackOutcome::kLost) {
      ++lost;
      continue;
    }
    if (i > kFirst) least_share = std::min(least_share, stats.moving_share);
    if (i > 0 && i < kFirst) most_static_share = std::max(most_static_share, stats.moving_share);
    const double e = translationError(rig.last_pose, f.T_world_cam);
    sq += e * e, ++n, worst = std::max(worst, e);
  }
  const double rmse = std::sqrt(sq / std::max(n, 1));
  std::printf("orbit with a box moving through a third: %d tracked, %d lost, RMSE %.2f mm, max %.2f mm, "
              "moving share at least %.3f with the box, at most %.3f before it\n",
              n, lost, rmse * 1e3, worst * 1e3, least_share, most_static_share);
  EXPECT_EQ(lost, 0);
  EXPECT_LT(rmse, 0.010);
  EXPECT_GT(least_share, 0.25) << "the box is a third of the view";
  EXPECT_LT(most_static_share, 0.01) << "the static room has no mover";
}

// The mock camera's `carried` scene: a cardboard box 0.6 to 0.9 m in front of
// the camera over the lower left of every frame (about 28 % of the view),
// carried with the orbiting camera (a robot's gripper holding it). It is in the
// map from the first frame, so it is never in front of what the map knows, and
// near the camera its pixels outweigh the room's (the noise weighting): left
// in, the pose follows it (docs/tracking.md: 153 mm ATE at 640x480, every frame
// reported tracked). Found still in the image while the room changes
// (carried_pixels.h), it is left out of the alignment and of the fusion from
// the second frame on, and the track holds to issue 42's bound, 10 mm.
struct CarriedRun {
  double rmse = 0.0, least_carried_share = 1.0;
  int tracked = 0, lost = 0;
};
CarriedRun trackCarried(std::vector<hal::RgbdFrame>& frames, bool find_carried) {
  Rig rig = Rig::make();
  if (!find_carried) {
    TrackerConfig tc = rig.tracker.config();
    tc.carried.enabled = false;
    rig.tracker = FrameToModelTracker::create(tc).value();
  }
  CarriedRun run;
  TrackStats stats;
  double sq = 0.0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    hal::RgbdFrame& f = frames[i];
    const TrackOutcome o = rig.step(f, stats, i == 0 ? &f.T_world_cam : nullptr);
    if (o == TrackOutcome::kLost) {
      ++run.lost;
      continue;
    }
    if (i >= 10 && stats.valid_pixels > 0) {
      run.least_carried_share = std::min(run.least_carried_share, static_cast<double>(stats.carried_pixels) / stats.valid_pixels);
    }
    const double e = translationError(rig.last_pose, f.T_world_cam);
    sq += e * e, ++run.tracked;
  }
  run.rmse = std::sqrt(sq / std::max(run.tracked, 1));
  return run;
}

TEST(TrackerHardCases, ABlockCarriedWithTheCameraIsLeftOutAndTheTrackHolds) {
  FOVEA_SKIP_LONG_SEQUENCE_UNDER_QEMU();
  std::vector<hal::RgbdFrame> frames = mockFrames("mock:carried,size=320x240,path=orbit", 30);
  ASSERT_EQ(frames.size(), 30u);
  std::vector<hal::RgbdFrame> copies = frames;
  const CarriedRun found = trackCarried(frames, true);
  const CarriedRun before = trackCarried(copies, false);
  std::printf("orbit carrying a block: %d tracked, %d lost, RMSE %.2f mm, carried share at least %.3f from frame 10; "
              "without finding it RMSE %.2f mm\n",
              found.tracked, found.lost, found.rmse * 1e3, found.least_carried_share, before.rmse * 1e3);
  EXPECT_EQ(found.lost, 0);
  EXPECT_LT(found.rmse, 0.010);
  EXPECT_GT(found.least_carried_share, 0.2) << "the block is about 28 % of the view";
  EXPECT_GT(before.rmse, 0.03) << "without the carried pixels the block must still take the pose, or this test shows nothing";
}

// The mock camera's `walker` scene: a person-sized box walking across the
// living room, between the orbiting camera and the room's middle, up to 45 %
// of the view here (fps=15: the orbit at twice its speed a frame, 40 frames
// to 2.7 s). Found moving after the alignment, left out of its judgement and
// of the fusion: the track holds to issue 42's bound, 10 mm. Before (every
// pixel fused, least squares) the pose followed it: 173 mm ATE at 640x480.
TEST(TrackerHardCases, APersonWalkingThroughTheViewIsLeftOutAndTheTrackHolds) {
  FOVEA_SKIP_LONG_SEQUENCE_UNDER_QEMU();
  constexpr int kFrames = 40;
  std::vector<hal::RgbdFrame> frames = mockFrames("mock:walker,size=320x240,path=orbit,fps=15", kFrames);
  ASSERT_EQ(frames.size(), static_cast<std::size_t>(kFrames));
  Rig rig = Rig::make();
  TrackStats stats;
  double sq = 0.0, worst = 0.0, most_share = 0.0;
  int n = 0, lost = 0;
  for (int i = 0; i < kFrames; ++i) {
    hal::RgbdFrame& f = frames[static_cast<std::size_t>(i)];
    const TrackOutcome o = rig.step(f, stats, i == 0 ? &f.T_world_cam : nullptr);
    most_share = std::max(most_share, stats.moving_share);
    if (o == TrackOutcome::kLost) {
      // Lost only with its reason where the person covers over half the view (then
      // what is left of the room can be too flat: kDegenerate), never tracked wrong.
      EXPECT_GT(stats.moving_share, 0.5) << "frame " << i << " lost: " << lostReasonName(stats.lost_reason);
      ++lost;
      continue;
    }
    const double e = translationError(rig.last_pose, f.T_world_cam);
    sq += e * e, ++n, worst = std::max(worst, e);
  }
  const double rmse = std::sqrt(sq / std::max(n, 1));
  std::printf("orbit with a person walking through: %d tracked, %d lost, RMSE %.2f mm, max %.2f mm, "
              "moving share up to %.3f\n", n, lost, rmse * 1e3, worst * 1e3, most_share);
  EXPECT_LE(lost, 2);
  EXPECT_LT(rmse, 0.010);
  EXPECT_GT(most_share, 0.30) << "the person covers over a third of the view";
}

// A board filling 90 % of the view at 0.7 m passes in front of the orbiting
// camera for five frames. What static remains (a strip at the top) is too
// little to trust: each of those frames is lost as mostly moving, not tracked
// on the strip or on the board, and the track returns when the board has gone.
TEST(TrackerHardCases, AViewFilledByAMoverIsLostAsMostlyMovingAndTheTrackReturns) {
  FOVEA_SKIP_LONG_SEQUENCE_UNDER_QEMU();
  constexpr int kFrames = 32, kFirst = 20, kLast = 24, kTop = kH / 10;
  std::vector<hal::RgbdFrame> frames = mockFrames("mock:living-room,size=320x240,path=orbit", kFrames);
  ASSERT_EQ(frames.size(), static_cast<std::size_t>(kFrames));
  Rig rig = Rig::make();
  TrackStats stats;
  int mostly_moving = 0, other_outcomes = 0;
  double after_sq = 0.0;
  int after_n = 0;
  for (int i = 0; i < kFrames; ++i) {
    hal::RgbdFrame& f = frames[static_cast<std::size_t>(i)];
    const bool board = i >= kFirst && i <= kLast;
    if (board) {
      for (int v = kTop; v < kH; ++v) {
        for (int u = 0; u < kW; ++u) {
          const std::size_t p = static_cast<std::size_t>(v) * kW + u;
          f.depth()[p] = static_cast<uint16_t>(std::lround(0.7 / f.depth_scale_m));
          const bool check = ((u + 4 * i) / 10 + v / 10) % 2 == 0;
          f.rgb()[3 * p] = check ? 230 : 30, f.rgb()[3 * p + 1] = check ? 200 : 60, f.rgb()[3 * p + 2] = 50;
        }
      }
    }
    const TrackOutcome o = rig.step(f, stats, i == 0 ? &f.T_world_cam : nullptr);
    if (board) {
      if (o == TrackOutcome::kLost && stats.lost_reason == LostReason::kMostlyMoving) {
        ++mostly_moving;
      } else {
        ++other_outcomes;
        ADD_FAILURE() << "frame " << i << ": " << trackOutcomeName(o) << " (" << lostReasonName(stats.lost_reason)
                      << "), moving share " << stats.moving_share;
      }
    } else if (i > kLast + 1) {
      EXPECT_NE(o, TrackOutcome::kLost) << "frame " << i;
      const double e = translationError(rig.last_pose, f.T_world_cam);
      after_sq += e * e, ++after_n;
    }
  }
  const double after_rmse = std::sqrt(after_sq / std::max(after_n, 1));
  std::printf("a board over 90 %% of the view for %d frames: %d lost as mostly moving; RMSE after it %.2f mm\n",
              kLast - kFirst + 1, mostly_moving, after_rmse * 1e3);
  EXPECT_EQ(mostly_moving, kLast - kFirst + 1);
  EXPECT_EQ(other_outcomes, 0);
  EXPECT_LT(after_rmse, 0.010);
}

// The balloon scene: a striped balloon of 0.3 m drifting (0.6 m amplitude)
// before a wall over a floor, on its orbit. The static scene is two planes,
// which leave the translation along their intersection to the plaster's and
// tiles' faint texture, while the balloon constrains every axis and moves. With
// least squares the pose followed the balloon: 351 mm RMS over these 30 frames
// (402 mm without the noise weighting), 354 mm with the moving pixels left out
// (the balloon is in the map from the first frame and drifts a few centimetres
// a frame, within the association's reach). Cauchy's weights (issue 42) take
// its terms, centimetres off, to a few per cent of the walls': 33 mm here, and
// 5.8 mm at 640x480 over 60 frames (fovea-track, docs/tracking.md).
TEST(TrackerHardCases, AMovingBalloonBeforeTwoPlanesNoLongerTakesThePose) {
  FOVEA_SKIP_LONG_SEQUENCE_UNDER_QEMU();
  std::vector<hal::RgbdFrame> frames = mockFrames("mock:balloon,size=320x240,path=orbit", 30);
  ASSERT_EQ(frames.size(), 30u);
  Rig rig = Rig::make();
  TrackStats stats;
  double sq = 0.0;
  int n = 0, lost = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const TrackOutcome o = rig.step(frames[i], stats, i == 0 ? &frames[0].T_world_cam : nullptr);
    if (o == TrackOutcome::kLost) {
      ++lost;
      continue;
    }
    const double e = translationError(rig.last_pose, frames[i].T_world_cam);
    sq += e * e, ++n;
  }
  const double rmse = std::sqrt(sq / std::max(n, 1));
  std::printf("balloon scene, orbit: %d tracked, %d lost, RMSE %.2f mm\n", n, lost, rmse * 1e3);
  EXPECT_EQ(lost, 0);
  EXPECT_LT(rmse, 0.05);
}

// Tracked, then frames the model cannot explain (no depth, a wall of one
// colour elsewhere), then the view returns: relocalised against the model.
TEST(TrackerHardCases, TheViewReturningAfterALossIsRelocalised) {
  std::vector<hal::RgbdFrame> frames = mockFrames("mock:living-room,size=320x240,path=orbit", 8);
  ASSERT_EQ(frames.size(), 8u);
  Rig rig = Rig::make();
  TrackStats stats;
  for (std::size_t i = 0; i < 6; ++i) {
    ASSERT_NE(rig.step(frames[i], stats, i == 0 ? &frames[0].T_world_cam : nullptr), TrackOutcome::kLost) << i;
  }
  hal::RgbdFrame wall(kW, kH);
  ASSERT_TRUE(wall.setSize(kW, kH));
  renderWall(wall, 0.0);
  wall.intrinsics = frames[6].intrinsics;
  EXPECT_EQ(rig.step(wall, stats), TrackOutcome::kLost);
  EXPECT_TRUE(rig.tracker.lost());
  hal::RgbdFrame empty = frames[6];
  std::fill(empty.depth(), empty.depth() + empty.pixelCount(), uint16_t{0});
  EXPECT_EQ(rig.step(empty, stats), TrackOutcome::kLost);
  const TrackOutcome back = rig.step(frames[7], stats);
  EXPECT_EQ(back, TrackOutcome::kRelocalised) << lostReasonName(stats.lost_reason);
  EXPECT_GT(stats.relocalise_candidates, 1);
  EXPECT_LT(translationError(rig.last_pose, frames[7].T_world_cam), 0.01);
  EXPECT_FALSE(rig.tracker.lost());
  EXPECT_EQ(rig.tracker.counters().relocalised, 1u);
}

}  // namespace
}  // namespace fovea::pipeline::map
