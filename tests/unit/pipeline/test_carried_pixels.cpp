// The pixels carried with the camera (pipeline/map/carried_pixels.h): against a
// brute-force reference written here from the header's rules, on random scenes
// of a room that drifts through the image with boxes held still in it, frame
// after frame; a camera at rest finds nothing; a box held from the first frame
// is found from the second, and the room found with it at first drops out as
// it drifts; the moving pixels take the carried ones and never settle them;
// bad input.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "core/depth_noise.h"
#include "pipeline/map/carried_pixels.h"
#include "pipeline/map/moving_pixels.h"

namespace fovea::pipeline::map {
namespace {

constexpr int kW = 40, kH = 30;  // the half level
constexpr int kPixels = kW * kH;

struct Frame {
  std::vector<float> z = std::vector<float>(kPixels, 0.0f), intensity = z;
  CarriedPixels::FrameIn in() const { return {kW, kH, z.data(), intensity.data()}; }
};

// The header's rules, written plainly.
struct Reference {
  CarriedPixelsConfig config;
  std::vector<float> depth = std::vector<float>(kPixels, 0.0f);
  std::vector<int> shade = std::vector<int>(kPixels, 0), age = shade;
  bool have = false;
  int compared = 0;

  static int level(float v) { return static_cast<int>(std::lround((v >= 0.0f ? std::min(v, 1.0f) : 0.0f) * 255.0f)); }

  std::vector<uint8_t> step(const Frame& f) {
    if (have) compared = std::min(compared + 1, config.still_frames);
    const int long_frames = std::max(compared, 1);
    std::vector<bool> still_long(kPixels, false);
    int valid = 0, changed = 0;
    for (int i = 0; i < kPixels; ++i) {
      const bool depth_now = f.z[i] > 0.0f;
      const bool still = have && depth_now && depth[i] > 0.0f &&
                         std::abs(f.z[i] - depth[i]) <= static_cast<float>(config.still_sigmas) * depthSigma(f.z[i]) &&
                         std::abs(level(f.intensity[i]) - shade[i]) <= std::lround(config.still_intensity * 255.0);
      if (still) {
        age[i] = std::min(age[i] + 1, 255);
      } else {
        depth[i] = depth_now ? f.z[i] : 0.0f;
        shade[i] = level(f.intensity[i]);
        age[i] = 0;
      }
      still_long[i] = still && age[i] >= long_frames;
      valid += depth_now ? 1 : 0;
      changed += depth_now && !still_long[i] ? 1 : 0;
    }
    const bool had = have;
    have = true;
    std::vector<uint8_t> mask(kPixels, 0);
    const double share = valid > 0 ? static_cast<double>(changed) / valid : 0.0;
    if (!had || share < config.min_changed_share) return mask;
    // The regions by a flood fill; those large enough are carried.
    std::vector<int> region(kPixels, -1);
    const double min_pixels = std::ceil(config.min_region_share * kPixels);
    for (int seed = 0; seed < kPixels; ++seed) {
      if (!still_long[seed] || region[seed] >= 0) continue;
      std::vector<int> members, stack = {seed};
      region[seed] = seed;
      while (!stack.empty()) {
        const int i = stack.back();
        stack.pop_back();
        members.push_back(i);
        const int u = i % kW, v = i / kW;
        const int du[4] = {-1, 1, 0, 0}, dv[4] = {0, 0, -1, 1};
        for (int k = 0; k < 4; ++k) {
          const int nu = u + du[k], nv = v + dv[k];
          if (nu < 0 || nv < 0 || nu >= kW || nv >= kH) continue;
          const int j = nv * kW + nu;
          if (region[j] >= 0 || !still_long[j]) continue;
          if (!(std::abs(f.z[j] - f.z[i]) <= static_cast<float>(config.region_step_share) * f.z[i])) continue;
          region[j] = seed;
          stack.push_back(j);
        }
      }
      if (static_cast<double>(members.size()) < min_pixels) continue;
      double depth_sum = 0.0;
      for (int i : members) depth_sum += f.z[i];
      if (depth_sum / static_cast<double>(members.size()) > config.max_depth_m) continue;  // beyond reach
      for (int i : members) mask[i] = 1;
    }
    // Widened by the margin: a pixel is carried when one within the square is.
    std::vector<uint8_t> wide(kPixels, 0);
    const int r = config.margin_pixels;
    for (int v = 0; v < kH; ++v) {
      for (int u = 0; u < kW; ++u) {
        for (int y = std::max(v - r, 0); y <= std::min(v + r, kH - 1); ++y) {
          for (int x = std::max(u - r, 0); x <= std::min(u + r, kW - 1); ++x) wide[v * kW + u] |= mask[y * kW + x];
        }
      }
    }
    return wide;
  }
};

// A textured room at 2 to 4 m that drifts `drift` pixels a frame across the
// image (0: the camera at rest), with boxes held still before it at under a
// metre; the sensor's noise on every depth, some pixels without depth.
struct RandomScene {
  std::mt19937 rng;
  struct Box {
    int u0, v0, u1, v1;
    float depth, shade;
  };
  std::vector<Box> boxes;

  explicit RandomScene(uint32_t seed) : rng(seed) {
    std::uniform_int_distribution<int> u(0, kW - 1), v(0, kH - 1), count(0, 2);
    std::uniform_real_distribution<float> d(0.5f, 0.9f), shade(0.2f, 0.8f);
    for (int k = count(rng); k > 0; --k) {
      const int a = u(rng), b = u(rng), c = v(rng), e = v(rng);
      boxes.push_back({std::min(a, b), std::min(c, e), std::max(a, b), std::max(c, e), d(rng), shade(rng)});
    }
  }
  Frame frame(int k, int drift) {
    Frame f;
    std::normal_distribution<float> noise(0.0f, 1.0f);
    std::uniform_real_distribution<float> drop(0.0f, 1.0f);
    for (int v = 0; v < kH; ++v) {
      for (int u = 0; u < kW; ++u) {
        const int x = u + k * drift;  // the room's column under this pixel
        // A shelf within reach on the left half of the room, the rest beyond it.
        float depth = (x / 20) % 2 ? 2.0f + 0.05f * static_cast<float>((x / 5) % 40) : 0.9f + 0.01f * static_cast<float>(x % 20);
        float shade = ((x / 2 + v / 2) % 2) ? 0.7f : 0.3f;
        if (x % 13 == 0) shade = 0.5f;  // some plain stripes, still for a frame or two as they pass
        for (const Box& b : boxes) {
          if (u >= b.u0 && u <= b.u1 && v >= b.v0 && v <= b.v1) depth = b.depth, shade = b.shade;
        }
        depth += 0.5f * depthSigma(depth) * noise(rng);
        f.z[v * kW + u] = drop(rng) < 0.02f ? 0.0f : depth;
        f.intensity[v * kW + u] = shade;
      }
    }
    return f;
  }
};

TEST(CarriedPixels, MatchesABruteForceReferenceOnRandomScenes) {
  CarriedPixelsConfig config;
  config.still_frames = 4;  // so that the frames below pass it
  int carried_seen = 0, frames = 0;
  for (uint32_t seed = 1; seed <= 40; ++seed) {
    RandomScene scene(seed);
    CarriedPixels carried = CarriedPixels::create(2 * kW, 2 * kH, config).value();
    Reference reference{config};
    const int drift = static_cast<int>(seed % 3);  // at rest, 1 or 2 pixels a frame
    for (int k = 0; k < 8; ++k) {
      const Frame f = scene.frame(k, drift);
      const uint32_t count = carried.find(f.in());
      const std::vector<uint8_t> expected = reference.step(f);
      ASSERT_EQ(carried.width(), kW);
      ASSERT_EQ(carried.height(), kH);
      uint32_t expected_count = 0;
      for (int i = 0; i < kPixels; ++i) {
        ASSERT_EQ(carried.mask()[i], expected[i]) << "seed " << seed << " frame " << k << " pixel " << i;
        expected_count += expected[i];
      }
      EXPECT_EQ(count, expected_count);
      carried_seen += expected_count > 0 ? 1 : 0;
      ++frames;
    }
  }
  EXPECT_GT(carried_seen, frames / 4) << "the scenes must have carried boxes for the comparison to mean anything";
  EXPECT_LT(carried_seen, frames) << "and frames without";
}

// A box held before a drifting shelf within reach: found from the second frame
// (with the shelf that had not changed yet), and once every stripe changed the
// box alone, widened by the margin; before a room beyond reach the box alone
// from the start; at rest, nothing.
TEST(CarriedPixels, AHeldBoxIsFoundFromTheSecondFrameAndTheRoomDropsOut) {
  CarriedPixelsConfig config;
  CarriedPixels carried = CarriedPixels::create(2 * kW, 2 * kH, config).value();
  CarriedPixels far_room = CarriedPixels::create(2 * kW, 2 * kH, config).value();
  CarriedPixels at_rest = CarriedPixels::create(2 * kW, 2 * kH, config).value();
  const auto boxFrame = [](int k, int drift, float room_m = 1.0f) {
    Frame f;
    for (int v = 0; v < kH; ++v) {
      for (int u = 0; u < kW; ++u) {
        const bool box = u < 12 && v >= 15;
        const int x = u + k * drift;
        // The room's shade in columns 0.3, 0.3, 0.6, 0.9 over and over: a
        // pixel is still from frame 0 to 1 in a quarter of the columns, and
        // never for two frames; its depth moves by a quarter of the sensor's
        // noise a frame.
        f.z[v * kW + u] = box ? 0.7f : room_m + 0.0005f * static_cast<float>(x % 50);
        constexpr float kShades[4] = {0.3f, 0.3f, 0.6f, 0.9f};
        f.intensity[v * kW + u] = box ? 0.4f : kShades[x % 4];
      }
    }
    return f;
  };
  const uint32_t widened = (12 + 2) * (15 + 2);  // the box and the margin inside the image
  EXPECT_EQ(carried.find(boxFrame(0, 1).in()), 0u) << "the first frame: references only";
  EXPECT_EQ(at_rest.find(boxFrame(0, 0).in()), 0u);
  EXPECT_EQ(far_room.find(boxFrame(0, 1, 2.5f).in()), 0u);
  for (int k = 1; k < config.still_frames + 5; ++k) {
    const uint32_t n = carried.find(boxFrame(k, 1).in());
    if (k == 1) {
      EXPECT_GT(n, 2 * widened) << "the room that has not changed yet is found with the box";
    }
    if (k >= 2) {
      EXPECT_EQ(n, widened) << "frame " << k << ": no column of the room is still for two frames, the box is left";
    }
    EXPECT_GE(n, widened) << "frame " << k;
    EXPECT_EQ(far_room.find(boxFrame(k, 1, 2.5f).in()), widened) << "frame " << k << ": the room is beyond reach";
    for (int v = 15; v < kH; ++v) {
      for (int u = 0; u < 12; ++u) ASSERT_EQ(carried.mask()[v * kW + u], 1) << u << "," << v << " frame " << k;
    }
    EXPECT_EQ(at_rest.find(boxFrame(k, 0).in()), 0u) << "a camera at rest: every pixel still, nothing told apart";
    EXPECT_EQ(at_rest.changedShare(), 0.0);
  }
  EXPECT_GT(carried.changedShare(), 0.5);
}

// The moving pixels take the carried ones, whatever their class, and never
// settle them however steady they are.
TEST(CarriedPixels, TheMovingPixelsTakeThemAndNeverSettleThem) {
  constexpr int kFineW = 2 * kW, kFineH = 2 * kH;
  MovingPixelsConfig config;
  config.settle_frames = 3;
  MovingPixels moving = MovingPixels::create(kFineW, kFineH, config).value();
  std::vector<float> x(kPixels, 0.0f), y = x, z(kPixels, 2.0f), intensity(kPixels, 0.5f);
  std::vector<float> model_z(kFineW * kFineH, 2.0f);
  std::vector<uint8_t> from_surfel(kFineW * kFineH, 1), carried(kPixels, 0);
  for (int v = 0; v < 10; ++v) {
    for (int u = 0; u < 10; ++u) carried[v * kW + u] = 1;
  }
  const MovingPixels::FrameIn half{kW, kH, x.data(), y.data(), z.data(), intensity.data()};
  const MovingPixels::ModelIn model{kFineW, kFineH, 50.0f, 50.0f, kFineW / 2.0f, kFineH / 2.0f, model_z.data(),
                                    from_surfel.data()};
  for (int k = 0; k < 10; ++k) {
    EXPECT_EQ(moving.update(half, model, Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero(), carried.data()), 400u)
        << "frame " << k;
    EXPECT_EQ(moving.mask()[0], 1);
    EXPECT_EQ(moving.mask()[19 * kFineW + 19], 1);
    EXPECT_EQ(moving.mask()[20 * kFineW + 20], 0);
  }
  EXPECT_EQ(moving.update(half, model, Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()), 0u) << "none carried";
}

TEST(CarriedPixels, BadInputMarksNothingAndBadConfigsAreRefused) {
  CarriedPixels carried = CarriedPixels::create(2 * kW, 2 * kH, CarriedPixelsConfig{}).value();
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  for (int k = 0; k < 5; ++k) {
    Frame f;
    for (int i = 0; i < kPixels; ++i) {
      f.z[i] = i % 3 == 0 ? nan : (i % 5 == 0 ? -1.0f : (i % 7 == 0 ? inf : 1.0f + 0.1f * static_cast<float>(k)));
      f.intensity[i] = i % 4 == 0 ? nan : (i % 6 == 0 ? -inf : 0.5f);
    }
    EXPECT_LE(carried.find(f.in()), static_cast<uint32_t>(kPixels));
    EXPECT_TRUE(std::isfinite(carried.changedShare()));
  }
  // Sizes that do not fit: none, and the mask's size says so; a new size starts again.
  Frame f;
  CarriedPixels::FrameIn big = f.in();
  big.width = 2 * kW + 2;
  EXPECT_EQ(carried.find(big), 0u);
  EXPECT_EQ(carried.width(), 0);
  CarriedPixels::FrameIn empty = f.in();
  empty.height = 0;
  EXPECT_EQ(carried.find(empty), 0u);
  CarriedPixels::FrameIn smaller = f.in();
  smaller.width = kW - 4;
  EXPECT_EQ(carried.find(smaller), 0u) << "a new size: references only";
  // Switched off: none.
  CarriedPixelsConfig off;
  off.enabled = false;
  CarriedPixels none = CarriedPixels::create(2 * kW, 2 * kH, off).value();
  EXPECT_EQ(none.find(f.in()), 0u);
  EXPECT_EQ(none.find(f.in()), 0u);
  const auto refused = [](auto edit) {
    CarriedPixelsConfig c;
    edit(c);
    return !CarriedPixels::create(2 * kW, 2 * kH, c).isOk();
  };
  EXPECT_TRUE(refused([&](CarriedPixelsConfig& c) { c.still_sigmas = nan; }));
  EXPECT_TRUE(refused([](CarriedPixelsConfig& c) { c.still_sigmas = -1.0; }));
  EXPECT_TRUE(refused([](CarriedPixelsConfig& c) { c.still_intensity = 1.5; }));
  EXPECT_TRUE(refused([](CarriedPixelsConfig& c) { c.still_frames = 0; }));
  EXPECT_TRUE(refused([](CarriedPixelsConfig& c) { c.still_frames = 256; }));
  EXPECT_TRUE(refused([](CarriedPixelsConfig& c) { c.min_changed_share = 0.0; }));
  EXPECT_TRUE(refused([&](CarriedPixelsConfig& c) { c.min_region_share = nan; }));
  EXPECT_TRUE(refused([](CarriedPixelsConfig& c) { c.region_step_share = -0.5; }));
  EXPECT_TRUE(refused([](CarriedPixelsConfig& c) { c.max_depth_m = 0.0; }));
  EXPECT_TRUE(refused([&](CarriedPixelsConfig& c) { c.max_depth_m = nan; }));
  EXPECT_TRUE(refused([](CarriedPixelsConfig& c) { c.margin_pixels = -1; }));
  EXPECT_TRUE(refused([](CarriedPixelsConfig& c) { c.margin_pixels = 65; }));
  EXPECT_FALSE(CarriedPixels::create(1, 2 * kH, CarriedPixelsConfig{}).isOk());
  EXPECT_FALSE(CarriedPixels::create(2 * kW, 9000, CarriedPixelsConfig{}).isOk());
}

}  // namespace
}  // namespace fovea::pipeline::map
