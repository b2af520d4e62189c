// Fusion on a thread of its own (Mapper's fusion_thread, pipeline/map/map_gate.h):
// the gate lets a reader through while the writer holds it, only between the
// writer's whole steps; and a mapper fusing on another thread while this one
// hands frames over, thins them and plans bricks from the map under way ends
// with exactly the map a mapper on one thread makes from the same frames.
// Under ThreadSanitizer (THREADS) this is also the race check of the hand-off.
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/backproject.h"
#include "pipeline/map/map_gate.h"
#include "pipeline/map/mapper.h"
#include "tests/support/cameras.h"
#include "tests/support/test_time.h"

namespace fovea::pipeline::map {
namespace {

constexpr int kW = 160, kH = 120;

// The reader locks again as soon as it unlocked: the holder still gets the gate
// back between two of its reads (the reader sees it advance every time).
TEST(MapGate, AReaderGetsInAtTheHoldersSafePointsAndSeesOnlyWholeSteps) {
  MapGate gate;
  uint64_t a = 0, b = 0;  // the holder keeps a == b at every safe point
  std::atomic<bool> holding{false}, done{false};
  std::atomic<uint64_t> reads_while_held{0};
  std::atomic<uint64_t> torn{0}, same_step{0};
  std::thread writer([&] {
    gate.lock();
    holding.store(true, std::memory_order_release);
    // Hold until the reader got in a few times (or a generous time passed).
    const auto until = std::chrono::steady_clock::now() + test::scaled(std::chrono::seconds(10));
    while (reads_while_held.load(std::memory_order_acquire) < 20 && std::chrono::steady_clock::now() < until) {
      ++a;
      ++b;
      gate.yield();
    }
    holding.store(false, std::memory_order_release);
    gate.unlock();
    done.store(true, std::memory_order_release);
  });
  while (!holding.load(std::memory_order_acquire)) std::this_thread::yield();
  uint64_t last_seen = 0;
  while (!done.load(std::memory_order_acquire)) {
    MapReadLock hold(gate);
    if (a != b) torn.fetch_add(1, std::memory_order_relaxed);
    if (holding.load(std::memory_order_acquire)) {
      if (a == last_seen) same_step.fetch_add(1, std::memory_order_relaxed);
      last_seen = a;
      reads_while_held.fetch_add(1, std::memory_order_release);
    }
  }
  writer.join();
  EXPECT_GE(reads_while_held.load(), 20u) << "the reader got in while the writer held the gate";
  EXPECT_EQ(torn.load(), 0u);
  EXPECT_EQ(same_step.load(), 0u) << "the holder got the gate back between two reads";
  EXPECT_GE(gate.yields(), 20u);
}

MapperConfig mapperConfig(bool fusion_thread) {
  MapperConfig c;
  c.map.max_width = kW;
  c.map.max_height = kH;
  c.map.max_surfels = 1 << 17;
  c.map.max_bricks = 1024;
  c.output = MapOutput::kBricks;
  c.fusion_thread = fusion_thread;
  return c;
}

void expectSameMap(const SurfelMap& a, const SurfelMap& b) {
  ASSERT_EQ(a.size(), b.size());
  ASSERT_EQ(a.slotCount(), b.slotCount());
  ASSERT_EQ(a.brickCount(), b.brickCount());
  ASSERT_EQ(a.counters().frames_fused, b.counters().frames_fused);
  for (std::size_t slot = 0; slot < a.slotCount(); ++slot) {
    ASSERT_EQ(a.live(slot), b.live(slot)) << slot;
    if (a.live(slot)) {
      ASSERT_EQ(std::memcmp(&a.surfel(slot), &b.surfel(slot), sizeof(Surfel)), 0) << slot;
    }
  }
}

TEST(MapperThread, FusingOnAnotherThreadMakesTheMapOneThreadMakesFromTheSameFrames) {
  std::unique_ptr<hal::Camera> camera = test::startedCamera("mock:living-room,size=160x120,path=orbit");
  ASSERT_TRUE(camera);
  Mapper mapper = Mapper::create(mapperConfig(true)).value();
  ASSERT_TRUE(mapper.fusionThread());
  std::atomic<bool> stop{false};
  std::thread fusion([&] {
    while (!stop.load(std::memory_order_acquire)) {
      if (!mapper.fuseSubmitted()) std::this_thread::yield();
    }
    while (mapper.fuseSubmitted()) {
    }
  });
  std::vector<hal::RgbdFrame> handed;  // in the order handed over
  hal::RgbdFrame frame(kW, kH);
  PointCloud cloud(static_cast<std::size_t>(kW) * kH);
  BrickBatch batch(1 << 16, 256);
  uint64_t busy = 0, thinned = 0, took = 0, planned = 0;
  const int frames = test::repetitions(40, 16);
  for (int i = 0; i < frames; ++i) {
    ASSERT_TRUE(camera->acquire(frame, test::scaled(std::chrono::seconds(1))).isOk());
    const hal::RgbdFrame before = frame;
    MapperFrame out;
    EXPECT_FALSE(mapper.addFrame(frame, true, out)) << "with a fusion thread nothing is fused on the caller's";
    EXPECT_FALSE(out.fused());
    EXPECT_NE(out.handed_off, out.fusion_skipped) << "handed over, or left for a busy fusion";
    if (out.handed_off) handed.push_back(before);
    busy += out.fusion_skipped ? 1 : 0;
    // What the service does meanwhile: the frame thinned by the last fused
    // view, bricks planned for a gaze, the finished fusion's figures.
    cloud.origin_m = frame.T_world_cam.t_world_cam;
    LiveFigures live;
    ASSERT_TRUE(mapper.collectLive(frame, out, mapperConfig(true).map.depth, {}, cloud, live).isOk());
    EXPECT_EQ(live.points.stride, 1) << "a cloud of the whole frame is never thinned";
    EXPECT_EQ(cloud.size() + live.explained_by_last_view, live.valid);
    thinned += live.explained_by_last_view;
    Gaze gaze;
    gaze.origin_m = frame.T_world_cam.t_world_cam;
    gaze.direction = frame.T_world_cam.R_world_cam.col(2);
    MapperPlan plan;
    ASSERT_TRUE(mapper.planBricks(gaze, 1e5, 0.0, gaze.origin_m, batch, plan).isOk());
    planned += plan.bricks_planned;
    MapperFrame fused;
    if (mapper.takeFused(fused)) {
      ++took;
      EXPECT_TRUE(fused.fused());
      EXPECT_GT(fused.fuse.fuse_ns, 0);
    }
  }
  stop.store(true, std::memory_order_release);
  fusion.join();
  // The plan pins what the operator may draw (under the gate, beside fusion):
  // the map reuses none of those bricks.
  std::size_t pinned = 0;
  for (std::size_t b = 0; b < mapper.map().brickCount(); ++b) {
    const auto brick = static_cast<uint16_t>(b);
    EXPECT_EQ(mapper.map().brickPinned(brick), mapper.delta()->holds(brick)) << "brick " << b;
    pinned += mapper.map().brickPinned(brick) ? 1 : 0;
  }
  // Nothing was forgotten: a brick planned is held, and pinned (under qemu's
  // fewer frames the bricks may not have settled in time to be planned).
  EXPECT_EQ(pinned > 0, planned > 0) << planned << " bricks planned";
  ASSERT_FALSE(handed.empty());
  EXPECT_EQ(handed.size() + busy, static_cast<std::size_t>(frames));
  EXPECT_EQ(mapper.status().fusion_busy, busy);
  EXPECT_LE(took, handed.size());
  // The same frames, fused on one thread.
  Mapper alone = Mapper::create(mapperConfig(false)).value();
  for (hal::RgbdFrame& f : handed) {
    MapperFrame out;
    EXPECT_TRUE(alone.addFrame(f, true, out));
  }
  expectSameMap(mapper.map(), alone.map());
  EXPECT_GT(mapper.map().size(), 0u);
  RecordProperty("frames_handed_over", static_cast<int>(handed.size()));
  RecordProperty("points_thinned", static_cast<int>(thinned));
}

// With tracking, the pixels the tracker finds moving travel with the frame to
// the fusion thread (the hand-off's copy), which leaves them out: a box pasted
// into the orbit's frames, standing where the map has seen the room, is counted
// moving on the fusion thread's frames too. Under ThreadSanitizer, the race
// check of that copy beside the tracker's model, built on the fusion thread.
TEST(MapperThread, TheTrackersMovingPixelsGoWithTheFrameToTheFusionThread) {
  std::unique_ptr<hal::Camera> camera = test::startedCamera("mock:living-room,size=160x120,path=orbit");
  ASSERT_TRUE(camera);
  MapperConfig config = mapperConfig(true);
  config.tracking = PoseTracking::kAlone;
  config.tracker.moving.settle_frames = 255;  // the box never settles here
  Mapper mapper = Mapper::create(config).value();
  std::atomic<bool> stop{false};
  std::thread fusion([&] {
    while (!stop.load(std::memory_order_acquire)) {
      if (!mapper.fuseSubmitted()) std::this_thread::yield();
    }
    while (mapper.fuseSubmitted()) {
    }
  });
  hal::RgbdFrame frame(kW, kH);
  uint64_t tracked_moving = 0, fused_moving = 0, fused = 0;
  const int frames = test::repetitions(30, 14);
  for (int i = 0; i < frames; ++i) {
    ASSERT_TRUE(camera->acquire(frame, test::scaled(std::chrono::seconds(1))).isOk());
    if (i >= 6) {  // a box at 0.8 m over the left third, textured
      for (int v = 0; v < kH; ++v) {
        for (int u = 0; u < kW / 3; ++u) {
          const std::size_t p = static_cast<std::size_t>(v) * kW + u;
          frame.depth()[p] = static_cast<uint16_t>(std::lround(0.8 / frame.depth_scale_m));
          frame.rgb()[3 * p] = ((u / 6 + v / 6 + i) % 2) ? 220 : 30;
        }
      }
    }
    MapperFrame out;
    (void)mapper.addFrame(frame, false, out);
    tracked_moving += out.track.moving_pixels > 0 ? 1 : 0;
    // Fusion may lag: wait for the frame handed over, so that the next one is handed too.
    if (out.handed_off) {
      const auto until = std::chrono::steady_clock::now() + test::scaled(std::chrono::seconds(5));
      MapperFrame done;
      while (!mapper.takeFused(done) && std::chrono::steady_clock::now() < until) std::this_thread::yield();
      fused += done.fused() ? 1 : 0;
      fused_moving += done.fuse.pixels_moving > 0 ? 1 : 0;
    }
  }
  stop.store(true, std::memory_order_release);
  fusion.join();
  EXPECT_GT(tracked_moving, 0u) << "the tracker found the box moving";
  EXPECT_GT(fused, static_cast<uint64_t>(frames) / 2);
  EXPECT_GT(fused_moving, 0u) << "the fusion thread left the box's pixels out";
}

}  // namespace
}  // namespace fovea::pipeline::map
