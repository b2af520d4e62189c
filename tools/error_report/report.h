// fovea-error-report: what one configuration's measurements sum up to, and the
// writers of the Markdown table, the CSV and the gnuplot script.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"
#include "pipeline/acuity.h"

namespace fovea::tools {

// The raw payload of a point, x, y, z as float and r, g, b as uchar: what a
// stream without fovea's codec would send (the report's "raw bytes").
inline constexpr double kRawBytesPerPoint = 15.0;

// One region (or all regions pooled) of one configuration, over the frames.
struct RegionSummary {
  int index = -1;            // region index; -1 for all regions
  std::string name;          // "fovea", ..., or "all"
  double ecc_min_deg = 0.0;  // eccentricity band (min exclusive except for the fovea)
  double ecc_max_deg = 180.0;
  double voxel_mm = 0.0;     // mean over frames; 0: no voxel (fovea, all)
  double points_in = 0.0;    // mean per frame
  double points_out = 0.0;   // mean per frame
  double wire_bytes = 0.0;   // mean per frame: the region's chunks as datagrams (net/codec.h, MTU 1200)
  double rms_mm = 0.0;       // pooled over every point of every frame
  double max_mm = 0.0;       // over every frame
  double rms_over_voxel = 0.0;  // NaN without a voxel
  double max_over_voxel = 0.0;  // NaN without a voxel
  uint64_t seen = 0;            // points with a defined angle, over the frames
  double share_above_mar = 0.0; // pooled: above / seen
  double share_above_reference_mar = 0.0;  // the same for the fixed observer (ReportContext)
  // alpha / MAR(ecc): median over frames of each frame's median / p95; max over all.
  double ratio_median = 0.0;
  double ratio_p95 = 0.0;
  double ratio_max = 0.0;
  // Median over frames of the median ratio within 1 degree of the inner / outer
  // bound; NaN when the band is empty (or absent).
  double ratio_first_deg = 0.0;
  double ratio_last_deg = 0.0;
};

struct ConfigSummary {
  std::string preset;  // "F1", "F2", "F3", "FREF"
  double slope = 0.0;
  int frames = 0;
  // Back-projection through sampled output, per frame: thread CPU time (median,
  // p90) and wall-clock time (median).
  double time_ms_median = 0.0;
  double time_ms_p90 = 0.0;
  double wall_ms_median = 0.0;
  double d0_median_m = 0.0;  // NaN: no d0 (ACUITY)
  uint64_t at_eye = 0;
  uint64_t no_representative = 0;
  std::vector<RegionSummary> regions;
  RegionSummary all;
  // All points against the true (noiseless) surface, when the camera has one.
  bool have_truth = false;
  RegionSummary truth;
  // What the frame costs on the wire: fovea's chunk codec (default settings,
  // 1200-byte datagrams, framing and authentication tag included).
  double bytesPerFrame() const { return all.wire_bytes; }
  double rawBytesPerFrame() const { return all.points_out * kRawBytesPerPoint; }
};

struct ReportContext {
  std::string command_line;  // as the user typed it (argv joined)
  std::string camera;        // e.g. "mock:living-room 640x480"
  std::string gaze;          // how the gaze was chosen
  std::string host;          // CPU architecture, cores, compiler, build type, load
  int frames = 0;            // frames measured
  double pixel_pitch_arcmin = 0.0;  // atan(1 / fx) of the camera
  double reference_slope = 0.022;   // the fixed observer's m
  std::string date_utc;
  std::string extra_markdown;  // sections appended to report.md (dynamics.h)
};

// ACUITY's sensor floor of one row: constant (AcuityConfig::floor_m) and growing
// with the squared distance (floor_per_m2).
struct AcuityFloor {
  double m = 0.0;
  double per_m2 = 0.0;
};
// The rows' floors: each constant one in mm (0: none), then each distance-dependent
// one in mm per m^2 (--acuity-floors, --acuity-noise-floors).
std::vector<AcuityFloor> acuityFloors(const std::vector<double>& floors_mm, const std::vector<double>& noise_floors_mm);

// A configuration's name in the tables: the preset, and for ACUITY its level
// margin, then `after_margin` (e.g. " growth"), its floors and its view cull.
std::string configName(const pipeline::AcuityConfig& a, std::string_view after_margin = "");

// "%.*f" of v, or `missing` for NaN (the tables' number format).
std::string formatFixed(double v, int precision, const char* missing = "-");

// Writes out_dir/report.csv, out_dir/report.md, out_dir/report_plot.dat and
// out_dir/report.gp. kIoError naming the file on failure.
Status writeCsv(const std::string& path, const std::vector<ConfigSummary>& configs);
Status writeMarkdown(const std::string& path, const ReportContext& context, const std::vector<ConfigSummary>& configs,
                     bool have_plot);
// The plot data (one block per slope, one line per preset) and a script that
// draws report.png from it when run in the same directory.
Status writePlotFiles(const std::string& data_path, const std::string& script_path, const ReportContext& context,
                      const std::vector<ConfigSummary>& configs);

}  // namespace fovea::tools
