// fovea-error-report: what the sent points look like against the true surface,
// the same way for every source (the frame's own cloud, or the fused map).
//
// The report's other error columns pair each input point with its
// representative (pipeline/error_metrics.h): that needs the input, and the map
// source's input (its surfels) is not the frame's pixels. This measure needs
// only the true surface and what is sent:
//
//   for every point P of the true surface (the noiseless twin's frame,
//   back-projected: every pixel whose noiseless depth is in range), S is the
//   sent point nearest P in 3D (an exact nearest neighbour, a k-d tree over the
//   sent points); with a = P - H and b = S - H (H the eye), P is "above its
//   MAR" when angle(a, b) > MAR(ecc(P)) = m ecc(P) + 1 arcmin (Eq. 1, strictly
//   greater; m the configuration's own, and a fixed observer's m beside it).
//   A frame with nothing sent counts every P above. P at the eye (a = 0) or
//   S at the eye (b = 0) has no angle and is left out, as in error_metrics.h.
//
// Both a hole (no sent point near P) and a displaced point (noise, a voxel's
// centroid) count; sent points away from the true surface that are not the
// nearest to any P (e.g. the map's surfels outside the camera's view, which the
// true frame does not cover) are not judged. Occlusion is ignored.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"
#include "pipeline/point_cloud.h"
#include "pipeline/partition.h"

namespace fovea::tools {

struct SurfaceError {
  uint64_t points = 0;               // true surface points measured
  uint64_t seen = 0;                 // ... with a defined angle
  uint64_t above_mar = 0;            // ... whose nearest sent point is displaced beyond MAR (the configuration's m)
  uint64_t above_reference_mar = 0;  // ... beyond the fixed observer's MAR
  double sum_sq_m2 = 0.0;            // squared distance to the nearest sent point (points with a sent point)
  uint64_t with_nearest = 0;         // points that had a nearest sent point (0 when nothing was sent)

  void add(const SurfaceError& e) {
    points += e.points;
    seen += e.seen;
    above_mar += e.above_mar;
    above_reference_mar += e.above_reference_mar;
    sum_sq_m2 += e.sum_sq_m2;
    with_nearest += e.with_nearest;
  }
  double shareAboveMar() const { return seen ? static_cast<double>(above_mar) / static_cast<double>(seen) : 0.0; }
  double shareAboveReferenceMar() const {
    return seen ? static_cast<double>(above_reference_mar) / static_cast<double>(seen) : 0.0;
  }
};

class SurfaceErrorEvaluator {
 public:
  // Scratch for up to max_sent sent points.
  explicit SurfaceErrorEvaluator(std::size_t max_sent);

  // Measures `sent` against `truth` (both in world coordinates through their
  // origin_m) for the gaze used (normalised here). kInvalidInput for a gaze
  // whose origin or direction is not usable, kCapacityExceeded beyond max_sent.
  Status evaluate(const pipeline::PointCloud& truth, const pipeline::PointCloud& sent, const pipeline::Gaze& gaze,
                  double slope, double reference_slope, SurfaceError& error);

 private:
  void build(std::size_t lo, std::size_t hi, int axis);
  void nearest(std::size_t lo, std::size_t hi, const Eigen::Vector3d& q, double& best_d2, std::size_t& best) const;

  std::size_t max_sent_;
  std::vector<Eigen::Vector3d> points_;  // sent points relative to the truth's origin, in k-d tree order
  std::vector<uint8_t> axis_;            // split axis of the node at each index
};

}  // namespace fovea::tools
