// The moving pixels (pipeline/map/moving_pixels.h): against a brute-force
// reference written here from the header's rules, on random scenes of boxes
// before a wall with holes in the map, frame after frame; a box that stops
// settles after settle_frames frames and one that keeps changing never does;
// what is not a mover (nothing known behind it, a speckle, a region mostly
// unknown); each pixel judged by the nearest surfel of its window; and bad
// input. And the intensity's rounding both references share
// (intensity_level.h) against std::lround.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/depth_noise.h"
#include "pipeline/map/intensity_level.h"
#include "pipeline/map/moving_pixels.h"

namespace fovea::pipeline::map {
namespace {

constexpr int kW = 64, kH = 48, kHalfW = kW / 2, kHalfH = kH / 2;
constexpr float kF = 60.0f, kC = 31.5f, kCy = 23.5f;

// A scene: the model's finest level (a wall, with holes where the map has no
// surfel) and the frame's half level (the camera the model's, R = I, t = 0).
struct Scene {
  std::vector<float> model_z = std::vector<float>(kW * kH, 0.0f);
  std::vector<uint8_t> from_surfel = std::vector<uint8_t>(kW * kH, 0);
  std::vector<float> x = std::vector<float>(kHalfW * kHalfH, 0.0f), y = x, z = x, intensity = x;

  MovingPixels::ModelIn model() const { return {kW, kH, kF, kF, kC, kCy, model_z.data(), from_surfel.data()}; }
  MovingPixels::FrameIn half() const { return {kHalfW, kHalfH, x.data(), y.data(), z.data(), intensity.data()}; }
  // Half-level pixel (u, v) at depth d: its ray at the half level's camera.
  void setDepth(int u, int v, float d, float shade) {
    const std::size_t i = static_cast<std::size_t>(v) * kHalfW + u;
    const float hf = kF / 2, hcx = (kC + 0.5f) / 2 - 0.5f, hcy = (kCy + 0.5f) / 2 - 0.5f;
    z[i] = d;
    x[i] = (static_cast<float>(u) - hcx) / hf * d;
    y[i] = (static_cast<float>(v) - hcy) / hf * d;
    intensity[i] = shade;
  }
};

// The header's rules, written plainly: each half pixel's class, the regions by
// a flood fill, the movers, the ages, the finest mask.
struct Reference {
  MovingPixelsConfig config;
  std::vector<int> age = std::vector<int>(kHalfW * kHalfH, 0);
  std::vector<float> depth = std::vector<float>(kHalfW * kHalfH, 0.0f);
  std::vector<int> shade = std::vector<int>(kHalfW * kHalfH, 0);

  static constexpr int kExplained = 0, kUnknown = 1, kInFront = 2;
  int classOf(const Scene& s, int i) const {
    const float pz = s.z[i];
    if (!(pz > 0.0f)) return kExplained;
    const float fu = kF * s.x[i] / pz + kC, fv = kF * s.y[i] / pz + kCy;
    if (!(fu >= -0.5f && fu < kW - 0.5f && fv >= -0.5f && fv < kH - 0.5f)) return kUnknown;
    const float near = windowNear(s, static_cast<int>(fu + 0.5f) / 2, static_cast<int>(fv + 0.5f) / 2);
    if (std::isinf(near)) return kUnknown;
    return pz < near - gap(near) ? kInFront : kExplained;
  }
  // The nearest surfel depth of the finest pixels 2 bu - 1 .. 2 bu + 2 by 2 bv - 1 .. 2 bv + 2
  // (infinity: none).
  static float windowNear(const Scene& s, int bu, int bv) {
    float near = std::numeric_limits<float>::infinity();
    for (int v = 2 * bv - 1; v <= 2 * bv + 2; ++v) {
      for (int u = 2 * bu - 1; u <= 2 * bu + 2; ++u) {
        if (u < 0 || v < 0 || u >= kW || v >= kH) continue;
        const int j = v * kW + u;
        if (s.from_surfel[j] && s.model_z[j] > 0.0f) near = std::min(near, s.model_z[j]);
      }
    }
    return near;
  }
  float gap(float near) const {
    return std::max(static_cast<float>(config.min_gap_m), static_cast<float>(config.gap_sigmas) * depthSigma(near));
  }
  // The finest mask after one more frame.
  std::vector<uint8_t> step(const Scene& s) {
    const int n = kHalfW * kHalfH;
    std::vector<int> cls(n);
    for (int i = 0; i < n; ++i) cls[i] = classOf(s, i);
    std::vector<int> region(n, -1);
    std::vector<bool> mover(n, false);
    int regions = 0;
    for (int seed = 0; seed < n; ++seed) {
      if (cls[seed] != kInFront || region[seed] >= 0) continue;
      std::vector<int> members, stack = {seed};
      region[seed] = regions;
      while (!stack.empty()) {
        const int i = stack.back();
        stack.pop_back();
        members.push_back(i);
        const int u = i % kHalfW, v = i / kHalfW;
        const int du[4] = {-1, 1, 0, 0}, dv[4] = {0, 0, -1, 1};
        for (int k = 0; k < 4; ++k) {
          const int nu = u + du[k], nv = v + dv[k];
          if (nu < 0 || nv < 0 || nu >= kHalfW || nv >= kHalfH) continue;
          const int j = nv * kHalfW + nu;
          if (region[j] >= 0 || cls[j] == kExplained) continue;
          if (!(std::abs(s.z[j] - s.z[i]) <= static_cast<float>(config.region_step_share) * s.z[i])) continue;
          region[j] = regions;
          stack.push_back(j);
        }
      }
      const auto front = std::count_if(members.begin(), members.end(), [&](int i) { return cls[i] == kInFront; });
      const bool is_mover = static_cast<double>(members.size()) >= std::ceil(config.min_region_share * n) &&
                            2 * front >= static_cast<long>(members.size());
      for (int i : members) mover[i] = is_mover;
      ++regions;
    }
    std::vector<uint8_t> mask(kW * kH, 0);
    for (int i = 0; i < n; ++i) {
      bool moving = false;
      if (mover[i]) {
        const int sh = static_cast<int>(std::lround(std::clamp(s.intensity[i], 0.0f, 1.0f) * 255.0f));
        const bool steady = age[i] > 0 && std::abs(s.z[i] - depth[i]) <= static_cast<float>(config.steady_depth_share) * s.z[i] &&
                            std::abs(sh - shade[i]) <= std::lround(config.steady_intensity * 255.0);
        age[i] = steady ? std::min(age[i] + 1, 255) : 1;
        depth[i] = s.z[i];
        shade[i] = sh;
        moving = age[i] < config.settle_frames;
      } else {
        age[i] = 0;
      }
      const int u = i % kHalfW, v = i / kHalfW;
      for (int dv = 0; dv < 2; ++dv) {
        for (int du = 0; du < 2; ++du) mask[(2 * v + dv) * kW + 2 * u + du] = moving ? 1 : 0;
      }
    }
    return mask;
  }
};

// A wall at 2 m with rectangular holes in the map, and boxes before it.
struct RandomScene {
  std::mt19937 rng;
  struct Box {
    int u0, v0, u1, v1;
    float depth;
  };
  std::vector<Box> boxes;
  std::vector<std::array<int, 4>> holes;

  explicit RandomScene(uint32_t seed) : rng(seed) {
    std::uniform_int_distribution<int> u(0, kHalfW - 1), v(0, kHalfH - 1), count(0, 3);
    std::uniform_real_distribution<float> d(0.6f, 1.9f);
    for (int k = count(rng) + 1; k > 0; --k) {
      int a = u(rng), b = u(rng), c = v(rng), e = v(rng);
      boxes.push_back({std::min(a, b), std::min(c, e), std::max(a, b), std::max(c, e), d(rng)});
    }
    for (int k = count(rng); k > 0; --k) {
      std::uniform_int_distribution<int> fu(0, kW - 1), fv(0, kH - 1);
      int a = fu(rng), b = fu(rng), c = fv(rng), e = fv(rng);
      holes.push_back({std::min(a, b), std::min(c, e), std::max(a, b), std::max(c, e)});
    }
  }
  // Frame k: the boxes moved by `drift` half pixels a frame (0: still), with
  // noise; some pixels without depth.
  Scene frame(int k, int drift) {
    Scene s;
    for (int v = 0; v < kH; ++v) {
      for (int u = 0; u < kW; ++u) {
        bool hole = false;
        for (const auto& h : holes) hole = hole || (u >= h[0] && u <= h[2] && v >= h[1] && v <= h[3]);
        s.model_z[v * kW + u] = 2.0f;
        s.from_surfel[v * kW + u] = hole ? 0 : 1;
      }
    }
    std::normal_distribution<float> noise(0.0f, 0.002f);
    std::uniform_real_distribution<float> drop(0.0f, 1.0f);
    for (int v = 0; v < kHalfH; ++v) {
      for (int u = 0; u < kHalfW; ++u) {
        float depth = 2.0f + noise(rng), shade = 0.5f;
        for (const Box& b : boxes) {
          const int bu0 = b.u0 + k * drift, bu1 = b.u1 + k * drift;
          if (u >= bu0 && u <= bu1 && v >= b.v0 && v <= b.v1 && b.depth < depth) {
            depth = b.depth + noise(rng);
            shade = ((u - bu0) / 3 + v / 3) % 2 ? 0.9f : 0.1f;
          }
        }
        s.setDepth(u, v, drop(rng) < 0.02f ? 0.0f : depth, shade);
      }
    }
    return s;
  }
};

TEST(MovingPixels, MatchesABruteForceReferenceOnRandomScenes) {
  MovingPixelsConfig config;
  config.settle_frames = 3;  // so that some boxes settle within the frames below
  int moving_seen = 0, settled_seen = 0;  // frames with movers; still scenes whose movers mostly settled
  for (uint32_t seed = 1; seed <= 40; ++seed) {
    RandomScene scene(seed);
    MovingPixels moving = MovingPixels::create(kW, kH, config).value();
    Reference reference{config};
    const int drift = static_cast<int>(seed % 3);  // still, 1 or 2 half pixels a frame
    uint32_t first_count = 0;
    for (int k = 0; k < 6; ++k) {
      const Scene s = scene.frame(k, drift);
      const uint32_t count = moving.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero());
      const std::vector<uint8_t> expected = reference.step(s);
      ASSERT_EQ(moving.width(), kW);
      ASSERT_EQ(moving.height(), kH);
      uint32_t expected_count = 0;
      for (int i = 0; i < kW * kH; ++i) {
        ASSERT_EQ(moving.mask()[i], expected[i]) << "seed " << seed << " frame " << k << " pixel " << i;
        expected_count += expected[i];
      }
      EXPECT_EQ(count, expected_count);
      moving_seen += expected_count > 0 ? 1 : 0;
      if (k == 0) first_count = expected_count;
      settled_seen += k == 5 && drift == 0 && 2 * expected_count < first_count ? 1 : 0;
    }
  }
  EXPECT_GT(moving_seen, 40) << "the scenes must have movers for the comparison to mean anything";
  EXPECT_GE(settled_seen, 5) << "and still boxes that settle";
}

// A box 1 m before the wall: moving for settle_frames - 1 frames, then settled
// (fused again) while it stands still; one whose texture changes every frame
// (a person's clothes, a balloon's stripes turning) never settles.
TEST(MovingPixels, AStoppedBoxSettlesAndAChangingOneNever) {
  MovingPixelsConfig config;
  MovingPixels still = MovingPixels::create(kW, kH, config).value();
  MovingPixels changing = MovingPixels::create(kW, kH, config).value();
  for (int k = 0; k < config.settle_frames + 5; ++k) {
    Scene s;
    std::fill(s.model_z.begin(), s.model_z.end(), 2.0f);
    std::fill(s.from_surfel.begin(), s.from_surfel.end(), uint8_t{1});
    for (int v = 0; v < kHalfH; ++v) {
      for (int u = 0; u < kHalfW; ++u) {
        const bool box = u >= 8 && u < 20 && v >= 6 && v < 18;
        s.setDepth(u, v, box ? 1.0f : 2.0f, box ? 0.8f : 0.3f);
      }
    }
    const uint32_t n = still.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero());
    EXPECT_EQ(n, k + 1 < config.settle_frames ? 4u * 12 * 12 : 0u) << "frame " << k;
    for (std::size_t i = 0; i < s.intensity.size(); ++i) {
      if (s.intensity[i] == 0.8f) s.intensity[i] = k % 2 ? 0.8f : 0.2f;
    }
    EXPECT_EQ(changing.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()),
              4u * 12 * 12)
        << "frame " << k;
  }
}

// A model whose depth differs from pixel to pixel (some without a surfel) and a
// frame whose every pixel lies just in front of, or just behind, the nearest
// surfel of its window less the gap: the window decides each pixel, so a window
// searched a column too narrow or shifted, or cut wrong at the image's edge,
// shows (the random scenes above, a flat wall, did not tell).
TEST(MovingPixels, EachPixelIsJudgedByTheNearestSurfelOfItsWindow) {
  MovingPixelsConfig config;
  config.min_region_share = 1e-6;  // one pixel in front is a mover: each pixel's class shows
  Scene s;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> rough(0.0f, 0.02f);  // 1 % of the depth: one region
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      s.model_z[v * kW + u] = 2.0f + rough(rng);
      s.from_surfel[v * kW + u] = (u * 5 + v * 3) % 11 == 0 ? 0 : 1;
    }
  }
  for (const float side : {-0.0002f, 0.0002f}) {  // in front, behind
    Reference reference{config};
    for (int v = 0; v < kHalfH; ++v) {
      for (int u = 0; u < kHalfW; ++u) {
        const float near = Reference::windowNear(s, u, v);
        s.setDepth(u, v, near - reference.gap(near) + side, 0.5f);
      }
    }
    MovingPixels moving = MovingPixels::create(kW, kH, config).value();
    const uint32_t count = moving.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero());
    const std::vector<uint8_t> expected = reference.step(s);
    for (int i = 0; i < kW * kH; ++i) ASSERT_EQ(moving.mask()[i], expected[i]) << "pixel " << i << ", side " << side;
    EXPECT_EQ(count, side < 0.0f ? static_cast<uint32_t>(kW * kH) : 0u) << "side " << side;
  }
}

// Nothing known behind it, a speckle, a region mostly unknown: not movers.
TEST(MovingPixels, WhatIsNotAMover) {
  MovingPixels moving = MovingPixels::create(kW, kH, MovingPixelsConfig{}).value();
  Scene s;
  for (int v = 0; v < kHalfH; ++v) {
    for (int u = 0; u < kHalfW; ++u) s.setDepth(u, v, 1.0f, 0.5f);
  }
  // No surfel anywhere: every pixel unknown.
  EXPECT_EQ(moving.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()), 0u);
  // The map's wall behind only a strip of 2 columns: the region in front of
  // it is 2 columns of 32, the rest of it unknown.
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < 4; ++u) {
      s.model_z[v * kW + u] = 2.0f;
      s.from_surfel[v * kW + u] = 1;
    }
  }
  EXPECT_EQ(moving.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()), 0u);
  // The wall known everywhere: all of it in front, a mover.
  std::fill(s.model_z.begin(), s.model_z.end(), 2.0f);
  std::fill(s.from_surfel.begin(), s.from_surfel.end(), uint8_t{1});
  EXPECT_EQ(moving.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()),
            static_cast<uint32_t>(kW * kH));
  // A speckle: one half pixel in front, the rest at the wall.
  MovingPixelsConfig config;
  config.min_region_share = 0.01;  // 8 of the 768 half pixels
  MovingPixels speckles = MovingPixels::create(kW, kH, config).value();
  for (int v = 0; v < kHalfH; ++v) {
    for (int u = 0; u < kHalfW; ++u) s.setDepth(u, v, u == 5 && v == 5 ? 1.0f : 2.0f, 0.5f);
  }
  EXPECT_EQ(speckles.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()), 0u);
}

TEST(MovingPixels, BadInputMarksNothingAndBadConfigsAreRefused) {
  MovingPixels moving = MovingPixels::create(kW, kH, MovingPixelsConfig{}).value();
  Scene s;
  std::fill(s.model_z.begin(), s.model_z.end(), 2.0f);
  std::fill(s.from_surfel.begin(), s.from_surfel.end(), uint8_t{1});
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  for (int v = 0; v < kHalfH; ++v) {
    for (int u = 0; u < kHalfW; ++u) s.setDepth(u, v, 1.0f, 0.5f);
  }
  // Vertices that are not finite, behind the camera, projecting anywhere.
  for (std::size_t i = 0; i < s.z.size(); i += 3) s.x[i] = nan;
  for (std::size_t i = 1; i < s.z.size(); i += 7) s.z[i] = -1.0f;
  for (std::size_t i = 2; i < s.z.size(); i += 11) s.y[i] = inf;
  for (std::size_t i = 5; i < s.z.size(); i += 13) s.intensity[i] = nan;
  const uint32_t n = moving.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero());
  EXPECT_LE(n, static_cast<uint32_t>(kW * kH));
  // A rotation that is not finite: nothing is in front of anything.
  Eigen::Matrix3f broken = Eigen::Matrix3f::Identity();
  broken(0, 0) = nan;
  EXPECT_LE(moving.update(s.half(), s.model(), broken, Eigen::Vector3f::Zero()), static_cast<uint32_t>(kW * kH));
  // Sizes that do not fit: none, and the mask's size says so.
  MovingPixels::FrameIn big = s.half();
  big.width = kW;  // larger than create()'s half level
  EXPECT_EQ(moving.update(big, s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()), 0u);
  EXPECT_EQ(moving.width(), 0);
  MovingPixels::ModelIn other = s.model();
  other.width = kW - 2;  // not the frame's
  EXPECT_EQ(moving.update(s.half(), other, Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()), 0u);
  MovingPixels::FrameIn empty = s.half();
  empty.height = 0;
  EXPECT_EQ(moving.update(empty, s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()), 0u);
  // Switched off: none.
  MovingPixelsConfig off;
  off.enabled = false;
  MovingPixels none = MovingPixels::create(kW, kH, off).value();
  EXPECT_EQ(none.update(s.half(), s.model(), Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()), 0u);
  // Configurations.
  const auto refused = [](auto edit) {
    MovingPixelsConfig c;
    edit(c);
    return !MovingPixels::create(kW, kH, c).isOk();
  };
  EXPECT_TRUE(refused([](MovingPixelsConfig& c) { c.min_gap_m = 0.0; }));
  EXPECT_TRUE(refused([&](MovingPixelsConfig& c) { c.gap_sigmas = nan; }));
  EXPECT_TRUE(refused([](MovingPixelsConfig& c) { c.settle_frames = 0; }));
  EXPECT_TRUE(refused([](MovingPixelsConfig& c) { c.settle_frames = 256; }));
  EXPECT_TRUE(refused([](MovingPixelsConfig& c) { c.region_step_share = -0.1; }));
  EXPECT_TRUE(refused([](MovingPixelsConfig& c) { c.min_region_share = 1.5; }));
  EXPECT_TRUE(refused([&](MovingPixelsConfig& c) { c.steady_intensity = nan; }));
  EXPECT_FALSE(MovingPixels::create(1, kH, MovingPixelsConfig{}).isOk());
  EXPECT_FALSE(MovingPixels::create(kW, 9000, MovingPixelsConfig{}).isOk());
}

// As std::lround(c * 255.0f) on [0, 1], the halves between levels and their
// neighbouring floats included; clamped outside; NaN is level 0.
TEST(IntensityLevel, IsLroundOfTheClampedIntensityAndNaNIsZero) {
  const auto lroundLevel = [](float c) { return static_cast<int>(std::lround(c * 255.0f)); };
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (int k = 0; k < 200000; ++k) {
    const float c = unit(rng);
    ASSERT_EQ(intensityLevel(c), lroundLevel(c)) << c;
  }
  for (int level = 0; level < 255; ++level) {
    const float half = (static_cast<float>(level) + 0.5f) / 255.0f;
    for (float c : {std::nextafter(half, 0.0f), half, std::nextafter(half, 1.0f)}) {
      ASSERT_EQ(intensityLevel(c), lroundLevel(c)) << c;
    }
  }
  EXPECT_EQ(intensityLevel(0.0f), 0);
  EXPECT_EQ(intensityLevel(1.0f), 255);
  EXPECT_EQ(intensityLevel(-0.2f), 0);
  EXPECT_EQ(intensityLevel(7.0f), 255);
  EXPECT_EQ(intensityLevel(std::numeric_limits<float>::infinity()), 255);
  EXPECT_EQ(intensityLevel(-std::numeric_limits<float>::infinity()), 0);
  EXPECT_EQ(intensityLevel(std::numeric_limits<float>::quiet_NaN()), 0);
}

}  // namespace
}  // namespace fovea::pipeline::map
