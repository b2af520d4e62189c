// Objective image quality per eccentricity ring around the gaze: PSNR and SSIM
// of a foveated rendering against the reference, each ring weighted by the
// acuity there, so an error in the fovea counts more than one in the periphery.
//
// PSNR: dB on 8-bit RGB, the MSE over the 3 channels; identical images give
// +infinity. SSIM: Wang, Bovik, Sheikh, Simoncelli 2004 on luma
// Y = 0.299 R + 0.587 G + 0.114 B (unrounded), an 11x11 Gaussian window of sigma
// 1.5, K1 = 0.01, K2 = 0.03, L = 255. The SSIM map is defined at the pixels whose
// window fits in the image; a region's SSIM is the map's mean over its pixels
// there (NaN when it has none).
#pragma once

#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"
#include "tools/eval/quality/splat_renderer.h"

namespace fovea::tools::eval {

struct Ring {
  double inner_deg = 0, outer_deg = 0;
  std::size_t pixels = 0;
  double mse = 0;
  double psnr_db = 0;
  double ssim = 0;
  double weight = 0;
};

struct FoveatedQuality {
  std::vector<Ring> rings;
  double weighted_psnr_db = 0;  // PSNR of the weighted mean MSE
  // The weighted mean of the rings' SSIM, over the rings whose SSIM is defined
  // (their weights renormalised).
  double weighted_ssim = 0;
  double psnr_db = 0, ssim = 0;  // the whole image, unweighted
};

// Both images non-empty, of the same size, their buffers that size, and the
// camera's image that size too.
Status checkImagePair(const Image& reference, const Image& test, const EyeCamera& camera);

// The ring of every pixel of the camera's image (row-major): k when the angle
// between the pixel centre's ray and the gaze is in [edge k, edge k+1), -1 when
// in no ring. Errors: fewer than 2 edges, edges negative, not finite or not
// strictly increasing, a zero or non-finite gaze.
Result<std::vector<int>> ringOfEachPixel(const EyeCamera& camera, const Eigen::Vector3d& gaze_direction_world,
                                         const std::vector<double>& ring_edges_deg);

// Ring k is [edge k, edge k+1). Its weight is proportional to its pixel count
// over MAR(E_mid) = slope * E_mid + 1/60 (degrees; E_mid the middle of the ring),
// normalised to sum to 1 over the rings with pixels. Rings without pixels get
// pixels = weight = 0 and NaN PSNR, MSE and SSIM. Errors: checkImagePair's,
// ringOfEachPixel's, and a slope that is negative or not finite.
Result<FoveatedQuality> foveatedQuality(const Image& reference, const Image& test, const EyeCamera& camera,
                                        const Eigen::Vector3d& gaze_direction_world,
                                        const std::vector<double>& ring_edges_deg, double slope);

}  // namespace fovea::tools::eval
