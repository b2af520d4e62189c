// PNG files of the renderings, for a person to look at what the numbers of
// image_quality.h measure.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"
#include "tools/eval/quality/splat_renderer.h"

namespace fovea::tools::eval {

// Writes an 8-bit RGB PNG (rgb: 3 bytes per pixel, row-major). Errors name the
// path and libpng's reason.
Status writePng(const std::string& path, int width, int height, const uint8_t* rgb);

// reference | test | difference side by side, each box-filtered `scale` times
// smaller (scale >= 1; a 1440x1600 eye at scale 4 gives 360x400 panels). The
// difference is |reference - test| per channel, x4, clamped; on it the ring
// edges are drawn as thin lines where the ring (image_quality.h) changes between
// neighbouring panel pixels, and a small cross marks the gaze. Errors:
// checkImagePair's, ringOfEachPixel's, a scale below 1 or above the image's
// smaller side, and writePng's.
Status writeSideBySidePng(const std::string& path, const Image& reference, const Image& test, const EyeCamera& camera,
                          const Eigen::Vector3d& gaze_direction_world, const std::vector<double>& ring_edges_deg,
                          int scale);

}  // namespace fovea::tools::eval
