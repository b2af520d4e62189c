// fovea-error-report: a configuration's record over the frames, the run's plan of
// configurations, and their summaries.
#include "tools/error_report/config_run.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "pipeline/quantile.h"
#include "tools/common/nan.h"

namespace fovea::tools {
namespace {

// Nearest-rank quantile of the values that are numbers; NaN when none is.
double quantileOf(std::vector<double> values, double q) {
  values.erase(std::remove_if(values.begin(), values.end(), [](double v) { return std::isnan(v); }), values.end());
  return values.empty() ? kNaN : pipeline::nearestRankQuantile(values, q);
}

}  // namespace

void RegionAccumulator::add(const pipeline::RegionError& e, uint32_t in, uint32_t out, double voxel_m, uint64_t bytes) {
  points_in += in;
  points_out += out;
  wire_bytes += bytes;
  voxel_sum_m += voxel_m;
  points += e.points;
  seen += e.seen;
  above += e.above_mar;
  above_reference += e.above_reference_mar;
  sum_sq_m2 += e.sum_sq_m2;
  max_m = std::max(max_m, e.max_m);
  ratio_max = std::max(ratio_max, e.ratio_max);
  if (e.seen > 0) {
    ratio_median.push_back(e.ratio_median);
    ratio_p95.push_back(e.ratio_p95);
  }
  ratio_first.push_back(e.first_deg_points ? e.ratio_median_first_deg : kNaN);
  ratio_last.push_back(e.last_deg_points ? e.ratio_median_last_deg : kNaN);
}

RegionSummary RegionAccumulator::summarise(int frames) const {
  RegionSummary s;
  const double n = std::max(frames, 1);
  s.voxel_mm = 1e3 * voxel_sum_m / n;
  s.points_in = static_cast<double>(points_in) / n;
  s.points_out = static_cast<double>(points_out) / n;
  s.wire_bytes = static_cast<double>(wire_bytes) / n;
  s.rms_mm = points ? 1e3 * std::sqrt(sum_sq_m2 / static_cast<double>(points)) : 0.0;
  s.max_mm = 1e3 * max_m;
  s.rms_over_voxel = s.voxel_mm > 0.0 ? s.rms_mm / s.voxel_mm : kNaN;
  s.max_over_voxel = s.voxel_mm > 0.0 ? s.max_mm / s.voxel_mm : kNaN;
  s.seen = seen;
  s.share_above_mar = seen ? static_cast<double>(above) / static_cast<double>(seen) : 0.0;
  s.share_above_reference_mar = seen ? static_cast<double>(above_reference) / static_cast<double>(seen) : 0.0;
  s.ratio_median = ratio_median.empty() ? 0.0 : quantileOf(ratio_median, 0.5);
  s.ratio_p95 = ratio_p95.empty() ? 0.0 : quantileOf(ratio_p95, 0.5);
  s.ratio_max = ratio_max;
  s.ratio_first_deg = quantileOf(ratio_first, 0.5);
  s.ratio_last_deg = quantileOf(ratio_last, 0.5);
  return s;
}

std::vector<ConfigRun> planRuns(const Options& options) {
  std::vector<ConfigRun> runs;
  for (firmware::FoveationSource source : options.sources) {
  for (pipeline::Preset preset : options.presets) {
    for (double slope : options.slopes) {
      // The acuity mode once per level margin (its rows say which).
      const bool acuity = preset == pipeline::Preset::kAcuity;
      std::vector<std::pair<double, int>> margins;  // (k, refinement passes)
      for (double margin : acuity ? options.acuity_margins : std::vector<double>{0.0}) margins.emplace_back(margin, 0);
      if (acuity) margins.insert(margins.end(), options.acuity_refined.begin(), options.acuity_refined.end());
      for (const auto& [margin, passes] : margins) {
        // Refined rows without floors: refinement already keeps only what the eye resolves.
        const std::vector<AcuityFloor> floors =
            acuity && passes == 0 ? acuityFloors(options.acuity_floors_mm, options.acuity_noise_floors_mm)
                                  : std::vector<AcuityFloor>{AcuityFloor{}};
        for (const AcuityFloor& floor : floors) {
          for (pipeline::ViewCull cull : acuity ? options.view_culls : std::vector<pipeline::ViewCull>{pipeline::ViewCull::kOff}) {
            ConfigRun r;
            r.source = source;
            r.config.acuity.preset = preset;
            r.config.acuity.slope = slope;
            if (acuity) {
              r.config.acuity.level_margin = margin;
              r.config.acuity.refine_passes = passes;
              r.config.acuity.floor_m = floor.m;
              r.config.acuity.floor_per_m2 = floor.per_m2;
              r.config.acuity.view_cull = cull;
            }
            r.time_ms.reserve(options.frames);
            r.wall_ms.reserve(options.frames);
            runs.push_back(std::move(r));
          }
        }
      }
    }
  }
  }
  return runs;
}

ConfigSummary summarise(const ConfigRun& r) {
  Result<pipeline::RegionModel> model = pipeline::RegionModel::create(r.config.acuity);
  ConfigSummary c;
  c.preset = configName(r.config.acuity);
  c.source = std::string(firmware::foveationSourceName(r.source));
  c.slope = r.config.acuity.slope;
  c.frames = r.frames;
  c.time_ms_median = quantileOf(r.time_ms, 0.5);
  c.time_ms_p90 = quantileOf(r.time_ms, 0.9);
  c.wall_ms_median = quantileOf(r.wall_ms, 0.5);
  c.d0_median_m = quantileOf(r.d0_m, 0.5);
  c.at_eye = r.at_eye;
  c.no_representative = r.no_representative;
  for (int reg = 0; reg < model->regionCount(); ++reg) {
    RegionSummary s = r.regions[reg].summarise(r.frames);
    s.index = reg;
    s.name = model->regionName(reg);
    if (model->levels()) {
      s.ecc_min_deg = s.ecc_max_deg = kNaN;  // no band: each point at its own eccentricity
    } else {
      s.ecc_min_deg = reg == 0 ? 0.0 : model->boundDeg(reg - 1);
      s.ecc_max_deg = reg < model->boundCount() ? model->boundDeg(reg) : 180.0;
    }
    if (reg == 0) s.voxel_mm = 0.0, s.rms_over_voxel = kNaN, s.max_over_voxel = kNaN;
    c.regions.push_back(s);
  }
  c.all = r.all.summarise(r.frames);
  c.all.name = "all";
  c.all.voxel_mm = 0.0;
  c.all.ratio_first_deg = kNaN;
  c.all.ratio_last_deg = kNaN;
  if (r.truth.seen > 0) {
    c.truth = r.truth.summarise(r.frames);
    c.have_truth = true;
  }
  if (r.surface_frames > 0) {
    c.have_surface = true;
    c.surface_share_above_mar = r.surface.shareAboveMar();
    c.surface_share_above_reference_mar = r.surface.shareAboveReferenceMar();
    c.surface_rms_mm = r.surface.with_nearest ? 1e3 * std::sqrt(r.surface.sum_sq_m2 / static_cast<double>(r.surface.with_nearest)) : kNaN;
    c.surface_points = static_cast<double>(r.surface.points) / static_cast<double>(r.surface_frames);
  }
  if (r.source == firmware::FoveationSource::kMap) {
    const double n = std::max(r.frames, 1);
    c.fuse_ms_median = quantileOf(r.fuse_ms, 0.5);
    c.map_frame_points = static_cast<double>(r.map_frame_points) / n;
    c.map_surfels = static_cast<double>(r.map_surfels) / n;
  }
  return c;
}

}  // namespace fovea::tools
