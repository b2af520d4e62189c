// ACUITY on the image pyramid against a brute-force reference written here: every
// output point is checked from the pixels it stands for, in double, with libm's
// atan2 and sin (pipeline/pyramid_sampler.h gives the rule).
#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "pipeline/pyramid_sampler.h"

namespace fovea::pipeline {
namespace {

constexpr double kPi = 3.14159265358979323846;

hal::RgbdFrame makeFrame(int w, int h, double fx = 500.0) {
  hal::RgbdFrame frame(w, h);
  frame.intrinsics = {w, h, fx, fx * 1.01, 0.5 * (w - 1), 0.5 * (h - 1)};
  frame.depth_scale_m = 0.001;
  return frame;
}

// A random scene: a slanted plane with a box in front (a depth step), holes,
// out-of-range pixels, sensor-like noise, random colours, a random pose.
hal::RgbdFrame randomFrame(std::mt19937& rng, int w, int h) {
  hal::RgbdFrame frame = makeFrame(w, h, std::uniform_real_distribution<double>(100.0, 600.0)(rng));
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 1.0);
  const double base = 800.0 + 3000.0 * unit(rng), slope_u = 20.0 * (unit(rng) - 0.5), slope_v = 20.0 * (unit(rng) - 0.5);
  const int bx0 = static_cast<int>(w * unit(rng)), by0 = static_cast<int>(h * unit(rng));
  const int bx1 = bx0 + static_cast<int>(w * 0.4 * unit(rng)), by1 = by0 + static_cast<int>(h * 0.4 * unit(rng));
  const double sigma = 4.0 * unit(rng);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      double z = base + slope_u * u + slope_v * v;
      if (u >= bx0 && u < bx1 && v >= by0 && v < by1) z *= 0.5;
      z += sigma * noise(rng);
      const double roll = unit(rng);
      uint16_t raw = static_cast<uint16_t>(std::clamp(z, 1.0, 60000.0));
      if (roll < 0.05) raw = 0;
      else if (roll < 0.06) raw = 65535;  // beyond the range
      const std::size_t p = static_cast<std::size_t>(v) * w + u;
      frame.depth()[p] = raw;
      for (int c = 0; c < 3; ++c) frame.rgb()[3 * p + c] = static_cast<uint8_t>(rng() & 0xFF);
    }
  }
  const Eigen::Quaterniond q(Eigen::Vector4d(noise(rng), noise(rng), noise(rng), noise(rng)).normalized());
  frame.T_world_cam.R_world_cam = q.toRotationMatrix();
  frame.T_world_cam.t_world_cam = Eigen::Vector3d(100.0 * noise(rng), 100.0 * noise(rng), noise(rng));
  return frame;
}

bool validPixel(const hal::RgbdFrame& f, std::size_t p, const DepthRange& range) {
  const RawDepthRange raw = rawDepthRange(range, f.depth_scale_m);
  return f.depth()[p] >= raw.min && f.depth()[p] <= raw.max;
}

Eigen::Vector3d cameraPoint(const hal::RgbdFrame& f, int u, int v) {
  const double z = f.depth()[static_cast<std::size_t>(v) * f.width() + u] * f.depth_scale_m;
  return {(u - f.intrinsics.cx) / f.intrinsics.fx * z, (v - f.intrinsics.cy) / f.intrinsics.fy * z, z};
}

// The rule of pyramid_sampler.h for the valid pixels of the 2^k square at (i, j), in
// double: whether it merges, and how far each of its tests is from its threshold
// (relative), so that the checks can leave out cells the float arithmetic may
// decide either way.
struct RuleVerdict {
  bool empty = true;
  bool merges = false;
  double closeness = 1.0;  // min |ratio - 1| over the tests that decide
};

RuleVerdict rule(const hal::RgbdFrame& f, const DepthRange& range, const Gaze& gaze, const PyramidRule& r, int k,
                 int i, int j) {
  RuleVerdict verdict;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double szz = 0.0, zmax = 0.0;
  int n = 0;
  for (int v = j << k; v < std::min((j + 1) << k, f.height()); ++v) {
    for (int u = i << k; u < std::min((i + 1) << k, f.width()); ++u) {
      if (!validPixel(f, static_cast<std::size_t>(v) * f.width() + u, range)) continue;
      const Eigen::Vector3d p = cameraPoint(f, u, v);
      sum += p;
      szz += p.z() * p.z();
      zmax = std::max(zmax, p.z());
      ++n;
    }
  }
  if (n == 0) return verdict;
  verdict.empty = false;
  const Eigen::Vector3d m = sum / n;
  const double sigma = std::sqrt(std::max(0.0, szz / n - m.z() * m.z()));
  const double inv_f = std::max(1.0 / f.intrinsics.fx, 1.0 / f.intrinsics.fy);
  const double e = std::max((1 << k) * zmax * inv_f, 2.0 * sigma);
  const double diagonal = std::sqrt(3.0) * e;
  bool merges = false;
  double closeness = 1e9;
  if (r.floor_m > 0.0f || r.floor_per_m2 > 0.0f) {
    const double floor = r.floor_m + r.floor_per_m2 * m.squaredNorm();
    merges = e <= floor;
    closeness = std::min(closeness, std::abs(e / floor - 1.0));
  }
  const Eigen::Vector3d a =
      f.T_world_cam.R_world_cam * m + (f.T_world_cam.t_world_cam - gaze.origin_m);
  const double dist = a.norm();
  closeness = std::min(closeness, std::abs(dist / (2.0 * diagonal) - 1.0));
  if (!merges && dist > 2.0 * diagonal) {
    const Eigen::Vector3d l = gaze.direction.normalized();
    const double t = a.dot(l);
    const double d = (a - t * l).norm();
    const double r_min = dist - diagonal;
    const double ecc = std::max(0.0, std::atan2(d, t) * 180.0 / kPi - diagonal / r_min * 180.0 / kPi -
                                         gaze.fovea_growth_deg);
    const double mar_rad = std::min((r.slope * ecc + 1.0 / 60.0) * kPi / 180.0, kPi / 2.0);
    const double allowed = r_min * std::sin(mar_rad);
    merges = r.margin * e <= allowed;
    closeness = std::min(closeness, std::abs(r.margin * e / allowed - 1.0));
  }
  verdict.merges = merges;
  verdict.closeness = closeness;
  return verdict;
}

struct Sampled {
  FoveatedCloud out;
  PyramidStats stats;
  std::vector<uint32_t> representative;
};

Sampled sample(PyramidSampler& sampler, const hal::RgbdFrame& f, const Gaze& gaze, const PyramidRule& r) {
  Sampled s{FoveatedCloud(f.pixelCount()), {}, std::vector<uint32_t>(f.pixelCount())};
  const Status st = sampler.sample(f, DepthRange{}, gaze, r, s.out, s.stats, s.representative.data());
  EXPECT_TRUE(st.isOk()) << st.toString();
  return s;
}

// Every property the header promises, checked point by point from the pixels.
void checkAgainstBruteForce(const hal::RgbdFrame& f, const Gaze& gaze, const PyramidRule& r, int levels,
                            const Sampled& s, int* checked_rules = nullptr) {
  const DepthRange range;
  const std::size_t out_n = s.out.size();
  std::vector<std::vector<std::size_t>> members(out_n);
  uint32_t valid = 0;
  for (std::size_t p = 0; p < f.pixelCount(); ++p) {
    const bool ok = validPixel(f, p, range);
    valid += ok;
    if (!ok) {
      ASSERT_EQ(s.representative[p], PyramidSampler::kNoRepresentative) << "invalid pixel " << p;
      continue;
    }
    ASSERT_LT(s.representative[p], out_n) << "valid pixel " << p << " has no output point";
    members[s.representative[p]].push_back(p);
  }
  EXPECT_EQ(s.stats.points_in, valid);
  EXPECT_EQ(s.stats.points_out, out_n);
  uint32_t by_level_total = 0;
  for (uint32_t c : s.stats.out_by_level) by_level_total += c;
  EXPECT_EQ(by_level_total, out_n);
  const Eigen::Matrix3d& R = f.T_world_cam.R_world_cam;
  int rules = 0;
  for (std::size_t o = 0; o < out_n; ++o) {
    const int k = s.out.region[o];
    ASSERT_LE(k, levels);
    ASSERT_FALSE(members[o].empty()) << "output point " << o << " stands for no pixel";
    ASSERT_EQ(s.out.weight[o], members[o].size());
    // One aligned 2^k square, and all its valid pixels.
    const int u0 = static_cast<int>(members[o][0] % f.width()) >> k;
    const int v0 = static_cast<int>(members[o][0] / f.width()) >> k;
    std::size_t in_square = 0;
    for (int v = v0 << k; v < std::min((v0 + 1) << k, f.height()); ++v) {
      for (int u = u0 << k; u < std::min((u0 + 1) << k, f.width()); ++u) {
        in_square += validPixel(f, static_cast<std::size_t>(v) * f.width() + u, range);
      }
    }
    ASSERT_EQ(in_square, members[o].size()) << "output point " << o << " level " << k;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    uint32_t cr = 0, cg = 0, cb = 0;
    for (std::size_t p : members[o]) {
      const int u = static_cast<int>(p % f.width()), v = static_cast<int>(p / f.width());
      ASSERT_EQ(u >> k, u0);
      ASSERT_EQ(v >> k, v0);
      mean += cameraPoint(f, u, v);
      cr += f.rgb()[3 * p], cg += f.rgb()[3 * p + 1], cb += f.rgb()[3 * p + 2];
    }
    const auto n = static_cast<uint32_t>(members[o].size());
    mean /= n;
    // Position: the centroid, rotated into the world, relative to the camera.
    const Eigen::Vector3d expected = R * mean;
    const Eigen::Vector3d got(s.out.points.x()[o], s.out.points.y()[o], s.out.points.z()[o]);
    ASSERT_LT((got - expected).norm(), 2e-6 * std::max(1.0, expected.norm())) << "output point " << o;
    // Colour: the rounded mean, exact.
    const auto round = [n](uint32_t sum) { return static_cast<uint8_t>((sum + n / 2) / n); };
    ASSERT_EQ(s.out.points.rgb()[o], packRgb(round(cr), round(cg), round(cb))) << "output point " << o;
    // The rule: a merged cell passes it, and a cell's parent failed it (else the
    // parent would have been emitted), unless the float arithmetic is too close to call.
    if (k >= 1) {
      const RuleVerdict here = rule(f, range, gaze, r, k, u0, v0);
      if (here.closeness > 5e-3) {
        EXPECT_TRUE(here.merges) << "level " << k << " cell (" << u0 << ", " << v0 << ") merged against the rule";
        ++rules;
      }
    }
    if (k < levels) {
      const RuleVerdict parent = rule(f, range, gaze, r, k + 1, u0 >> 1, v0 >> 1);
      ASSERT_FALSE(parent.empty);
      if (parent.closeness > 5e-3) {
        EXPECT_FALSE(parent.merges) << "level " << k + 1 << " cell (" << (u0 >> 1) << ", " << (v0 >> 1)
                                    << ") should have merged";
        ++rules;
      }
    }
  }
  if (checked_rules != nullptr) *checked_rules = rules;
}

Gaze gazeAtPixel(const hal::RgbdFrame& f, double u, double v, double back_m = 0.1) {
  const Eigen::Matrix3d& R = f.T_world_cam.R_world_cam;
  const Eigen::Vector3d ray_cam((u - f.intrinsics.cx) / f.intrinsics.fx, (v - f.intrinsics.cy) / f.intrinsics.fy, 1.0);
  Gaze gaze;
  gaze.direction = (R * ray_cam).normalized();
  gaze.origin_m = f.T_world_cam.t_world_cam - back_m * gaze.direction;
  return gaze;
}

TEST(PyramidSampler, RandomFramesAgreeWithTheBruteForce) {
  std::mt19937 rng(27);
  int rules = 0;
  const int sizes[][2] = {{1, 1}, {2, 3}, {7, 5}, {33, 17}, {64, 48}, {97, 71}, {160, 120}};
  for (int round = 0; round < 3; ++round) {
    for (const auto& size : sizes) {
      for (int levels = 1; levels <= kMaxPyramidLevels; levels += 2) {
        SCOPED_TRACE(testing::Message() << size[0] << "x" << size[1] << " levels " << levels << " round " << round);
        const hal::RgbdFrame f = randomFrame(rng, size[0], size[1]);
        PyramidSampler sampler = PyramidSampler::create(size[0] + round, size[1] + 1, levels).value();
        PyramidRule r;
        r.margin = std::uniform_real_distribution<float>(0.1f, 1.0f)(rng);
        r.slope = std::uniform_real_distribution<float>(0.01f, 0.05f)(rng);
        if (round == 1) r.floor_per_m2 = 0.002f, r.floor_m = 0.001f;
        Gaze gaze = gazeAtPixel(f, size[0] * 0.3, size[1] * 0.6);
        if (round == 2) gaze.fovea_growth_deg = 4.0;
        const Sampled s = sample(sampler, f, gaze, r);
        int checked = 0;
        checkAgainstBruteForce(f, gaze, r, levels, s, &checked);
        rules += checked;
      }
    }
  }
  EXPECT_GT(rules, 1000);  // the rule was really checked, not left out as too close
}

// One sampler for frames of changing sizes: a smaller frame must not see the sums a
// larger one left past its edges.
TEST(PyramidSampler, FramesOfChangingSizesShareOneSampler) {
  std::mt19937 rng(9);
  PyramidSampler sampler = PyramidSampler::create(161, 121, 5).value();
  for (const auto& size : {std::pair{161, 121}, std::pair{33, 17}, std::pair{160, 120}, std::pair{7, 5},
                           std::pair{97, 71}}) {
    SCOPED_TRACE(testing::Message() << size.first << "x" << size.second);
    const hal::RgbdFrame f = randomFrame(rng, size.first, size.second);
    const Gaze gaze = gazeAtPixel(f, size.first * 0.7, size.second * 0.2);
    const Sampled s = sample(sampler, f, gaze, PyramidRule{});
    checkAgainstBruteForce(f, gaze, PyramidRule{}, 5, s);
  }
}

// A cloud made without weights (the service's slots) gets the same points.
TEST(PyramidSampler, ACloudWithoutWeightsGetsTheSamePoints) {
  std::mt19937 rng(31);
  const hal::RgbdFrame f = randomFrame(rng, 97, 71);
  PyramidSampler sampler = PyramidSampler::create(97, 71, 5).value();
  const Gaze gaze = gazeAtPixel(f, 40, 30);
  const Sampled with = sample(sampler, f, gaze, PyramidRule{});
  FoveatedCloud without(f.pixelCount(), FoveatedCloud::Weights::kNone);
  PyramidStats stats;
  ASSERT_TRUE(sampler.sample(f, DepthRange{}, gaze, PyramidRule{}, without, stats).isOk());
  ASSERT_FALSE(without.hasWeights());
  ASSERT_EQ(without.size(), with.out.size());
  ASSERT_GT(without.size(), 0u);
  for (std::size_t o = 0; o < without.size(); ++o) {
    ASSERT_EQ(without.points.x()[o], with.out.points.x()[o]) << o;
    ASSERT_EQ(without.points.z()[o], with.out.points.z()[o]) << o;
    ASSERT_EQ(without.points.rgb()[o], with.out.points.rgb()[o]) << o;
    ASSERT_EQ(without.region[o], with.out.region[o]) << o;
  }
}

TEST(PyramidSampler, TheFoveaKeepsEveryPixelAndThePeripheryMerges) {
  hal::RgbdFrame f = makeFrame(320, 240, 300.0);
  for (std::size_t p = 0; p < f.pixelCount(); ++p) f.depth()[p] = 3000;  // a wall 3 m away
  PyramidSampler sampler = PyramidSampler::create(320, 240).value();
  const Gaze gaze = gazeAtPixel(f, 160, 120, 0.0);
  const Sampled s = sample(sampler, f, gaze, PyramidRule{});
  checkAgainstBruteForce(f, gaze, PyramidRule{}, 5, s);
  // Pixels at the gaze are their own points; the corners (about 28 degrees out) are not.
  EXPECT_EQ(s.out.region[s.representative[120 * 320 + 160]], 0);
  EXPECT_GE(s.out.region[s.representative[0]], 2);
  EXPECT_LT(s.out.size(), f.pixelCount() / 4);
  EXPECT_GT(s.stats.out_by_level[0], 100u);
}

TEST(PyramidSampler, NoPointBetweenTheTwoSidesOfADepthStep) {
  hal::RgbdFrame f = makeFrame(256, 192, 250.0);
  for (int v = 0; v < 192; ++v) {
    for (int u = 0; u < 256; ++u) f.depth()[static_cast<std::size_t>(v) * 256 + u] = u < 131 ? 2000 : 5000;
  }
  PyramidSampler sampler = PyramidSampler::create(256, 192).value();
  const Gaze gaze = gazeAtPixel(f, 10, 10, 0.0);  // the step lies in the periphery
  const Sampled s = sample(sampler, f, gaze, PyramidRule{});
  checkAgainstBruteForce(f, gaze, PyramidRule{}, 5, s);
  for (std::size_t o = 0; o < s.out.size(); ++o) {
    const float z = s.out.points.z()[o];
    EXPECT_TRUE(std::abs(z - 2.0f) < 1e-4f || std::abs(z - 5.0f) < 1e-4f) << "a flying point at z " << z;
  }
}

TEST(PyramidSampler, HardFrames) {
  PyramidSampler sampler = PyramidSampler::create(64, 48).value();
  hal::RgbdFrame f = makeFrame(64, 48);
  const Gaze gaze = gazeAtPixel(f, 32, 24);
  // No valid depth at all: no point, no error.
  for (std::size_t p = 0; p < f.pixelCount(); ++p) f.depth()[p] = p % 2 ? 0 : 65535;
  Sampled s = sample(sampler, f, gaze, PyramidRule{});
  EXPECT_EQ(s.out.size(), 0u);
  EXPECT_EQ(s.stats.points_in, 0u);
  // One valid pixel in a corner, no colour: it comes out alone, black.
  f.depth()[47 * 64 + 63] = 1234;
  f.has_rgb = false;
  s = sample(sampler, f, gaze, PyramidRule{});
  ASSERT_EQ(s.out.size(), 1u);
  EXPECT_EQ(s.out.weight[0], 1u);
  EXPECT_EQ(s.out.points.rgb()[0], 0u);
  EXPECT_FALSE(s.out.points.has_color);
  EXPECT_NEAR(s.out.points.z()[0], 1.234f, 1e-6f);
  // The eye inside the scene and looking backwards: everything far in the periphery.
  for (std::size_t p = 0; p < f.pixelCount(); ++p) f.depth()[p] = static_cast<uint16_t>(500 + p % 7);
  Gaze backwards = gaze;
  backwards.direction = -gaze.direction;
  backwards.origin_m = f.T_world_cam.t_world_cam + Eigen::Vector3d(0.0, 0.0, 0.5);
  s = sample(sampler, f, backwards, PyramidRule{});
  checkAgainstBruteForce(f, backwards, PyramidRule{}, 5, s);
  // Depth at the range's limits: 0.1 m and 10 m exactly are valid (raw 100, 10000).
  for (std::size_t p = 0; p < f.pixelCount(); ++p) f.depth()[p] = p % 2 ? 100 : 10000;
  s = sample(sampler, f, gaze, PyramidRule{});
  EXPECT_EQ(s.stats.points_in, f.pixelCount());
  checkAgainstBruteForce(f, gaze, PyramidRule{}, 5, s);
}

// Millimetres of spread at 9.99 m: sum(z^2)/n - mean^2 in float would lose them all
// (the random frames above failed on it before the pairwise update).
TEST(PyramidSampler, TheDepthSpreadStaysExactFarAway) {
  hal::RgbdFrame f = makeFrame(128, 96, 600.0);
  std::mt19937 rng(5);
  for (std::size_t p = 0; p < f.pixelCount(); ++p) f.depth()[p] = static_cast<uint16_t>(9990 + rng() % 4);
  PyramidSampler sampler = PyramidSampler::create(128, 96).value();
  for (const float margin : {0.02f, 0.05f, 0.1f, 0.5f}) {
    PyramidRule r;
    r.margin = margin;
    const Gaze gaze = gazeAtPixel(f, 20, 20, 0.0);
    const Sampled s = sample(sampler, f, gaze, r);
    int checked = 0;
    checkAgainstBruteForce(f, gaze, r, 5, s, &checked);
    EXPECT_GT(checked, 50) << "margin " << margin;
  }
}

TEST(PyramidSampler, BadInputIsRefusedWithAReason) {
  EXPECT_FALSE(PyramidSampler::create(0, 10).isOk());
  EXPECT_FALSE(PyramidSampler::create(10, 10, 0).isOk());
  EXPECT_FALSE(PyramidSampler::create(10, 10, kMaxPyramidLevels + 1).isOk());
  PyramidSampler sampler = PyramidSampler::create(16, 16).value();
  hal::RgbdFrame f = makeFrame(16, 16);
  for (std::size_t p = 0; p < f.pixelCount(); ++p) f.depth()[p] = 1000;
  FoveatedCloud out(256);
  PyramidStats stats;
  const Gaze gaze = gazeAtPixel(f, 8, 8);
  ASSERT_TRUE(sampler.sample(f, DepthRange{}, gaze, PyramidRule{}, out, stats).isOk());
  Gaze nan_gaze = gaze;
  nan_gaze.direction.x() = std::nan("");
  Status s = sampler.sample(f, DepthRange{}, nan_gaze, PyramidRule{}, out, stats);
  EXPECT_EQ(s.code(), ErrorCode::kInvalidInput);
  EXPECT_EQ(out.size(), 0u);
  PyramidRule bad;
  bad.margin = 0.0f;
  EXPECT_EQ(sampler.sample(f, DepthRange{}, gaze, bad, out, stats).code(), ErrorCode::kInvalidArgument);
  bad = PyramidRule{};
  bad.floor_per_m2 = -1.0f;
  EXPECT_EQ(sampler.sample(f, DepthRange{}, gaze, bad, out, stats).code(), ErrorCode::kInvalidArgument);
  // An output too small for what the frame needs: refused, left empty; one that
  // fits exactly is enough.
  ASSERT_TRUE(sampler.sample(f, DepthRange{}, gaze, PyramidRule{}, out, stats).isOk());
  const std::size_t needed = out.size();
  ASSERT_GT(needed, 1u);
  FoveatedCloud small(needed - 1), exact(needed);
  s = sampler.sample(f, DepthRange{}, gaze, PyramidRule{}, small, stats);
  EXPECT_EQ(s.code(), ErrorCode::kCapacityExceeded);
  EXPECT_NE(s.toString().find(std::to_string(needed - 1)), std::string::npos) << s.toString();
  EXPECT_EQ(small.size(), 0u);
  EXPECT_TRUE(sampler.sample(f, DepthRange{}, gaze, PyramidRule{}, exact, stats).isOk());
  EXPECT_EQ(exact.size(), needed);
  hal::RgbdFrame big = makeFrame(17, 16);
  s = sampler.sample(big, DepthRange{}, gaze, PyramidRule{}, out, stats);
  EXPECT_EQ(s.code(), ErrorCode::kCapacityExceeded);
  EXPECT_NE(s.toString().find("17x16"), std::string::npos) << s.toString();
  f.intrinsics.fx = 0.0;  // validateFrame's reason
  EXPECT_EQ(sampler.sample(f, DepthRange{}, gaze, PyramidRule{}, out, stats).code(), ErrorCode::kInvalidInput);
}

}  // namespace
}  // namespace fovea::pipeline
