// fovea-error-report: the "speed against error" report of issue 3. Runs every
// configuration (preset x slope m) on the same camera frames, side by side, and
// writes report.md, report.csv, report_plot.dat, report.gp (and report.png when
// gnuplot is installed) to an output directory.
//
// The run's parts: its options (options.h), the measuring (measure.h, one frame
// at a time in frame_measurer.h, each configuration's record in config_run.h),
// and the output (output.h; the writers in report.h and dynamics.h).
#include <cstdio>
#include <vector>

#include "firmware/mcap_camera.h"
#include "tools/error_report/config_run.h"
#include "tools/error_report/dynamics.h"
#include "tools/error_report/exit_code.h"
#include "tools/error_report/measure.h"
#include "tools/error_report/options.h"
#include "tools/error_report/output.h"
#include "tools/error_report/report.h"

namespace fovea::tools {
namespace {

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

  Measurement measured;
  if (const int code = measure(options, measured); code != kExitOk) return code;
  // Summaries, in the order presets x slopes.
  std::vector<ConfigSummary> summaries;
  for (const ConfigRun& r : measured.runs) summaries.push_back(summarise(r));
  ReportContext context =
      reportContext(argc, argv, options, measured.info, measured.gaze, measured.load_before, measured.frames);
  if (measured.dynamics) context.extra_markdown = dynamicsMarkdown(*measured.dynamics);
  context.map_warmup_frames = options.map_warmup;
  return writeReport(options, context, summaries, measured.dynamics);
}

}  // namespace
}  // namespace fovea::tools

int main(int argc, char** argv) { return fovea::tools::run(argc, argv); }
