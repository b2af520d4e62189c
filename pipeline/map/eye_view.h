// The surfel map as the operator's eye sees it: which of the map's settled
// surfels an eye at a given position can see, found with a coarse depth buffer
// around the eye, so that the map's foveation sends what the operator can look
// at and nothing hidden behind nearer surfaces.
//
// The depth buffer is a cube map (six faces of face_cells x face_cells cells,
// each holding the distance to the nearest surface in its direction): it covers
// every direction, so the head may turn anywhere, and a cell is found with one
// division, not a trigonometric function. Pass one splats every settled surfel
// over its footprint (a radius of up to 2.5 cells around its centre, kMaxSplatCells) and every point already
// in the cloud (the frame's points the map does not explain: a moving object
// hides the wall behind it) into its cell; pass two appends each settled surfel
// that is not farther than its cell's nearest surface by more than the margin.
// A surfel is judged at its centre's cell, as a renderer's z-buffer would.
//
// Memory: the cube map and a per-brick table, allocated by create();
// appendVisible() allocates nothing.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline::map {

struct EyeViewConfig {
  // Cells per side of a cube face: 256 makes a cell 0.45 degrees at the face's
  // centre (0.2 at its corners), finer than the fovea's 1-2 degrees, in 1.5 MiB.
  int face_cells = 256;
  // A surfel is hidden when it lies behind its cell's nearest surface by more
  // than this fraction of its distance (plus the sensor's 3 sigma there): a
  // surface slanted up to about 60 degrees from the eye spans that much depth
  // over a splat of 3 cells, and must not hide itself.
  double occlusion_margin = 0.05;

  Status validate() const;
};

struct EyeViewStats {
  uint32_t settled = 0;       // settled surfels in the map (kSurfelSettled)
  uint32_t hidden = 0;        // ... behind a nearer surface from the eye: not sent
  uint32_t appended = 0;      // ... appended to the cloud
  uint32_t dropped_full = 0;  // ... visible but not appended: the cloud was full
  uint32_t frame_points = 0;  // points in the cloud before (they occlude, all are kept)
  int64_t ns = 0;
};

class EyeView {
 public:
  // max_bricks: the map's (SurfelMapConfig::max_bricks).
  static Result<EyeView> create(const EyeViewConfig& config, std::size_t max_bricks);

  // Appends to `cloud` (relative to cloud.origin_m) the settled surfels of `map`
  // that an eye at eye_m sees. The points already in the cloud occlude too and
  // stay. Never allocates.
  void appendVisible(const SurfelMap& map, const Eigen::Vector3d& eye_m, PointCloud& cloud, EyeViewStats& stats);

  // The depth buffer after appendVisible(): the nearest distance (metres from the
  // eye) in direction `dir` (any length), +infinity where nothing was splatted.
  float nearestAt(const Eigen::Vector3f& dir) const;

  const EyeViewConfig& config() const { return config_; }
  std::size_t memoryBytes() const { return nearest_.capacity() * sizeof(float) + brick_rel_.capacity() * sizeof(Eigen::Vector3f); }

 private:
  explicit EyeView(const EyeViewConfig& config, std::size_t max_bricks);

  // The cell of direction d (not zero), and the face coordinates' scale there.
  struct Cell {
    uint32_t face = 0;  // 0..5: +x, -x, +y, -y, +z, -z
    int u = 0, v = 0;
    float fu = 0.0f, fv = 0.0f;  // the direction's position in cell units (u <= fu < u + 1)
    float axis = 0.0f;           // |d| along the face's axis
  };
  Cell cellOf(const Eigen::Vector3f& d) const;
  // appendVisible()'s steps.
  void splatFramePoints(const PointCloud& cloud, const Eigen::Vector3f& eye);
  void splatSurfels(const SurfelMap& map, std::size_t bricks, EyeViewStats& stats);
  void splatDisc(const Cell& c, float radius, float dist);
  void appendUnhidden(const SurfelMap& map, std::size_t bricks, const Eigen::Vector3f& eye, PointCloud& cloud,
                      EyeViewStats& stats) const;
  std::size_t indexOf(const Cell& c, int u, int v) const {
    return (static_cast<std::size_t>(c.face) * face_cells_ + static_cast<std::size_t>(v)) * face_cells_ +
           static_cast<std::size_t>(u);
  }

  EyeViewConfig config_;
  int face_cells_ = 0;
  std::vector<float> nearest_;                 // 6 * face_cells^2
  std::vector<Eigen::Vector3f> brick_rel_;     // per frame: brick origin relative to the eye
};

}  // namespace fovea::pipeline::map
