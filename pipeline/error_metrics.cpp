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
  const Eigen::Vector3d l = unit_gaze->direction;
  for (int r = 1; r < region_count; ++r) metrics.regions[r].voxel_size_m = error_model.voxel_size_m[r];

  // P - H = (origin_in - H) + p; R - P = (origin_out - origin_in) + (r - p): the
  // large parts cancel first (docs/precision.md).
  const Eigen::Vector3d in_to_eye = in.origin_m - unit_gaze->origin_m;
  const Eigen::Vector3d shift = out.origin_m - in.origin_m;
  const double slope = model.slope();
  const double reference_slope = error_model.reference_slope;
  if (!(std::isfinite(reference_slope) && reference_slope >= 0.0)) {
    return {ErrorCode::kInvalidArgument, "error evaluator: reference slope must be finite and >= 0"};
  }
  for (std::size_t i = 0; i < n; ++i) {
    ratio_[i] = kNaN;
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
    const Eigen::Vector3d d = (q - p) + shift;
    const Eigen::Vector3d a = in_to_eye + p;
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
    const double ecc_deg = eccentricityDeg(a, l);
    const double mar_deg = marDeg(slope, ecc_deg);
    const double reference_mar_deg = marDeg(reference_slope, ecc_deg);
    const double ratio = alpha_deg / mar_deg;
    ratio_[i] = ratio;
    ecc_deg_[i] = ecc_deg;
    for (RegionError* e : {&metrics.regions[r], &metrics.all}) {
      ++e->seen;
      e->above_mar += alpha_deg > mar_deg ? 1u : 0u;
      e->above_reference_mar += alpha_deg > reference_mar_deg ? 1u : 0u;
      e->ratio_max = std::max(e->ratio_max, ratio);
    }
  }

  // Quantiles: gather each region's ratios (and its border bands') into scratch.
  auto gather = [&](auto&& keep) {
    std::size_t k = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (!std::isnan(ratio_[i]) && keep(i)) scratch_[k++] = ratio_[i];
    }
    return k;
  };
  std::size_t k = gather([](std::size_t) { return true; });
  metrics.all.ratio_median = quantile(scratch_.data(), k, 0.5);
  metrics.all.ratio_p95 = quantile(scratch_.data(), k, 0.95);
  metrics.all.ratio_median_first_deg = kNaN;
  metrics.all.ratio_median_last_deg = kNaN;
  for (int r = 0; r < region_count; ++r) {
    RegionError& e = metrics.regions[r];
    const auto in_region = [&](std::size_t i) { return region[i] == r; };
    k = gather(in_region);
    e.ratio_median = quantile(scratch_.data(), k, 0.5);
    e.ratio_p95 = quantile(scratch_.data(), k, 0.95);
    e.ratio_median_first_deg = kNaN;
    e.ratio_median_last_deg = kNaN;
    if (r >= 1 && r - 1 < model.boundCount()) {  // levels (Preset::kAcuity) have no bounds
      const double inner = model.boundDeg(r - 1);
      k = gather([&](std::size_t i) { return in_region(i) && ecc_deg_[i] <= inner + kBorderBandDeg; });
      e.first_deg_points = static_cast<uint32_t>(k);
      if (k > 0) e.ratio_median_first_deg = quantile(scratch_.data(), k, 0.5);
    }
    if (r < model.boundCount()) {
      const double outer = model.boundDeg(r);
      k = gather([&](std::size_t i) { return in_region(i) && ecc_deg_[i] >= outer - kBorderBandDeg; });
      e.last_deg_points = static_cast<uint32_t>(k);
      if (k > 0) e.ratio_median_last_deg = quantile(scratch_.data(), k, 0.5);
    }
  }
  return Status::ok();
}

}  // namespace fovea::pipeline
