// Foveated voxel sampling (Eq. 7) against a brute-force std::map reference,
// and its properties: lattice anchoring, order, conservation, containment.
#include <algorithm>
#include <bit>
#include <map>
#include <random>

#include <gtest/gtest.h>

#include "pipeline/partition.h"
#include "pipeline/voxel_sampler.h"
#include "tests/support/clouds.h"

namespace fovea::pipeline {
namespace {

using test::BruteKey;
using test::BruteVoxel;

struct Sampled {
  Status status;
  FoveatedCloud out;
  SampleCounts counts;
};

Sampled sample(const PointCloud& in, const std::vector<uint8_t>& region, int region_count,
               const std::array<double, kMaxRegions>& voxel_m, std::size_t max_voxels = 0) {
  VoxelSampler sampler(in.size(), max_voxels ? max_voxels : std::max<std::size_t>(in.size(), 1));
  Sampled s{Status::ok(), FoveatedCloud(in.size()), {}};
  s.status = sampler.sample(in, region.data(), region_count, voxel_m, s.out, s.counts);
  return s;
}

std::vector<uint8_t> randomRegions(std::size_t n, int region_count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> pick(0, region_count - 1);
  std::vector<uint8_t> region(n);
  for (auto& r : region) r = static_cast<uint8_t>(pick(rng));
  return region;
}

std::map<BruteKey, BruteVoxel> bruteVoxels(const PointCloud& in, const std::vector<uint8_t>& region,
                                           const std::array<double, kMaxRegions>& voxel_m) {
  std::map<BruteKey, BruteVoxel> voxels;
  for (std::size_t i = 0; i < in.size(); ++i) {
    if (region[i] == 0 || region[i] == kRegionInvalid) continue;
    const long double wx = static_cast<long double>(in.origin_m.x()) + in.x()[i];
    const long double wy = static_cast<long double>(in.origin_m.y()) + in.y()[i];
    const long double wz = static_cast<long double>(in.origin_m.z()) + in.z()[i];
    BruteVoxel& v = voxels[test::bruteKey(region[i], wx, wy, wz, voxel_m[region[i]])];
    ++v.count;
    v.sx += wx;
    v.sy += wy;
    v.sz += wz;
    v.sr += rgbRed(in.rgb()[i]);
    v.sg += rgbGreen(in.rgb()[i]);
    v.sb += rgbBlue(in.rgb()[i]);
  }
  return voxels;
}

// Checks `s` against the brute-force reference: the same voxel set, each output
// point inside its voxel, centroids within tol_m, exact counts and mean colours.
void expectMatchesBruteForce(const PointCloud& in, const std::vector<uint8_t>& region,
                             const std::array<double, kMaxRegions>& voxel_m, const Sampled& s, double tol_m) {
  ASSERT_TRUE(s.status.isOk()) << s.status.toString();
  const auto expected = bruteVoxels(in, region, voxel_m);
  std::size_t fovea = std::count(region.begin(), region.end(), 0);
  ASSERT_EQ(s.out.size(), fovea + expected.size());
  std::map<BruteKey, bool> seen;
  for (std::size_t o = fovea; o < s.out.size(); ++o) {
    const int r = s.out.region[o];
    ASSERT_GE(r, 1);
    const Eigen::Vector3d w = s.out.points.world(o);
    const BruteKey key = test::bruteKey(r, w.x(), w.y(), w.z(), voxel_m[r]);
    auto it = expected.find(key);
    ASSERT_NE(it, expected.end()) << "output point " << o << " is not inside any occupied voxel of region " << r;
    ASSERT_FALSE(seen[key]) << "voxel emitted twice";
    seen[key] = true;
    const BruteVoxel& v = it->second;
    EXPECT_EQ(s.out.weight[o], v.count);
    EXPECT_NEAR(w.x(), static_cast<double>(v.sx / v.count), tol_m);
    EXPECT_NEAR(w.y(), static_cast<double>(v.sy / v.count), tol_m);
    EXPECT_NEAR(w.z(), static_cast<double>(v.sz / v.count), tol_m);
    const uint32_t c = s.out.points.rgb()[o];
    EXPECT_EQ(rgbRed(c), (v.sr + v.count / 2) / v.count);
    EXPECT_EQ(rgbGreen(c), (v.sg + v.count / 2) / v.count);
    EXPECT_EQ(rgbBlue(c), (v.sb + v.count / 2) / v.count);
  }
  EXPECT_EQ(seen.size(), expected.size());
}

struct RandomCase {
  double origin_offset_m;
  float half_extent_m;
  double base_voxel_m;
  uint64_t seed;
};

void PrintTo(const RandomCase& c, std::ostream* os) { *os << "offset" << c.origin_offset_m << "_seed" << c.seed; }

class SamplerMatchesBruteForce : public ::testing::TestWithParam<RandomCase> {};

TEST_P(SamplerMatchesBruteForce, SameVoxelsAndCentroids) {
  const RandomCase& c = GetParam();
  const Eigen::Vector3d origin(c.origin_offset_m, 0.3 * c.origin_offset_m, -0.7 * c.origin_offset_m);
  PointCloud in = test::randomCloud(30000, origin, c.half_extent_m, c.seed);
  const std::vector<uint8_t> region = randomRegions(in.size(), 6, c.seed + 1);
  std::array<double, kMaxRegions> voxel_m{};
  for (int r = 1; r < 6; ++r) voxel_m[r] = c.base_voxel_m * (1.0 + 1.7 * r);
  const Sampled s = sample(in, region, 6, voxel_m);
  expectMatchesBruteForce(in, region, voxel_m, s, 1e-5);
}

INSTANTIATE_TEST_SUITE_P(RandomClouds, SamplerMatchesBruteForce,
                         ::testing::Values(RandomCase{0.0, 2.0f, 0.01, 1}, RandomCase{0.0, 5.0f, 0.1, 2},
                                           RandomCase{1e4, 3.0f, 0.02, 3}, RandomCase{-3e4, 1.0f, 0.005, 4},
                                           RandomCase{0.0, 0.05f, 0.001, 5}));

TEST(VoxelSampler, FoveaPassesUntouchedInInputOrder) {
  PointCloud in = test::randomCloud(2000, Eigen::Vector3d(1, 2, 3), 1.0f, 9);
  const std::vector<uint8_t> region = randomRegions(in.size(), 3, 10);
  const Sampled s = sample(in, region, 3, {0, 0.05, 0.2});
  ASSERT_TRUE(s.status.isOk());
  std::size_t o = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    if (region[i] != 0) continue;
    ASSERT_EQ(s.out.region[o], 0);
    EXPECT_EQ(s.out.points.x()[o], in.x()[i]);
    EXPECT_EQ(s.out.points.y()[o], in.y()[i]);
    EXPECT_EQ(s.out.points.z()[o], in.z()[i]);
    EXPECT_EQ(s.out.points.rgb()[o], in.rgb()[i]);
    EXPECT_EQ(s.out.weight[o], 1u);
    ++o;
  }
  EXPECT_EQ(o, s.counts.out[0]);
  EXPECT_EQ(s.counts.in[0], s.counts.out[0]);
}

TEST(VoxelSampler, VoxelCountsSumToRegionPopulations) {
  PointCloud in = test::randomCloud(20000, Eigen::Vector3d::Zero(), 2.0f, 11);
  const std::vector<uint8_t> region = randomRegions(in.size(), 4, 12);
  const Sampled s = sample(in, region, 4, {0, 0.03, 0.1, 0.4});
  ASSERT_TRUE(s.status.isOk());
  std::array<uint64_t, kMaxRegions> sum{};
  for (std::size_t o = 0; o < s.out.size(); ++o) sum[s.out.region[o]] += s.out.weight[o];
  for (int r = 0; r < 4; ++r) {
    EXPECT_EQ(sum[r], static_cast<uint64_t>(std::count(region.begin(), region.end(), r))) << "region " << r;
    EXPECT_EQ(s.counts.in[r], sum[r]);
  }
}

TEST(VoxelSampler, OutputIsSortedByRegionThenVoxelAndIndependentOfInputOrder) {
  PointCloud in = test::randomCloud(10000, Eigen::Vector3d(-50, 10, 5), 3.0f, 13);
  std::vector<uint8_t> region = randomRegions(in.size(), 4, 14);
  for (auto& r : region) r = static_cast<uint8_t>(std::max<int>(r, 1));  // no fovea: order is all voxels
  const std::array<double, kMaxRegions> voxel_m{0, 0.05, 0.11, 0.37};
  const Sampled a = sample(in, region, 4, voxel_m);
  ASSERT_TRUE(a.status.isOk());
  for (std::size_t o = 1; o < a.out.size(); ++o) {
    const Eigen::Vector3d p = a.out.points.world(o - 1), q = a.out.points.world(o);
    const BruteKey kp = test::bruteKey(a.out.region[o - 1], p.x(), p.y(), p.z(), voxel_m[a.out.region[o - 1]]);
    const BruteKey kq = test::bruteKey(a.out.region[o], q.x(), q.y(), q.z(), voxel_m[a.out.region[o]]);
    ASSERT_LT(kp, kq) << "at output " << o;
  }
  // Reverse the input: the voxel set, centroids up to summation order, and order stay.
  PointCloud reversed(in.size());
  reversed.origin_m = in.origin_m;
  std::vector<uint8_t> reversed_region(in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    const std::size_t j = in.size() - 1 - i;
    (void)reversed.push(in.x()[j], in.y()[j], in.z()[j], in.rgb()[j]);
    reversed_region[i] = region[j];
  }
  const Sampled b = sample(reversed, reversed_region, 4, voxel_m);
  ASSERT_EQ(a.out.size(), b.out.size());
  for (std::size_t o = 0; o < a.out.size(); ++o) {
    EXPECT_EQ(a.out.region[o], b.out.region[o]);
    EXPECT_EQ(a.out.weight[o], b.out.weight[o]);
    EXPECT_NEAR(a.out.points.x()[o], b.out.points.x()[o], 1e-6);
    EXPECT_EQ(a.out.points.rgb()[o], b.out.points.rgb()[o]);
  }
}

TEST(VoxelSampler, LatticeIsAnchoredAtTheWorldOriginNotTheCloud) {
  // The same world points, held relative to two different origins and with an
  // extra far-away point that moves the bounding box: identical voxels.
  PointCloud a = test::randomCloud(5000, Eigen::Vector3d(100.0, 0.0, 0.0), 1.0f, 15);
  // On a 1/1024 m grid, so that the shifted copies below are exact in float.
  for (std::size_t i = 0; i < a.size(); ++i) {
    a.x()[i] = std::round(a.x()[i] * 1024.0f) / 1024.0f;
    a.y()[i] = std::round(a.y()[i] * 1024.0f) / 1024.0f;
    a.z()[i] = std::round(a.z()[i] * 1024.0f) / 1024.0f;
  }
  PointCloud b(a.size() + 1);
  b.origin_m = Eigen::Vector3d(97.0, 1.0, -2.0);
  for (std::size_t i = 0; i < a.size(); ++i) {
    (void)b.push(a.x()[i] + 3.0f, a.y()[i] - 1.0f, a.z()[i] + 2.0f, a.rgb()[i]);
  }
  (void)b.push(-40.0f, 30.0f, 20.0f, 0);
  std::vector<uint8_t> ra(a.size(), 1), rb(b.size(), 1);
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a.world(i), b.world(i));
  const std::array<double, kMaxRegions> voxel_m{0, 0.125};
  const Sampled sa = sample(a, ra, 2, voxel_m);
  const Sampled sb = sample(b, rb, 2, voxel_m);
  ASSERT_TRUE(sa.status.isOk());
  ASSERT_TRUE(sb.status.isOk());
  ASSERT_EQ(sb.out.size(), sa.out.size() + 1);
  for (std::size_t o = 0; o < sa.out.size(); ++o) {
    const Eigen::Vector3d wa = sa.out.points.world(o);
    // b's extra point sorts first (smallest x index): shift by one.
    const Eigen::Vector3d wb = sb.out.points.world(o + 1);
    EXPECT_NEAR((wa - wb).norm(), 0.0, 1e-5);
    EXPECT_EQ(sa.out.weight[o], sb.out.weight[o + 1]);
  }
}

TEST(VoxelSampler, RadixSortMatchesStableSort) {
  std::mt19937_64 rng(17);
  for (std::size_t n : {0, 1, 2, 100, 5000}) {
    std::vector<uint64_t> keys(n), scratch_keys(n);
    std::vector<uint32_t> index(n), scratch_index(n);
    for (std::size_t i = 0; i < n; ++i) {
      keys[i] = (i % 3 == 0) ? rng() : (rng() & 0x00F000000000FF0Full);  // some bytes constant, many ties
      index[i] = static_cast<uint32_t>(i);
    }
    std::vector<std::pair<uint64_t, uint32_t>> expected(n);
    for (std::size_t i = 0; i < n; ++i) expected[i] = {keys[i], index[i]};
    std::stable_sort(expected.begin(), expected.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    radixSortPairs(keys.data(), index.data(), scratch_keys.data(), scratch_index.data(), n);
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(keys[i], expected[i].first);
      ASSERT_EQ(index[i], expected[i].second);
    }
  }
}

TEST(VoxelSampler, RadixSortBitsMatchesStableSortOnTheField) {
  std::mt19937_64 rng(23);
  struct Field {
    int lo_bit, bits;
  };
  for (const Field f : {Field{0, 64}, Field{0, 0}, Field{17, 40}, Field{20, 44}, Field{1, 11}, Field{3, 12},
                        Field{9, 23}, Field{0, 33}, Field{63, 1}}) {
    for (std::size_t n : {0, 1, 2, 100, 5000, 70000}) {
      std::vector<uint64_t> values(n), scratch(n);
      for (std::size_t i = 0; i < n; ++i) {
        // Every third value random; the rest with many ties and digits that never vary.
        values[i] = (i % 3 == 0) ? rng() : (rng() & 0xF00F0000FF0F00F3ull);
      }
      const auto field = [&](uint64_t v) {
        return f.bits == 0 ? uint64_t{0} : (v >> f.lo_bit) & (~uint64_t{0} >> (64 - f.bits));
      };
      std::vector<uint64_t> expected = values;
      std::stable_sort(expected.begin(), expected.end(),
                       [&](uint64_t a, uint64_t b) { return field(a) < field(b); });
      radixSortBits(values.data(), scratch.data(), n, f.lo_bit, f.bits);
      ASSERT_EQ(values, expected) << "lo_bit " << f.lo_bit << " bits " << f.bits << " n " << n;
    }
  }
}

TEST(VoxelSampler, TooManyVoxelsForTheCapacityIsAnError) {
  PointCloud in = test::randomCloud(1000, Eigen::Vector3d::Zero(), 10.0f, 19);
  const std::vector<uint8_t> region(in.size(), 1);
  const Sampled s = sample(in, region, 2, {0, 0.001}, /*max_voxels=*/100);
  EXPECT_EQ(s.status.code(), ErrorCode::kCapacityExceeded);
  EXPECT_NE(s.status.message().find("max_voxels"), std::string::npos);
}

// sampleAt() writes sample()'s points after the ones out holds, which stay
// (and a request that does not fit writes nothing).
TEST(VoxelSampler, SampleAtAppendsWhatSampleWritesAndKeepsWhatWasThere) {
  PointCloud in = test::randomCloud(3000, Eigen::Vector3d(-4, 2, 7), 1.0f, 25);
  const std::vector<uint8_t> region = randomRegions(in.size(), 3, 26);
  const std::array<double, kMaxRegions> voxel_m{0, 0.05, 0.2};
  const Sampled alone = sample(in, region, 3, voxel_m);
  ASSERT_TRUE(alone.status.isOk());
  constexpr std::size_t kHeld = 37;
  FoveatedCloud out(kHeld + alone.out.size());
  for (std::size_t i = 0; i < kHeld; ++i) {
    ASSERT_TRUE(out.points.push(float(i), -float(i), 0.5f, 0x123456u));
  }
  std::fill_n(out.region.begin(), kHeld, uint8_t{4});
  std::fill_n(out.weight.begin(), kHeld, 9u);
  VoxelSampler sampler(in.size(), in.size());
  SampleCounts counts;
  ASSERT_TRUE(sampler.sampleAt(in, region.data(), 3, voxel_m, out, kHeld, counts).isOk());
  ASSERT_EQ(out.size(), kHeld + alone.out.size());
  for (std::size_t i = 0; i < kHeld; ++i) {
    ASSERT_EQ(out.points.x()[i], float(i));
    ASSERT_EQ(out.points.rgb()[i], 0x123456u);
    ASSERT_EQ(out.region[i], 4);
    ASSERT_EQ(out.weight[i], 9u);
  }
  for (std::size_t o = 0; o < alone.out.size(); ++o) {
    const std::size_t a = kHeld + o;
    ASSERT_EQ(std::bit_cast<uint32_t>(out.points.x()[a]), std::bit_cast<uint32_t>(alone.out.points.x()[o])) << o;
    ASSERT_EQ(std::bit_cast<uint32_t>(out.points.y()[a]), std::bit_cast<uint32_t>(alone.out.points.y()[o])) << o;
    ASSERT_EQ(std::bit_cast<uint32_t>(out.points.z()[a]), std::bit_cast<uint32_t>(alone.out.points.z()[o])) << o;
    ASSERT_EQ(out.points.rgb()[a], alone.out.points.rgb()[o]) << o;
    ASSERT_EQ(out.region[a], alone.out.region[o]) << o;
    ASSERT_EQ(out.weight[a], alone.out.weight[o]) << o;
  }
  EXPECT_EQ(counts.out, alone.counts.out);
  // One point short: an error, and the cloud as it was.
  FoveatedCloud tight(kHeld + alone.out.size() - 1);
  for (std::size_t i = 0; i < kHeld; ++i) ASSERT_TRUE(tight.points.push(1.0f, 2.0f, 3.0f, 0u));
  EXPECT_EQ(sampler.sampleAt(in, region.data(), 3, voxel_m, tight, kHeld, counts).code(), ErrorCode::kCapacityExceeded);
  EXPECT_EQ(tight.size(), kHeld);
}

TEST(VoxelSampler, RejectsNonPositiveVoxelSizes) {
  PointCloud in = test::randomCloud(10, Eigen::Vector3d::Zero(), 1.0f, 21);
  const std::vector<uint8_t> region(in.size(), 1);
  EXPECT_EQ(sample(in, region, 2, {0, 0.0}).status.code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(sample(in, region, 2, {0, NAN}).status.code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(sample(in, region, 2, {0, 1e-320}).status.code(), ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace fovea::pipeline

namespace fovea::pipeline {
namespace {

TEST(VoxelSampler, RepresentativeMapsEveryInputPointToItsOutputPoint) {
  PointCloud in = test::randomCloud(5000, Eigen::Vector3d(3, -2, 1), 1.5f, 33);
  std::vector<uint8_t> region = randomRegions(in.size(), 4, 34);
  region[7] = kRegionInvalid;
  const std::array<double, kMaxRegions> voxel_m{0, 0.05, 0.2, 0.5};
  VoxelSampler sampler(in.size(), in.size());
  FoveatedCloud out(in.size());
  SampleCounts counts;
  std::vector<uint32_t> representative(in.size(), 12345);
  ASSERT_TRUE(sampler.sample(in, region.data(), 4, voxel_m, out, counts, representative.data()).isOk());
  std::vector<uint32_t> members(out.size(), 0);
  for (std::size_t i = 0; i < in.size(); ++i) {
    if (region[i] == kRegionInvalid) {
      EXPECT_EQ(representative[i], kNoRepresentative);
      continue;
    }
    const uint32_t o = representative[i];
    ASSERT_LT(o, out.size());
    ASSERT_EQ(out.region[o], region[i]);
    ++members[o];
    if (region[i] == 0) {
      EXPECT_EQ(out.points.x()[o], in.x()[i]);
    } else {
      // Same voxel as its representative.
      const Eigen::Vector3d p = in.world(i), q = out.points.world(o);
      EXPECT_EQ(test::bruteKey(region[i], p.x(), p.y(), p.z(), voxel_m[region[i]]),
                test::bruteKey(region[i], q.x(), q.y(), q.z(), voxel_m[region[i]]));
    }
  }
  for (std::size_t o = 0; o < out.size(); ++o) EXPECT_EQ(members[o], out.weight[o]) << o;
}

}  // namespace
}  // namespace fovea::pipeline
