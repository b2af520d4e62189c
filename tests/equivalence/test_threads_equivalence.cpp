// Splitting a frame across 1, 2, 3 or 4 threads gives output identical to the
// single-threaded reference: back-projection, partition and the whole Foveator.
#include <atomic>
#include <bit>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "hal/camera.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/kernels/hash_voxel_sampler.h"
#include "pipeline/kernels/worker_pool.h"
#include "tests/support/clouds.h"
#include "tests/support/test_time.h"

namespace fovea::pipeline {
namespace {

TEST(WorkerPool, EveryPartRunsOncePerRun) {
  for (int parts : {1, 2, 3, 4, 7}) {
    WorkerPool pool(parts);
    ASSERT_EQ(pool.parts(), parts);
    std::vector<std::atomic<int>> hits(static_cast<std::size_t>(parts));
    for (int run = 0; run < 200; ++run) {
      pool.run([](void* ctx, int part, int n) {
        auto* h = static_cast<std::vector<std::atomic<int>>*>(ctx);
        EXPECT_EQ(static_cast<std::size_t>(n), h->size());
        ++(*h)[static_cast<std::size_t>(part)];
      }, &hits);
      for (int p = 0; p < parts; ++p) ASSERT_EQ(hits[static_cast<std::size_t>(p)].load(), run + 1);
    }
  }
}

TEST(WorkerPool, RangesCoverEverythingOnce) {
  for (std::size_t n : {0, 1, 2, 3, 5, 100, 307200}) {
    for (int parts : {1, 2, 3, 4}) {
      std::size_t expected = 0;
      for (int p = 0; p < parts; ++p) {
        EXPECT_EQ(WorkerPool::rangeBegin(n, p, parts), expected);
        expected = WorkerPool::rangeBegin(n, p + 1, parts);
      }
      EXPECT_EQ(expected, n);
    }
  }
}

bool sameCloud(const PointCloud& a, const PointCloud& b) {
  if (a.size() != b.size() || a.origin_m != b.origin_m || a.has_color != b.has_color) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::bit_cast<uint32_t>(a.x()[i]) != std::bit_cast<uint32_t>(b.x()[i]) ||
        std::bit_cast<uint32_t>(a.y()[i]) != std::bit_cast<uint32_t>(b.y()[i]) ||
        std::bit_cast<uint32_t>(a.z()[i]) != std::bit_cast<uint32_t>(b.z()[i]) || a.rgb()[i] != b.rgb()[i]) {
      return false;
    }
  }
  return true;
}

bool sameFoveated(const FoveatedCloud& a, const FoveatedCloud& b) {
  if (!sameCloud(a.points, b.points)) return false;
  for (std::size_t o = 0; o < a.size(); ++o) {
    if (a.region[o] != b.region[o] || a.weight[o] != b.weight[o]) return false;
  }
  return true;
}

TEST(Threads, BackprojectionIsIdenticalForOneToFourThreads) {
  std::mt19937_64 rng(61);
  const int sizes[][2] = {{640, 480}, {33, 1}, {7, 3}, {1, 5}, {129, 17}};
  for (const auto& s : sizes) {
    hal::RgbdFrame frame(s[0], s[1]);
    frame.intrinsics = {s[0], s[1], 400.0, 410.0, s[0] / 2.0, s[1] / 2.0};
    frame.T_world_cam.R_world_cam = Eigen::Quaterniond::UnitRandom().toRotationMatrix();
    frame.T_world_cam.t_world_cam = Eigen::Vector3d(1e4, 2, -3);
    for (std::size_t i = 0; i < frame.pixelCount(); ++i) {
      frame.depth()[i] = (rng() % 5 == 0) ? 0 : static_cast<uint16_t>(rng() % 12000);
      frame.rgb()[3 * i] = static_cast<uint8_t>(rng());
    }
    PointCloud ref(frame.pixelCount());
    BackprojectCounts cr;
    ASSERT_TRUE(backprojectRef(frame, DepthRange{}, ref, cr).isOk());
    for (int threads = 1; threads <= 4; ++threads) {
      Backprojector bp(threads, KernelSet::kSimd);
      EXPECT_EQ(bp.threads(), threads);
      PointCloud cloud(frame.pixelCount());
      BackprojectCounts c;
      ASSERT_TRUE(bp.run(frame, DepthRange{}, cloud, c).isOk());
      EXPECT_TRUE(sameCloud(ref, cloud)) << s[0] << "x" << s[1] << ", " << threads << " threads";
      EXPECT_EQ(c.valid, cr.valid);
      EXPECT_EQ(c.no_depth, cr.no_depth);
      EXPECT_EQ(c.out_of_range, cr.out_of_range);
      EXPECT_EQ(c.pixels, cr.pixels);
      // Too small a cloud: the same error, nothing written.
      if (cr.valid > 0) {
        PointCloud small(cr.valid - 1);
        EXPECT_EQ(bp.run(frame, DepthRange{}, small, c).code(), ErrorCode::kCapacityExceeded);
        EXPECT_EQ(small.size(), 0u);
      }
    }
  }
}

TEST(Threads, FoveatorIsIdenticalForOneToFourThreads) {
  std::mt19937_64 rng(62);
  // ACUITY four times: plain; with a grown fovea and a view cull that drops points;
  // refined; refined with a distance floor and a view cull to the coarsest level.
  for (int variant = 0; variant < 6; ++variant) {
    FoveationConfig config;
    config.acuity.preset = variant == 0 ? Preset::kF1 : variant == 1 ? Preset::kF3 : Preset::kAcuity;
    if (variant == 3) {
      config.acuity.view_cull = ViewCull::kDrop;
      config.acuity.view_cull_deg = 30.0;
    }
    if (variant >= 4) {
      config.acuity.level_margin = 0.15;
      config.acuity.refine_passes = variant == 4 ? kMaxRefinePasses : 2;
    }
    if (variant == 5) {
      config.acuity.floor_per_m2 = 0.002;
      config.acuity.view_cull = ViewCull::kCoarsest;
      config.acuity.view_cull_deg = 30.0;
    }
    for (std::size_t n : {std::size_t{3}, std::size_t{50001}}) {
      PointCloud cloud = test::randomCloud(n, Eigen::Vector3d(1e4, 0, 0), 4.0f, rng());
      cloud.x()[n / 2] = std::numeric_limits<float>::quiet_NaN();
      Gaze gaze;
      gaze.origin_m = cloud.origin_m + Eigen::Vector3d(0, 0, -4);
      gaze.direction = Eigen::Vector3d(0.1, 0, 1);
      if (variant == 3 || variant == 5) {
        gaze.fovea_growth_deg = 6.0;
        gaze.view_known = true;
        gaze.view_forward = Eigen::Vector3d(0.4, 0.1, 1);
      }
      Foveator ref = Foveator::create({n, n, KernelSet::kRef}, config).value();
      FoveatedCloud expected(n);
      FoveationStats es;
      std::vector<uint32_t> expected_rep(n);
      ASSERT_TRUE(ref.foveate(cloud, gaze, expected, es, expected_rep.data()).isOk());
      for (int threads = 1; threads <= 4; ++threads) {
        Foveator f = Foveator::create({n, n, KernelSet::kSimd, threads}, config).value();
        FoveatedCloud out(n);
        FoveationStats st;
        std::vector<uint32_t> rep(n);
        ASSERT_TRUE(f.foveate(cloud, gaze, out, st, rep.data()).isOk());
        EXPECT_TRUE(sameFoveated(expected, out)) << threads << " threads";
        EXPECT_EQ(expected_rep, rep);
        EXPECT_EQ(es.dropped_nonfinite, st.dropped_nonfinite);
        EXPECT_EQ(es.culled, st.culled);
        if (variant == 3 && n > 3) {
          EXPECT_GT(st.culled, 0u);
        }
        EXPECT_EQ(es.refined, st.refined);
        EXPECT_EQ(es.refine_passes, st.refine_passes);
        if (variant >= 4 && n > 3) {
          EXPECT_GT(st.refined, 0u);
        }
        for (int r = 0; r < kMaxRegions; ++r) EXPECT_EQ(es.regions[r].points_in, st.regions[r].points_in);
        // The refinement keeps its own representatives when the caller asks for none.
        FoveatedCloud unasked(n);
        ASSERT_TRUE(f.foveate(cloud, gaze, unasked, st).isOk());
        EXPECT_TRUE(sameFoveated(expected, unasked)) << threads << " threads, no representative asked";
      }
    }
  }
}

TEST(Threads, MockCameraPipelineIsIdenticalForOneToFourThreads) {
  auto camera = hal::createCamera("mock:living-room,path=orbit");
  ASSERT_TRUE(camera.isOk());
  hal::Camera& cam = *camera.value();
  ASSERT_TRUE(cam.open().isOk());
  ASSERT_TRUE(cam.start().isOk());
  const std::size_t pixels = static_cast<std::size_t>(cam.info().intrinsics.width) * cam.info().intrinsics.height;
  hal::RgbdFrame frame(cam.info().intrinsics.width, cam.info().intrinsics.height);
  ASSERT_TRUE(cam.acquire(frame, test::scaled(std::chrono::seconds(2))).isOk());
  Gaze gaze;
  gaze.origin_m = frame.T_world_cam.t_world_cam;
  gaze.direction = frame.T_world_cam.R_world_cam.col(2);
  PointCloud ref_cloud(pixels);
  BackprojectCounts bc;
  ASSERT_TRUE(backprojectRef(frame, DepthRange{}, ref_cloud, bc).isOk());
  Foveator ref = Foveator::create({pixels, pixels, KernelSet::kRef}, {}).value();
  FoveatedCloud expected(pixels);
  FoveationStats st;
  ASSERT_TRUE(ref.foveate(ref_cloud, gaze, expected, st).isOk());
  for (int threads = 1; threads <= 4; ++threads) {
    Backprojector bp(threads, KernelSet::kSimd);
    Foveator f = Foveator::create({pixels, pixels, KernelSet::kSimd, threads}, {}).value();
    PointCloud cloud(pixels);
    FoveatedCloud out(pixels);
    ASSERT_TRUE(bp.run(frame, DepthRange{}, cloud, bc).isOk());
    ASSERT_TRUE(f.foveate(cloud, gaze, out, st).isOk());
    EXPECT_TRUE(sameFoveated(expected, out)) << threads << " threads";
  }
  cam.stop();
}

TEST(Threads, HashSamplerOnAPoolMatchesTheReferenceIncludingErrors) {
  std::mt19937_64 rng(63);
  const std::size_t n = 40000;
  PointCloud base = test::randomCloud(n, Eigen::Vector3d(-1e4, 0, 1e4), 3.0f, 64);
  std::vector<uint8_t> region(n);
  for (auto& r : region) r = static_cast<uint8_t>(rng() % 4);
  struct Case {
    const char* what;
    std::size_t bad_point;  // n: none
    float bad_value;
    std::array<double, kMaxRegions> voxel_m;
    std::size_t max_voxels;
  };
  const Case cases[] = {
      {"ok", n, 0.0f, {0, 0.01, 0.05, 0.2}, n},
      {"nan early", 5, std::numeric_limits<float>::quiet_NaN(), {0, 0.01, 0.05, 0.2}, n},
      {"inf late", n - 3, std::numeric_limits<float>::infinity(), {0, 0.01, 0.05, 0.2}, n},
      {"huge in the middle", n / 2 + 1, 3e38f, {0, 0.01, 0.05, 0.2}, n},
      {"span", n, 0.0f, {0, 1e-6, 0.05, 0.2}, n},
      {"too many voxels", n, 0.0f, {0, 0.01, 0.05, 0.2}, 1000},
  };
  for (const Case& c : cases) {
    PointCloud cloud = base;
    std::vector<uint8_t> reg = region;
    if (c.bad_point < n) {
      cloud.y()[c.bad_point] = c.bad_value;
      reg[c.bad_point] = 2;
      cloud.x()[c.bad_point + 2] = c.bad_value;  // a second bad point after it
      reg[c.bad_point + 2] = 1;
    }
    VoxelSampler ref(n, c.max_voxels);
    FoveatedCloud expected(n);
    SampleCounts ce;
    std::vector<uint32_t> rep_expected(n);
    const Status se = ref.sample(cloud, reg.data(), 4, c.voxel_m, expected, ce, rep_expected.data());
    for (int threads = 1; threads <= 4; ++threads) {
      WorkerPool pool(threads);
      HashVoxelSampler fast(n, c.max_voxels);
      fast.setWorkerPool(&pool);
      FoveatedCloud out(n);
      SampleCounts cf;
      std::vector<uint32_t> rep(n);
      const Status sf = fast.sample(cloud, reg.data(), 4, c.voxel_m, out, cf, rep.data());
      ASSERT_EQ(se.code(), sf.code()) << c.what << ", " << threads << " threads: " << sf.toString();
      if (se.code() == ErrorCode::kRangeExceeded) {
        EXPECT_EQ(se.message(), sf.message()) << c.what;
      }
      if (!se) continue;
      EXPECT_TRUE(sameFoveated(expected, out)) << c.what << ", " << threads << " threads";
      EXPECT_EQ(rep_expected, rep) << c.what;
      EXPECT_EQ(ce.in, cf.in);
      EXPECT_EQ(ce.out, cf.out);
    }
  }
}

TEST(Threads, ThreadCountIsValidated) {
  EXPECT_EQ(Foveator::create({10, 10, KernelSet::kSimd, 0}, {}).status().code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(Foveator::create({10, 10, KernelSet::kSimd, 65}, {}).status().code(), ErrorCode::kInvalidArgument);
  EXPECT_TRUE(Foveator::create({10, 10, KernelSet::kRef, 4}, {}).isOk());  // the reference ignores threads
}

}  // namespace
}  // namespace fovea::pipeline
