#include "pipeline/acuity.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <numbers>

namespace fovea::pipeline {

namespace {

// Table I: outer eccentricity of each named retinal region, in degrees.
constexpr std::array<double, 5> kTableIBoundsDeg = {5.0, 8.0, 18.0, 30.0, 60.0};
constexpr std::array<const char*, 6> kTableINames = {
    "fovea", "parafovea", "perifovea", "near-periphery", "mid-periphery", "far-periphery"};
constexpr std::array<const char*, kMaxRegions> kLevelNames = {"raw", "level1", "level2", "level3",
                                                              "level4", "level5", "level6", "level7"};
constexpr std::array<const char*, kMaxRegions> kCustomNames = {
    "region0", "region1", "region2", "region3", "region4", "region5", "region6", "region7"};

std::string formatDouble(double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.17g", v);
  return buffer;
}

Status invalid(const std::string& field, const std::string& what) {
  return {ErrorCode::kInvalidArgument, "acuity." + field + ": " + what};
}

}  // namespace

double foveaVoxelSizeM(double d0_m) {
  return d0_m * std::tan(kMar0Deg * std::numbers::pi / 180.0);
}

std::string_view presetName(Preset preset) {
  switch (preset) {
    case Preset::kF1: return "F1";
    case Preset::kF2: return "F2";
    case Preset::kF3: return "F3";
    case Preset::kFRef: return "FREF";
    case Preset::kCustom: return "custom";
    case Preset::kAcuity: return "ACUITY";
  }
  return "?";
}

Result<Preset> parsePreset(std::string_view text) {
  std::string upper;
  for (char c : text) upper.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
  if (upper == "F1") return Preset::kF1;
  if (upper == "F2") return Preset::kF2;
  if (upper == "F3") return Preset::kF3;
  if (upper == "FREF") return Preset::kFRef;
  if (upper == "CUSTOM") return Preset::kCustom;
  if (upper == "ACUITY") return Preset::kAcuity;
  return Result<Preset>(ErrorCode::kInvalidArgument,
                        "preset: unknown name '" + std::string(text) + "' (use F1, F2, F3, FREF or ACUITY)");
}

std::string_view viewCullName(ViewCull cull) {
  switch (cull) {
    case ViewCull::kOff: return "off";
    case ViewCull::kCoarsest: return "coarsest";
    case ViewCull::kDrop: return "drop";
  }
  return "?";
}

Result<ViewCull> parseViewCull(std::string_view text) {
  if (text == "off") return ViewCull::kOff;
  if (text == "coarsest") return ViewCull::kCoarsest;
  if (text == "drop") return ViewCull::kDrop;
  return Result<ViewCull>(ErrorCode::kInvalidArgument,
                          "view cull: unknown value '" + std::string(text) + "' (use off, coarsest or drop)");
}

Result<RegionModel> RegionModel::create(const AcuityConfig& config) {
  if (!std::isfinite(config.slope)) return invalid("slope", "must be a finite number, got " + formatDouble(config.slope));
  if (config.slope < 0.0) return invalid("slope", "must not be negative, got " + formatDouble(config.slope));

  RegionModel model;
  model.preset_ = config.preset;
  model.slope_ = config.slope;

  // Section III: F1 = fovea, parafovea, perifovea and the rest; F2 adds the near
  // periphery; F3 uses all six regions of Table I; FREF does not foveate.
  int table_bounds = 0;
  switch (config.preset) {
    case Preset::kF1: table_bounds = 3; break;
    case Preset::kF2: table_bounds = 4; break;
    case Preset::kF3: table_bounds = 5; break;
    case Preset::kFRef: table_bounds = 0; break;
    case Preset::kCustom: table_bounds = -1; break;
    case Preset::kAcuity: table_bounds = -2; break;
  }
  Status regions;
  if (table_bounds == -2) {
    regions = model.setAcuityLevels(config);
  } else if (table_bounds >= 0) {
    model.setTableIRegions(table_bounds);
  } else {
    regions = model.setCustomRegions(config.custom_bounds_deg);
  }
  if (!regions) return regions;
  if (Status far = model.setFarEccentricity(config.far_ecc_deg); !far) return far;
  return model;
}

Status RegionModel::setAcuityLevels(const AcuityConfig& config) {
  // Levels 1 .. kMaxRegions - 1 of the nested lattice; region 0 holds the raw points.
  const double v = config.level_voxel_m;
  if (!std::isfinite(v) || !(v >= 1e-4 && v <= 1.0)) {
    return invalid("level_voxel_m", formatDouble(v) + " is outside [0.0001, 1] m");
  }
  const double f = config.floor_m;
  if (!std::isfinite(f) || !(f >= 0.0 && f <= 1.0)) return invalid("floor_m", formatDouble(f) + " is outside [0, 1] m");
  const double k = config.level_margin;
  if (!std::isfinite(k) || !(k >= 0.1 && k <= 10.0)) return invalid("level_margin", formatDouble(k) + " is outside [0.1, 10]");
  level_voxel_m_ = v;
  floor_m_ = f;
  const double q = config.floor_per_m2;
  if (!std::isfinite(q) || !(q >= 0.0 && q <= 1.0)) {
    return invalid("floor_per_m2", formatDouble(q) + " is outside [0, 1] m per square metre");
  }
  floor_per_m2_ = q;
  level_margin_ = k;
  if (config.refine_passes < 0 || config.refine_passes > kMaxRefinePasses) {
    return invalid("refine_passes", std::to_string(config.refine_passes) + " is outside [0, " +
                                        std::to_string(kMaxRefinePasses) + "]");
  }
  refine_passes_ = config.refine_passes;
  const double c = config.view_cull_deg;
  if (!std::isfinite(c) || !(c > 0.0 && c <= 180.0)) {
    return invalid("view_cull_deg", formatDouble(c) + " is outside (0, 180] degrees");
  }
  view_cull_ = config.view_cull;
  view_cull_deg_ = c;
  region_count_ = kMaxRegions;
  for (int n = 0; n < kMaxRegions; ++n) names_[n] = kLevelNames[n];
  return Status::ok();
}

void RegionModel::setTableIRegions(int table_bounds) {
  for (int n = 0; n < table_bounds; ++n) bound_deg_[n] = kTableIBoundsDeg[n];
  region_count_ = table_bounds + 1;
  for (int n = 0; n < table_bounds; ++n) names_[n] = kTableINames[n];
  // The outermost region is "the rest", sampled like the far periphery.
  names_[table_bounds] = table_bounds == 0 ? "all" : (table_bounds == 5 ? "far-periphery" : "rest");
}

Status RegionModel::setCustomRegions(const std::vector<double>& bounds) {
  if (bounds.size() > kMaxRegions - 1) {
    return invalid("bounds_deg", "at most " + std::to_string(kMaxRegions - 1) + " bounds, got " +
                                     std::to_string(bounds.size()));
  }
  for (std::size_t i = 0; i < bounds.size(); ++i) {
    // The field's name only on error: a valid configuration is applied on the
    // frame path (Foveator::setConfig), which must not build strings.
    auto field = [i] { return "bounds_deg[" + std::to_string(i) + "]"; };
    const double b = bounds[i];
    if (!std::isfinite(b)) return invalid(field(), "must be a finite number, got " + formatDouble(b));
    if (!(b > 0.0 && b < 180.0)) return invalid(field(), formatDouble(b) + " is outside (0, 180) degrees");
    if (i > 0 && !(b > bounds[i - 1])) {
      return invalid(field(), formatDouble(b) + " is not greater than the previous bound " +
                                  formatDouble(bounds[i - 1]) + " (bounds must increase strictly)");
    }
    bound_deg_[i] = b;
  }
  region_count_ = static_cast<int>(bounds.size()) + 1;
  for (int n = 0; n < region_count_; ++n) names_[n] = kCustomNames[n];
  return Status::ok();
}

Status RegionModel::setFarEccentricity(double far) {
  if (!std::isfinite(far)) return invalid("far_ecc_deg", "must be a finite number, got " + formatDouble(far));
  if (!(far > 0.0 && far <= 180.0)) return invalid("far_ecc_deg", formatDouble(far) + " is outside (0, 180] degrees");
  if (region_count_ > 1 && far < bound_deg_[region_count_ - 2]) {
    return invalid("far_ecc_deg", formatDouble(far) + " is below the last region bound " +
                                      formatDouble(bound_deg_[region_count_ - 2]) +
                                      " (the outermost voxels would be smaller than the next inner ones)");
  }
  far_ecc_deg_ = far;
  return Status::ok();
}

double RegionModel::voxelEccDeg(int n) const {
  if (n <= 0) return 0.0;
  if (n == region_count_ - 1) return far_ecc_deg_;
  return bound_deg_[n];
}

double RegionModel::voxelScale(int n) const {
  if (n <= 0) return 1.0;
  return marDeg(slope_, voxelEccDeg(n)) / kMar0Deg;
}

}  // namespace fovea::pipeline
