// fovea-compare's report: the preamble, the table with its legend, the pyramid's
// cells, what differs from PCL and why, and the `method=...` lines.
#include "bench/compare_report.h"

#include <cstdio>
#include <set>
#include <string>
#include <string_view>

#include "bench/compare_against_pcl.h"
#include "pipeline/kernels/foveation_simd.h"

namespace fovea::bench::compare {
namespace {

// fovea-ref's fixation distance and voxel sizes.
void printFixation(const FoveaMethod& fovea_ref) {
  const pipeline::FoveationStats& s = fovea_ref.stats();
  std::printf("  d0 %.3f m (%s); voxel sizes:", s.fixation.d0_m,
              std::string(pipeline::fixationSourceName(s.fixation.source)).c_str());
  for (int r = 1; r < s.region_count; ++r) std::printf(" region %d %.2f mm", r, 1000.0 * s.regions[r].voxel_size_m);
  std::printf("\n");
}

void printTableRow(const Row& row, const Timing* pcl, const Timing* floor, std::size_t input_points) {
  const Timing& t = row.timing;
  if (!t.ran) {
    std::printf("%-23s %9s   -- %s\n", row.entry->name, "-", row.entry->what);
    return;
  }
  char vs_pcl[16] = "-", vs_floor[16] = "-", diff[24] = "-";
  if (pcl) std::snprintf(vs_pcl, sizeof vs_pcl, "%.2fx", pcl->median / t.median);
  if (floor) std::snprintf(vs_floor, sizeof vs_floor, "%.3fx", floor->median / t.median);
  if (pcl && t.has_output && &t != pcl) {
    std::snprintf(diff, sizeof diff, "%.4f", compareWithPcl(t.output, pcl->output).max_mm);
  } else if (&t == pcl) {
    std::snprintf(diff, sizeof diff, "(reference)");
  }
  char above[16] = "-", rms[16] = "-";
  if (row.error) {
    std::snprintf(above, sizeof above, "%.3f", 100.0 * row.error->all.shareAboveReferenceMar());
    std::snprintf(rms, sizeof rms, "%.3f", 1000.0 * row.error->all.rmsM());
  }
  std::printf("%-23s %9.3f %9.3f %9.3f %10zu %9.2f %9s %9s %12s %9s %8s\n", row.entry->name, t.median, t.min, t.max,
              t.out_points, 1e6 * t.median / static_cast<double>(input_points), vs_pcl, vs_floor, diff, above, rms);
}

// The table, one line per row, and its legend.
void printTable(const std::vector<Row>& rows, const Input& input) {
  const Timing* pcl = findTiming(rows, "pcl");
  const Timing* floor = findTiming(rows, "floor");
  std::printf("\n%-23s %9s %9s %9s %10s %9s %9s %9s %12s %9s %8s\n", "method", "median ms", "min ms", "max ms",
              "out points", "ns/point", "vs pcl", "vs floor", "max d [mm]", ">MAR %", "rms mm");
  for (const Row& row : rows) printTableRow(row, pcl, floor, input.input_points);
  std::printf(
      "\n  ns/point: median time / %zu input points. vs pcl, vs floor: speed-up = that method's median / this "
      "method's\n  (above 1: faster). The floor only reads the input once; it produces nothing.\n"
      "  >MAR %%: input points whose move to their output point the eye resolves (pipeline/error_metrics.h, the\n"
      "  fixed observer m = 0.022); rms mm: root mean square of those moves. Measured after the timing.\n",
      input.input_points);
}

// The pyramid's cells: where its points came from and how many cells it tested.
void printPyramidCells(const std::vector<Row>& rows) {
  for (const Row& row : rows) {
    if (row.method == nullptr || std::string_view(row.entry->name).find("pyramid") == std::string_view::npos) {
      continue;
    }
    const pipeline::PyramidStats& ps = static_cast<const PyramidMethod*>(row.method.get())->stats();
    std::printf("  %s: %u cells tested; points by level (0 = pixels):", row.entry->name, ps.cells_tested);
    for (std::size_t k = 0; k < ps.out_by_level.size(); ++k) std::printf(" %u", ps.out_by_level[k]);
    std::printf("\n");
  }
}

// What differs from PCL in one row's output, and (for fovea-ref) why.
void printPclDifference(const Row& row, const Timing& pcl, const FoveaMethod* fovea_ref) {
  const Timing& t = row.timing;
  std::set<VoxelKey> moved;
  std::size_t sampled = 0, differ = 0;
  const bool is_ref = fovea_ref != nullptr && std::string_view(row.entry->name) == "fovea-ref";
  if (is_ref) differ = latticeDisagreements(fovea_ref->cloud(), fovea_ref->regions(), t.output, sampled, moved);
  const Difference d = compareWithPcl(t.output, pcl.output, is_ref ? &moved : nullptr);
  std::printf("\n  %s vs pcl, voxels matched by (region, world voxel index floor(c / v)):\n", row.entry->name);
  std::printf("    fovea points: %zu vs %zu (%s); voxel sizes %s\n", d.fovea_here, d.fovea_pcl,
              d.fovea_here == d.fovea_pcl ? "both untouched" : "DIFFERENT",
              d.same_voxel_sizes ? "identical" : "DIFFERENT");
  std::printf("    %zu voxels matched, %zu only in %s, %zu only in pcl\n", d.matched, d.only_here, row.entry->name,
              d.only_pcl);
  std::printf("    centroid distance, matched voxels with the same points: median %.5f mm, p99 %.5f mm, max %.5f mm\n",
              d.median_mm, d.p99_mm, d.same_members_max_mm);
  if (is_ref) {
    std::printf("    centroid distance, %zu matched voxels that gained or lost a point to PCL's lattice: max %.4f mm\n",
                d.moved_voxels, d.moved_max_mm);
    std::printf(
        "    why: PCL's lattice is world-anchored too (it floors p * inverse_leaf), but in float: the world\n"
        "    coordinate, 1/leaf and their product are rounded to float, so %zu of %zu sampled points (%.4f %%)\n"
        "    fall into a neighbouring voxel; those voxels gain or lose a point (centroids up to millimetres\n"
        "    apart, or unmatched voxels). Elsewhere PCL sums in float (pcl::CentroidPoint, Vector3f) where\n"
        "    fovea sums in double relative to the voxel's first point: float rounding (micrometres).\n",
        differ, sampled, sampled ? 100.0 * static_cast<double>(differ) / static_cast<double>(sampled) : 0.0);
  }
}

// One `method=... ms_median=...` line per row that ran.
void printMachineLines(const std::vector<Row>& rows, const Input& input) {
  std::printf("\n");
  for (const Row& row : rows) {
    const Timing& t = row.timing;
    if (!t.ran) continue;
    std::printf("method=%s ms_median=%.4f ms_min=%.4f ms_max=%.4f out_points=%zu ns_per_point=%.3f", row.entry->name,
                t.median, t.min, t.max, t.out_points, 1e6 * t.median / static_cast<double>(input.input_points));
    if (row.error) {
      std::printf(" above_mar_pct=%.4f rms_mm=%.4f", 100.0 * row.error->all.shareAboveReferenceMar(),
                  1000.0 * row.error->all.rmsM());
    }
    std::printf("\n");
  }
}

}  // namespace

void printPreamble(const CompareOptions& options, const Input& input) {
  std::printf("fovea-compare: %s\n", input.description.c_str());
  std::printf("  SIMD target %s, %d cores for fovea-simd-mt\n", pipeline::simdTargetName(pipeline::activeSimdTarget()),
              allCores());
  std::printf("  gaze origin (%.3f, %.3f, %.3f) m, direction (%.4f, %.4f, %.4f); preset %s, fixation hit; "
              "%zu input points; %d timed rounds (each method once per round) after one warm-up; ACUITY's "
              "distance floor %g mm/m^2\n",
              input.gaze.origin_m.x(), input.gaze.origin_m.y(), input.gaze.origin_m.z(), input.gaze.direction.x(),
              input.gaze.direction.y(), input.gaze.direction.z(), options.preset_name.c_str(), input.input_points,
              options.runs, options.acuity_floor_mm);
}

void printReport(const std::vector<Row>& rows, const Input& input) {
  const FoveaMethod* fovea_ref = foveaRef(rows);
  if (fovea_ref != nullptr) printFixation(*fovea_ref);
  printTable(rows, input);
  printPyramidCells(rows);
  // What differs from PCL, and why.
  if (const Timing* pcl = findTiming(rows, "pcl")) {
    for (const Row& row : rows) {
      const Timing& t = row.timing;
      if (!t.ran || !t.has_output || &t == pcl) continue;
      printPclDifference(row, *pcl, fovea_ref);
    }
  }
  printMachineLines(rows, input);
}

}  // namespace fovea::bench::compare
