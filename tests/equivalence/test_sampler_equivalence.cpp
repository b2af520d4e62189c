// The hash-table sampler against the reference VoxelSampler: every field of the
// output (positions bit for bit, colours, regions, weights, order), the counts, the
// representatives and the error codes; on every Highway target (its voxel
// indices come from voxelIndexSimd). Then the whole Foveator, kernel set simd
// against ref, on random clouds and mock camera frames.
#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "hal/camera.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/kernels/hash_voxel_sampler.h"
#include "pipeline/voxel_sampler.h"
#include "tests/support/clouds.h"
#include "tests/support/guarded_array.h"
#include "tests/support/simd_targets.h"
#include "tests/support/test_time.h"

namespace fovea::pipeline {
namespace {

using SamplerTarget = test::TargetTest;  // tests/support/simd_targets.h

::testing::AssertionResult sameFoveated(const FoveatedCloud& a, const FoveatedCloud& b) {
  if (a.size() != b.size()) return ::testing::AssertionFailure() << "size " << a.size() << " vs " << b.size();
  if (a.points.origin_m != b.points.origin_m || a.points.has_color != b.points.has_color) {
    return ::testing::AssertionFailure() << "origin or colour flag";
  }
  for (std::size_t o = 0; o < a.size(); ++o) {
    const bool same = std::bit_cast<uint32_t>(a.points.x()[o]) == std::bit_cast<uint32_t>(b.points.x()[o]) &&
                      std::bit_cast<uint32_t>(a.points.y()[o]) == std::bit_cast<uint32_t>(b.points.y()[o]) &&
                      std::bit_cast<uint32_t>(a.points.z()[o]) == std::bit_cast<uint32_t>(b.points.z()[o]) &&
                      a.points.rgb()[o] == b.points.rgb()[o] && a.region[o] == b.region[o] &&
                      a.weight[o] == b.weight[o];
    if (!same) {
      return ::testing::AssertionFailure()
             << "output point " << o << ": ref (" << a.points.x()[o] << ", " << a.points.y()[o] << ", "
             << a.points.z()[o] << ") rgb " << a.points.rgb()[o] << " region " << int(a.region[o]) << " weight "
             << a.weight[o] << "; fast (" << b.points.x()[o] << ", " << b.points.y()[o] << ", " << b.points.z()[o]
             << ") rgb " << b.points.rgb()[o] << " region " << int(b.region[o]) << " weight " << b.weight[o];
    }
  }
  return ::testing::AssertionSuccess();
}

void expectSameSampling(const PointCloud& in, const std::vector<uint8_t>& region, int region_count,
                        const std::array<double, kMaxRegions>& voxel_m, std::size_t max_voxels, const char* what,
                        std::size_t out_capacity = 0) {
  const std::size_t cap = out_capacity ? out_capacity : std::max<std::size_t>(in.size(), 1);
  VoxelSampler ref(in.size(), max_voxels);
  HashVoxelSampler fast(in.size(), max_voxels);
  FoveatedCloud out_ref(cap), out_fast(cap);
  SampleCounts c_ref, c_fast;
  std::vector<uint32_t> rep_ref(in.size() + 1, 12345), rep_fast(in.size() + 1, 12345);
  const Status s_ref = ref.sample(in, region.data(), region_count, voxel_m, out_ref, c_ref, rep_ref.data());
  const Status s_fast = fast.sample(in, region.data(), region_count, voxel_m, out_fast, c_fast, rep_fast.data());
  ASSERT_EQ(s_ref.code(), s_fast.code()) << what << ": " << s_ref.toString() << " vs " << s_fast.toString();
  if (!s_ref) {
    if (s_ref.code() == ErrorCode::kRangeExceeded) {
      EXPECT_EQ(s_ref.message(), s_fast.message()) << what;
    }
    return;
  }
  EXPECT_TRUE(sameFoveated(out_ref, out_fast)) << what;
  EXPECT_EQ(c_ref.in, c_fast.in) << what;
  EXPECT_EQ(c_ref.out, c_fast.out) << what;
  EXPECT_EQ(rep_ref, rep_fast) << what;
  // The same sampler again (its table must be clean after a frame) and without representatives.
  FoveatedCloud again(cap);
  ASSERT_TRUE(fast.sample(in, region.data(), region_count, voxel_m, again, c_fast).isOk());
  EXPECT_TRUE(sameFoveated(out_ref, again)) << what << " (second run)";
}

std::vector<uint8_t> randomRegions(std::size_t n, int region_count, std::mt19937_64& rng, bool invalid = true) {
  std::vector<uint8_t> region(n);
  for (auto& r : region) {
    r = static_cast<uint8_t>(rng() % region_count);
    if (invalid && rng() % 50 == 0) r = kRegionInvalid;
  }
  return region;
}

TEST_P(SamplerTarget, RandomClouds) {
  std::mt19937_64 rng(41);
  for (std::size_t n : {0, 1, 2, 7, 100, 5000, 60001}) {
    for (int region_count : {1, 2, 4, 8}) {
      for (const Eigen::Vector3d& origin : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1e4, -1e4, 1e4 + 0.3)}) {
        const PointCloud cloud = test::randomCloud(n, origin, 3.0f, rng());
        const std::vector<uint8_t> region = randomRegions(n, region_count, rng);
        std::array<double, kMaxRegions> voxel_m{};
        std::uniform_real_distribution<double> size(0.002, 0.5);
        for (int r = 1; r < region_count; ++r) voxel_m[r] = size(rng);
        expectSameSampling(cloud, region, region_count, voxel_m, std::max<std::size_t>(n, 1), "random");
      }
    }
  }
}

TEST_P(SamplerTarget, ImageCoherentCloud) {
  // A back-projected frame: neighbouring points share voxels (the last-key cache path).
  Result<std::unique_ptr<hal::Camera>> camera = hal::createCamera("mock:living-room,size=320x240");
  ASSERT_TRUE(camera.isOk());
  ASSERT_TRUE(camera.value()->open().isOk());
  ASSERT_TRUE(camera.value()->start().isOk());
  hal::RgbdFrame frame(320, 240);
  ASSERT_TRUE(camera.value()->acquire(frame, test::scaled(std::chrono::seconds(2))).isOk());
  PointCloud cloud(frame.pixelCount());
  BackprojectCounts bc;
  ASSERT_TRUE(backprojectSimd(frame, DepthRange{}, cloud, bc).isOk());
  std::mt19937_64 rng(42);
  std::vector<uint8_t> region(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) region[i] = static_cast<uint8_t>((i / 5000) % 4);
  expectSameSampling(cloud, region, 4, {0, 0.01, 0.03, 0.1}, cloud.size(), "image");
  camera.value()->stop();
}

TEST_P(SamplerTarget, AMillionPointsInOneVoxel) {
  constexpr std::size_t kN = 1000000;
  PointCloud cloud(kN);
  cloud.origin_m = Eigen::Vector3d(1e4 + 0.5, 0.5, 0.5);
  for (std::size_t i = 0; i < kN; ++i) {
    const float d = 0.001f * static_cast<float>(i % 200) - 0.0995f;
    (void)cloud.push(d, -d, 0.25f * d, packRgb(static_cast<uint8_t>(i % 256), 128, 3));
  }
  expectSameSampling(cloud, std::vector<uint8_t>(kN, 1), 2, {0, 1.0}, 16, "million");
}

// The largest colour sums a test can afford: the fast sampler's 32-bit sums (a
// million white points, 255 million each) against the reference's 64-bit ones.
TEST_P(SamplerTarget, AMillionWhitePointsInOneVoxel) {
  constexpr std::size_t kN = 1000000;
  PointCloud cloud(kN);
  for (std::size_t i = 0; i < kN; ++i) {
    const float d = 0.0001f * static_cast<float>(i % 97);
    (void)cloud.push(d, d, d, packRgb(255, 255, i % 2 == 0 ? 255 : 254));
  }
  expectSameSampling(cloud, std::vector<uint8_t>(kN, 1), 2, {0, 1.0}, 16, "white");
}

TEST_P(SamplerTarget, ManyTinyVoxelsAndFarOffsets) {
  std::mt19937_64 rng(43);
  // Nearly every point its own voxel: 1 mm voxels in a 0.5 m cube, 10 km from the origin.
  for (const Eigen::Vector3d& origin : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(-1e4, 1e4, 1e4)}) {
    const PointCloud cloud = test::randomCloud(200000, origin, 0.25f, rng());
    expectSameSampling(cloud, std::vector<uint8_t>(cloud.size(), 1), 2, {0, 1.0 / 1024}, cloud.size(), "tiny");
    expectSameSampling(cloud, randomRegions(cloud.size(), 8, rng), 8,
                       {0, 1e-3, 2e-3, 3e-3, 5e-3, 1e-2, 1.0 / 1024, 0.25}, cloud.size(), "tiny, regions");
  }
}

TEST_P(SamplerTarget, PointsOnVoxelFaces) {
  PointCloud cloud(4000);
  cloud.origin_m = Eigen::Vector3d(0.25, -0.5, 1e4);
  for (int i = -10; i < 10; ++i) {
    for (int j = -10; j < 10; ++j) {
      const float x = 0.25f * i, y = 0.25f * j;
      for (float dx : {0.0f, 1e-7f, -1e-7f}) {
        (void)cloud.push(x + dx, y, std::nextafter(0.25f * j, 1.0f), static_cast<uint32_t>(i * 131 + j));
        (void)cloud.push(std::nextafter(x, -1.0f), y + dx, 0.0f, static_cast<uint32_t>(j * 7));
      }
    }
  }
  std::mt19937_64 rng(44);
  expectSameSampling(cloud, std::vector<uint8_t>(cloud.size(), 1), 2, {0, 0.25}, cloud.size(), "faces");
  expectSameSampling(cloud, randomRegions(cloud.size(), 3, rng, false), 3, {0, 0.25, 0.5}, cloud.size(), "faces 3");
}

TEST_P(SamplerTarget, ErrorsMatch) {
  std::mt19937_64 rng(45);
  PointCloud cloud = test::randomCloud(3000, Eigen::Vector3d::Zero(), 2.0f, 46);
  const std::vector<uint8_t> ones(cloud.size(), 1);
  expectSameSampling(cloud, ones, 2, {0, 0.01}, 10, "too many voxels");
  expectSameSampling(cloud, ones, 2, {0, 0.01}, 3000, "output too small", 5);
  expectSameSampling(cloud, ones, 2, {0, 1e-7}, 3000, "span");
  expectSameSampling(cloud, ones, 2, {0, -1.0}, 3000, "bad size");
  expectSameSampling(cloud, ones, 9, {0, 0.1}, 3000, "bad region count");
  cloud.x()[1234] = std::numeric_limits<float>::quiet_NaN();  // non-finite in a sampled region
  expectSameSampling(cloud, ones, 2, {0, 0.1}, 3000, "nan");
  cloud.x()[1234] = 3e38f;
  expectSameSampling(cloud, ones, 2, {0, 1e-3}, 3000, "huge");
}

TEST_P(SamplerTarget, RunsAndAlternatingKeys) {
  // The last-voxel cache: runs of every length, keys alternating point by point
  // between two voxels, cycles through more voxels than the recent-voxel cache holds
  // (1024 lines) and than the table's first prefix holds, fovea and skipped points
  // inside runs, region changes inside a SIMD vector.
  std::mt19937_64 rng(47);
  for (std::size_t cycle : {std::size_t{1}, std::size_t{2}, std::size_t{3}, std::size_t{1100}, std::size_t{9000}}) {
    PointCloud cloud(60000);
    std::vector<uint8_t> region;
    std::size_t run = 1;
    for (std::size_t i = 0; cloud.size() < 60000; ++i) {
      if (i % 997 == 0) run = 1 + rng() % 40;
      const std::size_t v = (i / run) % cycle;
      const float x = 0.1f * static_cast<float>(v % 97) + 0.01f * static_cast<float>(rng() % 8);
      const float y = 0.1f * static_cast<float>(v / 97) - 0.01f * static_cast<float>(rng() % 8);
      (void)cloud.push(x, y, 0.05f, static_cast<uint32_t>(rng()));
      const uint64_t pick = rng() % 64;
      region.push_back(pick == 0 ? 0 : (pick == 1 ? kRegionInvalid : (pick == 2 ? 2 : 1)));
    }
    expectSameSampling(cloud, region, 3, {0, 0.1, 0.3}, cloud.size(), "runs");
    expectSameSampling(cloud, std::vector<uint8_t>(cloud.size(), 1), 2, {0, 0.1}, cloud.size(), "runs, one region");
  }
}

TEST_P(SamplerTarget, AVoxelOnTheRecentCacheLineOfFoveaPoints) {
  // Fovea and skipped points look up kNoVoxelKey, whose recent-voxel cache line always
  // answers "no voxel"; a voxel whose key hashes to that line must still be found (in
  // the table, every time) and must never take the line over.
  constexpr int kShift = 64 - HashVoxelSampler::kRecentBits;
  const uint64_t empty_line = hashVoxelKey(kernels::kNoVoxelKey) >> kShift;
  // Region 1, 1 m voxels, the origin at 0: voxel (i, 0, 0) packs to 1 << 60 | i << 40.
  int64_t found = -1;
  for (int64_t i = 0; i < (int64_t{1} << 20) && found < 0; ++i) {
    const uint64_t key = (uint64_t{1} << 60) | (static_cast<uint64_t>(i) << 40);
    if (hashVoxelKey(key) >> kShift == empty_line) found = i;
  }
  ASSERT_GE(found, 0);
  std::mt19937_64 rng(48);
  PointCloud cloud(4000);
  std::vector<uint8_t> region;
  std::size_t on_line = 0;
  for (int i = 0; i < 4000; ++i) {
    const uint64_t pick = rng() % 6;
    // The voxel on the line, a neighbour, fovea points and skipped points, interleaved.
    const float x = static_cast<float>(found) + (pick == 1 ? 1.5f : 0.5f) + 0.01f * static_cast<float>(rng() % 40);
    (void)cloud.push(x, 0.5f, 0.5f, static_cast<uint32_t>(rng()));
    region.push_back(pick == 2 ? 0 : (pick == 3 ? kRegionInvalid : 1));
    if (pick != 1 && pick != 2 && pick != 3) ++on_line;
  }
  expectSameSampling(cloud, region, 2, {0, 1.0}, cloud.size(), "a voxel on the fovea's cache line");
  HashVoxelSampler fast(cloud.size(), cloud.size());
  FoveatedCloud out(cloud.size());
  SampleCounts counts;
  ASSERT_TRUE(fast.sample(cloud, region.data(), 2, {0, 1.0}, out, counts).isOk());
  EXPECT_EQ(counts.out[1], 2u);
  EXPECT_GE(fast.lastTableLookups(), on_line);  // each of its points went to the table
}

TEST_P(SamplerTarget, SortKeysAtAndPastTheWidthThatPacksWithTheSlot) {
  // The output order comes from a sort key of the region and each axis's index within
  // its span. Where the key and the voxel's slot fit one 64-bit word the slot is packed
  // below the key; where they do not, (key, slot) pairs are sorted. Regions spanning the
  // widest span on every axis (20 bits each) put the key at 61 bits (2 regions) or 63
  // (8 regions): with 2 regions, 4 to 7 voxels (3 bits of slot) fill exactly 64 bits and
  // 8 or more pass it; with 8 regions every case passes it.
  std::mt19937_64 rng(49);
  const float far = static_cast<float>(kMaxVoxelSpan - 1) + 0.5f;  // 1 m voxels: index 2^20 - 1
  for (int region_count : {2, 8}) {
    for (std::size_t points : {std::size_t{4}, std::size_t{7}, std::size_t{8}, std::size_t{9}, std::size_t{40}}) {
      PointCloud cloud(points);
      std::vector<uint8_t> region;
      (void)cloud.push(0.5f, 0.5f, 0.5f, 1);  // the span's two corners, in the last region
      (void)cloud.push(far, far, far, 2);
      region.insert(region.end(), 2, static_cast<uint8_t>(region_count - 1));
      while (cloud.size() < cloud.capacity()) {  // at most one voxel a point
        const auto at = [&] { return static_cast<float>(rng() % 4) * 0.25f * far + 0.5f; };
        (void)cloud.push(at(), at(), at(), static_cast<uint32_t>(rng()));
        region.push_back(static_cast<uint8_t>(1 + rng() % (region_count - 1)));
      }
      expectSameSampling(cloud, region, region_count, {0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}, cloud.size(),
                         "widest spans");
    }
  }
}

TEST_P(SamplerTarget, LargeIndicesAndSpecialsOutsideTheSampledRegions) {
  // Indices between 2^51 and 2^52 are valid but leave the SIMD key path; at 2^52 and
  // beyond they are refused. NaN and infinities in the fovea or skipped points are ignored.
  PointCloud cloud(5000);
  std::mt19937_64 rng(48);
  std::vector<uint8_t> region;
  for (int i = 0; i < 5000; ++i) {
    const float f = 0.001f * static_cast<float>(i % 300);
    (void)cloud.push(f, -f, 0.5f * f, static_cast<uint32_t>(i));
    region.push_back(static_cast<uint8_t>(1 + i % 2));
  }
  for (int i : {7, 8, 9, 100, 2047, 2048, 4999}) {
    cloud.x()[i] = std::numeric_limits<float>::quiet_NaN();
    cloud.y()[i] = std::numeric_limits<float>::infinity();
    region[i] = (i % 2) ? 0 : kRegionInvalid;
  }
  expectSameSampling(cloud, region, 3, {0, 0.01, 0.02}, cloud.size(), "specials outside");
  // 0.1 nm voxels 300 km from the origin: indices near 3e15, between 2^51 and 2^52, valid
  // (spans of about 1e5 voxels) but outside the SIMD key path; then beyond 2^52.
  for (const double far : {3e5, -3.5e5, 5e5}) {
    PointCloud cloud_far(3000);
    cloud_far.origin_m = Eigen::Vector3d(far, -far, 0.25);
    std::vector<uint8_t> region_far;
    for (int i = 0; i < 3000; ++i) {
      const float f = 1e-9f * static_cast<float>(rng() % 10000);
      (void)cloud_far.push(f, -f, 1e-9f * static_cast<float>(i % 7), static_cast<uint32_t>(rng()));
      region_far.push_back(static_cast<uint8_t>(i % 13 == 0 ? 1 : 2));
    }
    VoxelSampler ref(cloud_far.size(), cloud_far.size());
    FoveatedCloud out_ref(cloud_far.size());
    SampleCounts counts;
    const Status s = ref.sample(cloud_far, region_far.data(), 3, {0, 0.01, 1e-10}, out_ref, counts);
    EXPECT_EQ(s.isOk(), std::fabs(far) < 4e5) << s.toString();  // 5e15 > 2^52: refused
    expectSameSampling(cloud_far, region_far, 3, {0, 0.01, 1e-10}, cloud_far.size(), "indices near 2^52");
  }
  cloud.x()[3005] = -std::numeric_limits<float>::infinity();
  region[3005] = 1;
  expectSameSampling(cloud, region, 3, {0, 0.01, 0.02}, cloud.size(), "infinity sampled");
}

TEST_P(SamplerTarget, ErrorPrecedence) {
  // A voxel overflow early in the cloud, a bad point late: the bad point wins (as in
  // the reference, which checks every index before counting voxels); then spans.
  PointCloud cloud = test::randomCloud(20000, Eigen::Vector3d::Zero(), 2.0f, 49);
  std::vector<uint8_t> ones(cloud.size(), 1);
  cloud.z()[19999] = std::numeric_limits<float>::quiet_NaN();
  expectSameSampling(cloud, ones, 2, {0, 0.01}, 10, "overflow then nan");
  cloud.z()[19999] = 1e9f;  // a span beyond 2^20 voxels of 1 cm
  expectSameSampling(cloud, ones, 2, {0, 0.01}, 10, "overflow then span");
  cloud.z()[19999] = 0.0f + static_cast<float>(0.01 * 1048576.0 * 2);  // aliases a wrapped key
  cloud.z()[19998] = 0.0f;
  cloud.x()[19999] = cloud.x()[19998];
  cloud.y()[19999] = cloud.y()[19998];
  expectSameSampling(cloud, ones, 2, {0, 0.01}, cloud.size(), "aliasing span");
}

TEST_P(SamplerTarget, FixationMatchesTheReference) {
  // computeFixationSimd against computeFixation: every mode, cone angles, percentiles,
  // all-fovea clouds (FREF), fovea-less ones (fallbacks), specials, points behind the eye,
  // far origins, min_m clamping; d0 compared bit for bit.
  std::mt19937_64 rng(50);
  for (std::size_t n : {0, 1, 3, 17, 1000, 30001}) {
    for (const Eigen::Vector3d& origin : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1e4, -1e4, 3)}) {
      PointCloud cloud = test::randomCloud(n, origin, 3.0f, rng());
      for (std::size_t i = 0; i < n; i += 97) cloud.z()[i] = std::numeric_limits<float>::quiet_NaN();
      for (int fovea_share : {0, 1, 2, 100}) {
        std::vector<uint8_t> region(n);
        for (auto& r : region) r = (static_cast<int>(rng() % 100) < fovea_share) ? 0 : static_cast<uint8_t>(1 + rng() % 3);
        if (fovea_share == 100) std::fill(region.begin(), region.end(), uint8_t{0});
        for (const Eigen::Vector3d& dir : {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, -0.3, 0.2)}) {
          Gaze gaze;
          gaze.origin_m = origin + Eigen::Vector3d(0.1, -0.2, -2.0);
          gaze.direction = dir.normalized();
          for (FixationMode mode : {FixationMode::kHit, FixationMode::kCentroid, FixationMode::kFixed}) {
            for (double cone : {0.5, 1.0, 20.0, 89.0}) {
              FixationConfig config;
              config.mode = mode;
              config.hit_cone_deg = cone;
              config.hit_percentile = cone < 1.0 ? 0.0 : (cone > 30.0 ? 1.0 : 0.05);
              config.min_m = cone > 30.0 ? 1e3 : 0.05;
              // The SIMD scratch ends at the cloud's end, before a page it may not touch.
              std::vector<double> t_ref(n + 1);
              test::GuardedArray<double> t_simd(n);
              const Fixation a = computeFixation(cloud, region.data(), gaze, config, t_ref.data());
              const Fixation b = computeFixationSimd(cloud, region.data(), gaze, config, t_simd.data());
              EXPECT_EQ(std::bit_cast<uint64_t>(a.d0_m), std::bit_cast<uint64_t>(b.d0_m)) << n << " " << cone;
              EXPECT_EQ(a.source, b.source);
              EXPECT_EQ(a.support, b.support);
              EXPECT_EQ(a.clamped, b.clamped);
            }
          }
        }
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Targets, SamplerTarget, ::testing::ValuesIn(test::simdTargetsHere()), test::simdTargetName);

// ---- the whole Foveator, kernel set simd against ref ----------------------------

TEST(FoveatorKernelSets, SimdGivesTheReferenceOutput) {
  std::mt19937_64 rng(51);
  for (Preset preset : {Preset::kF1, Preset::kF2, Preset::kF3, Preset::kFRef}) {
    for (FixationMode mode : {FixationMode::kHit, FixationMode::kCentroid}) {
      FoveationConfig config;
      config.acuity.preset = preset;
      config.fixation.mode = mode;
      const PointCloud cloud = test::randomCloud(30000, Eigen::Vector3d(1e4 * (rng() % 2), 2, 3), 4.0f, rng());
      Foveator ref = Foveator::create({30000, 30000, KernelSet::kRef}, config).value();
      Foveator simd = Foveator::create({30000, 30000, KernelSet::kSimd}, config).value();
      Gaze gaze;
      gaze.origin_m = cloud.origin_m + Eigen::Vector3d(0.1, -0.2, -5.0);
      gaze.direction = Eigen::Vector3d(0.05, 0.02, 1.0);
      FoveatedCloud a(30000), b(30000);
      FoveationStats sa, sb;
      std::vector<uint32_t> ra(30000), rb(30000);
      ASSERT_TRUE(ref.foveate(cloud, gaze, a, sa, ra.data()).isOk());
      ASSERT_TRUE(simd.foveate(cloud, gaze, b, sb, rb.data()).isOk());
      EXPECT_TRUE(sameFoveated(a, b));
      EXPECT_EQ(ra, rb);
      EXPECT_EQ(sa.fixation.d0_m, sb.fixation.d0_m);
      EXPECT_EQ(sa.dropped_nonfinite, sb.dropped_nonfinite);
      for (int r = 0; r < kMaxRegions; ++r) {
        EXPECT_EQ(sa.regions[r].points_in, sb.regions[r].points_in);
        EXPECT_EQ(sa.regions[r].points_out, sb.regions[r].points_out);
      }
      EXPECT_EQ(0, std::memcmp(ref.lastRegions(), simd.lastRegions(), cloud.size()));
    }
  }
}

TEST(FoveatorKernelSets, MockCameraFramesEndToEnd) {
  Result<std::unique_ptr<hal::Camera>> camera = hal::createCamera("mock:balloon,path=orbit");
  ASSERT_TRUE(camera.isOk());
  hal::Camera& cam = *camera.value();
  ASSERT_TRUE(cam.open().isOk());
  ASSERT_TRUE(cam.start().isOk());
  const hal::CameraIntrinsics& k = cam.info().intrinsics;
  const std::size_t pixels = static_cast<std::size_t>(k.width) * k.height;
  hal::RgbdFrame frame(k.width, k.height);
  PointCloud ca(pixels), cb(pixels);
  FoveatedCloud a(pixels), b(pixels);
  FoveationConfig config;
  config.acuity.preset = Preset::kF3;
  Foveator ref = Foveator::create({pixels, pixels, KernelSet::kRef}, config).value();
  Foveator simd = Foveator::create({pixels, pixels, KernelSet::kSimd}, config).value();
  // Two frames where rendering and foveating one costs 10 to 40 times as much.
  const int frames = test::repetitions(5, 2);
  for (int i = 0; i < frames; ++i) {
    ASSERT_TRUE(cam.acquire(frame, test::scaled(std::chrono::seconds(2))).isOk());
    BackprojectCounts ba, bb;
    ASSERT_TRUE(backproject(frame, DepthRange{}, ca, ba, KernelSet::kRef).isOk());
    ASSERT_TRUE(backproject(frame, DepthRange{}, cb, bb, KernelSet::kSimd).isOk());
    Gaze gaze;
    gaze.origin_m = frame.T_world_cam.t_world_cam;
    gaze.direction = frame.T_world_cam.R_world_cam.col(2);
    FoveationStats sa, sb;
    ASSERT_TRUE(ref.foveate(ca, gaze, a, sa).isOk());
    ASSERT_TRUE(simd.foveate(cb, gaze, b, sb).isOk());
    EXPECT_TRUE(sameFoveated(a, b)) << "frame " << i;
  }
  cam.stop();
}

// The sampler's division-free mean colour against the integer division, for every
// colour sum of up to 300 points and sampled sums (the extremes included) up to 2^24
// points; the reciprocal is the one the sampler computes.
TEST(RoundedMeanColour, EqualsTheIntegerDivision) {
  std::mt19937_64 rng(3);
  for (uint64_t count = 1; count <= (uint64_t{1} << 24); count = count < 300 ? count + 1 : count * 3 / 2) {
    const double inv = 1.0 / static_cast<double>(count);
    const auto check = [&](uint64_t sum) {
      ASSERT_EQ(roundedMeanColour(sum, count, inv), static_cast<uint8_t>((sum + count / 2) / count))
          << sum << " / " << count;
    };
    if (count <= 300) {
      for (uint64_t sum = 0; sum <= 255 * count; ++sum) check(sum);
    } else {
      for (uint64_t sum : {uint64_t{0}, count / 2 - 1, count / 2, 255 * count, 255 * count - count / 2 - 1,
                           255 * count - count / 2}) {
        check(sum);
      }
      for (int i = 0; i < 20000; ++i) check(rng() % (255 * count + 1));
      for (uint64_t k = 0; k <= 255; ++k) {  // at each rounding boundary and either side of it
        for (uint64_t at : {k * count + (count + 1) / 2, k * count + count / 2}) {
          for (uint64_t sum : {at - 1, at, at + 1}) {
            if (sum <= 255 * count) check(sum);
          }
        }
      }
    }
  }
}

}  // namespace
}  // namespace fovea::pipeline
