#include "pipeline/error_metrics.h"

#include "pipeline/quantile.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include <Eigen/Geometry>

namespace fovea::pipeline {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kDegPerRad = 180.0 / std::numbers::pi;

// Angle between a and a + d: atan2(|a x d|, a.(a + d)). Taking the cross product
// with the displacement d rather than with b = a + d keeps its precision when d is
// tiny against a (a x b = a x d exactly, but not in floating point).
double displacementAngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& d) {
  return std::atan2(a.cross(d).norm(), a.squaredNorm() + a.dot(d)) * kDegPerRad;
}

// Nearest-rank quantile of values[0..n) (reordered); 0 when n is 0.
double quantile(double* values, std::size_t n, double q) {
  return n == 0 ? 0.0 : nearestRankQuantile(std::span<double>(values, n), q);
}


// The frame one evaluation measures in: the unit gaze l, and P - H = in_to_eye + p,
// R - P = shift + (r - p), so that the large parts cancel first (docs/precision.md);
// the slopes of the model's MAR and of the reference MAR.
struct EyeFrame {
  Eigen::Vector3d l;
  Eigen::Vector3d in_to_eye;
  Eigen::Vector3d shift;
  double slope = 0.0;
  double reference_slope = 0.0;
};

Result<EyeFrame> eyeFrame(const PointCloud& in, const PointCloud& out, const Gaze& unit_gaze,
                          const RegionModel& model, const ErrorModel& error_model) {
  EyeFrame frame;
  frame.l = unit_gaze.direction;
  frame.in_to_eye = in.origin_m - unit_gaze.origin_m;
  frame.shift = out.origin_m - in.origin_m;
  frame.slope = model.slope();
  frame.reference_slope = error_model.reference_slope;
  if (!(std::isfinite(frame.reference_slope) && frame.reference_slope >= 0.0)) {
    return Result<EyeFrame>(ErrorCode::kInvalidArgument,
                            "error evaluator: reference slope must be finite and >= 0");
  }
  return frame;
}

// The displacement of each point of `in` to its representative in `out`, into the
// regions' and the cloud's sums, and its angle over the MAR into ratio[i] (NaN for a
// point without a representative or at the eye) with its eccentricity in ecc_deg[i].
Status measurePoints(const PointCloud& in, const uint8_t* region, const uint32_t* representative,
                     const PointCloud& out, const EyeFrame& frame, int region_count, double* ratio_out,
                     double* ecc_deg_out, ErrorMetrics& metrics) {
  const std::size_t n = in.size();
  for (std::size_t i = 0; i < n; ++i) {
    ratio_out[i] = kNaN;
    const uint8_t r = region[i];
    const uint32_t rep = representative[i];
    if (r == kRegionInvalid || rep == kNoRepresentative) {
      ++metrics.no_representative;
      continue;
    }
    if (r >= region_count) {
      return {ErrorCode::kInvalidInput, "error evaluator: point " + std::to_string(i) + " has region " +
                                            std::to_string(r) + ", the model has " + std::to_string(region_count)};
    }
    if (rep >= out.size()) {
      return {ErrorCode::kInvalidInput, "error evaluator: point " + std::to_string(i) + " has representative " +
                                            std::to_string(rep) + ", the output has " + std::to_string(out.size()) +
                                            " points"};
    }
    const Eigen::Vector3d p(in.x()[i], in.y()[i], in.z()[i]);
    const Eigen::Vector3d q(out.x()[rep], out.y()[rep], out.z()[rep]);
    const Eigen::Vector3d d = (q - p) + frame.shift;
    const Eigen::Vector3d a = frame.in_to_eye + p;
    const double dist_sq = d.squaredNorm();
    const double dist = std::sqrt(dist_sq);
    for (RegionError* e : {&metrics.regions[r], &metrics.all}) {
      ++e->points;
      e->sum_sq_m2 += dist_sq;
      e->max_m = std::max(e->max_m, dist);
    }
    if (a.isZero(0.0) || (a + d).isZero(0.0)) {
      ++metrics.at_eye;
      continue;
    }
    const double alpha_deg = displacementAngleDeg(a, d);
    const double ecc_deg = eccentricityDeg(a, frame.l);
    const double mar_deg = marDeg(frame.slope, ecc_deg);
    const double reference_mar_deg = marDeg(frame.reference_slope, ecc_deg);
    const double ratio = alpha_deg / mar_deg;
    ratio_out[i] = ratio;
    ecc_deg_out[i] = ecc_deg;
    for (RegionError* e : {&metrics.regions[r], &metrics.all}) {
      ++e->seen;
      e->above_mar += alpha_deg > mar_deg ? 1u : 0u;
      e->above_reference_mar += alpha_deg > reference_mar_deg ? 1u : 0u;
      e->ratio_max = std::max(e->ratio_max, ratio);
    }
  }
  return Status::ok();
}

// The ratios' quantiles, of the cloud, of each region and of each region's border
// bands, from ratio[0..n) and ecc_deg[0..n) (measurePoints); scratch holds n values.
void fillRatioQuantiles(const double* ratio, const double* ecc_deg, double* scratch, std::size_t n,
                        const uint8_t* region, const RegionModel& model, ErrorMetrics& metrics) {
  // Gather each region's ratios (and its border bands') into scratch.
  auto gather = [&](auto&& keep) {
    std::size_t k = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (!std::isnan(ratio[i]) && keep(i)) scratch[k++] = ratio[i];
    }
    return k;
  };
  std::size_t k = gather([](std::size_t) { return true; });
  metrics.all.ratio_median = quantile(scratch, k, 0.5);
  metrics.all.ratio_p95 = quantile(scratch, k, 0.95);
  metrics.all.ratio_median_first_deg = kNaN;
  metrics.all.ratio_median_last_deg = kNaN;
  for (int r = 0; r < model.regionCount(); ++r) {
    RegionError& e = metrics.regions[r];
    const auto in_region = [&](std::size_t i) { return region[i] == r; };
    k = gather(in_region);
    e.ratio_median = quantile(scratch, k, 0.5);
    e.ratio_p95 = quantile(scratch, k, 0.95);
    e.ratio_median_first_deg = kNaN;
    e.ratio_median_last_deg = kNaN;
    if (r >= 1 && r - 1 < model.boundCount()) {  // levels (Preset::kAcuity) have no bounds
      const double inner = model.boundDeg(r - 1);
      k = gather([&](std::size_t i) { return in_region(i) && ecc_deg[i] <= inner + kBorderBandDeg; });
      e.first_deg_points = static_cast<uint32_t>(k);
      if (k > 0) e.ratio_median_first_deg = quantile(scratch, k, 0.5);
    }
    if (r < model.boundCount()) {
      const double outer = model.boundDeg(r);
      k = gather([&](std::size_t i) { return in_region(i) && ecc_deg[i] >= outer - kBorderBandDeg; });
      e.last_deg_points = static_cast<uint32_t>(k);
      if (k > 0) e.ratio_median_last_deg = quantile(scratch, k, 0.5);
    }
  }
}

}  // namespace

double RegionError::rmsM() const { return points ? std::sqrt(sum_sq_m2 / points) : 0.0; }
double RegionError::rmsOverVoxel() const { return voxel_size_m > 0.0 ? rmsM() / voxel_size_m : kNaN; }
double RegionError::maxOverVoxel() const { return voxel_size_m > 0.0 ? max_m / voxel_size_m : kNaN; }
double RegionError::shareAboveMar() const { return seen ? static_cast<double>(above_mar) / seen : 0.0; }
double RegionError::shareAboveReferenceMar() const {
  return seen ? static_cast<double>(above_reference_mar) / seen : 0.0;
}

double angleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  if (a.isZero(0.0) || b.isZero(0.0)) return 0.0;
  return displacementAngleDeg(a, b - a);
}

double eccentricityDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& l) {
  return std::atan2(a.cross(l).norm(), a.dot(l)) * kDegPerRad;
}

Result<ErrorEvaluator> ErrorEvaluator::create(std::size_t max_points) {
  if (max_points == 0 || max_points > UINT32_MAX) {
    return Result<ErrorEvaluator>(ErrorCode::kInvalidArgument, "error evaluator: max_points must be in [1, 2^32)");
  }
  return ErrorEvaluator(max_points);
}

ErrorEvaluator::ErrorEvaluator(std::size_t max_points)
    : ratio_(max_points), ecc_deg_(max_points), scratch_(max_points) {}

Status ErrorEvaluator::evaluate(const PointCloud& in, const uint8_t* region, const uint32_t* representative,
                                const PointCloud& out, const Gaze& gaze, const ErrorModel& error_model,
                                ErrorMetrics& metrics) {
  metrics = {};
  if (error_model.model == nullptr) return {ErrorCode::kInvalidArgument, "error evaluator: no region model"};
  const RegionModel& model = *error_model.model;
  const int region_count = model.regionCount();
  metrics.region_count = region_count;
  const std::size_t n = in.size();
  if (n > ratio_.size()) {
    return {ErrorCode::kCapacityExceeded, "error evaluator: cloud has " + std::to_string(n) +
                                              " points, capacity is " + std::to_string(ratio_.size())};
  }
  Result<Gaze> unit_gaze = normalizeGaze(gaze);
  if (!unit_gaze) return unit_gaze.status();
  for (int r = 1; r < region_count; ++r) metrics.regions[r].voxel_size_m = error_model.voxel_size_m[r];

  Result<EyeFrame> frame = eyeFrame(in, out, *unit_gaze, model, error_model);
  if (!frame) return frame.status();
  Status measured = measurePoints(in, region, representative, out, *frame, region_count, ratio_.data(),
                                  ecc_deg_.data(), metrics);
  if (!measured) return measured;
  fillRatioQuantiles(ratio_.data(), ecc_deg_.data(), scratch_.data(), n, region, model, metrics);
  return Status::ok();
}

}  // namespace fovea::pipeline
