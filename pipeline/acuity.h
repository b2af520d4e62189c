// The acuity model of the paper (Eq. 1, 5, 6) and its regions (Table I).
//
// MAR(E) = m * E + MAR0, E and MAR in degrees, MAR0 = 1 arcmin. Region n >= 1 is
// sampled with voxels of v_n = v_0 * MAR(E_n) / MAR0 where v_0 = d0 * tan(MAR0)
// and E_n is the region's outer bound (the far periphery, which has none, uses a
// configurable eccentricity). The fovea (region 0) is never resampled.
// docs/acuity.md explains this reading of the paper.
#pragma once

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"

namespace fovea::pipeline {

inline constexpr double kMar0Deg = 1.0 / 60.0;  // 1 arcmin: 20/20 acuity
inline constexpr int kMaxRegions = 8;            // region index fits 3 bits of a voxel key
inline constexpr double kDefaultSlope = 0.022;   // the paper's range is 0.022 .. 0.034
inline constexpr double kDefaultFarEccDeg = 90.0;
inline constexpr int kMaxRefinePasses = kMaxRegions - 1;

// Eq. 1: minimum angle of resolution at eccentricity ecc_deg, in degrees.
inline double marDeg(double slope, double ecc_deg) { return slope * ecc_deg + kMar0Deg; }

// Eq. 5: v_0 = d0 * tan(MAR0), the smallest resolvable length at distance d0.
double foveaVoxelSizeM(double d0_m);

// The paper's test conditions (section III), a user-defined list, and fovea's
// own mode beyond the paper (kAcuity, docs/acuity-levels.md): each point on the
// coarsest level of a nested world lattice that its own acuity allows.
enum class Preset { kF1, kF2, kF3, kFRef, kCustom, kAcuity };

std::string_view presetName(Preset preset);
// Accepts "F1", "F2", "F3", "FREF", "ACUITY" (any case).
Result<Preset> parsePreset(std::string_view text);

// What Preset::kAcuity does with points outside the viewer's field of view.
enum class ViewCull { kOff, kCoarsest, kDrop };
std::string_view viewCullName(ViewCull cull);
// Accepts "off", "coarsest", "drop".
Result<ViewCull> parseViewCull(std::string_view text);

struct AcuityConfig {
  Preset preset = Preset::kF1;
  // For Preset::kCustom: the outer eccentricity bound of each region but the last,
  // strictly increasing, each in (0, 180) degrees. Empty means no foveation.
  std::vector<double> custom_bounds_deg;
  double slope = kDefaultSlope;                 // m of Eq. 1
  double far_ecc_deg = kDefaultFarEccDeg;       // E used for the outermost region
  // Preset::kAcuity: the finest lattice's voxel (level 1; level n is 2^(n-1) times
  // it, up to kMaxRegions - 1) and the sensor floor: no point is kept finer than
  // the level whose voxel reaches floor_m (0: no floor, points too fine for
  // level 1 stay raw in region 0).
  double level_voxel_m = 0.002;
  double floor_m = 0.0;
  // ... and a floor that grows with the square of the point's distance s from the
  // sensor (the cloud's origin: the camera, for a captured frame), as a depth
  // camera's noise does (about 0.0019 s^2 m for a Kinect-type sensor): no point
  // finer than the level whose voxel reaches floor_m + floor_per_m2 * s^2.
  // 0: the constant floor only.
  double floor_per_m2 = 0.0;
  // A point may use level n when margin * v_n <= r sin(MAR(E)) (acuity_levels.h):
  // sqrt(3) guarantees every displacement under the MAR (a voxel's diagonal);
  // smaller values trade a measured share above the MAR for bytes. 0.5: about
  // F3's bytes at half its share above the MAR (docs/acuity-levels.md).
  double level_margin = 0.5;
  // Preset::kAcuity: passes of error-driven refinement after the first sampling
  // (acuity_levels.h, refineTestRef and moveRefinedVoxels): each moves every voxel
  // with a point its centroid displaces, seen from the eye, by more than the
  // point's MAR one level down, and samples again. 0: none (the levels come from
  // the margin alone); at most kMaxRefinePasses, which brings every point under its
  // MAR (a point can go down at most kMaxRegions - 1 levels).
  int refine_passes = 0;
  // Preset::kAcuity, when the gaze carries the head's pose (Gaze::view_known): a
  // point further than view_cull_deg from the head's forward axis (the HMD's field
  // of view plus a margin for head motion within the loop's latency) goes to the
  // coarsest level (kCoarsest) or is not sent (kDrop). docs/acuity-levels.md.
  ViewCull view_cull = ViewCull::kOff;
  double view_cull_deg = 70.0;
};

// A validated region list. Region n < count-1 holds the points whose eccentricity
// is within bound_deg[n] (and beyond the previous bound); the last region holds
// the rest. With a single region (FREF) every point is in the untouched fovea.
class RegionModel {
 public:
  // Validates the configuration; the message names the offending field.
  static Result<RegionModel> create(const AcuityConfig& config);

  int regionCount() const { return region_count_; }
  // Preset::kAcuity: the regions are lattice levels, not eccentricity bands.
  bool levels() const { return preset_ == Preset::kAcuity; }
  int boundCount() const { return levels() ? 0 : region_count_ - 1; }
  double boundDeg(int n) const { return bound_deg_[n]; }
  // Eccentricity whose MAR sets region n's voxel size (n >= 1).
  double voxelEccDeg(int n) const;
  // v_n / v_0 = MAR(E_n) / MAR0; 1 for the fovea.
  double voxelScale(int n) const;
  // v_n for fixation distance d0_m (levels: the level's voxel, whatever d0).
  double voxelSizeM(int n, double d0_m) const {
    if (levels()) return n <= 0 ? 0.0 : level_voxel_m_ * static_cast<double>(1 << (n - 1));
    return foveaVoxelSizeM(d0_m) * voxelScale(n);
  }
  double levelVoxelM() const { return level_voxel_m_; }
  double levelMargin() const { return level_margin_; }
  int refinePasses() const { return refine_passes_; }
  double floorM() const { return floor_m_; }
  double floorPerM2() const { return floor_per_m2_; }
  ViewCull viewCull() const { return view_cull_; }
  double viewCullDeg() const { return view_cull_deg_; }
  const char* regionName(int n) const { return names_[n]; }
  double slope() const { return slope_; }
  double farEccDeg() const { return far_ecc_deg_; }
  Preset preset() const { return preset_; }

 private:
  RegionModel() = default;
  // The steps of create(): the regions of one kind of preset (ACUITY's levels, Table
  // I's regions, custom bounds), then the far eccentricity they all share.
  Status setAcuityLevels(const AcuityConfig& config);
  void setTableIRegions(int table_bounds);
  Status setCustomRegions(const std::vector<double>& bounds);
  Status setFarEccentricity(double far);
  Preset preset_ = Preset::kFRef;
  int region_count_ = 1;
  std::array<double, kMaxRegions - 1> bound_deg_{};
  std::array<const char*, kMaxRegions> names_{};
  double slope_ = kDefaultSlope;
  double far_ecc_deg_ = kDefaultFarEccDeg;
  double level_voxel_m_ = 0.0;
  double floor_m_ = 0.0;
  double floor_per_m2_ = 0.0;
  double level_margin_ = 0.0;
  int refine_passes_ = 0;
  ViewCull view_cull_ = ViewCull::kOff;
  double view_cull_deg_ = 0.0;
};

}  // namespace fovea::pipeline
