// fovea-error-report's output: the report's header, the files in --out-dir and
// the summary on standard output, and --replot-from.
#include "tools/error_report/output.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <iterator>
#include <thread>
#include <utility>

#include "tools/common/gnuplot.h"
#include "tools/common/host.h"
#include "tools/error_report/exit_code.h"

#ifndef FOVEA_BUILD_TYPE
#define FOVEA_BUILD_TYPE "unknown"
#endif

namespace fovea::tools {
namespace {

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

// report.csv and report.md into dir: kExitOk, or kExitFailure said on standard error.
int writeTables(const std::filesystem::path& dir, const ReportContext& context,
                const std::vector<ConfigSummary>& summaries, bool have_plot) {
  for (const auto& [writer, name] :
       {std::pair{0, "report.csv"}, std::pair{1, "report.md"}}) {
    const std::string path = (dir / name).string();
    Status s = writer == 0 ? writeCsv(path, summaries) : writeMarkdown(path, context, summaries, have_plot);
    if (!s) {
      std::fprintf(stderr, "fovea-error-report: %s\n", s.message().c_str());
      return kExitFailure;
    }
  }
  return kExitOk;
}

// The summary on standard output: the frame source's rows, and with the map
// source every row against the true surface.
void printSummary(const Options& options, const std::vector<ConfigSummary>& summaries) {
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
}

// dynamics.csv into dir and its summary on standard output: kExitOk, or
// kExitFailure said on standard error.
int writeDynamics(const std::filesystem::path& dir, const DynamicsReport& dynamics) {
  if (Status s = writeDynamicsCsv((dir / "dynamics.csv").string(), dynamics); !s) {
    std::fprintf(stderr, "fovea-error-report: %s\n", s.message().c_str());
    return kExitFailure;
  }
  std::printf("%-22s %9s %9s %10s %10s %9s\n", "over time", "chg fix", "chg drift", "cover all", "cover mov",
              "MB/frame");
  for (std::size_t c = 0; c < dynamics.stability.size(); ++c) {
    const StabilityResult& s = dynamics.stability[c];
    const CoverageResult& r = dynamics.coverage[c];
    std::printf("%-22s %8.1f%% %8.1f%% %9.1f%% %9.1f%% %9.3f\n", s.name.c_str(), 100.0 * s.changed_fixed,
                100.0 * s.changed_drift, 100.0 * r.coverage_all, 100.0 * r.coverage_moving, r.bytes_per_frame / 1e6);
  }
  return kExitOk;
}
}  // namespace

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
  if (const int code = writeTables(dir, context, summaries, *have_plot); code != kExitOk) return code;
  printSummary(options, summaries);
  if (dynamics) {
    if (const int code = writeDynamics(dir, *dynamics); code != kExitOk) return code;
  }
  std::printf("wrote report.md, report.csv, the plot scripts and data%s%s to %s\n", *have_plot ? ", the plots" : "",
              dynamics ? ", dynamics.csv" : "", options.out_dir.c_str());
  return kExitOk;
}

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

}  // namespace fovea::tools
