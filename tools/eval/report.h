// fovea-eval's report: report.md (the table laid out as the paper's Table II,
// with the paper's own figures beside it, the stages, the quality measures and
// the images), the CSV files behind it, and gnuplot scripts for its plots.
#pragma once

#include <string>
#include <vector>

#include "core/result.h"
#include "tools/eval/plan.h"
#include "tools/eval/quality_eval.h"
#include "tools/eval/results.h"

namespace fovea::tools::eval {

struct ReportDataset {
  Dataset dataset;
  SceneGeometry geometry;
  std::vector<HmdPosition> positions;
};

struct ReportInput {
  std::string options_line;  // the command as run
  int frames = 0;            // per position
  uint64_t seed = 0;
  std::vector<Condition> conditions;
  std::vector<ReportDataset> datasets;
  std::vector<RunResult> runs;
  int failed_runs = 0;
  int resumed_runs = 0;  // read back from runs/ rather than measured by this invocation
  QualityOptions quality_options;
  int quality_frame = 0;
  std::vector<QualityRow> quality;
  double elapsed_s = 0.0;
};

// The paper's Table II (its hardware, its encoder): MB/s and ms per condition for
// LIV and BAL; NaN where it has no figure.
struct PaperFigures {
  double mb_per_s = 0.0;
  double latency_ms = 0.0;
};
PaperFigures paperTableII(const std::string& paper_dataset, const std::string& condition);

// Writes report.md, runs.csv, table2.csv, stages.csv, quality.csv, bandwidth.gp,
// stages.gp (and, with plot and gnuplot installed, bandwidth.png and stages.png) to dir.
Status writeReport(const std::string& dir, const ReportInput& input, bool plot);

}  // namespace fovea::tools::eval
