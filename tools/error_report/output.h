// fovea-error-report's output: the report's header (ReportContext), the files
// in --out-dir (report.md, report.csv, the plots, dynamics.csv), the summary on
// standard output; and --replot-from, which redraws an earlier run's plots. The
// page and table writers themselves are report.h's and dynamics.h's.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "hal/camera.h"
#include "tools/error_report/dynamics.h"
#include "tools/error_report/options.h"
#include "tools/error_report/report.h"

namespace fovea::tools {

// The report's header: the command, camera, gaze, host and load, date.
ReportContext reportContext(int argc, char** argv, const Options& options, const hal::CameraInfo& info,
                            const std::string& gaze_text, double load_before, long frames);

// report.md, report.csv, the plots (and dynamics.csv) into --out-dir, and the
// summary table on standard output. Returns an exit code (exit_code.h).
int writeReport(const Options& options, const ReportContext& context, const std::vector<ConfigSummary>& summaries,
                const std::optional<DynamicsReport>& dynamics);

// --replot-from: the plots of an earlier run from its report.csv, and the title's
// camera from its report.md, so that a change to the plots does not cost a new
// measurement. The plot files come out as that run would write them now.
// Returns an exit code (exit_code.h).
int replot(const Options& options);

}  // namespace fovea::tools
