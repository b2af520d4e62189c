// fovea-eval's image measures: PSNR and SSIM per eccentricity ring against
// analytic values and a brute-force SSIM, ring assignment, weights, errors, and
// the PNG writer (read back with libpng).
#include "tools/eval/quality/image_quality.h"
#include "tools/eval/quality/png_writer.h"

#include <gtest/gtest.h>

#include <png.h>
#include <unistd.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace fovea::tools::eval {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
const std::vector<double> kEdges{0, 5, 10, 20, 40, 60};

// f = 32 px at 64 px wide: the corners are 51.3 degrees off the axis.
EyeCamera cameraFor(int width, int height) {
  EyeCamera camera;
  camera.width = width;
  camera.height = height;
  camera.horizontal_fov_deg = 90.0;
  return camera;
}

Image blankImage(int width, int height) {
  Image image;
  image.width = width;
  image.height = height;
  image.rgb.assign(static_cast<std::size_t>(width) * height * 3, 0);
  image.depth.assign(static_cast<std::size_t>(width) * height, 1.0f);
  return image;
}

// Smooth structure plus noise, values in [lo, hi].
Image randomImage(int width, int height, uint32_t seed, int lo = 0, int hi = 255) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> noise(-40, 40);
  Image image = blankImage(width, height);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      for (int c = 0; c < 3; ++c) {
        const double smooth = 128 + 90 * std::sin(0.3 * x + 0.7 * c) * std::cos(0.2 * y - c);
        const int v = static_cast<int>(smooth) + noise(rng);
        image.rgb[(static_cast<std::size_t>(y) * width + x) * 3 + c] = static_cast<uint8_t>(std::clamp(v, lo, hi));
      }
    }
  }
  return image;
}

Image perturbed(const Image& image, uint32_t seed, int amplitude) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> noise(-amplitude, amplitude);
  Image out = image;
  for (uint8_t& v : out.rgb) {
    v = static_cast<uint8_t>(std::clamp(v + noise(rng), 0, 255));
  }
  return out;
}

double psnrOf(double mse) { return 10.0 * std::log10(255.0 * 255.0 / mse); }

TEST(ImageQuality, IdenticalImagesAreInfinitePsnrAndUnitSsimInEveryRing) {
  const Image image = randomImage(64, 48, 1);
  auto q = foveatedQuality(image, image, cameraFor(64, 48), Eigen::Vector3d::UnitZ(), kEdges, 0.022);
  ASSERT_TRUE(q.isOk()) << q.status().toString();
  ASSERT_EQ(q->rings.size(), kEdges.size() - 1);
  for (const Ring& r : q->rings) {
    EXPECT_GT(r.pixels, 0u) << r.inner_deg;
    EXPECT_EQ(r.mse, 0.0);
    EXPECT_EQ(r.psnr_db, kInf);
    EXPECT_NEAR(r.ssim, 1.0, 1e-12) << r.inner_deg;
  }
  EXPECT_EQ(q->psnr_db, kInf);
  EXPECT_EQ(q->weighted_psnr_db, kInf);
  EXPECT_NEAR(q->ssim, 1.0, 1e-12);
  EXPECT_NEAR(q->weighted_ssim, 1.0, 1e-12);
}

TEST(ImageQuality, UniformOffsetGivesTheAnalyticPsnr) {
  const Image ref = randomImage(64, 48, 2, 0, 240);
  Image test = ref;
  for (uint8_t& v : test.rgb) {
    v = static_cast<uint8_t>(v + 10);
  }
  auto q = foveatedQuality(ref, test, cameraFor(64, 48), Eigen::Vector3d::UnitZ(), kEdges, 0.022);
  ASSERT_TRUE(q.isOk()) << q.status().toString();
  const double expected = psnrOf(100.0);  // 28.13 dB
  EXPECT_NEAR(q->psnr_db, expected, 1e-12);
  EXPECT_NEAR(q->weighted_psnr_db, expected, 1e-12);
  for (const Ring& r : q->rings) {
    EXPECT_NEAR(r.mse, 100.0, 1e-12);
    EXPECT_NEAR(r.psnr_db, expected, 1e-12);
  }

  // One channel off by 30: the MSE over the three channels is 900 / 3.
  Image green = ref;
  for (std::size_t p = 1; p < green.rgb.size(); p += 3) {
    green.rgb[p] = static_cast<uint8_t>(green.rgb[p] + 15);
  }
  q = foveatedQuality(ref, green, cameraFor(64, 48), Eigen::Vector3d::UnitZ(), kEdges, 0.022);
  ASSERT_TRUE(q.isOk());
  EXPECT_NEAR(q->psnr_db, psnrOf(225.0 / 3.0), 1e-12);
}

TEST(ImageQuality, SsimOfConstantImagesMatchesTheFormula) {
  for (int b : {100, 120, 0, 255}) {
    Image ref = blankImage(32, 24), test = blankImage(32, 24);
    std::fill(ref.rgb.begin(), ref.rgb.end(), uint8_t{100});
    std::fill(test.rgb.begin(), test.rgb.end(), static_cast<uint8_t>(b));
    auto q = foveatedQuality(ref, test, cameraFor(32, 24), Eigen::Vector3d::UnitZ(), {0, 90}, 0.022);
    ASSERT_TRUE(q.isOk());
    // No variance: SSIM is the luminance term alone.
    const double ya = 0.299 * 100 + 0.587 * 100 + 0.114 * 100, yb = 0.299 * b + 0.587 * b + 0.114 * b;
    const double c1 = (0.01 * 255) * (0.01 * 255);
    const double expected = (2 * ya * yb + c1) / (ya * ya + yb * yb + c1);
    EXPECT_NEAR(q->ssim, expected, 1e-9) << b;
    EXPECT_NEAR(q->rings[0].ssim, expected, 1e-9) << b;
    if (b == 100) {
      EXPECT_NEAR(q->ssim, 1.0, 1e-12);
    }
  }
}

// SSIM at every pixel whose 11x11 window fits, by direct 2D window sums; NaN elsewhere.
std::vector<double> bruteForceSsimMap(const Image& a, const Image& b) {
  const int w = a.width, h = a.height;
  auto luma = [](const Image& im, int x, int y) {
    const std::size_t p = (static_cast<std::size_t>(y) * im.width + x) * 3;
    return 0.299 * im.rgb[p] + 0.587 * im.rgb[p + 1] + 0.114 * im.rgb[p + 2];
  };
  double window[11][11];
  double total = 0;
  for (int j = 0; j < 11; ++j) {
    for (int i = 0; i < 11; ++i) {
      window[j][i] = std::exp(-((i - 5) * (i - 5) + (j - 5) * (j - 5)) / (2 * 1.5 * 1.5));
      total += window[j][i];
    }
  }
  const double c1 = (0.01 * 255) * (0.01 * 255), c2 = (0.03 * 255) * (0.03 * 255);
  std::vector<double> map(static_cast<std::size_t>(w) * h, std::numeric_limits<double>::quiet_NaN());
  for (int y = 5; y + 5 < h; ++y) {
    for (int x = 5; x + 5 < w; ++x) {
      double ma = 0, mb = 0;
      for (int j = 0; j < 11; ++j) {
        for (int i = 0; i < 11; ++i) {
          ma += window[j][i] / total * luma(a, x - 5 + i, y - 5 + j);
          mb += window[j][i] / total * luma(b, x - 5 + i, y - 5 + j);
        }
      }
      double va = 0, vb = 0, cov = 0;
      for (int j = 0; j < 11; ++j) {
        for (int i = 0; i < 11; ++i) {
          const double da = luma(a, x - 5 + i, y - 5 + j) - ma, db = luma(b, x - 5 + i, y - 5 + j) - mb;
          va += window[j][i] / total * da * da;
          vb += window[j][i] / total * db * db;
          cov += window[j][i] / total * da * db;
        }
      }
      map[static_cast<std::size_t>(y) * w + x] =
          ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
    }
  }
  return map;
}

TEST(ImageQuality, RingSsimMatchesABruteForceSsim) {
  const int w = 40, h = 30;
  const Image ref = randomImage(w, h, 3);
  const Image test = perturbed(ref, 4, 35);
  const EyeCamera camera = cameraFor(w, h);
  const Eigen::Vector3d gaze(0.2, -0.1, 1.0);
  const std::vector<double> edges{0, 4, 8, 15, 25, 40, 60};
  auto q = foveatedQuality(ref, test, camera, gaze, edges, 0.03);
  ASSERT_TRUE(q.isOk()) << q.status().toString();
  auto rings = ringOfEachPixel(camera, gaze, edges);
  ASSERT_TRUE(rings.isOk());
  const std::vector<double> map = bruteForceSsimMap(ref, test);
  std::vector<double> sum(edges.size() - 1, 0.0);
  std::vector<int> count(edges.size() - 1, 0);
  double whole = 0;
  int whole_count = 0;
  for (std::size_t p = 0; p < map.size(); ++p) {
    if (std::isnan(map[p])) {
      continue;
    }
    whole += map[p];
    ++whole_count;
    if (rings.value()[p] >= 0) {
      sum[static_cast<std::size_t>(rings.value()[p])] += map[p];
      ++count[static_cast<std::size_t>(rings.value()[p])];
    }
  }
  ASSERT_EQ(whole_count, (w - 10) * (h - 10));
  EXPECT_NEAR(q->ssim, whole / whole_count, 1e-9);
  // Not degenerate: clearly below 1 and above 0.
  EXPECT_GT(q->ssim, 0.2);
  EXPECT_LT(q->ssim, 0.95);
  int rings_with_ssim = 0;
  for (std::size_t k = 0; k < sum.size(); ++k) {
    if (count[k] == 0) {
      EXPECT_TRUE(std::isnan(q->rings[k].ssim)) << k;
      continue;
    }
    ++rings_with_ssim;
    EXPECT_NEAR(q->rings[k].ssim, sum[k] / count[k], 1e-9) << k;
  }
  EXPECT_GE(rings_with_ssim, 5);
}

TEST(ImageQuality, RingOfAPixelMatchesAnIndependentAngle) {
  EyeCamera camera = cameraFor(80, 60);
  camera.horizontal_fov_deg = 100.0;
  camera.position_m = Eigen::Vector3d(3, -1, 2);
  camera.world_from_eye = (Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()) *
                           Eigen::AngleAxisd(-0.3, Eigen::Vector3d::UnitX())).toRotationMatrix();
  // The gaze 10 degrees right of and 5 degrees above the forward axis, not unit length.
  const Eigen::Vector3d gaze_eye(std::tan(10 * std::numbers::pi / 180), -std::tan(5 * std::numbers::pi / 180), 1.0);
  const Eigen::Vector3d gaze = camera.world_from_eye * gaze_eye * 3.0;
  const std::vector<double> edges{2, 5, 10, 20, 30, 45};
  auto rings = ringOfEachPixel(camera, gaze, edges);
  ASSERT_TRUE(rings.isOk()) << rings.status().toString();
  const double f = 40.0 / std::tan(50 * std::numbers::pi / 180);
  int compared = 0;
  std::vector<int> seen(edges.size() + 1, 0);
  for (int y = 0; y < 60; ++y) {
    for (int x = 0; x < 80; ++x) {
      // Angle in the eye's frame: rotation keeps angles.
      const Eigen::Vector3d ray((x + 0.5 - 40) / f, (y + 0.5 - 30) / f, 1.0);
      const double cosine = ray.dot(gaze_eye) / (ray.norm() * gaze_eye.norm());
      const double deg = std::acos(std::clamp(cosine, -1.0, 1.0)) * 180 / std::numbers::pi;
      int expected = -1;
      bool near_edge = false;
      for (std::size_t k = 0; k < edges.size(); ++k) {
        near_edge = near_edge || std::abs(deg - edges[k]) < 1e-6;
        if (k + 1 < edges.size() && deg >= edges[k] && deg < edges[k + 1]) {
          expected = static_cast<int>(k);
        }
      }
      if (near_edge) {
        continue;
      }
      ++compared;
      const int got = rings.value()[static_cast<std::size_t>(y) * 80 + x];
      EXPECT_EQ(got, expected) << x << "," << y << " at " << deg << " deg";
      ++seen[static_cast<std::size_t>(got + 1)];
    }
  }
  EXPECT_GT(compared, 80 * 60 - 10);
  // Every ring, the inside of the first edge and the outside of the last occur.
  for (std::size_t k = 0; k < seen.size() - 1; ++k) {
    EXPECT_GT(seen[k], 0) << k;
  }
}

TEST(ImageQuality, WeightsSumToOneAndFavourTheInnerRings) {
  const Image ref = randomImage(64, 48, 5);
  const Image test = perturbed(ref, 6, 20);
  const double slope = 0.022;
  auto q = foveatedQuality(ref, test, cameraFor(64, 48), Eigen::Vector3d::UnitZ(), kEdges, slope);
  ASSERT_TRUE(q.isOk());
  double sum = 0, raw_sum = 0;
  std::size_t pixels = 0;
  for (const Ring& r : q->rings) {
    sum += r.weight;
    raw_sum += r.pixels / (slope * 0.5 * (r.inner_deg + r.outer_deg) + 1.0 / 60);
    pixels += r.pixels;
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  EXPECT_EQ(pixels, 64u * 48);  // every pixel is within 60 degrees
  for (std::size_t k = 0; k < q->rings.size(); ++k) {
    const Ring& r = q->rings[k];
    const double mar = slope * 0.5 * (r.inner_deg + r.outer_deg) + 1.0 / 60;
    EXPECT_NEAR(r.weight, r.pixels / mar / raw_sum, 1e-12) << k;
    if (k > 0) {
      EXPECT_LT(r.weight / r.pixels, q->rings[k - 1].weight / q->rings[k - 1].pixels) << k;
    }
  }
  // The weighted PSNR is that of the weighted MSE; the weighted SSIM the weighted mean.
  double mse = 0, ssim = 0;
  for (const Ring& r : q->rings) {
    mse += r.weight * r.mse;
    ssim += r.weight * r.ssim;
  }
  EXPECT_NEAR(q->weighted_psnr_db, psnrOf(mse), 1e-9);
  EXPECT_NEAR(q->weighted_ssim, ssim, 1e-12);
}

TEST(ImageQuality, RingsWithoutPixelsGetNoWeight) {
  const Image ref = randomImage(64, 48, 7);
  const Image test = perturbed(ref, 8, 20);
  auto q = foveatedQuality(ref, test, cameraFor(64, 48), Eigen::Vector3d::UnitZ(), {0, 10, 70, 80}, 0.022);
  ASSERT_TRUE(q.isOk());
  ASSERT_EQ(q->rings.size(), 3u);
  const Ring& empty = q->rings[2];
  EXPECT_EQ(empty.pixels, 0u);
  EXPECT_EQ(empty.weight, 0.0);
  EXPECT_TRUE(std::isnan(empty.psnr_db));
  EXPECT_TRUE(std::isnan(empty.ssim));
  EXPECT_NEAR(q->rings[0].weight + q->rings[1].weight, 1.0, 1e-12);
  EXPECT_TRUE(std::isfinite(q->weighted_psnr_db));
  EXPECT_TRUE(std::isfinite(q->weighted_ssim));
}

TEST(ImageQuality, BadInputsAreErrors) {
  const Image ref = randomImage(64, 48, 9);
  const EyeCamera camera = cameraFor(64, 48);
  const Eigen::Vector3d gaze = Eigen::Vector3d::UnitZ();
  auto expectError = [](const Result<FoveatedQuality>& q, ErrorCode code, const char* what) {
    ASSERT_FALSE(q.isOk()) << what;
    EXPECT_EQ(q.status().code(), code) << what;
    EXPECT_FALSE(q.status().message().empty()) << what;
  };
  const Image smaller = randomImage(32, 48, 9);
  expectError(foveatedQuality(ref, smaller, camera, gaze, kEdges, 0.022), ErrorCode::kInvalidInput, "sizes");
  expectError(foveatedQuality(Image{}, Image{}, cameraFor(0, 0), gaze, kEdges, 0.022), ErrorCode::kInvalidInput,
              "empty");
  Image short_buffer = ref;
  short_buffer.rgb.pop_back();
  expectError(foveatedQuality(ref, short_buffer, camera, gaze, kEdges, 0.022), ErrorCode::kInvalidInput, "buffer");
  expectError(foveatedQuality(ref, ref, cameraFor(48, 64), gaze, kEdges, 0.022), ErrorCode::kInvalidInput, "camera");
  expectError(foveatedQuality(ref, ref, camera, gaze, {0, 5, 5, 10}, 0.022), ErrorCode::kInvalidArgument, "equal");
  expectError(foveatedQuality(ref, ref, camera, gaze, {10, 5}, 0.022), ErrorCode::kInvalidArgument, "decreasing");
  expectError(foveatedQuality(ref, ref, camera, gaze, {5}, 0.022), ErrorCode::kInvalidArgument, "one edge");
  expectError(foveatedQuality(ref, ref, camera, gaze, {-1, 5}, 0.022), ErrorCode::kInvalidArgument, "negative");
  expectError(foveatedQuality(ref, ref, camera, gaze, {0, std::nan("")}, 0.022), ErrorCode::kInvalidArgument, "nan");
  expectError(foveatedQuality(ref, ref, camera, Eigen::Vector3d::Zero(), kEdges, 0.022), ErrorCode::kInvalidInput,
              "zero gaze");
  expectError(foveatedQuality(ref, ref, camera, gaze, kEdges, -0.1), ErrorCode::kInvalidArgument, "slope");
  expectError(foveatedQuality(ref, ref, camera, gaze, kEdges, std::nan("")), ErrorCode::kInvalidArgument, "nan slope");
}

// A PNG read back through libpng's simplified API as 8-bit RGB.
struct ReadPng {
  bool ok = false;
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;
};
ReadPng readPng(const std::string& path) {
  ReadPng out;
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  if (png_image_begin_read_from_file(&image, path.c_str()) == 0) {
    return out;
  }
  image.format = PNG_FORMAT_RGB;
  out.rgb.resize(PNG_IMAGE_SIZE(image));
  if (png_image_finish_read(&image, nullptr, out.rgb.data(), 0, nullptr) == 0) {
    return out;
  }
  out.ok = true;
  out.width = static_cast<int>(image.width);
  out.height = static_cast<int>(image.height);
  return out;
}

std::string tempPath(const char* name) {
  return testing::TempDir() + "fovea_quality_" + std::to_string(getpid()) + "_" + name;
}

TEST(PngWriter, WritesAnImageLibpngReadsBack) {
  const Image image = randomImage(7, 5, 10);
  const std::string path = tempPath("small.png");
  const Status s = writePng(path, 7, 5, image.rgb.data());
  ASSERT_TRUE(s.isOk()) << s.toString();
  const ReadPng back = readPng(path);
  std::remove(path.c_str());
  ASSERT_TRUE(back.ok);
  EXPECT_EQ(back.width, 7);
  EXPECT_EQ(back.height, 5);
  EXPECT_EQ(back.rgb, image.rgb);
}

TEST(PngWriter, UnwritablePathIsAnError) {
  const Image image = randomImage(7, 5, 10);
  const Status s = writePng("/nonexistent-fovea-dir/x.png", 7, 5, image.rgb.data());
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.code(), ErrorCode::kIoError);
  EXPECT_NE(s.message().find("/nonexistent-fovea-dir/x.png"), std::string::npos) << s.message();
  EXPECT_FALSE(writePng(tempPath("none.png"), 0, 5, image.rgb.data()).isOk());
}

TEST(PngWriter, SideBySideHasThePanelsTheDifferenceTheRingsAndTheGaze) {
  const int w = 64, h = 48, scale = 4;
  const Image ref = randomImage(w, h, 11);
  const Image test = perturbed(ref, 12, 30);
  const EyeCamera camera = cameraFor(w, h);
  const std::string path = tempPath("side.png");
  const Status s = writeSideBySidePng(path, ref, test, camera, Eigen::Vector3d::UnitZ(), kEdges, scale);
  ASSERT_TRUE(s.isOk()) << s.toString();
  const ReadPng back = readPng(path);
  std::remove(path.c_str());
  ASSERT_TRUE(back.ok);
  const int pw = w / scale, ph = h / scale, gap = (back.width - 3 * pw) / 2;
  ASSERT_EQ(back.height, ph);
  ASSERT_GT(gap, 0);
  ASSERT_EQ(back.width, 3 * pw + 2 * gap);
  auto at = [&](int x, int y, int c) { return back.rgb[(static_cast<std::size_t>(y) * back.width + x) * 3 + c]; };
  // A panel pixel is its block's rounded mean.
  for (int c = 0; c < 3; ++c) {
    int sum_ref = 0, sum_test = 0;
    for (int y = 4; y < 8; ++y) {
      for (int x = 8; x < 12; ++x) {
        sum_ref += ref.rgb[(static_cast<std::size_t>(y) * w + x) * 3 + c];
        sum_test += test.rgb[(static_cast<std::size_t>(y) * w + x) * 3 + c];
      }
    }
    EXPECT_EQ(at(2, 1, c), (sum_ref + 8) / 16) << c;
    EXPECT_EQ(at(pw + gap + 2, 1, c), (sum_test + 8) / 16) << c;
  }
  // The gaze cross (magenta) at panel pixel (8, 6), and ring lines (cyan) in the difference panel only.
  const int diff_x = 2 * (pw + gap);
  EXPECT_EQ(at(diff_x + 8, 6, 0), 255);
  EXPECT_EQ(at(diff_x + 8, 6, 1), 0);
  EXPECT_EQ(at(diff_x + 8, 6, 2), 255);
  int cyan = 0;
  for (int y = 0; y < ph; ++y) {
    for (int x = 0; x < back.width; ++x) {
      if (at(x, y, 0) == 0 && at(x, y, 1) == 255 && at(x, y, 2) == 255) {
        ++cyan;
        EXPECT_GE(x, diff_x);
      }
    }
  }
  EXPECT_GT(cyan, 10);

  EXPECT_FALSE(writeSideBySidePng(path, ref, test, camera, Eigen::Vector3d::UnitZ(), kEdges, 0).isOk());
  EXPECT_FALSE(writeSideBySidePng(path, ref, randomImage(32, 48, 1), camera, Eigen::Vector3d::UnitZ(), kEdges, 2)
                   .isOk());
  EXPECT_FALSE(writeSideBySidePng(path, ref, test, camera, Eigen::Vector3d::Zero(), kEdges, 2).isOk());
}

}  // namespace
}  // namespace fovea::tools::eval
