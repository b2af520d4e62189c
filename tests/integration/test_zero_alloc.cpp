// The design card's fixed-memory promise: after start-up, processing frames
// allocates nothing. The allocator of this binary is replaced by a counting one.
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <string>
#include <string_view>
#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "firmware/frame_foveator.h"
#include "hal/camera.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/map/tracker.h"
#include "pipeline/pyramid_sampler.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/clouds.h"
#include "tests/support/test_time.h"
#include "tests/support/cameras.h"
#include "tests/support/tum_frames.h"

namespace fovea {
namespace {

// Frames counted per test: 100 natively; 10 where a frame costs 10 to 40 times as
// much (sanitizers, qemu), which is still enough, since an allocation on the
// frame path shows on every frame. Under ASan the three mock runs took 6 of CI's
// 25 minutes at 100 frames, and 5 of its 50 at 20.
int framesCounted() { return test::repetitions(100, 10); }

using test::startedCamera;

TEST(ZeroAllocation, CounterSeesAllocations) {
  // The test below means something only if the counter works.
  test::AllocationScope scope;
  auto p = std::make_unique<std::vector<int>>(1000);
  void* volatile raw = std::malloc(10);  // volatile: GCC may elide a malloc/free pair
  std::free(raw);
  EXPECT_GE(scope.allocations(), 3u);
}

// Both kernel sets: the scalar references, and the SIMD kernels with the hash
// sampler on one and on three threads.
struct KernelChoice {
  fovea::KernelSet kernels;
  int threads;
};
void PrintTo(const KernelChoice& c, std::ostream* os) {
  *os << fovea::kernelSetName(c.kernels) << " on " << c.threads << " threads";
}
class ZeroAllocationKernels : public ::testing::TestWithParam<KernelChoice> {};

TEST_P(ZeroAllocationKernels, HundredMockFramesAfterWarmUp) {
  const fovea::KernelSet kernels = GetParam().kernels;
  const int threads = GetParam().threads;
  // 320x240 where a mock frame's ray cast costs 20 times as much (the frame path is the same code).
  const std::unique_ptr<hal::Camera> camera = startedCamera(
      test::timeScale() > 1.0 ? "mock:living-room,path=orbit,size=320x240" : "mock:living-room,path=orbit");
  ASSERT_TRUE(camera);
  hal::Camera& cam = *camera;
  const hal::CameraIntrinsics& k = cam.info().intrinsics;
  const std::size_t pixels = static_cast<std::size_t>(k.width) * k.height;

  hal::RgbdFrame frame(k.width, k.height);
  pipeline::PointCloud cloud(pixels);
  pipeline::FoveatedCloud out(pixels);
  pipeline::FoveationConfig config;
  pipeline::Foveator foveator = pipeline::Foveator::create({pixels, pixels, kernels, threads}, config).value();
  pipeline::FoveationConfig f3 = config;
  f3.acuity.preset = pipeline::Preset::kF3;

  pipeline::Backprojector backprojector(threads, kernels);
  auto runFrame = [&](int i) {
    pipeline::BackprojectCounts bc;
    pipeline::FoveationStats stats;
    if (!cam.acquire(frame, test::scaled(std::chrono::milliseconds(100))).isOk()) return false;
    if (!backprojector.run(frame, pipeline::DepthRange{}, cloud, bc).isOk()) return false;
    pipeline::Gaze gaze;
    gaze.origin_m = frame.T_world_cam.t_world_cam;
    gaze.direction = frame.T_world_cam.R_world_cam.col(2) + Eigen::Vector3d(0.01 * (i % 7), 0.0, 0.0);
    return foveator.foveate(cloud, gaze, out, stats).isOk() && out.size() > 0;
  };
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(runFrame(i));  // warm-up

  test::AllocationScope scope;
  bool all_ok = true;
  const int frames = framesCounted();
  for (int i = 0; i < frames; ++i) {
    all_ok = runFrame(i) && all_ok;
    if (i == frames / 2) all_ok = foveator.setConfig(f3).isOk() && all_ok;  // a live preset change is on the frame path too
  }
  const uint64_t allocations = scope.allocations();
  EXPECT_TRUE(all_ok);
  EXPECT_EQ(allocations, 0u);
  cam.stop();
}

// ACUITY on the image pyramid (pipeline/pyramid_sampler.h), frame after frame with a
// moving gaze, from the camera's frame to the output, with the representatives too.
TEST(ZeroAllocation, PyramidSamplerOnMockFrames) {
  const std::unique_ptr<hal::Camera> camera = startedCamera(
      test::timeScale() > 1.0 ? "mock:living-room,path=orbit,size=320x240" : "mock:living-room,path=orbit");
  ASSERT_TRUE(camera);
  hal::Camera& cam = *camera;
  const hal::CameraIntrinsics& k = cam.info().intrinsics;
  const std::size_t pixels = static_cast<std::size_t>(k.width) * k.height;
  hal::RgbdFrame frame(k.width, k.height);
  pipeline::FoveatedCloud out(pixels);
  std::vector<uint32_t> representative(pixels);
  pipeline::PyramidSampler sampler = pipeline::PyramidSampler::create(k.width, k.height).value();
  pipeline::AcuityConfig acuity;
  acuity.floor_per_m2 = 0.001;
  const pipeline::PyramidRule rule = pipeline::PyramidRule::fromAcuity(acuity);
  auto runFrame = [&](int i) {
    pipeline::PyramidStats stats;
    if (!cam.acquire(frame, test::scaled(std::chrono::milliseconds(100))).isOk()) return false;
    pipeline::Gaze gaze;
    gaze.origin_m = frame.T_world_cam.t_world_cam;
    gaze.direction = frame.T_world_cam.R_world_cam.col(2) + Eigen::Vector3d(0.01 * (i % 7), 0.0, 0.0);
    return sampler.sample(frame, pipeline::DepthRange{}, gaze, rule, out, stats, i % 2 ? representative.data() : nullptr)
               .isOk() &&
           out.size() > 0;
  };
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(runFrame(i));  // warm-up
  test::AllocationScope scope;
  bool all_ok = true;
  for (int i = 0; i < framesCounted(); ++i) all_ok = runFrame(i) && all_ok;
  const uint64_t allocations = scope.allocations();
  EXPECT_TRUE(all_ok);
  EXPECT_EQ(allocations, 0u);
  cam.stop();
}

// Fusing posed mock frames into the surfel map, with the pool full enough that
// eviction runs inside the counted frames; with either per-pixel kernel set.
TEST(ZeroAllocation, FusingMockFramesIntoTheMap) {
  for (KernelSet kernels : {KernelSet::kRef, KernelSet::kSimd}) {
    SCOPED_TRACE(std::string("kernels ") + std::string(kernelSetName(kernels)));
    const std::unique_ptr<hal::Camera> camera = startedCamera("mock:living-room,path=orbit,size=160x120");
    ASSERT_TRUE(camera);
    hal::Camera& cam = *camera;
    const hal::CameraIntrinsics& k = cam.info().intrinsics;
    hal::RgbdFrame frame(k.width, k.height);
    pipeline::map::SurfelMapConfig config;
    config.max_width = k.width;
    config.max_height = k.height;
    config.max_surfels = static_cast<std::size_t>(k.width) * k.height / 4;  // less than a frame: eviction every frame
    config.kernels = kernels;
    Result<pipeline::map::SurfelMap> created = pipeline::map::SurfelMap::create(config);
    ASSERT_TRUE(created.isOk()) << created.status().toString();
    pipeline::map::SurfelMap& map = created.value();
    auto fuseFrame = [&] {
      pipeline::map::FuseStats stats;
      return cam.acquire(frame, test::scaled(std::chrono::milliseconds(100))).isOk() &&
             map.fuse(frame, stats) == pipeline::map::FuseOutcome::kFused;
    };
    for (int i = 0; i < 3; ++i) ASSERT_TRUE(fuseFrame());  // warm-up

    const uint64_t evicted_before = map.counters().evicted;
    test::AllocationScope scope;
    bool all_ok = true;
    const int frames = framesCounted();
    for (int i = 0; i < frames; ++i) all_ok = fuseFrame() && all_ok;
    const uint64_t allocations = scope.allocations();
    EXPECT_TRUE(all_ok);
    EXPECT_EQ(allocations, 0u);
    EXPECT_GT(map.size(), 0u);
    EXPECT_GT(map.counters().evicted, evicted_before) << "no eviction among the counted frames";
    cam.stop();
  }
}

// Tracking each mock frame against the map's model and fusing it at the
// tracked pose (pipeline/map/tracker.h): track() and modelFused() allocate
// nothing, a lost frame (no depth) included; with either kernel set.
TEST(ZeroAllocation, TrackingMockFramesAgainstTheMap) {
  for (KernelSet kernels : {KernelSet::kRef, KernelSet::kSimd}) {
    SCOPED_TRACE(std::string("kernels ") + std::string(kernelSetName(kernels)));
    const std::unique_ptr<hal::Camera> camera = startedCamera("mock:living-room,path=orbit,size=160x120");
    ASSERT_TRUE(camera);
    hal::Camera& cam = *camera;
    const hal::CameraIntrinsics& k = cam.info().intrinsics;
    hal::RgbdFrame frame(k.width, k.height);
    pipeline::map::SurfelMapConfig config;
    config.max_width = k.width;
    config.max_height = k.height;
    config.max_surfels = static_cast<std::size_t>(k.width) * k.height * 4;
    config.kernels = kernels;
    pipeline::map::SurfelMap map = pipeline::map::SurfelMap::create(config).value();
    pipeline::map::TrackerConfig tc;
    tc.max_width = k.width;
    tc.max_height = k.height;
    tc.kernels = kernels;
    pipeline::map::FrameToModelTracker tracker = pipeline::map::FrameToModelTracker::create(tc).value();
    int frames_done = 0;
    auto trackFrame = [&] {
      if (!cam.acquire(frame, test::scaled(std::chrono::milliseconds(100))).isOk()) return false;
      if (frames_done++ % 10 == 9) {  // every tenth frame without depth: lost, then relocalised
        std::fill(frame.depth(), frame.depth() + frame.pixelCount(), uint16_t{0});
      }
      hal::Pose pose;
      pipeline::map::TrackStats stats;
      const bool first = frames_done == 1;
      const pipeline::map::TrackOutcome o = tracker.track(frame, first ? &frame.T_world_cam : nullptr, pose, stats);
      if (o == pipeline::map::TrackOutcome::kLost) return true;
      frame.T_world_cam = pose;
      pipeline::map::FuseStats fs;
      if (map.fuse(frame, fs) != pipeline::map::FuseOutcome::kFused) return false;
      tracker.modelFused(frame, pose, map);
      return true;
    };
    for (int i = 0; i < 3; ++i) ASSERT_TRUE(trackFrame());  // warm-up

    test::AllocationScope scope;
    bool all_ok = true;
    const int frames = framesCounted();
    for (int i = 0; i < frames; ++i) all_ok = trackFrame() && all_ok;
    const uint64_t allocations = scope.allocations();
    EXPECT_TRUE(all_ok);
    EXPECT_EQ(allocations, 0u);
    EXPECT_GT(tracker.counters().tracked, 0u);
    EXPECT_GT(tracker.counters().lost, 0u);
    EXPECT_GT(tracker.counters().relocalised, 0u);
    cam.stop();
  }
}

// The service's map source (firmware/frame_foveator.h): each frame fused, the
// map's surfels the eye sees gathered with the frame's unexplained points and
// foveated, the eye moving, the pool small enough that eviction runs too.
TEST(ZeroAllocation, FoveatingTheMapAsTheEyeSeesIt) {
  const std::unique_ptr<hal::Camera> camera = startedCamera("mock:living-room,path=orbit,size=160x120");
  ASSERT_TRUE(camera);
  hal::Camera& cam = *camera;
  const hal::CameraIntrinsics& k = cam.info().intrinsics;
  const std::size_t pixels = static_cast<std::size_t>(k.width) * k.height;
  firmware::MapSettings settings;
  settings.source = firmware::FoveationSource::kMap;
  settings.map.max_surfels = pixels / 2;
  Result<firmware::FrameFoveator> created = firmware::FrameFoveator::create(
      {pixels, pixels, fovea::defaultKernelSet(), 1}, pipeline::FoveationConfig{}, pipeline::DepthRange{}, settings,
      k.width, k.height);
  ASSERT_TRUE(created.isOk()) << created.status().toString();
  firmware::FrameFoveator& stage = created.value();
  hal::RgbdFrame frame(k.width, k.height);
  pipeline::FoveatedCloud out(firmware::FrameFoveator::cloudCapacity(pixels, settings));
  auto runFrame = [&](int i) {
    pipeline::BackprojectCounts counts;
    pipeline::FoveationStats stats;
    if (!cam.acquire(frame, test::scaled(std::chrono::milliseconds(100))).isOk()) return false;
    if (!stage.backproject(frame, counts).isOk()) return false;
    pipeline::Gaze gaze;
    gaze.origin_m = frame.T_world_cam.t_world_cam + Eigen::Vector3d(0.05 * (i % 5), 0.0, -0.1);
    gaze.direction = frame.T_world_cam.R_world_cam.col(2);
    return stage.foveate(gaze, out, stats).isOk() && out.size() > 0;
  };
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(runFrame(i));  // warm-up

  const uint64_t evicted_before = stage.map()->counters().evicted;
  test::AllocationScope scope;
  bool all_ok = true;
  const int frames = framesCounted();
  for (int i = 0; i < frames; ++i) all_ok = runFrame(i) && all_ok;
  const uint64_t allocations = scope.allocations();
  EXPECT_TRUE(all_ok);
  EXPECT_EQ(allocations, 0u);
  EXPECT_GT(stage.mapFigures().eye.appended, 0u) << "no map surfel reached the foveator";
  EXPECT_GT(stage.map()->counters().evicted, evicted_before) << "no eviction among the counted frames";
  cam.stop();
}

#ifdef FOVEA_HAVE_PNG
// The same on real frames: the 60 TUM frames of shared/data, looped (open()
// decodes them all; acquire() must only copy).
TEST_P(ZeroAllocationKernels, HundredTumFramesAfterWarmUp) {
  const fovea::KernelSet kernels = GetParam().kernels;
  const int threads = GetParam().threads;
  FOVEA_REQUIRE_TUM_TEDDY(path);
  const std::unique_ptr<hal::Camera> camera = startedCamera("tum:" + path + ",loop=on");
  ASSERT_TRUE(camera);
  hal::Camera& cam = *camera;
  const std::size_t pixels = 640 * 480;
  hal::RgbdFrame frame(640, 480);
  pipeline::PointCloud cloud(pixels);
  pipeline::FoveatedCloud out(pixels);
  pipeline::Foveator foveator = pipeline::Foveator::create({pixels, pixels, kernels, threads}, {}).value();
  pipeline::Backprojector backprojector(threads, kernels);
  auto runFrame = [&] {
    pipeline::BackprojectCounts bc;
    pipeline::FoveationStats stats;
    if (!cam.acquire(frame, test::scaled(std::chrono::milliseconds(100))).isOk()) return false;
    if (!backprojector.run(frame, pipeline::DepthRange{}, cloud, bc).isOk()) return false;
    pipeline::Gaze gaze;
    gaze.origin_m = frame.T_world_cam.t_world_cam;
    gaze.direction = frame.T_world_cam.R_world_cam.col(2);
    return foveator.foveate(cloud, gaze, out, stats).isOk() && out.size() > 0;
  };
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(runFrame());

  test::AllocationScope scope;
  bool all_ok = true;
  for (int i = 0, frames = framesCounted(); i < frames; ++i) all_ok = runFrame() && all_ok;
  const uint64_t allocations = scope.allocations();
  EXPECT_TRUE(all_ok);
  EXPECT_EQ(allocations, 0u);
  cam.stop();
}
#endif

TEST_P(ZeroAllocationKernels, FoveatingRandomCloudsWithEveryPreset) {
  std::vector<pipeline::PointCloud> clouds;
  for (uint64_t seed = 1; seed <= 4; ++seed) clouds.push_back(test::randomCloud(50000, Eigen::Vector3d(seed, 0, 0), 4.0f, seed));
  pipeline::FoveatedCloud out(50000);
  pipeline::Foveator foveator = pipeline::Foveator::create({50000, 50000, GetParam().kernels, GetParam().threads}, {}).value();
  // The stages this case means to count: the references, the SIMD kernels, or their pooled ranges.
  const std::string_view partition = foveator.stageKernels().partition;
  EXPECT_EQ(partition, GetParam().kernels == fovea::KernelSet::kRef ? "partitionRef"
                       : GetParam().threads > 1                     ? "partitionRange/pool"
                                                                    : "partitionSimd");
  std::vector<pipeline::FoveationConfig> configs(7);
  configs[0].acuity.preset = pipeline::Preset::kF1;
  configs[1].acuity.preset = pipeline::Preset::kF2;
  configs[2].acuity.preset = pipeline::Preset::kF3;
  configs[3].acuity.preset = pipeline::Preset::kFRef;
  configs[4].acuity.preset = pipeline::Preset::kAcuity;
  configs[4].acuity.floor_m = 0.008;
  // ACUITY with its distance floor and view cull, under a gaze with a grown fovea and a head.
  configs[5].acuity.preset = pipeline::Preset::kAcuity;
  configs[5].acuity.floor_per_m2 = 0.001;
  configs[5].acuity.view_cull = pipeline::ViewCull::kDrop;
  configs[5].acuity.view_cull_deg = 40.0;
  pipeline::Gaze head;
  head.fovea_growth_deg = 5.0;
  head.view_known = true;
  head.view_forward = Eigen::Vector3d(0.5, 0.0, 1.0);
  // ACUITY refined: every pass samples again, with the Foveator's own representatives.
  configs[6].acuity.preset = pipeline::Preset::kAcuity;
  configs[6].acuity.level_margin = 0.15;
  configs[6].acuity.refine_passes = pipeline::kMaxRefinePasses;
  configs[1].fixation.mode = pipeline::FixationMode::kCentroid;
  pipeline::FoveationStats stats;
  ASSERT_TRUE(foveator.foveate(clouds[0], pipeline::Gaze{}, out, stats).isOk());

  test::AllocationScope scope;
  bool all_ok = true;
  // 28 = 4 clouds x 7 configurations: every pair once (in slow builds, once only).
  for (int i = 0, n = test::repetitions(120, 28); i < n; ++i) {
    all_ok = foveator.setConfig(configs[i % 7]).isOk() && all_ok;
    all_ok = foveator.foveate(clouds[i % 4], i % 7 == 5 ? head : pipeline::Gaze{}, out, stats).isOk() && all_ok;
  }
  const uint64_t allocations = scope.allocations();
  EXPECT_TRUE(all_ok);
  EXPECT_EQ(allocations, 0u);
}

INSTANTIATE_TEST_SUITE_P(KernelSets, ZeroAllocationKernels,
                         ::testing::Values(KernelChoice{fovea::KernelSet::kRef, 1},
                                           KernelChoice{fovea::KernelSet::kSimd, 1},
                                           KernelChoice{fovea::KernelSet::kSimd, 3}),
                         [](const ::testing::TestParamInfo<KernelChoice>& info) {
                           return std::string(fovea::kernelSetName(info.param.kernels)) + "_" +
                                  std::to_string(info.param.threads) + "_threads";
                         });

}  // namespace
}  // namespace fovea
