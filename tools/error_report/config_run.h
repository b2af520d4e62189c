// fovea-error-report: what one configuration gathers over the measured frames,
// the plan of every configuration a run measures, and what each sums up to
// (report.h's ConfigSummary). Apart from the measuring, so that the frame loop
// and the summaries share one record of a configuration.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "firmware/frame_foveator.h"
#include "pipeline/error_metrics.h"
#include "pipeline/foveator.h"
#include "tools/error_report/options.h"
#include "tools/error_report/report.h"
#include "tools/error_report/surface_error.h"

namespace fovea::tools {

// One region's (or all regions') measurements over the frames.
struct RegionAccumulator {
  uint64_t points_in = 0, points_out = 0, wire_bytes = 0;
  double voxel_sum_m = 0.0;
  uint64_t points = 0, seen = 0, above = 0, above_reference = 0;
  double sum_sq_m2 = 0.0, max_m = 0.0, ratio_max = 0.0;
  std::vector<double> ratio_median, ratio_p95, ratio_first, ratio_last;  // one per frame

  void add(const pipeline::RegionError& e, uint32_t in, uint32_t out, double voxel_m, uint64_t bytes);
  RegionSummary summarise(int frames) const;
};

struct ConfigRun {
  pipeline::FoveationConfig config;
  firmware::FoveationSource source = firmware::FoveationSource::kFrame;
  std::vector<double> time_ms;  // thread CPU time (map source: the frame's fusion included)
  std::vector<double> wall_ms;  // wall clock
  std::vector<double> d0_m;
  std::array<RegionAccumulator, pipeline::kMaxRegions> regions;
  RegionAccumulator all;
  RegionAccumulator truth;  // all points, against the noiseless surface (mock cameras)
  SurfaceError surface;     // the true surface against its nearest sent points (surface_error.h)
  uint64_t surface_frames = 0;
  std::vector<double> fuse_ms;  // map source: the frame's fusion (thread CPU time), part of time_ms
  uint64_t map_frame_points = 0, map_surfels = 0;  // map source: the frame's unexplained points, the map's surfels sent
  uint64_t at_eye = 0, no_representative = 0;
  int frames = 0;
};

// Every configuration the report measures, in the order presets x slopes (x
// ACUITY's margins, floors and view culls), each with room for its frames.
std::vector<ConfigRun> planRuns(const Options& options);

// A run's figures over its frames, per region and in all.
ConfigSummary summarise(const ConfigRun& r);

}  // namespace fovea::tools
