// ACUITY on the image pyramid: an approximate foveation that works on the organised
// depth image instead of a point cloud (issue 27; docs/kernels.md, "The image pyramid").
//
// The exact methods back-project every pixel, then put every point in a world
// voxel. A camera frame is organised: a square of 2^k x 2^k neighbouring pixels on
// one surface is a patch of about 2^k z / f metres, so a pyramid of per-cell sums
// (valid pixels, camera-frame x, y, z sums, the depths' spread and largest value,
// and at level 1 the colour sums) gives every coarse "voxel" the image can offer
// without touching a point twice. The sampler decides the rule for the cells the
// walk will reach, level by level from the top (pyramidMergeRef / Simd below), then
// walks the pyramid from its coarsest cells down and emits a cell's centroid where
// ACUITY's rule holds for the whole cell:
//
//     margin * e <= r_min * sin(MAR(E_min))        (acuity_levels.h, with e for v_n)
//
// e is the cell's extent, max(2^k z_max max(1/fx, 1/fy), 2 sigma_z), sigma_z the
// standard deviation of its depths: the side of a cube that holds its points but
// for the depth noise's tails, so a point moves about sqrt(3) e to the centroid at
// most, as a point moves at most sqrt(3) v_n to its voxel's. (The depths' range
// instead of 2 sigma would hold every point, but a noisy sensor's range is several
// sigma and nothing would merge; the measured share above the MAR tells the cost.)
// r_min and E_min are the nearest distance and the smallest eccentricity any point
// of that cube can have seen from the eye (the centroid's, less the cube's diagonal
// and the angle it subtends, less the fovea's growth). A cell thinner than the
// sensor floor (floor_m + floor_per_m2 s^2 at the centroid's distance s from the
// camera) merges too. A cell that fails splits into its four children; a single
// pixel is emitted as its back-projected point. A depth step inside a cell makes e
// large, so cells never average across a silhouette.
//
// What it is not: the exact world-voxel sampling. Cells are anchored to the image,
// not to the world, so a static scene's points move with the camera, and a cell's
// extent is a power of two in pixels, not the voxel size (between one and two times
// finer than the rule needs). The view cull is not applied. Its error against the
// exact methods is measured (bench/fovea-compare's pyramid rows), not assumed.
//
// Output order: the coarsest cells in row-major order, each cell's children in
// (top-left, top-right, bottom-left, bottom-right) order, depth first. Region of an
// output point: the pyramid level it came from (0 = a pixel); weight: its pixels.
// All memory is allocated by create(); sample() never allocates.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/kernel_set.h"
#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/acuity.h"
#include "pipeline/backproject.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"

namespace fovea::pipeline {

// The levels above the pixels: the coarsest cell is 2^levels pixels square. At most
// kMaxRegions - 1, so that the level fits the stream's region field.
inline constexpr int kMaxPyramidLevels = kMaxRegions - 1;

struct PyramidRule {
  float slope = static_cast<float>(kDefaultSlope);  // m of Eq. 1
  float margin = 0.5f;                              // AcuityConfig::level_margin
  float floor_m = 0.0f;                             // AcuityConfig::floor_m
  float floor_per_m2 = 0.0f;                        // AcuityConfig::floor_per_m2

  // The ACUITY knobs that apply (slope, margin, floors); the rest is ignored.
  static PyramidRule fromAcuity(const AcuityConfig& config);
  Status validate() const;
};

struct PyramidStats {
  uint32_t points_in = 0;   // valid pixels
  uint32_t points_out = 0;
  uint32_t cells_tested = 0;
  std::array<uint32_t, kMaxPyramidLevels + 1> out_by_level{};  // [0]: pixels
};

// The rule for `count` cells of one level, the specification: merge[i] = 1 where
// cell i merges, 0 where it splits. In float, one operation a step, in this order,
// no FMA (pyramidMergeSimd reproduces it bit for bit): inv_n = 1 / n; m = s inv_n;
// e = max(lateral zmax, 2 sqrt(m2 inv_n)); diagonal = sqrt(3) e; the floor test
// e <= floor_m + floor_per_m2 ((mx mx + my my) + mz mz) when floors; v = R m + o
// (each row ((r0 mx + r1 my) + r2 mz) + o); r and the centre's eccentricity as
// eyeViewSpec (growth 0); r_min = r - diagonal; spread = (diagonal / r_min) x
// rad-to-deg; E = (ecc - spread) - growth, 0 below 0; allowed = LevelBounds::allowedM
// (r_min, E); merge = floor test or (r > 2 diagonal and margin e <= allowed).
void pyramidMergeRef(const kernels::PyramidMergeParams& params, const kernels::PyramidCellSums& cells,
                     std::size_t count, float* merge);

class PyramidSampler {
 public:
  // Sized for frames up to max_width x max_height; levels in [1, kMaxPyramidLevels].
  // kernels: the rule's kernel, pyramidMergeRef or pyramidMergeSimd (same output).
  static Result<PyramidSampler> create(int max_width, int max_height, int levels = 5,
                                       KernelSet kernels = defaultKernelSet());

  // Foveates `frame` for `gaze` (from normalizeGaze(); its fovea growth is used)
  // into `out` (its capacity: at most the frame's pixels are ever needed). The
  // cloud's origin is the camera's position, as back-projection's. Errors: a frame
  // that validateFrame() refuses or larger than create()'s size, a bad range, rule
  // or gaze; kCapacityExceeded when the points do not fit `out` (left empty). representative_by_pixel, if not null (frame.pixelCount()
  // entries), gets for every valid pixel the index of its output point and
  // kNoRepresentative for the others (for error measures; it costs a pass).
  Status sample(const hal::RgbdFrame& frame, const DepthRange& range, const Gaze& gaze, const PyramidRule& rule,
                FoveatedCloud& out, PyramidStats& stats, uint32_t* representative_by_pixel = nullptr);

  static constexpr uint32_t kNoRepresentative = 0xFFFFFFFFu;

  int levels() const { return levels_; }
  // Bytes allocated by create().
  std::size_t memoryBytes() const;

 private:
  // Sums over each cell's valid pixels, camera frame, one array per sum (the
  // build's loops run over cells in step). Counts are exact in float (at most 4^7).
  // m2: the squared deviations of the depths from their mean (each square's own,
  // then combined pairwise). Cell (i, j) is at j * stride + i; the cells past width
  // and height up to stride and rows (even) are empty, so that every cell of the
  // level above has four children.
  struct Level {
    int width = 0, height = 0;
    int stride = 0, rows = 0;
    void setSize(int w, int h);
    void clearPadding();
    std::vector<float> n, sx, sy, sz, m2, zmax;
    std::vector<float> merge;  // the rule's verdict, for the cells the walk reaches
    std::vector<float> cr, cg, cb;  // level 1 only: colour sums over the valid pixels
    void resize(std::size_t cells);
  };
  struct Walk;  // one sample() call's constants

  PyramidSampler(int max_width, int max_height, int levels, KernelSet kernels);
  void buildFirstLevel(const hal::RgbdFrame& frame, const RawDepthRange& raw);
  void buildLevel(int k);
  // The rule for every cell the walk will reach, level by level from the top: the
  // non-empty top cells, then the non-empty children of the cells that split,
  // gathered into arrays for one kernel call a level.
  void decide(const hal::RgbdFrame& frame, const Gaze& gaze, const PyramidRule& rule, PyramidStats& stats);
  void visit(Walk& walk, int k, int i, int j) const;

  int max_width_ = 0;
  int max_height_ = 0;
  int levels_ = 0;
  KernelSet kernels_ = KernelSet::kSimd;
  std::vector<Level> pyramid_;  // [k - 1] is level k
  // decide()'s scratch, sized for level 1: the cells of this level and the last,
  // their sums gathered, the verdicts.
  std::vector<uint32_t> candidates_, parents_;
  std::vector<float> gathered_[6];
  std::vector<float> verdict_;
  // Two image rows, camera frame: x, z and validity (0 when invalid).
  std::vector<float> row_x_[2], row_z_[2], row_valid_[2];
  std::vector<float> column_xn_;                  // (u - cx) / fx per column
};

}  // namespace fovea::pipeline
