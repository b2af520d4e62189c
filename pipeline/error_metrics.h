// Error of a foveated cloud against the full cloud it came from (issue 3's
// "speed against error" report). No I/O; all memory is allocated by create().
//
// Every input point P has a representative R: the output point that stands for it
// (itself in the fovea, its voxel's centroid elsewhere; Foveator::foveate's
// `representative` output). Two kinds of error, per region (the region of P, which
// is also R's) and over all regions:
//
// - Geometric: the distance |R - P| in metres, its RMS and maximum, and both divided
//   by the region's voxel size v_n (the fovea has none; its error is exactly 0).
//   Since P and R lie in the same voxel, |R - P| <= sqrt(3) v_n.
//
// - Perceptual: what the displacement looks like from the eye H. With a = P - H and
//   b = R - H, the displacement angle is
//       alpha = atan2(|a x b|, a . b)            (degrees; accurate for tiny angles)
//   and P's eccentricity is ecc = atan2(|a x L|, a . L) for the unit gaze L. The
//   point is "above its MAR" when alpha > MAR(ecc) = m * ecc + MAR0 (Eq. 1, degrees,
//   strictly greater). The ratio alpha / MAR(ecc) is also summarised (median, 95th
//   percentile, max): below 1 the displacement is under the eye's resolution at
//   that point (the region is over-sampled), far above 1 it is visible.
//
// Edge cases, documented in docs/report/README.md:
// - P or R at the eye (a = 0 or b = 0 exactly, in double): there is no direction,
//   so no angle. Such points are counted in `at_eye` and left out of the
//   perceptual counts (numerator and denominator); their geometric error counts.
// - P == R (the fovea, FREF, a voxel with one point): alpha = 0, never above MAR.
// - Points behind the eye (ecc > 90 deg) are evaluated with Eq. 1 extrapolated
//   (MAR keeps growing linearly); nothing caps it at 90 degrees.
// - Input points without a representative (non-finite coordinates, skipped by the
//   partition) are counted in `no_representative` and excluded from everything.
// - Occlusion is ignored: a displaced point counts even if something hides it.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/result.h"
#include "pipeline/acuity.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::pipeline {

// Width of the eccentricity bands next to each region bound whose median ratio
// shows the steps at region borders.
inline constexpr double kBorderBandDeg = 1.0;

struct RegionError {
  uint32_t points = 0;        // input points with a representative
  double voxel_size_m = 0.0;  // 0 for the fovea and for the all-regions summary
  double sum_sq_m2 = 0.0;     // sum of |R - P|^2
  double max_m = 0.0;         // max |R - P|
  // Perceptual: points with a defined angle, those above their MAR, and the
  // ratio alpha / MAR(ecc) (nearest-rank quantiles; 0 when no point).
  uint32_t seen = 0;
  uint32_t above_mar = 0;
  // The same test against a fixed observer, MAR = reference_slope * ecc + MAR0
  // (ErrorModel): configurations with different m judged by the same eye.
  uint32_t above_reference_mar = 0;
  double ratio_median = 0.0;
  double ratio_p95 = 0.0;
  double ratio_max = 0.0;
  // Median ratio of the points within kBorderBandDeg inside the region's inner
  // bound (first) and outer bound (last); NaN when the band has no point (the
  // fovea has no inner band, the outermost region no outer band).
  double ratio_median_first_deg = 0.0;
  double ratio_median_last_deg = 0.0;
  uint32_t first_deg_points = 0;
  uint32_t last_deg_points = 0;

  double rmsM() const;
  double rmsOverVoxel() const;  // NaN when voxel_size_m is 0
  double maxOverVoxel() const;  // NaN when voxel_size_m is 0
  double shareAboveMar() const; // above_mar / seen; 0 when seen is 0
  double shareAboveReferenceMar() const;
};

struct ErrorMetrics {
  int region_count = 0;
  std::array<RegionError, kMaxRegions> regions{};
  RegionError all;                 // every region pooled (voxel_size_m 0)
  uint32_t no_representative = 0;  // input points skipped by the sampler
  uint32_t at_eye = 0;             // P or R exactly at the eye: no angle
};

// The geometry the metrics need from the foveation: the region model (bounds,
// slope m) and the voxel size per region for this cloud (FoveationStats). The
// perceptual test uses the model's m; reference_slope gives a second, fixed
// observer (default: the paper's most acute, m = 0.022).
struct ErrorModel {
  const RegionModel* model = nullptr;
  std::array<double, kMaxRegions> voxel_size_m{};
  double reference_slope = kDefaultSlope;
};

class ErrorEvaluator {
 public:
  // Allocates scratch for clouds of up to max_points points.
  static Result<ErrorEvaluator> create(std::size_t max_points);

  // Measures `out` against `in`. region[i] and representative[i] are those of the
  // foveation of `in` (Foveator::lastRegions() and foveate's representative);
  // gaze is the one used (normalised here). kInvalidInput when a representative
  // index is outside `out`, a region is out of range or the gaze is unusable;
  // kCapacityExceeded when `in` is larger than max_points. Never allocates.
  Status evaluate(const PointCloud& in, const uint8_t* region, const uint32_t* representative,
                  const PointCloud& out, const Gaze& gaze, const ErrorModel& error_model,
                  ErrorMetrics& metrics);

  std::size_t maxPoints() const { return ratio_.size(); }

 private:
  explicit ErrorEvaluator(std::size_t max_points);
  std::vector<double> ratio_;    // alpha / MAR(ecc) per seen point, NaN otherwise
  std::vector<double> ecc_deg_;  // eccentricity per seen point
  std::vector<double> scratch_;  // values of one region for the quantiles
};

// Eq. 1 helpers, exposed for the tests: the angle in degrees between a and b
// (0 when either is zero) and the eccentricity of a around the unit gaze l.
double angleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b);
double eccentricityDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& l);

}  // namespace fovea::pipeline
