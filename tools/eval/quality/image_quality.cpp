#include "tools/eval/quality/image_quality.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <string>

#include <Eigen/Geometry>

#include "tools/common/nan.h"

namespace fovea::tools::eval {

namespace {

constexpr int kSsimRadius = 5;  // the 11x11 window
constexpr int kSsimSide = 2 * kSsimRadius + 1;

std::string sizeText(int width, int height) { return std::to_string(width) + "x" + std::to_string(height); }

double psnrDb(double mse) {
  return mse == 0.0 ? std::numeric_limits<double>::infinity() : 10.0 * std::log10(255.0 * 255.0 / mse);
}

std::vector<double> luma(const Image& image) {
  std::vector<double> y(image.rgb.size() / 3);
  for (std::size_t p = 0; p < y.size(); ++p) {
    y[p] = 0.299 * image.rgb[p * 3] + 0.587 * image.rgb[p * 3 + 1] + 0.114 * image.rgb[p * 3 + 2];
  }
  return y;
}

// The Gaussian window is separable: the 2D weights g(i) g(j) are the products
// of the normalised 1D ones.
std::array<double, kSsimSide> gaussianWindow() {
  std::array<double, kSsimSide> g{};
  double sum = 0;
  for (int i = 0; i < kSsimSide; ++i) {
    const double d = i - kSsimRadius;
    g[i] = std::exp(-d * d / (2.0 * 1.5 * 1.5));
    sum += g[i];
  }
  for (double& v : g) {
    v /= sum;
  }
  return g;
}

// Calls visit(x, y, ssim) at every pixel whose window fits, row by row. The
// window's moments are filtered horizontally into a ring of kSsimSide rows, then
// vertically: memory of a few rows rather than five full-size maps.
template <typename Visit>
void forEachSsim(const std::vector<double>& a, const std::vector<double>& b, int width, int height, Visit visit) {
  if (width < kSsimSide || height < kSsimSide) {
    return;
  }
  constexpr double kC1 = (0.01 * 255) * (0.01 * 255);
  constexpr double kC2 = (0.03 * 255) * (0.03 * 255);
  constexpr int kMoments = 5;  // E[a], E[b], E[a^2], E[b^2], E[ab]
  const std::array<double, kSsimSide> g = gaussianWindow();
  const std::size_t cols = static_cast<std::size_t>(width - 2 * kSsimRadius);
  std::vector<double> rows(kMoments * kSsimSide * cols);
  const auto moments = [&](int row) {
    return rows.data() + static_cast<std::size_t>(row % kSsimSide) * kMoments * cols;
  };

  for (int r = 0; r < height; ++r) {
    const double* ar = a.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(width);
    const double* br = b.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(width);
    double* m = moments(r);
    for (std::size_t c = 0; c < cols; ++c) {
      double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
      for (int k = 0; k < kSsimSide; ++k) {
        const double x = ar[c + k], y = br[c + k], wk = g[k];
        sa += wk * x;
        sb += wk * y;
        saa += wk * x * x;
        sbb += wk * y * y;
        sab += wk * x * y;
      }
      m[c] = sa;
      m[cols + c] = sb;
      m[2 * cols + c] = saa;
      m[3 * cols + c] = sbb;
      m[4 * cols + c] = sab;
    }
    if (r < kSsimSide - 1) {
      continue;
    }
    const int y = r - kSsimRadius;  // the row whose window now lies in the ring
    std::array<const double*, kSsimSide> in{};
    for (int k = 0; k < kSsimSide; ++k) {
      in[k] = moments(y - kSsimRadius + k);
    }
    for (std::size_t c = 0; c < cols; ++c) {
      std::array<double, kMoments> s{};
      for (int k = 0; k < kSsimSide; ++k) {
        for (int q = 0; q < kMoments; ++q) {
          s[q] += g[k] * in[k][q * cols + c];
        }
      }
      const double mu_a = s[0], mu_b = s[1];
      const double var_a = s[2] - mu_a * mu_a, var_b = s[3] - mu_b * mu_b, cov = s[4] - mu_a * mu_b;
      const double ssim = ((2 * mu_a * mu_b + kC1) * (2 * cov + kC2)) /
                          ((mu_a * mu_a + mu_b * mu_b + kC1) * (var_a + var_b + kC2));
      visit(static_cast<int>(c) + kSsimRadius, y, ssim);
    }
  }
}

struct Sums {
  std::size_t pixels = 0;
  uint64_t squared_error = 0;  // over the 3 channels
  double ssim = 0;
  std::size_t ssim_pixels = 0;

  double mse() const { return pixels == 0 ? kNaN : static_cast<double>(squared_error) / (3.0 * pixels); }
  double meanSsim() const { return ssim_pixels == 0 ? kNaN : ssim / static_cast<double>(ssim_pixels); }
};

}  // namespace

Status checkImagePair(const Image& reference, const Image& test, const EyeCamera& camera) {
  for (const Image* image : {&reference, &test}) {
    const char* name = image == &reference ? "reference" : "test";
    if (image->width <= 0 || image->height <= 0) {
      return {ErrorCode::kInvalidInput, std::string(name) + " image is empty (" +
                                            sizeText(image->width, image->height) + ")"};
    }
    const std::size_t pixels = static_cast<std::size_t>(image->width) * static_cast<std::size_t>(image->height);
    if (image->rgb.size() != pixels * 3) {
      return {ErrorCode::kInvalidInput, std::string(name) + " image: " + std::to_string(image->rgb.size()) +
                                            " RGB bytes for " + sizeText(image->width, image->height)};
    }
  }
  if (reference.width != test.width || reference.height != test.height) {
    return {ErrorCode::kInvalidInput, "images of different sizes: reference " +
                                          sizeText(reference.width, reference.height) + ", test " +
                                          sizeText(test.width, test.height)};
  }
  if (camera.width != reference.width || camera.height != reference.height) {
    return {ErrorCode::kInvalidInput, "camera image " + sizeText(camera.width, camera.height) +
                                          " differs from the images' " + sizeText(reference.width, reference.height)};
  }
  return Status::ok();
}

Result<std::vector<int>> ringOfEachPixel(const EyeCamera& camera, const Eigen::Vector3d& gaze_direction_world,
                                         const std::vector<double>& ring_edges_deg) {
  if (ring_edges_deg.size() < 2) {
    return Status(ErrorCode::kInvalidArgument, "ring edges: need at least 2 (got " +
                                                   std::to_string(ring_edges_deg.size()) + ")");
  }
  for (std::size_t k = 0; k < ring_edges_deg.size(); ++k) {
    const double e = ring_edges_deg[k];
    if (!std::isfinite(e) || e < 0 || (k > 0 && !(e > ring_edges_deg[k - 1]))) {
      return Status(ErrorCode::kInvalidArgument, "ring edges: must be finite, >= 0 and strictly increasing (edge " +
                                                     std::to_string(k) + " is " + std::to_string(e) + ")");
    }
  }
  if (!gaze_direction_world.allFinite() || gaze_direction_world.norm() == 0.0) {
    return Status(ErrorCode::kInvalidInput, "gaze direction is zero or not finite");
  }
  const Eigen::Vector3d gaze = gaze_direction_world.normalized();
  const int rings = static_cast<int>(ring_edges_deg.size()) - 1;
  std::vector<int> ring(static_cast<std::size_t>(std::max(camera.width, 0)) *
                        static_cast<std::size_t>(std::max(camera.height, 0)));
  std::size_t p = 0;
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x, ++p) {
      const Eigen::Vector3d ray = camera.rayThroughPixel(x, y);
      // atan2 of the cross and dot products: accurate near the gaze, unlike acos.
      const double deg = std::atan2(ray.cross(gaze).norm(), ray.dot(gaze)) * 180.0 / std::numbers::pi;
      const int k = static_cast<int>(std::upper_bound(ring_edges_deg.begin(), ring_edges_deg.end(), deg) -
                                     ring_edges_deg.begin()) - 1;
      ring[p] = k >= 0 && k < rings ? k : -1;
    }
  }
  return ring;
}

Result<FoveatedQuality> foveatedQuality(const Image& reference, const Image& test, const EyeCamera& camera,
                                        const Eigen::Vector3d& gaze_direction_world,
                                        const std::vector<double>& ring_edges_deg, double slope) {
  if (Status s = checkImagePair(reference, test, camera); !s) {
    return s;
  }
  if (!std::isfinite(slope) || slope < 0) {
    return Status(ErrorCode::kInvalidArgument, "MAR slope must be finite and >= 0 (got " + std::to_string(slope) + ")");
  }
  Result<std::vector<int>> ring_map = ringOfEachPixel(camera, gaze_direction_world, ring_edges_deg);
  if (!ring_map) {
    return ring_map.status();
  }
  const std::vector<int>& ring_of = ring_map.value();
  const std::size_t ring_count = ring_edges_deg.size() - 1;
  std::vector<Sums> rings(ring_count);
  Sums whole;

  for (std::size_t p = 0; p < ring_of.size(); ++p) {
    uint64_t e = 0;
    for (std::size_t c = 0; c < 3; ++c) {
      const int d = int{reference.rgb[p * 3 + c]} - int{test.rgb[p * 3 + c]};
      e += static_cast<uint64_t>(d * d);
    }
    whole.squared_error += e;
    if (ring_of[p] >= 0) {
      Sums& r = rings[static_cast<std::size_t>(ring_of[p])];
      ++r.pixels;
      r.squared_error += e;
    }
  }
  whole.pixels = ring_of.size();
  const std::size_t width = static_cast<std::size_t>(reference.width);
  forEachSsim(luma(reference), luma(test), reference.width, reference.height, [&](int x, int y, double ssim) {
    whole.ssim += ssim;
    ++whole.ssim_pixels;
    const int k = ring_of[static_cast<std::size_t>(y) * width + static_cast<std::size_t>(x)];
    if (k >= 0) {
      rings[static_cast<std::size_t>(k)].ssim += ssim;
      ++rings[static_cast<std::size_t>(k)].ssim_pixels;
    }
  });

  FoveatedQuality q;
  q.psnr_db = psnrDb(whole.mse());
  q.ssim = whole.meanSsim();
  double weight_sum = 0;
  for (std::size_t k = 0; k < ring_count; ++k) {
    Ring r;
    r.inner_deg = ring_edges_deg[k];
    r.outer_deg = ring_edges_deg[k + 1];
    r.pixels = rings[k].pixels;
    r.mse = rings[k].mse();
    r.psnr_db = r.pixels == 0 ? kNaN : psnrDb(r.mse);
    r.ssim = rings[k].meanSsim();
    if (r.pixels > 0) {
      const double mar_deg = slope * 0.5 * (r.inner_deg + r.outer_deg) + 1.0 / 60.0;
      r.weight = static_cast<double>(r.pixels) / mar_deg;
      weight_sum += r.weight;
    }
    q.rings.push_back(r);
  }
  double weighted_mse = 0, weighted_ssim = 0, ssim_weight = 0;
  for (Ring& r : q.rings) {
    if (r.pixels == 0) {
      continue;
    }
    r.weight /= weight_sum;
    weighted_mse += r.weight * r.mse;
    if (!std::isnan(r.ssim)) {
      weighted_ssim += r.weight * r.ssim;
      ssim_weight += r.weight;
    }
  }
  q.weighted_psnr_db = weight_sum > 0 ? psnrDb(weighted_mse) : kNaN;
  q.weighted_ssim = ssim_weight > 0 ? weighted_ssim / ssim_weight : kNaN;
  return q;
}

}  // namespace fovea::tools::eval
