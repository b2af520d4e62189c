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
  // What was foveated: "frame" or "map" (--sources).
  std::string source = "frame";
  // The true surface against its nearest sent points (surface_error.h), when
  // the run measured it (--sources with map, a camera with a noiseless twin).
  bool have_surface = false;
  double surface_share_above_mar = 0.0;
  double surface_share_above_reference_mar = 0.0;
  double surface_rms_mm = 0.0;     // distance from each true point to its nearest sent point, RMS
  double surface_points = 0.0;     // true surface points per frame
  // Map source: the frame's fusion per frame (thread CPU time, median; part of
  // time_ms_median), and per frame on average the frame's unexplained points and
  // the map's surfels in the foveated cloud. NaN / 0 for the frame source.
  double fuse_ms_median = 0.0;
  double map_frame_points = 0.0;
  double map_surfels = 0.0;
  bool isMap() const { return source == "map"; }
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
  long map_warmup_frames = 0;  // frames fused into the map before the measured ones (--sources with map)
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

// Writes out_dir/report.csv, out_dir/report.md and the plot files (writePlotFiles).
// kIoError naming the file on failure.
Status writeCsv(const std::string& path, const std::vector<ConfigSummary>& configs);
// have_plot: gnuplot drew the plots (report.png, and report_acuity.png when the run
// has ACUITY rows), which the page then shows.
Status writeMarkdown(const std::string& path, const ReportContext& context, const std::vector<ConfigSummary>& configs,
                     bool have_plot);

// What writeCsv wrote, read back: each configuration's `all` row, the fields the
// plots use (--replot-from). kIoError when the file cannot be read, kParseError
// naming the line when a row does not fit the header.
Result<std::vector<ConfigSummary>> readCsvSummaries(const std::string& path);
// The camera as writeMarkdown put it on report.md's "- camera: " line (the plots'
// title). kParseError when the page has no such line.
Result<std::string> readMarkdownCamera(const std::string& path);

// A gnuplot script, the data it reads and the PNG it draws, all in one directory.
struct PlotFiles {
  const char* data;
  const char* script;
  const char* png;
};
// The paper's presets and at most kMainPlotAcuitySettings ACUITY settings, so that
// a reader can tell every series and label apart.
inline constexpr PlotFiles kMainPlot = {"report_plot.dat", "report.gp", "report.png"};
// Every ACUITY setting of the run beside the paper's presets, a row of panels per slope.
inline constexpr PlotFiles kAcuityPlot = {"report_acuity_plot.dat", "report_acuity.gp", "report_acuity.png"};
inline constexpr std::size_t kMainPlotAcuitySettings = 3;

// The ACUITY settings kMainPlot names, by configName, at most kMainPlotAcuitySettings:
// first those docs/acuity-levels.md quotes, in this order, when the run has them (the
// default; the default with the floor of 1 mm x s^2 recommended for a link that must
// carry less than F1; one pass of refinement at k = 0.30, fovea-eval's
// ACUITY-REFINED), then the run's other ACUITY settings in the order of the run.
std::vector<std::string> mainPlotAcuitySettings(const std::vector<ConfigSummary>& configs);

// Writes kMainPlot's data and script, and kAcuityPlot's when the run has ACUITY rows,
// into dir; the scripts draw their PNG when gnuplot runs them in dir. Returns the
// plots written.
Result<std::vector<PlotFiles>> writePlotFiles(const std::string& dir, const ReportContext& context,
                                              const std::vector<ConfigSummary>& configs);

}  // namespace fovea::tools
