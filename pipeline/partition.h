// Map partitioning (Algorithm 1): assign each point to a concentric gaze cone.
//
// For a point P, eye H and unit gaze L: v = P - H, t = v.L (along the gaze) and
// d = |v - t L| (from the rejection vector, so far points near the axis keep their
// precision). The point belongs to the first region whose bound e satisfies
// "the angle between v and L is at most e", evaluated without tan() at 90 degrees:
//   e <  90:  d <= tan(e) * t            (false for every point behind the eye)
//   e == 90:  t >= 0
//   e >  90:  t >= 0  or  d >= tan(180 - e) * (-t)
// Boundaries are inclusive. A point at H (t = d = 0) lies within every bound and so
// goes to the fovea. Points with a non-finite coordinate get kRegionInvalid and are
// counted, never classified. The arithmetic below is the specification that the
// SIMD kernels must reproduce bit for bit: double precision, this operation order,
// no FMA (the build sets -ffp-contract=off).
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include <Eigen/Core>

#include "core/result.h"
#include "pipeline/acuity.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline {

inline constexpr uint8_t kRegionInvalid = 0xFF;
// Preset::kAcuity with view_cull = drop: outside the viewer's field of view, not sent.
inline constexpr uint8_t kRegionCulled = 0xFE;

// Eye position and gaze direction in world coordinates.
struct Gaze {
  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();
  // Used by Preset::kAcuity only (acuity_levels.h); the paper's presets ignore them.
  // Degrees by which the fovea is widened to cover where the eye may be when the
  // frame is shown (the gaze's age and the eye's speed: firmware/gaze_policy.h).
  double fovea_growth_deg = 0.0;
  // The forward axis of the viewer's head (HMD), when known: the view cull's axis.
  bool view_known = false;
  Eigen::Vector3d view_forward = Eigen::Vector3d::UnitZ();
};

// Checks that the gaze is finite and has a usable direction (and view_forward when
// view_known), and that fovea_growth_deg is within [0, 180]; returns it with unit
// directions. kInvalidInput otherwise (NaN/Inf, zero or denormal length).
Result<Gaze> normalizeGaze(const Gaze& gaze);

// The per-bound constants of the cone test, precomputed once per configuration.
struct ConeBounds {
  enum class Kind : uint8_t { kBelow90, kAt90, kAbove90 };
  int count = 0;                               // number of bounds = regions - 1
  std::array<Kind, kMaxRegions - 1> kind{};
  std::array<double, kMaxRegions - 1> tan_e{};  // tan(e) below 90, tan(180 - e) above

  static ConeBounds fromModel(const RegionModel& model);

  bool inside(int j, double t, double d) const {
    switch (kind[j]) {
      case Kind::kBelow90: return d <= tan_e[j] * t;
      case Kind::kAt90: return t >= 0.0;
      case Kind::kAbove90: return t >= 0.0 || d >= tan_e[j] * (-t);
    }
    return false;
  }
  // Region of a point at (t, d) from the eye; count (the outermost) if no bound holds.
  uint8_t classify(double t, double d) const {
    for (int j = 0; j < count; ++j) {
      if (inside(j, t, d)) return static_cast<uint8_t>(j);
    }
    return static_cast<uint8_t>(count);
  }
};

// Distance along the gaze (t) and from the gaze ray's line (d) of the point
// (vx, vy, vz) = P - H, for a unit direction l.
struct AxialRadial {
  double t;
  double d;
};
inline AxialRadial axialRadial(double vx, double vy, double vz, const Eigen::Vector3d& l) {
  const double t = vx * l.x() + vy * l.y() + vz * l.z();
  const double rx = vx - t * l.x();
  const double ry = vy - t * l.y();
  const double rz = vz - t * l.z();
  return {t, std::sqrt(rx * rx + ry * ry + rz * rz)};
}

struct PartitionCounts {
  std::array<uint32_t, kMaxRegions> per_region{};
  uint32_t invalid = 0;  // non-finite coordinates
  uint32_t culled = 0;   // outside the viewer's field of view, dropped (kRegionCulled)
};

// Scalar reference. gaze must come from normalizeGaze(). Writes cloud.size()
// region indices to region_out.
void partitionRef(const PointCloud& cloud, const Gaze& gaze, const ConeBounds& bounds,
                  uint8_t* region_out, PartitionCounts& counts);

}  // namespace fovea::pipeline
