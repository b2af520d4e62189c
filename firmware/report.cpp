#include "firmware/report.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "pipeline/quantile.h"

namespace fovea::firmware {

double Samples::quantile(double q) const {
  if (values_.empty()) return 0.0;
  std::vector<double> scratch = values_;
  return pipeline::nearestRankQuantile(scratch, q);
}

double Samples::max() const { return values_.empty() ? 0.0 : *std::max_element(values_.begin(), values_.end()); }

double Samples::mean() const {
  return values_.empty() ? 0.0 : std::accumulate(values_.begin(), values_.end(), 0.0) / static_cast<double>(values_.size());
}

void RegionTotals::add(const pipeline::FoveationStats& stats) {
  for (int r = 0; r < stats.region_count; ++r) {
    points_in[r] += stats.regions[r].points_in;
    points_out[r] += stats.regions[r].points_out;
    voxel_size_sum_m[r] += stats.regions[r].voxel_size_m;
  }
  ++frames;
}

void printRegionTable(std::FILE* out, const pipeline::RegionModel& model, const RegionTotals& totals) {
  if (totals.frames == 0) return;
  const double n = static_cast<double>(totals.frames);
  std::fprintf(out, "  %-16s %9s %10s %12s %12s %8s\n", "region", "ecc[deg]", "voxel[mm]", "points in", "points out",
               "kept");
  uint64_t all_in = 0, all_out = 0;
  for (int r = 0; r < model.regionCount(); ++r) {
    char ecc[16], voxel[16];
    if (model.levels()) {
      std::snprintf(ecc, sizeof ecc, "%s", "own");  // each point at its own eccentricity
    } else if (r < model.boundCount()) {
      std::snprintf(ecc, sizeof ecc, "<= %g", model.boundDeg(r));
    } else if (r > 0) {
      std::snprintf(ecc, sizeof ecc, "> %g", model.boundDeg(r - 1));
    } else {
      std::snprintf(ecc, sizeof ecc, "%s", "all");
    }
    if (r == 0) {
      std::snprintf(voxel, sizeof voxel, "%s", "(kept)");
    } else {
      std::snprintf(voxel, sizeof voxel, "%.2f", 1000.0 * totals.voxel_size_sum_m[r] / n);
    }
    const double in = static_cast<double>(totals.points_in[r]) / n;
    const double kept_out = static_cast<double>(totals.points_out[r]) / n;
    std::fprintf(out, "  %-16s %9s %10s %12.0f %12.0f %7.1f%%\n", model.regionName(r), ecc, voxel, in, kept_out,
                 in > 0 ? 100.0 * kept_out / in : 0.0);
    all_in += totals.points_in[r];
    all_out += totals.points_out[r];
  }
  std::fprintf(out, "  %-16s %9s %10s %12.0f %12.0f %7.1f%%\n", "total", "", "", static_cast<double>(all_in) / n,
               static_cast<double>(all_out) / n,
               all_in > 0 ? 100.0 * static_cast<double>(all_out) / static_cast<double>(all_in) : 0.0);
}

}  // namespace fovea::firmware
