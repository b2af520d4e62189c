// fovea-eval's splat renderer: projection, splat size, z-buffer and ties,
// skipped points, clipping, huge splats, determinism, and a brute-force reference.
#include "tools/eval/quality/splat_renderer.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "pipeline/point_cloud.h"

namespace fovea::tools::eval {
namespace {

constexpr std::array<uint8_t, 3> kBackground{10, 20, 30};
constexpr float kInf = std::numeric_limits<float>::infinity();

// The points a SplatCloud views.
struct Points {
  std::vector<float> x, y, z, size;
  std::vector<uint32_t> rgb;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();

  void add(double px, double py, double pz, double size_m, uint32_t colour) {
    x.push_back(static_cast<float>(px));
    y.push_back(static_cast<float>(py));
    z.push_back(static_cast<float>(pz));
    size.push_back(static_cast<float>(size_m));
    rgb.push_back(colour);
  }
  SplatCloud view() const {
    SplatCloud c;
    c.x = x.data();
    c.y = y.data();
    c.z = z.data();
    c.rgb = rgb.data();
    c.size_m = size.data();
    c.count = x.size();
    c.origin_m = origin;
    return c;
  }
};

// 64x48 with a 90 degree horizontal field: the focal length is 32 pixels.
EyeCamera smallCamera() {
  EyeCamera camera;
  camera.width = 64;
  camera.height = 48;
  camera.horizontal_fov_deg = 90.0;
  return camera;
}

std::array<uint8_t, 3> pixelAt(const Image& image, int x, int y) {
  const std::size_t p = (static_cast<std::size_t>(y) * image.width + x) * 3;
  return {image.rgb[p], image.rgb[p + 1], image.rgb[p + 2]};
}

std::array<uint8_t, 3> colourOf(uint32_t rgb) {
  return {pipeline::rgbRed(rgb), pipeline::rgbGreen(rgb), pipeline::rgbBlue(rgb)};
}

// How many pixels have exactly this colour.
int countCovered(const Image& image, uint32_t colour) {
  int n = 0;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      n += pixelAt(image, x, y) == colourOf(colour) ? 1 : 0;
    }
  }
  return n;
}

TEST(SplatRenderer, CameraFocalLengthAndCentreRay) {
  const EyeCamera camera = smallCamera();
  EXPECT_NEAR(camera.focalPx(), 32.0, 1e-12);
  Eigen::Vector2d uv;
  ASSERT_TRUE(camera.project(Eigen::Vector3d(1, 0.5, 2), uv));
  EXPECT_NEAR(uv.x(), 48.0, 1e-12);
  EXPECT_NEAR(uv.y(), 32.0, 1e-12);
  EXPECT_FALSE(camera.project(Eigen::Vector3d(0, 0, -1), uv));
  EXPECT_FALSE(camera.project(Eigen::Vector3d(0, 0, kNearPlaneM), uv));
  // The ray through pixel (48, 32)'s centre passes through the point (48.5, 32.5) projects to.
  const Eigen::Vector3d ray = camera.rayThroughPixel(48, 32);
  EXPECT_NEAR(ray.norm(), 1.0, 1e-15);
  const Eigen::Vector3d expected = Eigen::Vector3d(16.5 / 32, 8.5 / 32, 1).normalized();
  EXPECT_LT((ray - expected).norm(), 1e-15);
}

TEST(SplatRenderer, PointStraightAheadCoversTheCentreWithItsProjectedSide) {
  const EyeCamera camera = smallCamera();
  Points pts;
  // 0.25 m at 2 m with f = 32 px: 4 pixels a side, centred on (32, 24).
  pts.add(0, 0, 2, 0.25, 0xff8040);
  Image image;
  const RenderCounts counts = renderSplats(pts.view(), camera, kBackground, image);
  EXPECT_EQ(counts.drawn, 1u);
  EXPECT_EQ(counts.skipped_invalid + counts.behind + counts.outside, 0u);
  ASSERT_EQ(image.width, 64);
  ASSERT_EQ(image.height, 48);
  ASSERT_EQ(image.rgb.size(), 64u * 48 * 3);
  ASSERT_EQ(image.depth.size(), 64u * 48);
  for (int y = 0; y < 48; ++y) {
    for (int x = 0; x < 64; ++x) {
      const bool inside = x >= 30 && x < 34 && y >= 22 && y < 26;
      EXPECT_EQ(pixelAt(image, x, y), inside ? colourOf(0xff8040) : kBackground) << x << "," << y;
      EXPECT_EQ(image.depth[y * 64 + x], inside ? 2.0f : kInf) << x << "," << y;
    }
  }
}

TEST(SplatRenderer, SmallSplatsAreOnePixelAndSideFollowsDepth) {
  const EyeCamera camera = smallCamera();
  Points pts;
  pts.add(0, 0, 2, 0.001, 0x0000ff);   // 0.016 px: one pixel, the one (32, 24) falls in
  pts.add(1, 0.5, 2, 0.25, 0x00ff00);  // at (48, 32): 4 px
  pts.add(-1, -0.5, 1, 0.25, 0xff0000);  // at (0, 8), depth 1: 8 px, half clipped
  Image image;
  const RenderCounts counts = renderSplats(pts.view(), camera, kBackground, image);
  EXPECT_EQ(counts.drawn, 3u);
  EXPECT_EQ(countCovered(image, 0x0000ff), 1);
  EXPECT_EQ(pixelAt(image, 32, 24), colourOf(0x0000ff));
  EXPECT_EQ(countCovered(image, 0x00ff00), 16);
  EXPECT_EQ(pixelAt(image, 46, 30), colourOf(0x00ff00));
  EXPECT_EQ(pixelAt(image, 49, 33), colourOf(0x00ff00));
  EXPECT_EQ(countCovered(image, 0xff0000), 4 * 8);
  EXPECT_EQ(pixelAt(image, 3, 4), colourOf(0xff0000));
  EXPECT_EQ(pixelAt(image, 3, 11), colourOf(0xff0000));
  EXPECT_EQ(pixelAt(image, 4, 8), kBackground);
}

TEST(SplatRenderer, NearerPointWinsWhateverTheOrder) {
  const EyeCamera camera = smallCamera();
  for (bool near_first : {true, false}) {
    Points pts;
    // Both 4 px at (32, 24); the far one is wider so its rim shows.
    if (near_first) {
      pts.add(0, 0, 2, 0.25, 0x112233);
      pts.add(0, 0, 3, 0.75, 0x445566);
    } else {
      pts.add(0, 0, 3, 0.75, 0x445566);
      pts.add(0, 0, 2, 0.25, 0x112233);
    }
    Image image;
    renderSplats(pts.view(), camera, kBackground, image);
    EXPECT_EQ(countCovered(image, 0x112233), 16) << near_first;
    EXPECT_EQ(countCovered(image, 0x445566), 8 * 8 - 16) << near_first;
    EXPECT_EQ(image.depth[24 * 64 + 32], 2.0f);
    EXPECT_EQ(image.depth[20 * 64 + 28], 3.0f);
  }
}

TEST(SplatRenderer, EqualDepthGoesToTheLowerIndex) {
  const EyeCamera camera = smallCamera();
  for (uint32_t first : {0xaa0000u, 0x00bb00u}) {
    const uint32_t second = first == 0xaa0000u ? 0x00bb00u : 0xaa0000u;
    Points pts;
    pts.add(0.1, 0, 2, 0.25, first);
    pts.add(0.1, 0, 2, 0.25, second);
    Image image;
    renderSplats(pts.view(), camera, kBackground, image);
    EXPECT_EQ(countCovered(image, first), 16);
    EXPECT_EQ(countCovered(image, second), 0);
  }
}

TEST(SplatRenderer, InvalidAndBehindPointsAreSkippedAndCounted) {
  const EyeCamera camera = smallCamera();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  Points pts;
  pts.add(nan, 0, 2, 0.1, 0xffffff);
  pts.add(0, 0, inf, 0.1, 0xffffff);
  pts.add(0, 0, 2, 0.0, 0xffffff);
  pts.add(0, 0, 2, -0.1, 0xffffff);
  pts.add(0, 0, 2, nan, 0xffffff);
  pts.add(0, 0, 2, inf, 0xffffff);
  pts.add(0, 0, -1, 0.1, 0xffffff);
  pts.add(0, 0, 0, 0.1, 0xffffff);
  pts.add(0, 0, 0.01, 0.1, 0xffffff);  // on the near plane
  pts.add(100, 0, 1, 0.1, 0xffffff);   // in front, far to the right
  pts.add(0, -100, 1, 0.1, 0xffffff);  // in front, far above
  Image image;
  const RenderCounts counts = renderSplats(pts.view(), camera, kBackground, image);
  EXPECT_EQ(counts.skipped_invalid, 6u);
  EXPECT_EQ(counts.behind, 3u);
  EXPECT_EQ(counts.outside, 2u);
  EXPECT_EQ(counts.drawn, 0u);
  EXPECT_EQ(countCovered(image, 0xffffff), 0);
  EXPECT_TRUE(std::all_of(image.depth.begin(), image.depth.end(), [](float d) { return d == kInf; }));
}

TEST(SplatRenderer, SplatAtTheBorderIsClipped) {
  const EyeCamera camera = smallCamera();
  Points pts;
  // 4 px splats. At (0.7, 24): columns -1..2, rows 22..25. (Away from half-pixel
  // positions, where the choice of pixels would hang on the last bit of tan(45 deg).)
  pts.add((0.7 - 32) / 16, 0, 2, 0.25, 0x123456);
  // At (63.7, 47.7): columns 62..65, rows 46..49.
  pts.add((63.7 - 32) / 16, (47.7 - 24) / 16, 2, 0.25, 0x654321);
  Image image;
  const RenderCounts counts = renderSplats(pts.view(), camera, kBackground, image);
  EXPECT_EQ(counts.drawn, 2u);
  EXPECT_EQ(countCovered(image, 0x123456), 3 * 4);
  EXPECT_EQ(pixelAt(image, 0, 22), colourOf(0x123456));
  EXPECT_EQ(pixelAt(image, 2, 25), colourOf(0x123456));
  EXPECT_EQ(countCovered(image, 0x654321), 2 * 2);
  EXPECT_EQ(pixelAt(image, 62, 46), colourOf(0x654321));
  EXPECT_EQ(pixelAt(image, 63, 47), colourOf(0x654321));
}

TEST(SplatRenderer, HugeSplatNearTheEyeCoversTheImageWithoutHanging) {
  EyeCamera camera;  // 1440x1600
  Points pts;
  pts.add(0, 0, 0.02, 1.0, 0x00ffff);  // about 30000 px a side
  Image image;
  RenderCounts counts = renderSplats(pts.view(), camera, kBackground, image);
  EXPECT_EQ(counts.drawn, 1u);
  EXPECT_EQ(countCovered(image, 0x00ffff), 1440 * 1600);

  pts.add(0, 0, 0.011, 3e38, 0xff00ff);   // nearer, about 1e44 px a side
  pts.add(1e6, 0, 0.02, 1e30, 0xffff00);  // far off to the side, about 3e10 px off
  counts = renderSplats(pts.view(), camera, kBackground, image);
  EXPECT_EQ(counts.drawn, 2u);
  EXPECT_EQ(counts.outside, 1u);
  EXPECT_EQ(countCovered(image, 0xff00ff), 1440 * 1600);
}

// For every pixel, the nearest covering point (lowest index on ties), written
// independently of the renderer's span arithmetic: pixel centre c is covered by
// a splat of n pixels at u when -n/2 < c - u <= n/2 on both axes.
Image bruteForce(const Points& pts, const EyeCamera& camera, RenderCounts& counts) {
  Image image;
  image.width = camera.width;
  image.height = camera.height;
  const std::size_t pixels = static_cast<std::size_t>(camera.width) * camera.height;
  image.depth.assign(pixels, kInf);
  image.rgb.resize(pixels * 3);
  struct Splat {
    double u, v;
    int n;
    float depth;
    uint32_t rgb;
  };
  std::vector<Splat> splats;
  counts = {};
  for (std::size_t i = 0; i < pts.x.size(); ++i) {
    const Eigen::Vector3d world = pts.origin + Eigen::Vector3d(pts.x[i], pts.y[i], pts.z[i]);
    if (!world.allFinite() || !(pts.size[i] > 0) || !std::isfinite(pts.size[i])) {
      ++counts.skipped_invalid;
      continue;
    }
    const Eigen::Vector3d eye = camera.toEye(world);
    if (eye.z() <= kNearPlaneM) {
      ++counts.behind;
      continue;
    }
    const double u = camera.width / 2.0 + camera.focalPx() * eye.x() / eye.z();
    const double v = camera.height / 2.0 + camera.focalPx() * eye.y() / eye.z();
    const double side = camera.focalPx() * pts.size[i] / eye.z();
    const int n = std::max(1, static_cast<int>(std::lround(std::min(side, 64.0))));
    splats.push_back({u, v, n, static_cast<float>(eye.z()), pts.rgb[i]});
  }
  std::vector<bool> touches(splats.size(), false);
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      std::array<uint8_t, 3> colour = kBackground;
      float best = kInf;
      for (std::size_t s = 0; s < splats.size(); ++s) {
        const Splat& sp = splats[s];
        const double dx = x + 0.5 - sp.u, dy = y + 0.5 - sp.v;
        if (dx > -sp.n / 2.0 && dx <= sp.n / 2.0 && dy > -sp.n / 2.0 && dy <= sp.n / 2.0) {
          touches[s] = true;
          if (sp.depth < best) {
            best = sp.depth;
            colour = colourOf(sp.rgb);
          }
        }
      }
      const std::size_t p = static_cast<std::size_t>(y) * camera.width + x;
      image.depth[p] = best;
      std::copy(colour.begin(), colour.end(), image.rgb.begin() + static_cast<std::ptrdiff_t>(p * 3));
    }
  }
  counts.drawn = static_cast<std::size_t>(std::count(touches.begin(), touches.end(), true));
  counts.outside = splats.size() - counts.drawn;
  return image;
}

Points randomCloud(uint32_t seed, std::size_t count) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> lateral(-1.3, 1.3), depth(-1.0, 6.0), size(0.03, 0.3);
  std::uniform_int_distribution<uint32_t> colour(0, 0xffffff);
  Points pts;
  pts.origin = Eigen::Vector3d(1000.25, -20.5, 3.0);
  // Sizes proportional to depth: splats of 1 to 10 pixels, the near ones hiding many.
  for (std::size_t i = 0; i < count; ++i) {
    if (i % 50 == 49) {
      // An exact copy in another colour: a tie in depth.
      pts.add(pts.x[i - 7], pts.y[i - 7], pts.z[i - 7], pts.size[i - 7], colour(rng));
      continue;
    }
    const double z = depth(rng);
    pts.add(lateral(rng) * std::abs(z), lateral(rng) * std::abs(z), z, size(rng) * std::abs(z), colour(rng));
  }
  pts.add(std::nan(""), 0, 1, 0.1, 0);
  pts.add(0, 0, 1, 0, 0);
  return pts;
}

// A camera near the cloud's origin, turned 20 degrees about its down axis.
EyeCamera turnedCamera(const Points& pts) {
  EyeCamera camera = smallCamera();
  camera.position_m = pts.origin + Eigen::Vector3d(0.1, -0.05, 0.2);
  camera.world_from_eye =
      Eigen::AngleAxisd(20.0 * std::numbers::pi / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  return camera;
}

TEST(SplatRenderer, MatchesABruteForceReferenceOnARandomCloud) {
  const Points pts = randomCloud(7, 3000);
  const EyeCamera camera = turnedCamera(pts);
  Image image;
  const RenderCounts counts = renderSplats(pts.view(), camera, kBackground, image);
  RenderCounts expected_counts;
  const Image expected = bruteForce(pts, camera, expected_counts);
  EXPECT_EQ(counts.drawn, expected_counts.drawn);
  EXPECT_EQ(counts.skipped_invalid, 2u);
  EXPECT_EQ(counts.skipped_invalid, expected_counts.skipped_invalid);
  EXPECT_EQ(counts.behind, expected_counts.behind);
  EXPECT_EQ(counts.outside, expected_counts.outside);
  // The cloud is a real test: most points drawn, some behind, some outside, few pixels empty.
  EXPECT_GT(counts.drawn, 800u);
  EXPECT_GT(counts.behind, 100u);
  EXPECT_GT(counts.outside, 10u);
  EXPECT_LT(std::count(image.depth.begin(), image.depth.end(), kInf), 64 * 48 / 10);
  ASSERT_EQ(image.rgb.size(), expected.rgb.size());
  int rgb_mismatches = 0, depth_mismatches = 0;
  for (std::size_t p = 0; p < image.depth.size(); ++p) {
    depth_mismatches += image.depth[p] != expected.depth[p] ? 1 : 0;
    rgb_mismatches += !std::equal(image.rgb.begin() + p * 3, image.rgb.begin() + p * 3 + 3,
                                  expected.rgb.begin() + p * 3) ? 1 : 0;
  }
  EXPECT_EQ(rgb_mismatches, 0);
  EXPECT_EQ(depth_mismatches, 0);
}

TEST(SplatRenderer, RenderingTwiceGivesIdenticalBytes) {
  const Points pts = randomCloud(11, 4000);
  const EyeCamera camera = turnedCamera(pts);
  Image first, second;
  renderSplats(pts.view(), camera, kBackground, first);
  // A reused image of another size is overwritten completely.
  EyeCamera other = camera;
  other.width = 13;
  other.height = 7;
  renderSplats(pts.view(), other, {1, 2, 3}, second);
  renderSplats(pts.view(), camera, kBackground, second);
  EXPECT_EQ(first.width, second.width);
  EXPECT_EQ(first.height, second.height);
  EXPECT_EQ(first.rgb, second.rgb);
  EXPECT_EQ(first.depth, second.depth);
}

TEST(SplatRenderer, EmptyCloudGivesTheBackground) {
  const EyeCamera camera = smallCamera();
  Image image;
  const RenderCounts counts = renderSplats(SplatCloud{}, camera, kBackground, image);
  EXPECT_EQ(counts.drawn + counts.skipped_invalid + counts.behind + counts.outside, 0u);
  EXPECT_EQ(countCovered(image, 0x0a141e), 64 * 48);
}

}  // namespace
}  // namespace fovea::tools::eval
