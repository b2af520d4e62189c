#include "tools/eval/quality/png_writer.h"

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include <png.h>

#include "tools/eval/quality/image_quality.h"

namespace fovea::tools::eval {

Status writePng(const std::string& path, int width, int height, const uint8_t* rgb) {
  if (width <= 0 || height <= 0 || width > INT_MAX / 3 || rgb == nullptr) {
    return {ErrorCode::kInvalidArgument, "PNG '" + path + "': no pixels to write (" + std::to_string(width) + "x" +
                                             std::to_string(height) + ")"};
  }
  // libpng's simplified API: it keeps its setjmp/longjmp error handling inside,
  // and removes a partly written file.
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(width);
  image.height = static_cast<png_uint_32>(height);
  image.format = PNG_FORMAT_RGB;
  if (png_image_write_to_file(&image, path.c_str(), 0, rgb, width * 3, nullptr) == 0) {
    return {ErrorCode::kIoError, "PNG '" + path + "': " + image.message};
  }
  return Status::ok();
}

namespace {

constexpr int kGapPx = 2;  // between the panels
constexpr std::array<uint8_t, 3> kGapColour{128, 128, 128};
constexpr std::array<uint8_t, 3> kRingColour{0, 255, 255};
constexpr std::array<uint8_t, 3> kGazeColour{255, 0, 255};
constexpr int kDifferenceGain = 4;

// A panel scale times smaller than the image, each pixel the rounded mean of
// its scale x scale block (rows and columns past a whole block are dropped).
std::vector<uint8_t> boxFilter(const std::vector<uint8_t>& rgb, int width, int scale, int panel_w, int panel_h) {
  std::vector<uint8_t> out(static_cast<std::size_t>(panel_w) * static_cast<std::size_t>(panel_h) * 3);
  const int n = scale * scale;
  for (int py = 0; py < panel_h; ++py) {
    for (int px = 0; px < panel_w; ++px) {
      std::array<int, 3> sum{};
      for (int y = py * scale; y < (py + 1) * scale; ++y) {
        for (int x = px * scale; x < (px + 1) * scale; ++x) {
          const std::size_t p = (static_cast<std::size_t>(y) * static_cast<std::size_t>(width) +
                                 static_cast<std::size_t>(x)) * 3;
          for (std::size_t c = 0; c < 3; ++c) {
            sum[c] += rgb[p + c];
          }
        }
      }
      const std::size_t q = (static_cast<std::size_t>(py) * static_cast<std::size_t>(panel_w) +
                             static_cast<std::size_t>(px)) * 3;
      for (std::size_t c = 0; c < 3; ++c) {
        out[q + c] = static_cast<uint8_t>((sum[c] + n / 2) / n);
      }
    }
  }
  return out;
}

}  // namespace

Status writeSideBySidePng(const std::string& path, const Image& reference, const Image& test, const EyeCamera& camera,
                          const Eigen::Vector3d& gaze_direction_world, const std::vector<double>& ring_edges_deg,
                          int scale) {
  if (Status s = checkImagePair(reference, test, camera); !s) {
    return s;
  }
  const int w = reference.width, h = reference.height;
  if (scale < 1 || scale > std::min(w, h)) {
    return {ErrorCode::kInvalidArgument, "side-by-side PNG: scale " + std::to_string(scale) + " is not in [1, " +
                                             std::to_string(std::min(w, h)) + "]"};
  }
  Result<std::vector<int>> ring_map = ringOfEachPixel(camera, gaze_direction_world, ring_edges_deg);
  if (!ring_map) {
    return ring_map.status();
  }
  const std::vector<int>& ring_of = ring_map.value();

  std::vector<uint8_t> difference(reference.rgb.size());
  for (std::size_t i = 0; i < difference.size(); ++i) {
    difference[i] = static_cast<uint8_t>(std::min(255, kDifferenceGain * std::abs(reference.rgb[i] - test.rgb[i])));
  }
  const int pw = w / scale, ph = h / scale;
  std::vector<uint8_t> panels[3] = {boxFilter(reference.rgb, w, scale, pw, ph), boxFilter(test.rgb, w, scale, pw, ph),
                                    boxFilter(difference, w, scale, pw, ph)};

  // The ring of a panel pixel is that of its block's middle pixel.
  const auto ring_at = [&](int px, int py) {
    const int x = px * scale + scale / 2, y = py * scale + scale / 2;
    return ring_of[static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x)];
  };
  const auto paint = [&](int px, int py, const std::array<uint8_t, 3>& colour) {
    if (px >= 0 && px < pw && py >= 0 && py < ph) {
      std::copy(colour.begin(), colour.end(),
                panels[2].begin() + (static_cast<std::ptrdiff_t>(py) * pw + px) * 3);
    }
  };
  for (int py = 0; py < ph; ++py) {
    for (int px = 0; px < pw; ++px) {
      const int k = ring_at(px, py);
      if ((px + 1 < pw && ring_at(px + 1, py) != k) || (py + 1 < ph && ring_at(px, py + 1) != k)) {
        paint(px, py, kRingColour);
      }
    }
  }
  Eigen::Vector2d gaze_px;
  if (camera.project(camera.position_m + gaze_direction_world.normalized(), gaze_px) &&
      std::abs(gaze_px.x()) < w * 2.0 && std::abs(gaze_px.y()) < h * 2.0) {
    const int gx = static_cast<int>(std::floor(gaze_px.x() / scale));
    const int gy = static_cast<int>(std::floor(gaze_px.y() / scale));
    for (int d = -3; d <= 3; ++d) {
      paint(gx + d, gy, kGazeColour);
      paint(gx, gy + d, kGazeColour);
    }
  }

  const int out_w = 3 * pw + 2 * kGapPx;
  std::vector<uint8_t> out(static_cast<std::size_t>(out_w) * static_cast<std::size_t>(ph) * 3);
  for (std::size_t p = 0; p < out.size() / 3; ++p) {
    std::copy(kGapColour.begin(), kGapColour.end(), out.begin() + static_cast<std::ptrdiff_t>(p * 3));
  }
  for (int panel = 0; panel < 3; ++panel) {
    for (int py = 0; py < ph; ++py) {
      const auto src = panels[panel].begin() + static_cast<std::ptrdiff_t>(py) * pw * 3;
      std::copy(src, src + pw * 3,
                out.begin() + (static_cast<std::ptrdiff_t>(py) * out_w + panel * (pw + kGapPx)) * 3);
    }
  }
  return writePng(path, out_w, ph, out.data());
}

}  // namespace fovea::tools::eval
