// fovea-error-report: the "speed against error" report of issue 3. Runs every
// configuration (preset x slope m) on the same camera frames, side by side, and
// writes report.md, report.csv, report_plot.dat, report.gp (and report.png when
// gnuplot is installed) to an output directory.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <unistd.h>

#include <Eigen/Geometry>

#include "firmware/frame_foveator.h"
#include "firmware/mcap_camera.h"
#include "hal/camera.h"
#include "pipeline/backproject.h"
#include "net/codec.h"
#include "pipeline/error_metrics.h"
#include "pipeline/quantile.h"
#include "pipeline/foveator.h"
#include "tools/common/gnuplot.h"
#include "tools/common/host.h"
#include "tools/common/nan.h"
#include "tools/error_report/dynamics.h"
#include "tools/error_report/report.h"
#include "tools/error_report/surface_error.h"

#ifndef FOVEA_BUILD_TYPE
#define FOVEA_BUILD_TYPE "unknown"
#endif

namespace fovea::tools {
namespace {

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

const char* kHelp =
    "usage: fovea-error-report [--camera SPEC] [--frames N] [--out-dir DIR] [--presets LIST] [--slopes LIST]\n"
    "                          [--reference-m M] [--sources LIST] [--map-warmup N] [--no-plot] [--replot-from DIR]\n"
    "\n"
    "Foveates the same camera frames with every preset and slope m, side by side, and reports per\n"
    "configuration the output points, bytes on the wire (fovea's chunk codec), median time per frame (back-projection\n"
    "through sampled output, scalar reference kernels) and the error against the full cloud: the\n"
    "distance from each input point to its representative (RMS, max, per region, / voxel size) and the\n"
    "share of points displaced, seen from the eye, by more than the MAR at their eccentricity (Eq. 1).\n"
    "The gaze goes from the camera towards the scene's focus point (the camera's optical axis when it\n"
    "has none), as `fovead run` does by default.\n"
    "\n"
    "  --camera SPEC     camera (default mock:living-room); e.g. mock:living-room,size=160x120\n"
    "  --frames N        frames to average over (default 30)\n"
    "  --out-dir DIR     where report.md, report.csv, report.gp, report_plot.dat, report.png go\n"
    "                    (default docs/report; created if missing)\n"
    "  --presets LIST    comma-separated presets (default F1,F2,F3,FREF,ACUITY)\n"
    "  --slopes LIST     comma-separated slopes m of MAR = m E + 1 arcmin (default 0.022,0.028,0.034)\n"
    "  --acuity-margins LIST  ACUITY's level margins k, a row each (default 1.732,0.7,0.5,0.42;\n"
    "                    docs/acuity-levels.md)\n"
    "  --acuity-refined LIST  ACUITY's refined rows, K:PASSES each (level margin, refinement passes;\n"
    "                    default 0.3:1,0.12:2,0.15:7; none for none)\n"
    "  --acuity-floors LIST  ACUITY's sensor floors in mm, 0 for none (default 0); a row each margin x floor\n"
    "  --acuity-noise-floors LIST  ACUITY's distance-dependent floors, mm per square metre of distance\n"
    "                    (foveation.floor_per_m2 x 1000); a row each margin x floor besides (default none)\n"
    "  --view-culls LIST  ACUITY's view cull (off, coarsest, drop; foveation.view_cull_deg 70), a row each\n"
    "                    (default off)\n"
    "  --head-turn-deg D  the operator's head faces D degrees right of the gaze, about the camera's up axis\n"
    "                    (default 0: the head faces the gaze)\n"
    "  --eye-offset X,Y,Z  the eye relative to the camera, metres in the camera's frame (x right, y down,\n"
    "                    z forward; default 0,0,0): an operator's head is rarely where the camera is, and\n"
    "                    depth noise along the camera's rays is visible only from elsewhere\n"
    "  --reference-m M   slope of a fixed observer every configuration is also judged by (default 0.022)\n"
    "  --sources LIST    what is foveated, comma-separated: frame (each frame's own cloud) and map (the\n"
    "                    frame fused into the surfel map, the map's stable surfels the eye sees and the\n"
    "                    frame's unexplained points: foveation.source = map, docs/map.md); default frame.\n"
    "                    With map, every row (frame's too) is also judged against the true surface by the\n"
    "                    nearest sent point (docs/report/README.md), and the report compares the sources\n"
    "  --map-warmup N    frames fused into the map before the measured frames (default 60; with map only)\n"
    "  --dynamics-frames N  frames of the temporal-stability figure, after the measured ones (default 30;\n"
    "                    0 skips it and the latency-corrected coverage; both use the first slope)\n"
    "  --down-ms MS      capture to display for the coverage figure (default 13: the stream's p50 on loopback)\n"
    "  --up-ms MS        operator to robot for the coverage figure (default 1)\n"
    "  --coverage-seconds S  length of the scripted scan the coverage figure replays (default 3.6: two rounds)\n"
    "  --growth-max-deg D  ACUITY's fovea growth bound in the coverage figure (default 10, the service's)\n"
    "  --growth-lead-ms T  ACUITY's fovea growth lead in the coverage figure (default 30, the service's)\n"
    "  --no-plot         do not run gnuplot (report.gp and report_acuity.gp are still written)\n"
    "  --replot-from DIR  measure nothing: rewrite DIR's plot data and scripts from the report.csv and\n"
    "                    report.md an earlier run wrote there, and draw them (unless --no-plot)\n"
    "\n"
    "With a mock camera, the same scene without sensor noise (noise=off, same seed and path) is the true\n"
    "surface: every configuration is also judged against it (the columns 'true surface'), so that noise the\n"
    "output keeps counts as error, not as detail.\n";

struct Options {
  std::string camera = "mock:living-room";
  long frames = 30;
  std::string out_dir = "docs/report";
  std::vector<pipeline::Preset> presets = {pipeline::Preset::kF1, pipeline::Preset::kF2, pipeline::Preset::kF3,
                                           pipeline::Preset::kFRef, pipeline::Preset::kAcuity};
  std::vector<double> slopes = {0.022, 0.028, 0.034};
  // ACUITY's level margins k (AcuityConfig::level_margin): sqrt(3) guarantees
  // every point under its MAR; smaller ones trade a share above it for bytes.
  std::vector<double> acuity_margins = {1.7320508075688772, 0.7, 0.5, 0.42};
  // ... and refined rows: margin k and refinement passes (AcuityConfig::refine_passes).
  std::vector<std::pair<double, int>> acuity_refined = {{0.3, 1}, {0.12, 2}, {0.15, 7}};
  // ... and sensor floors in mm (0: none), a row each margin x floor.
  std::vector<double> acuity_floors_mm = {0.0};
  std::vector<double> acuity_noise_floors_mm = {};  // per m^2 of distance
  // ACUITY's view cull (foveation.view_cull_deg's default), a row each, and the
  // head's turn from the gaze about the camera's up axis.
  std::vector<pipeline::ViewCull> view_culls = {pipeline::ViewCull::kOff};
  double head_turn_deg = 0.0;
  double reference_slope = pipeline::kDefaultSlope;
  bool plot = true;
  std::string replot_from;  // non-empty: redraw this directory's plots, measure nothing
  Eigen::Vector3d eye_offset_cam = Eigen::Vector3d::Zero();
  DynamicsOptions dynamics;
  // What is foveated (--sources), and the frames fused into the map first.
  std::vector<firmware::FoveationSource> sources = {firmware::FoveationSource::kFrame};
  long map_warmup = 60;
  bool hasMap() const {
    return std::find(sources.begin(), sources.end(), firmware::FoveationSource::kMap) != sources.end();
  }
};

std::vector<std::string> splitCommas(std::string_view text) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = text.find(',', start);
    parts.emplace_back(text.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return parts;
}

Result<double> parseNumber(const std::string& flag, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v)) {
    return Result<double>(ErrorCode::kInvalidArgument, flag + ": '" + text + "' is not a finite number");
  }
  return v;
}

Result<Options> parseArgs(int argc, char** argv, bool& help) {
  Options options;
  help = false;
  for (int i = 1; i < argc; ++i) {
    std::string flag = argv[i];
    std::string value;
    const bool takes_value = flag != "--help" && flag != "-h" && flag != "--no-plot";
    if (const std::size_t eq = flag.find('='); flag.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = flag.substr(eq + 1);
      flag = flag.substr(0, eq);
    } else if (takes_value) {
      if (i + 1 >= argc) return Result<Options>(ErrorCode::kInvalidArgument, flag + " needs a value");
      value = argv[++i];
    }
    if (flag == "--help" || flag == "-h") {
      help = true;
    } else if (flag == "--no-plot") {
      options.plot = false;
    } else if (flag == "--replot-from") {
      if (value.empty()) return Result<Options>(ErrorCode::kInvalidArgument, "--replot-from: must not be empty");
      options.replot_from = value;
    } else if (flag == "--camera") {
      options.camera = value;
    } else if (flag == "--out-dir") {
      if (value.empty()) return Result<Options>(ErrorCode::kInvalidArgument, "--out-dir: must not be empty");
      options.out_dir = value;
    } else if (flag == "--frames") {
      Result<double> n = parseNumber(flag, value);
      if (!n) return n.status();
      if (*n < 1 || *n > 100000 || std::floor(*n) != *n) {
        return Result<Options>(ErrorCode::kInvalidArgument, "--frames: '" + value + "' is not an integer in [1, 100000]");
      }
      options.frames = static_cast<long>(*n);
    } else if (flag == "--presets") {
      options.presets.clear();
      for (const std::string& name : splitCommas(value)) {
        Result<pipeline::Preset> p = pipeline::parsePreset(name);
        if (!p || p.value() == pipeline::Preset::kCustom) {
          return Result<Options>(ErrorCode::kInvalidArgument, "--presets: '" + name + "' is not F1, F2, F3, FREF or ACUITY");
        }
        options.presets.push_back(p.value());
      }
    } else if (flag == "--acuity-margins") {
      options.acuity_margins.clear();
      for (const std::string& text : splitCommas(value)) {
        Result<double> k = parseNumber(flag, text);
        if (!k) return k.status();
        if (*k < 0.1 || *k > 10.0) return Result<Options>(ErrorCode::kInvalidArgument, "--acuity-margins: '" + text + "' is outside [0.1, 10]");
        options.acuity_margins.push_back(*k);
      }
    } else if (flag == "--acuity-refined") {
      options.acuity_refined.clear();
      for (const std::string& text : splitCommas(value)) {
        if (text == "none") continue;
        const std::size_t colon = text.find(':');
        Result<double> k = parseNumber(flag, text.substr(0, colon));
        if (!k) return k.status();
        if (*k < 0.1 || *k > 10.0) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + text + "': k is outside [0.1, 10]");
        char* end = nullptr;
        const std::string passes = colon == std::string::npos ? "" : text.substr(colon + 1);
        const long p = std::strtol(passes.c_str(), &end, 10);
        if (passes.empty() || end != passes.c_str() + passes.size() || p < 1 || p > pipeline::kMaxRefinePasses) {
          return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + text + "' is not K:PASSES with PASSES in [1, " +
                                                                  std::to_string(pipeline::kMaxRefinePasses) + "]");
        }
        options.acuity_refined.emplace_back(*k, static_cast<int>(p));
      }
    } else if (flag == "--view-culls") {
      options.view_culls.clear();
      for (const std::string& text : splitCommas(value)) {
        Result<pipeline::ViewCull> c = pipeline::parseViewCull(text);
        if (!c) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": " + c.status().message());
        options.view_culls.push_back(c.value());
      }
    } else if (flag == "--head-turn-deg") {
      Result<double> d = parseNumber(flag, value);
      if (!d) return d.status();
      if (std::fabs(*d) > 180.0) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + value + "' is outside [-180, 180]");
      options.head_turn_deg = *d;
    } else if (flag == "--acuity-noise-floors") {
      options.acuity_noise_floors_mm.clear();
      for (const std::string& text : splitCommas(value)) {
        Result<double> mm = parseNumber(flag, text);
        if (!mm) return mm.status();
        if (*mm <= 0.0 || *mm > 1000.0) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + text + "' is outside (0, 1000] mm per m^2");
        options.acuity_noise_floors_mm.push_back(*mm);
      }
    } else if (flag == "--acuity-floors") {
      options.acuity_floors_mm.clear();
      for (const std::string& text : splitCommas(value)) {
        Result<double> mm = parseNumber(flag, text);
        if (!mm) return mm.status();
        if (*mm < 0.0 || *mm > 1000.0) return Result<Options>(ErrorCode::kInvalidArgument, "--acuity-floors: '" + text + "' is outside [0, 1000] mm");
        options.acuity_floors_mm.push_back(*mm);
      }
    } else if (flag == "--eye-offset") {
      const std::vector<std::string> parts = splitCommas(value);
      if (parts.size() != 3) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + value + "' is not X,Y,Z");
      for (int a = 0; a < 3; ++a) {
        Result<double> v = parseNumber(flag, parts[a]);
        if (!v) return v.status();
        if (std::fabs(*v) > 100.0) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + parts[a] + "' is beyond 100 m");
        options.eye_offset_cam[a] = *v;
      }
    } else if (flag == "--dynamics-frames") {
      Result<double> n = parseNumber(flag, value);
      if (!n) return n.status();
      if (*n < 0 || *n > 10000 || std::floor(*n) != *n) {
        return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + value + "' is not an integer in [0, 10000]");
      }
      options.dynamics.stability_frames = static_cast<int>(*n);
    } else if (flag == "--coverage-seconds") {
      Result<double> t = parseNumber(flag, value);
      if (!t) return t.status();
      if (*t < 0.1 || *t > 3600.0) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + value + "' is outside [0.1, 3600] s");
      options.dynamics.coverage_seconds = *t;
    } else if (flag == "--growth-max-deg") {
      Result<double> g = parseNumber(flag, value);
      if (!g) return g.status();
      if (*g < 0.0 || *g > 90.0) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + value + "' is outside [0, 90]");
      options.dynamics.growth_max_deg = *g;
    } else if (flag == "--growth-lead-ms") {
      Result<double> t = parseNumber(flag, value);
      if (!t) return t.status();
      if (*t < 0.0 || *t > 1000.0) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + value + "' is outside [0, 1000] ms");
      options.dynamics.lead_ms = *t;
    } else if (flag == "--down-ms" || flag == "--up-ms") {
      Result<double> ms = parseNumber(flag, value);
      if (!ms) return ms.status();
      if (*ms < 0.0 || *ms > 10000.0) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + value + "' is outside [0, 10000] ms");
      (flag == "--down-ms" ? options.dynamics.down_ms : options.dynamics.up_ms) = *ms;
    } else if (flag == "--reference-m") {
      Result<double> m = parseNumber(flag, value);
      if (!m) return m.status();
      if (*m < 0.0) return Result<Options>(ErrorCode::kInvalidArgument, "--reference-m: '" + value + "' is negative");
      options.reference_slope = *m;
    } else if (flag == "--sources") {
      options.sources.clear();
      for (const std::string& name : splitCommas(value)) {
        const std::optional<firmware::FoveationSource> source = firmware::parseFoveationSource(name);
        if (!source) return Result<Options>(ErrorCode::kInvalidArgument, "--sources: '" + name + "' is not frame or map");
        if (std::find(options.sources.begin(), options.sources.end(), *source) != options.sources.end()) {
          return Result<Options>(ErrorCode::kInvalidArgument, "--sources: '" + name + "' is named twice");
        }
        options.sources.push_back(*source);
      }
    } else if (flag == "--map-warmup") {
      Result<double> n = parseNumber(flag, value);
      if (!n) return n.status();
      if (*n < 0 || *n > 100000 || std::floor(*n) != *n) {
        return Result<Options>(ErrorCode::kInvalidArgument, flag + ": '" + value + "' is not an integer in [0, 100000]");
      }
      options.map_warmup = static_cast<long>(*n);
    } else if (flag == "--slopes") {
      options.slopes.clear();
      for (const std::string& text : splitCommas(value)) {
        Result<double> m = parseNumber("--slopes", text);
        if (!m) return m.status();
        if (*m < 0.0) return Result<Options>(ErrorCode::kInvalidArgument, "--slopes: '" + text + "' is negative");
        options.slopes.push_back(*m);
      }
    } else {
      return Result<Options>(ErrorCode::kInvalidArgument, "unknown argument '" + flag + "' (see --help)");
    }
  }
  return options;
}

// Nearest-rank quantile of the values that are numbers; NaN when none is.
double quantileOf(std::vector<double> values, double q) {
  values.erase(std::remove_if(values.begin(), values.end(), [](double v) { return std::isnan(v); }), values.end());
  return values.empty() ? kNaN : pipeline::nearestRankQuantile(values, q);
}

// One region's (or all regions') measurements over the frames.
struct RegionAccumulator {
  uint64_t points_in = 0, points_out = 0, wire_bytes = 0;
  double voxel_sum_m = 0.0;
  uint64_t points = 0, seen = 0, above = 0, above_reference = 0;
  double sum_sq_m2 = 0.0, max_m = 0.0, ratio_max = 0.0;
  std::vector<double> ratio_median, ratio_p95, ratio_first, ratio_last;  // one per frame

  void add(const pipeline::RegionError& e, uint32_t in, uint32_t out, double voxel_m, uint64_t bytes) {
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

  RegionSummary summarise(int frames) const {
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

double msBetween(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// CPU time of the calling thread, in ms: unlike the wall clock, it does not count
// the time other processes on a shared host take from us.
double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

std::string hostDescription() {
  return std::string(cpuArchitecture()) + ", " + std::to_string(std::thread::hardware_concurrency()) +
         " hardware threads (the run uses one), " +
#if defined(__clang__)
         "clang " + std::string(__clang_version__) +
#else
         "g++ " + std::string(__VERSION__) +
#endif
         ", CMake build type " + FOVEA_BUILD_TYPE;
}

std::string utcNow() {
  const std::time_t now = std::time(nullptr);
  char buffer[32];
  std::strftime(buffer, sizeof buffer, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  return buffer;
}

// Writes the plot files into dir and, when `draw`, has gnuplot draw each: true
// when every plot was drawn.
Result<bool> writeAndDrawPlots(const std::string& dir, const ReportContext& context,
                               const std::vector<ConfigSummary>& summaries, bool draw) {
  // The plots show the frame source (the map's rows are in report.md's own section).
  std::vector<ConfigSummary> plotted;
  std::copy_if(summaries.begin(), summaries.end(), std::back_inserter(plotted),
               [](const ConfigSummary& c) { return !c.isMap(); });
  Result<std::vector<PlotFiles>> written = writePlotFiles(dir, context, plotted);
  if (!written) return written.status();
  bool drawn = draw;
  for (const PlotFiles& files : *written) drawn = drawn && drawWithGnuplot(dir, files.script, files.png);
  return drawn;
}

// --replot-from: the plots of an earlier run from its report.csv, and the title's
// camera from its report.md, so that a change to the plots does not cost a new
// measurement. The plot files come out as that run would write them now.
int replot(const Options& options) {
  const std::filesystem::path dir(options.replot_from);
  Result<std::vector<ConfigSummary>> summaries = readCsvSummaries((dir / "report.csv").string());
  Result<std::string> camera = readMarkdownCamera((dir / "report.md").string());
  for (const Status& s : {summaries.status(), camera.status()}) {
    if (!s.isOk()) {
      std::fprintf(stderr, "fovea-error-report: --replot-from: %s\n", s.message().c_str());
      return kExitFailure;
    }
  }
  ReportContext context;
  context.camera = *camera;
  context.reference_slope = options.reference_slope;
  for (const ConfigSummary& c : *summaries) context.frames = std::max(context.frames, c.frames);
  Result<bool> drawn = writeAndDrawPlots(dir.string(), context, *summaries, options.plot);
  if (!drawn) {
    std::fprintf(stderr, "fovea-error-report: %s\n", drawn.status().message().c_str());
    return kExitFailure;
  }
  std::printf("rewrote the plot scripts and data%s in %s\n", *drawn ? ", drew the plots" : "", dir.string().c_str());
  return kExitOk;
}

// Every configuration the report measures, in the order presets x slopes (x
// ACUITY's margins, floors and view culls), each with room for its frames.
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

// Where the eye is and where it looks, as the report states it.
std::string describeGaze(const Options& options, const hal::CameraInfo& info) {
  char gaze_text[320];
  char eye_text[96] = "the camera";
  if (!options.eye_offset_cam.isZero()) {
    std::snprintf(eye_text, sizeof eye_text, "an eye at (%.2f, %.2f, %.2f) m from the camera (its x right, y down, z forward)",
                  options.eye_offset_cam.x(), options.eye_offset_cam.y(), options.eye_offset_cam.z());
  }
  if (info.focus_point_m.has_value()) {
    std::snprintf(gaze_text, sizeof gaze_text, "from %s towards the scene's focus point (%.2f, %.2f, %.2f) m", eye_text,
                  info.focus_point_m->x(), info.focus_point_m->y(), info.focus_point_m->z());
  } else {
    std::snprintf(gaze_text, sizeof gaze_text, "from %s along the camera's optical axis (the camera has no focus point)",
                  eye_text);
  }
  return gaze_text;
}

// The gaze on a frame: from the eye towards the scene's focus point (or along the
// optical axis), and the head along it, turned about the camera's up axis
// (ACUITY's view cull).
pipeline::Gaze gazeOn(const hal::RgbdFrame& frame, const Options& options, const hal::CameraInfo& info) {
  pipeline::Gaze gaze;
  gaze.origin_m = frame.T_world_cam.t_world_cam + frame.T_world_cam.R_world_cam * options.eye_offset_cam;
  gaze.direction = info.focus_point_m.has_value() ? Eigen::Vector3d(*info.focus_point_m - gaze.origin_m)
                                                  : Eigen::Vector3d(frame.T_world_cam.R_world_cam.col(2));
  gaze.view_known = true;
  gaze.view_forward = Eigen::AngleAxisd(-options.head_turn_deg * std::numbers::pi / 180.0,
                                        Eigen::Vector3d(-frame.T_world_cam.R_world_cam.col(1))) *
                      gaze.direction;
  return gaze;
}

// The true position of every input point: the twin's frame (same pose and
// intrinsics) keeps its noiseless depth where both readings are valid and takes
// the noisy one elsewhere, so that its back-projection has the same points in
// the same order as the noisy frame's. `surface`, when given, receives the
// twin's own frame back-projected first: the true surface, every pixel in range
// (surface_error.h). False when the twin gave no frame.
bool backprojectTruth(hal::Camera& twin, const hal::RgbdFrame& frame, const pipeline::RawDepthRange& raw_range,
                      const pipeline::DepthRange& range, hal::RgbdFrame& truth_frame, pipeline::PointCloud& truth_cloud,
                      pipeline::PointCloud* surface) {
  if (!twin.acquire(truth_frame, std::chrono::seconds(2))) return false;
  if (surface != nullptr) {
    pipeline::BackprojectCounts surface_counts;
    if (!pipeline::backprojectRef(truth_frame, range, *surface, surface_counts)) return false;
  }
  const auto valid = [&](uint16_t raw) { return raw >= raw_range.min && raw <= raw_range.max; };
  const uint16_t* noisy = frame.depth();
  uint16_t* clean = truth_frame.depth();
  for (std::size_t i = 0; i < frame.pixelCount(); ++i) {
    if (!valid(noisy[i]) || !valid(clean[i])) clean[i] = noisy[i];
  }
  pipeline::BackprojectCounts truth_counts;
  return pipeline::backprojectRef(truth_frame, range, truth_cloud, truth_counts).isOk();
}

// What measuring a configuration on a frame uses: sized once at start-up.
struct Measurer {
  pipeline::Foveator& foveator;
  pipeline::ErrorEvaluator& evaluator;
  net::ChunkEncoder& encoder;
  SurfaceErrorEvaluator& surface_evaluator;
  pipeline::PointCloud& cloud;
  pipeline::FoveatedCloud& out;
  std::vector<uint32_t>& representative;
  pipeline::DepthRange range;
  double reference_slope;

  // One configuration on one frame, added to its run: back-projection and
  // foveation timed (what the service does per frame), then, untimed, the same
  // foveation with each input point's representative, its error (and against
  // the true surface when `truth` is given) and the bytes the stream would send.
  Status measure(const hal::RgbdFrame& frame, const pipeline::Gaze& gaze, const pipeline::PointCloud* truth,
                 const pipeline::PointCloud* surface, ConfigRun& r) {
    if (Status s = foveator.setConfig(r.config); !s) return s;
    pipeline::BackprojectCounts counts;
    pipeline::FoveationStats stats;
    const double cpu0 = threadCpuMs();
    const auto t0 = std::chrono::steady_clock::now();
    Status s = pipeline::backprojectRef(frame, range, cloud, counts);
    if (s) s = foveator.foveate(cloud, gaze, out, stats);
    const auto t1 = std::chrono::steady_clock::now();
    const double cpu1 = threadCpuMs();
    if (s) s = foveator.foveate(cloud, gaze, out, stats, representative.data());
    if (!s) return s;
    return record(foveator, cloud, gaze, stats, truth, surface, cpu1 - cpu0, msBetween(t0, t1), r);
  }

  // The same for the map source, on the frame `map` fused last (fuse_cpu_ms and
  // fuse_wall_ms: that fusion's times, which every configuration's time
  // includes): the eye's view of the map and the foveation timed, then the
  // foveation again with representatives, untimed. The map's rows have no
  // per-pixel truth (their input is surfels, not the frame's pixels): `surface`
  // judges them.
  Status measureMap(firmware::FrameFoveator& map, const pipeline::Gaze& gaze, const pipeline::PointCloud* surface,
                    double fuse_cpu_ms, double fuse_wall_ms, ConfigRun& r) {
    if (Status s = map.use(&r.config); !s) return s;
    pipeline::FoveationStats stats;
    const double cpu0 = threadCpuMs();
    const auto t0 = std::chrono::steady_clock::now();
    Status s = map.foveate(gaze, out, stats);
    const auto t1 = std::chrono::steady_clock::now();
    const double cpu1 = threadCpuMs();
    if (s) s = map.foveator().foveate(map.cloud(), gaze, out, stats, representative.data());
    if (!s) return s;
    r.fuse_ms.push_back(fuse_cpu_ms);
    r.map_frame_points += map.mapFigures().frame_points;
    r.map_surfels += map.mapFigures().eye.appended;
    return record(map.foveator(), map.cloud(), gaze, stats, nullptr, surface, fuse_cpu_ms + cpu1 - cpu0,
                  fuse_wall_ms + msBetween(t0, t1), r);
  }

  // The untimed part: the error of `out` against its input `in`, against the
  // true surface, and the bytes.
  Status record(pipeline::Foveator& used, const pipeline::PointCloud& in, const pipeline::Gaze& gaze,
                const pipeline::FoveationStats& stats, const pipeline::PointCloud* truth,
                const pipeline::PointCloud* surface, double cpu_ms, double wall_ms, ConfigRun& r) {
    pipeline::ErrorModel error_model{&used.model(), {}, reference_slope};
    for (int reg = 0; reg < stats.region_count; ++reg) error_model.voxel_size_m[reg] = stats.regions[reg].voxel_size_m;
    pipeline::ErrorMetrics metrics;
    Status s = evaluator.evaluate(in, used.lastRegions(), representative.data(), out.points, gaze, error_model, metrics);
    std::array<uint64_t, pipeline::kMaxRegions> wire_bytes{};
    uint64_t wire_total = 0;
    if (s) {
      std::array<double, pipeline::kMaxRegions> voxel_m{};
      for (int reg = 0; reg < stats.region_count; ++reg) voxel_m[reg] = stats.regions[reg].voxel_size_m;
      s = encoder.encode(out, std::span<const double>(voxel_m.data(), stats.region_count), 0, 0);
      for (std::size_t i = 0; s && i < encoder.chunkCount(); ++i) {
        wire_bytes[encoder.chunkRegion(i)] += encoder.chunk(i).size() + net::kDatagramOverhead;
        wire_total += encoder.chunk(i).size() + net::kDatagramOverhead;
      }
    }
    SurfaceError surface_error;
    if (s && surface != nullptr) {
      s = surface_evaluator.evaluate(*surface, out.points, gaze, used.model().slope(), reference_slope, surface_error);
    }
    if (!s) return s;
    r.time_ms.push_back(cpu_ms);
    r.wall_ms.push_back(wall_ms);
    // (ACUITY has no d0: its column says "-".)
    if (stats.fixation.source != pipeline::FixationSource::kNone) r.d0_m.push_back(stats.fixation.d0_m);
    for (int reg = 0; reg < stats.region_count; ++reg) {
      r.regions[reg].add(metrics.regions[reg], stats.regions[reg].points_in, stats.regions[reg].points_out,
                         stats.regions[reg].voxel_size_m, wire_bytes[reg]);
    }
    r.all.add(metrics.all, stats.points_in, stats.points_out, 0.0, wire_total);
    if (truth != nullptr) {
      pipeline::ErrorMetrics truth_metrics;
      if (evaluator.evaluate(*truth, used.lastRegions(), representative.data(), out.points, gaze, error_model,
                             truth_metrics)) {
        r.truth.add(truth_metrics.all, 0, 0, 0.0, 0);
      }
    }
    if (surface != nullptr) {
      r.surface.add(surface_error);
      ++r.surface_frames;
    }
    r.at_eye += metrics.at_eye;
    r.no_representative += metrics.no_representative;
    ++r.frames;
    return Status::ok();
  }
};

// A run's figures over its frames, per region and in all.
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

// The report's header: the command, camera, gaze, host and load, date.
ReportContext reportContext(int argc, char** argv, const Options& options, const hal::CameraInfo& info,
                            const std::string& gaze_text, double load_before, long frames) {
  ReportContext context;
  for (int i = 0; i < argc; ++i) {
    if (i > 0) context.command_line += ' ';
    // argv[0] as typed when relative (build/tools/fovea-error-report), else just the name.
    const std::filesystem::path self(argv[0]);
    context.command_line += i > 0 ? std::string(argv[i]) : self.is_relative() ? self.string() : self.filename().string();
  }
  context.camera = info.name + " " + std::to_string(info.intrinsics.width) + "x" + std::to_string(info.intrinsics.height);
  context.gaze = gaze_text;
  if (options.head_turn_deg != 0.0) {
    char head[128];
    std::snprintf(head, sizeof head, "; the head faces %.0f degrees right of the gaze (ACUITY's view cull)",
                  options.head_turn_deg);
    context.gaze += head;
  }
  char load_text[160] = "load average unknown";
  if (!std::isnan(load_before)) {
    std::snprintf(load_text, sizeof load_text, "1-minute load average %.2f before the run%s", load_before,
                  load_before > 0.5 ? " (other processes shared the CPU: times are noisier than on an idle machine)"
                                    : "");
  }
  context.host = hostDescription() + "; " + load_text;
  context.reference_slope = options.reference_slope;
  context.pixel_pitch_arcmin = std::atan(1.0 / info.intrinsics.fx) * 180.0 / 3.14159265358979323846 * 60.0;
  context.frames = static_cast<int>(frames);
  context.date_utc = utcNow();
  return context;
}

// report.md, report.csv, the plots (and dynamics.csv) into --out-dir, and the
// summary table on standard output.
int writeReport(const Options& options, const ReportContext& context, const std::vector<ConfigSummary>& summaries,
                const std::optional<DynamicsReport>& dynamics) {
  std::error_code ec;
  std::filesystem::create_directories(options.out_dir, ec);
  if (ec) {
    std::fprintf(stderr, "fovea-error-report: --out-dir %s: %s\n", options.out_dir.c_str(), ec.message().c_str());
    return kExitFailure;
  }
  const std::filesystem::path dir(options.out_dir);
  Result<bool> have_plot = writeAndDrawPlots(dir.string(), context, summaries, options.plot);
  if (!have_plot) {
    std::fprintf(stderr, "fovea-error-report: %s\n", have_plot.status().message().c_str());
    return kExitFailure;
  }
  for (const auto& [writer, name] :
       {std::pair{0, "report.csv"}, std::pair{1, "report.md"}}) {
    const std::string path = (dir / name).string();
    Status s = writer == 0 ? writeCsv(path, summaries) : writeMarkdown(path, context, summaries, *have_plot);
    if (!s) {
      std::fprintf(stderr, "fovea-error-report: %s\n", s.message().c_str());
      return kExitFailure;
    }
  }

  std::printf("%-5s %6s %9s %10s %9s %9s %8s %9s\n", "preset", "m", "points", "MB/frame", "ms/frame", "RMS[mm]",
              "max[mm]", ">MAR");
  for (const ConfigSummary& c : summaries) {
    if (c.isMap()) continue;
    std::printf("%-5s %6.3f %9.0f %10.3f %9.2f %9.2f %8.1f %8.1f%%\n", c.preset.c_str(), c.slope, c.all.points_out,
                c.bytesPerFrame() / 1e6, c.time_ms_median, c.all.rms_mm, c.all.max_mm, 100.0 * c.all.share_above_mar);
  }
  if (options.hasMap()) {
    // The sources side by side, judged against the true surface (surface_error.h).
    std::printf("%-6s %-22s %6s %9s %10s %12s %9s %9s\n", "source", "preset", "m", "points", "B/frame",
                ">MAR surface", "ms/frame", "fuse ms");
    for (const ConfigSummary& c : summaries) {
      std::printf("%-6s %-22s %6.3f %9.0f %10.0f %12s %9.2f %9s\n", c.source.c_str(), c.preset.c_str(), c.slope,
                  c.all.points_out, c.bytesPerFrame(),
                  c.have_surface ? (formatFixed(100.0 * c.surface_share_above_mar, 2) + "%").c_str() : "-", c.time_ms_median,
                  c.isMap() ? formatFixed(c.fuse_ms_median, 2).c_str() : "-");
    }
  }
  if (dynamics) {
    if (Status s = writeDynamicsCsv((dir / "dynamics.csv").string(), *dynamics); !s) {
      std::fprintf(stderr, "fovea-error-report: %s\n", s.message().c_str());
      return kExitFailure;
    }
    std::printf("%-22s %9s %9s %10s %10s %9s\n", "over time", "chg fix", "chg drift", "cover all", "cover mov",
                "MB/frame");
    for (std::size_t c = 0; c < dynamics->stability.size(); ++c) {
      const StabilityResult& s = dynamics->stability[c];
      const CoverageResult& r = dynamics->coverage[c];
      std::printf("%-22s %8.1f%% %8.1f%% %9.1f%% %9.1f%% %9.3f\n", s.name.c_str(), 100.0 * s.changed_fixed,
                  100.0 * s.changed_drift, 100.0 * r.coverage_all, 100.0 * r.coverage_moving, r.bytes_per_frame / 1e6);
    }
  }
  std::printf("wrote report.md, report.csv, the plot scripts and data%s%s to %s\n", *have_plot ? ", the plots" : "",
              dynamics ? ", dynamics.csv" : "", options.out_dir.c_str());
  return kExitOk;
}

int run(int argc, char** argv) {
  bool help = false;
  Result<Options> parsed = parseArgs(argc, argv, help);
  if (!parsed) {
    std::fprintf(stderr, "fovea-error-report: %s\n", parsed.status().message().c_str());
    return kExitUsage;
  }
  if (help) {
    std::printf("%s\ncameras:\n%s\n", kHelp, firmware::cameraSpecHelp().c_str());
    return kExitOk;
  }
  const Options& options = parsed.value();
  if (!options.replot_from.empty()) return replot(options);

  Result<std::unique_ptr<hal::Camera>> created = firmware::createCamera(options.camera);
  if (!created) {
    std::fprintf(stderr, "fovea-error-report: --camera: %s\n", created.status().message().c_str());
    return kExitUsage;
  }
  hal::Camera& camera = *created.value();
  if (Status s = camera.open(); !s) {
    std::fprintf(stderr, "fovea-error-report: camera %s: %s\n", options.camera.c_str(), s.message().c_str());
    return kExitFailure;
  }
  const hal::CameraInfo& info = camera.info();
  const int width = info.intrinsics.width, height = info.intrinsics.height;
  const std::size_t max_points = static_cast<std::size_t>(width) * height;

  // Start-up: every buffer sized once; one Foveator reconfigured per configuration.
  std::vector<ConfigRun> runs = planRuns(options);
  // The scalar reference kernels: the report's time column says so.
  Result<pipeline::Foveator> foveator =
      pipeline::Foveator::create({max_points, max_points, fovea::KernelSet::kRef, 1}, runs.front().config);
  if (!foveator) {
    std::fprintf(stderr, "fovea-error-report: %s\n", foveator.status().message().c_str());
    return kExitUsage;
  }
  for (const ConfigRun& r : runs) {
    if (Status s = foveator->setConfig(r.config); !s) {
      std::fprintf(stderr, "fovea-error-report: %s\n", s.message().c_str());
      return kExitUsage;
    }
  }
  // The map source (--sources with map): the service's map at its defaults, fed
  // the same frames; its cloud (and so the output) holds the map's surfels too.
  firmware::MapSettings map_settings;
  map_settings.source = firmware::FoveationSource::kMap;
  map_settings.map.kernels = fovea::KernelSet::kRef;  // the report times the scalar references throughout
  const std::size_t cloud_points =
      options.hasMap() ? firmware::FrameFoveator::cloudCapacity(max_points, map_settings) : max_points;
  std::unique_ptr<firmware::FrameFoveator> map;
  if (options.hasMap()) {
    const auto first = std::find_if(runs.begin(), runs.end(),
                                    [](const ConfigRun& r) { return r.source == firmware::FoveationSource::kMap; });
    Result<firmware::FrameFoveator> created_map = firmware::FrameFoveator::create(
        {max_points, max_points, fovea::KernelSet::kRef, 1}, first->config, pipeline::DepthRange{}, map_settings, width,
        height);
    if (!created_map) {
      std::fprintf(stderr, "fovea-error-report: map: %s\n", created_map.status().message().c_str());
      return kExitFailure;
    }
    map = std::make_unique<firmware::FrameFoveator>(std::move(created_map.value()));
    for (const ConfigRun& r : runs) {
      if (r.source != firmware::FoveationSource::kMap) continue;
      if (Status s = map->use(&r.config); !s) {
        std::fprintf(stderr, "fovea-error-report: map: %s\n", s.message().c_str());
        return kExitUsage;
      }
    }
  }
  Result<pipeline::ErrorEvaluator> evaluator = pipeline::ErrorEvaluator::create(cloud_points);
  // The stream's codec at its defaults (1200-byte datagrams), for the bytes columns.
  Result<net::ChunkEncoder> encoder = net::ChunkEncoder::create(net::CodecConfig{}, cloud_points);
  for (const Status& s : {evaluator.status(), encoder.status()}) {
    if (!s) {
      std::fprintf(stderr, "fovea-error-report: %s\n", s.message().c_str());
      return kExitFailure;
    }
  }
  // The true surface: the mock scene without sensor noise, frame for frame.
  std::unique_ptr<hal::Camera> truth_camera;
  if (options.camera.rfind("mock:", 0) == 0 && options.camera.find("noise=off") == std::string::npos) {
    Result<std::unique_ptr<hal::Camera>> t = firmware::createCamera(options.camera + ",noise=off");
    if (t && t.value()->open() && t.value()->start()) truth_camera = std::move(t.value());
    if (!truth_camera) std::printf("fovea-error-report: no noiseless twin of %s: no true-surface columns\n", options.camera.c_str());
  }
  hal::RgbdFrame truth_frame(width, height);
  pipeline::PointCloud truth_cloud(max_points);
  // The true surface for the nearest-point measure (only with the map source: it
  // costs a nearest-neighbour search per true point and configuration).
  pipeline::PointCloud surface_cloud(options.hasMap() ? max_points : 0);
  pipeline::PointCloud* surface = truth_camera && options.hasMap() ? &surface_cloud : nullptr;
  SurfaceErrorEvaluator surface_evaluator(options.hasMap() ? cloud_points : 0);
  const pipeline::RawDepthRange raw_range = pipeline::rawDepthRange(pipeline::DepthRange{}, info.depth_scale_m);
  hal::RgbdFrame frame(width, height);
  pipeline::PointCloud cloud(max_points);
  pipeline::FoveatedCloud out(cloud_points);
  std::vector<uint32_t> representative(cloud_points);
  // The range: the same as fovead's defaults.
  Measurer measurer{*foveator, *evaluator, *encoder, surface_evaluator, cloud, out, representative,
                    pipeline::DepthRange{}, options.reference_slope};

  const std::string gaze_text = describeGaze(options, info);
  std::printf("fovea-error-report: camera %s %dx%d, %ld frames, %zu configurations; gaze %s\n", info.name.c_str(),
              width, height, options.frames, runs.size(), gaze_text.c_str());
  if (Status s = camera.start(); !s) {
    std::fprintf(stderr, "fovea-error-report: camera %s: %s\n", info.name.c_str(), s.message().c_str());
    return kExitFailure;
  }
  const double load_before = loadAverage();
  long failed = 0;
  const bool interactive = isatty(STDOUT_FILENO) != 0;  // progress only on a terminal
  // The map's warm-up: the camera's first frames fused into it (the twin kept in
  // step), none measured.
  for (long f = 0; map && f < options.map_warmup; ++f) {
    if (Status s = camera.acquire(frame, std::chrono::seconds(2)); !s) {
      std::fprintf(stderr, "fovea-error-report: map warm-up frame %ld: capture: %s\n", f, s.toString().c_str());
      return kExitFailure;
    }
    if (truth_camera && !truth_camera->acquire(truth_frame, std::chrono::seconds(2))) {
      std::fprintf(stderr, "fovea-error-report: map warm-up frame %ld: the noiseless twin gave no frame\n", f);
      return kExitFailure;
    }
    pipeline::BackprojectCounts counts;
    if (Status s = map->backproject(frame, counts); !s) {
      std::fprintf(stderr, "fovea-error-report: map warm-up frame %ld: %s\n", f, s.toString().c_str());
      return kExitFailure;
    }
    if (interactive) {
      std::printf("\rmap warm-up %ld/%ld", f + 1, options.map_warmup);
      std::fflush(stdout);
    }
  }
  if (map) {
    if (interactive) std::printf("\n");
    const pipeline::map::SurfelMapCounters& counters = map->map()->counters();
    std::printf("fovea-error-report: map warmed up over %ld frames: %llu fused, %llu refused\n", options.map_warmup,
                static_cast<unsigned long long>(counters.frames_fused),
                static_cast<unsigned long long>(counters.refused()));
  }
  for (long f = 0; f < options.frames; ++f) {
    if (Status s = camera.acquire(frame, std::chrono::seconds(2)); !s) {
      std::fprintf(stderr, "frame %ld: capture: %s\n", f, s.toString().c_str());
      ++failed;
      continue;
    }
    const bool have_truth = truth_camera && backprojectTruth(*truth_camera, frame, raw_range, measurer.range,
                                                             truth_frame, truth_cloud, surface);
    const pipeline::Gaze gaze = gazeOn(frame, options, info);
    // The map source: this frame fused into the map once, timed, for all its rows.
    double fuse_cpu_ms = 0.0, fuse_wall_ms = 0.0;
    if (map) {
      pipeline::BackprojectCounts counts;
      const double cpu0 = threadCpuMs();
      const auto t0 = std::chrono::steady_clock::now();
      const Status s = map->backproject(frame, counts);
      fuse_wall_ms = msBetween(t0, std::chrono::steady_clock::now());
      fuse_cpu_ms = threadCpuMs() - cpu0;
      if (!s) {
        std::fprintf(stderr, "frame %ld, map: %s\n", f, s.toString().c_str());
        return kExitFailure;
      }
    }
    // Side by side: every configuration on this frame, starting with a different
    // one each frame so that no configuration always runs first (cold caches).
    for (std::size_t k = 0; k < runs.size(); ++k) {
      ConfigRun& r = runs[(k + static_cast<std::size_t>(f)) % runs.size()];
      const Status s =
          r.source == firmware::FoveationSource::kMap
              ? measurer.measureMap(*map, gaze, have_truth ? surface : nullptr, fuse_cpu_ms, fuse_wall_ms, r)
              : measurer.measure(frame, gaze, have_truth ? &truth_cloud : nullptr, have_truth ? surface : nullptr, r);
      if (!s) {
        std::fprintf(stderr, "frame %ld, %s %s m %.3f: %s\n", f, firmware::foveationSourceName(r.source).data(),
                     configName(r.config.acuity).c_str(), r.config.acuity.slope, s.toString().c_str());
        return kExitFailure;
      }
    }
    if (interactive) {
      std::printf("\rframe %ld/%ld", f + 1, options.frames);
      std::fflush(stdout);
    }
  }
  if (interactive) std::printf("\n");
  if (truth_camera) truth_camera->stop();
  // The figures over time, on the camera's next frames.
  std::optional<DynamicsReport> dynamics;
  if (options.dynamics.stability_frames > 0 && failed < options.frames) {
    DynamicsOptions d = options.dynamics;
    if (info.fps > 0) d.fps = info.fps;
    d.eye_offset_cam = options.eye_offset_cam;
    Result<DynamicsReport> measured = measureDynamics(camera, dynamicsConfigs(options.slopes.front(), acuityFloors(options.acuity_floors_mm, options.acuity_noise_floors_mm),
                                                                   options.acuity_refined), d);
    if (!measured) {
      std::fprintf(stderr, "fovea-error-report: temporal figures: %s\n", measured.status().toString().c_str());
      return kExitFailure;
    }
    dynamics = std::move(measured.value());
  }
  camera.stop();
  if (failed == options.frames) {
    std::fprintf(stderr, "fovea-error-report: no frame could be captured\n");
    return kExitFailure;
  }

  // Summaries, in the order presets x slopes.
  std::vector<ConfigSummary> summaries;
  for (const ConfigRun& r : runs) summaries.push_back(summarise(r));
  ReportContext context = reportContext(argc, argv, options, info, gaze_text, load_before, options.frames - failed);
  if (dynamics) context.extra_markdown = dynamicsMarkdown(*dynamics);
  context.map_warmup_frames = options.map_warmup;
  return writeReport(options, context, summaries, dynamics);
}

}  // namespace
}  // namespace fovea::tools

int main(int argc, char** argv) { return fovea::tools::run(argc, argv); }
