#include "tools/eval/report.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <fstream>
#include <limits>
#include <sstream>
#include <thread>

#include "tools/common/gnuplot.h"
#include "tools/common/host.h"
#include "tools/common/nan.h"
#include "tools/eval/statistics.h"

namespace fovea::tools::eval {

namespace {

std::string fixed(double v, int precision) {
  if (std::isnan(v)) return "-";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  std::ostringstream o;
  o.precision(precision);
  o << std::fixed << v;
  return o.str();
}

// p-values: "<1e-6" below that, else three significant digits.
std::string pValue(double p) {
  if (std::isnan(p)) return "-";
  if (p < 1e-6) return "<1e-6";
  std::ostringstream o;
  o.precision(3);
  o << p;
  return o.str();
}

std::string vec(const Eigen::Vector3d& v) { return "(" + fixed(v.x(), 2) + ", " + fixed(v.y(), 2) + ", " + fixed(v.z(), 2) + ")"; }

const ConditionSummary* find(const std::vector<ConditionSummary>& s, const std::string& dataset, const std::string& condition) {
  for (const ConditionSummary& c : s) {
    if (c.dataset == dataset && c.condition == condition) return &c;
  }
  return nullptr;
}

// The mean of each quality figure over the positions measured, per dataset and condition.
struct QualityMean {
  double weighted_psnr = kNaN, weighted_ssim = kNaN, psnr = kNaN, ssim = kNaN, above_mar = kNaN;
  double points = kNaN;
  int positions = 0;     // measured
  int not_measured = 0;  // MAP-DELTA positions without what the operator held
  std::string frames;    // the frames drawn, comma-separated
};
QualityMean qualityMean(const std::vector<QualityRow>& rows, const std::string& dataset, const std::string& condition) {
  std::vector<double> wp, ws, p, s, a, n;
  int not_measured = 0;
  std::string frames;
  for (const QualityRow& r : rows) {
    if (r.dataset != dataset || r.condition != condition) continue;
    if (!r.measured) {
      ++not_measured;
      continue;
    }
    const std::string frame = std::to_string(r.frame);
    if (frames.empty()) {
      frames = frame;
    } else if (("," + frames + ",").find("," + frame + ",") == std::string::npos) {
      frames += "," + frame;
    }
    wp.push_back(r.quality.weighted_psnr_db);
    ws.push_back(r.quality.weighted_ssim);
    p.push_back(r.quality.psnr_db);
    s.push_back(r.quality.ssim);
    a.push_back(r.above_mar_share);
    n.push_back(r.points);
  }
  QualityMean m;
  m.positions = static_cast<int>(wp.size());
  m.not_measured = not_measured;
  m.frames = frames;
  if (wp.empty()) return m;
  m.weighted_psnr = mean(wp);
  m.weighted_ssim = mean(ws);
  m.psnr = mean(p);
  m.ssim = mean(s);
  m.above_mar = mean(a);
  m.points = mean(n);
  return m;
}

std::string hostLine() {
  return std::string(cpuArchitecture()) + ", " + std::to_string(std::thread::hardware_concurrency()) +
         " hardware threads; 1-minute load " + fixed(loadAverage(), 2) + " when the report was written";
}

Status writeFile(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
  if (!f) return {ErrorCode::kIoError, path + ": cannot write"};
  return Status::ok();
}

// "NAME is `--preset P --set KEY=VALUE ...`; " for each condition with settings of its own
// (docs/acuity-levels.md says what they do).
std::string conditionSettingsText(const std::vector<Condition>& conditions) {
  std::string out;
  for (const Condition& c : conditions) {
    const std::vector<std::string> settings = conditionSettings(c);
    if (settings.empty()) continue;
    out += c.name + " is `--preset " + c.preset;
    for (const std::string& setting : settings) out += " --set " + setting;
    out += c.source.empty() ? "` (docs/acuity-levels.md); " : c.map_delta ? "` (docs/map-delta.md); " : "` (docs/map.md); ";
  }
  return out;
}

}  // namespace

PaperFigures paperTableII(const std::string& paper_dataset, const std::string& condition) {
  // Table II of the paper (MB/s; ms): LIV and BAL, F1, F2, F3, FREF.
  struct Row {
    const char* condition;
    double liv_mb, liv_ms, bal_mb, bal_ms;
  };
  static const Row kRows[] = {{"F1", 0.50, 223, 0.80, 226},
                              {"F2", 0.55, 242, 0.97, 235},
                              {"F3", 0.74, 257, 1.03, 256},
                              {"FREF", 1.32, 618, 1.82, 562}};
  for (const Row& r : kRows) {
    if (condition != r.condition) continue;
    if (paper_dataset == "LIV") return {r.liv_mb, r.liv_ms};
    if (paper_dataset == "BAL") return {r.bal_mb, r.bal_ms};
  }
  return {kNaN, kNaN};
}

namespace {

// runs.csv, table2.csv, stages.csv and quality.csv: the tables behind report.md.
Status writeCsvFiles(const std::string& dir, const ReportInput& in, const std::vector<ConditionSummary>& summary) {
  std::string runs_csv = runCsvHeader();
  for (const RunResult& r : in.runs) runs_csv += runCsvLine(r);
  std::string table_csv =
      "dataset,condition,positions,frames,mb_per_s_mean,mb_per_s_sd,bandwidth_reduction_pct,bandwidth_p,latency_mean_ms,"
      "latency_sd_ms,latency_p99_ms,latency_reduction_pct,latency_p,points_per_frame,incomplete_frames,datagrams,"
      "datagrams_lost\n";
  std::string stages_csv = "dataset,condition,stage,mean_ms,p99_ms\n";
  for (const ConditionSummary& c : summary) {
    table_csv += c.dataset + "," + c.condition + "," + std::to_string(c.positions) + "," + std::to_string(c.frames) + "," +
                 fixed(c.mb_per_s_mean, 5) + "," + fixed(c.mb_per_s_sd, 5) + "," + fixed(c.bandwidth_reduction, 2) + "," +
                 fixed(c.bandwidth_p, 8) + "," + fixed(c.latency_mean_ms, 3) + "," + fixed(c.latency_sd_ms, 3) + "," +
                 fixed(c.latency_p99_ms, 3) + "," + fixed(c.latency_reduction, 2) + "," + fixed(c.latency_p, 8) + "," +
                 fixed(c.points_per_frame, 0) + "," + std::to_string(c.incomplete) + "," + std::to_string(c.datagrams) + "," +
                 std::to_string(c.datagrams_lost) + "\n";
    for (std::size_t s = 0; s < kStageCount; ++s) {
      stages_csv += c.dataset + "," + c.condition + "," + kStageNames[s] + "," + fixed(c.stage_mean_ms[s], 4) + "," +
                    fixed(c.stage_p99_ms[s], 4) + "\n";
    }
  }
  std::string quality_csv = "dataset,condition,position,points,above_mar_share,weighted_psnr_db,weighted_ssim,psnr_db,ssim";
  const std::vector<double>& edges = in.quality_options.ring_edges_deg;
  for (std::size_t k = 0; k + 1 < edges.size(); ++k) {
    const std::string ring = "ring_" + fixed(edges[k], 1) + "_" + fixed(edges[k + 1], 1);
    quality_csv += "," + ring + "_psnr_db," + ring + "_ssim," + ring + "_weight";
  }
  quality_csv += ",image,frame,measured\n";
  for (const QualityRow& q : in.quality) {
    quality_csv += q.dataset + "," + q.condition + "," + std::to_string(q.position) + "," + std::to_string(q.points) + "," +
                   fixed(q.above_mar_share, 6) + "," + fixed(q.quality.weighted_psnr_db, 3) + "," +
                   fixed(q.quality.weighted_ssim, 5) + "," + fixed(q.quality.psnr_db, 3) + "," + fixed(q.quality.ssim, 5);
    for (const Ring& r : q.quality.rings) quality_csv += "," + fixed(r.psnr_db, 3) + "," + fixed(r.ssim, 5) + "," + fixed(r.weight, 5);
    quality_csv += "," + q.image + "," + std::to_string(q.frame) + "," + (q.measured ? "1" : "0") + "\n";
  }
  for (const auto& [name, text] : {std::pair<std::string, std::string>{"runs.csv", runs_csv},
                                   {"table2.csv", table_csv}, {"stages.csv", stages_csv}, {"quality.csv", quality_csv}}) {
    if (Status s = writeFile(dir + "/" + name, text); !s) return s;
  }
  return Status::ok();
}

// bandwidth.dat, bandwidth.gp, stages.dat and stages.gp, and, with plot, the PNGs
// gnuplot draws from them (have_bw, have_st: drawn).
Status writePlots(const std::string& dir, const ReportInput& in, const std::vector<ConditionSummary>& summary, bool plot,
                  bool& have_bw, bool& have_st) {
  // bandwidth.dat: one line per condition, a column per dataset (MB/s, then its SD).
  std::string bw_dat = "condition";
  for (const ReportDataset& d : in.datasets) bw_dat += " " + d.dataset.name + " " + d.dataset.name + "_sd";
  bw_dat += "\n";
  for (const Condition& c : in.conditions) {
    bw_dat += c.name;
    for (const ReportDataset& d : in.datasets) {
      const ConditionSummary* s = find(summary, d.dataset.name, c.name);
      bw_dat += " " + (s ? fixed(s->mb_per_s_mean, 5) : std::string("NaN")) + " " + (s ? fixed(s->mb_per_s_sd, 5) : "NaN");
    }
    bw_dat += "\n";
  }
  std::string bw_gp =
      "# Draws bandwidth.png from bandwidth.dat; written by fovea-eval. Run: gnuplot bandwidth.gp\n"
      "set terminal pngcairo size 900,500 noenhanced\nset output 'bandwidth.png'\n"
      "set title 'Bandwidth at the socket per condition (mean over HMD positions, error bar: SD)'\n"
      "set ylabel 'MB/s (UDP payloads + IP/UDP headers)'\nset style data histogram\n"
      "set style histogram errorbars gap 2 lw 1\nset style fill solid 0.7 border -1\nset key top left\n"
      "set yrange [0:*]\nset grid ytics\n";
  bw_gp += "plot ";
  for (std::size_t k = 0; k < in.datasets.size(); ++k) {
    bw_gp += (k ? ", " : "") + std::string("'bandwidth.dat' using ") + std::to_string(2 + 2 * k) + ":" +
             std::to_string(3 + 2 * k) + ":xtic(1) title '" + in.datasets[k].dataset.name + "'";
  }
  bw_gp += "\n";
  // stages.dat: per dataset a block, a line per condition, a column per stage (mean ms).
  std::string st_dat;
  for (std::size_t k = 0; k < in.datasets.size(); ++k) {
    if (k) st_dat += "\n\n";
    st_dat += "condition";
    for (const char* s : kStageNames) st_dat += std::string(" ") + s;
    st_dat += "\n";
    for (const Condition& c : in.conditions) {
      const ConditionSummary* s = find(summary, in.datasets[k].dataset.name, c.name);
      st_dat += c.name;
      // (acquire is left out of the stack: it waits for the camera, before capture)
      for (std::size_t j = 0; j < kStageCount; ++j) st_dat += " " + (s ? fixed(j == 0 ? 0.0 : s->stage_mean_ms[j], 4) : "NaN");
      st_dat += "\n";
    }
  }
  std::string st_gp =
      "# Draws stages.png from stages.dat; written by fovea-eval. Run: gnuplot stages.gp\n"
      "set terminal pngcairo size " + std::to_string(420 * std::max<std::size_t>(1, in.datasets.size())) +
      ",520 noenhanced\nset output 'stages.png'\n"
      "set style data histogram\nset style histogram rowstacked\nset style fill solid 0.8 border -1\n"
      "set key outside bottom horizontal\nset ylabel 'ms (mean per frame), capture to decoded'\nset grid ytics\nset yrange [0:*]\n"
      "set multiplot layout 1," + std::to_string(std::max<std::size_t>(1, in.datasets.size())) + "\n";
  for (std::size_t k = 0; k < in.datasets.size(); ++k) {
    st_gp += "set title '" + in.datasets[k].dataset.name + "'\n";
    st_gp += std::string(k + 1 < in.datasets.size() ? "unset key\n" : "set key\n");
    st_gp += "plot for [c=3:" + std::to_string(1 + kStageCount) + "] 'stages.dat' index " + std::to_string(k) +
             " using c:xtic(1) title columnheader(c)\n";
  }
  st_gp += "unset multiplot\n";
  for (const auto& [name, text] : {std::pair<std::string, std::string>{"bandwidth.dat", bw_dat}, {"bandwidth.gp", bw_gp},
                                   {"stages.dat", st_dat}, {"stages.gp", st_gp}}) {
    if (Status s = writeFile(dir + "/" + name, text); !s) return s;
  }
  if (plot) {
    have_bw = drawWithGnuplot(dir, "bandwidth.gp", "bandwidth.png");
    have_st = drawWithGnuplot(dir, "stages.gp", "stages.png");
  }
  return Status::ok();
}

// The title, the command, the host and what each figure measures.
void writeIntroMarkdown(std::ostream& md, const ReportInput& in) {
  char date[64];
  const std::time_t now = std::time(nullptr);
  std::strftime(date, sizeof date, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  md << "# fovea-eval: the paper's Table II on fovea's pipeline\n\n"
     << "Generated by `fovea-eval` (" << date << "), " << fixed(in.elapsed_s / 60.0, 1) << " minutes"
     << (in.resumed_runs > 0 ? " (" + std::to_string(in.resumed_runs) + " of the runs were finished by an earlier "
                                   "invocation and read back from runs/)"
                             : std::string())
     << ":\n\n"
     << "```\n" << in.options_line << "\n```\n\n"
     << "- host: " << hostLine() << "\n"
     << "- " << in.frames << " frames per HMD position, " << in.runs.size() << " runs" << (in.failed_runs ? ", " + std::to_string(in.failed_runs) + " failed (missing from the tables)" : std::string()) << "; seed " << in.seed << "\n"
     << "- each run: `fovead serve --preset P --camera SPEC --timing-log` and `fovea-operator --gaze scan:... --frame-log` "
        "as two processes over loopback (127.0.0.1), the camera paced at 30 fps; "
     << conditionSettingsText(in.conditions) << "the frames measured are the first "
     << in.frames << " the operator decoded; the link's budget is 125 MB/s (a gigabit link: no condition is cut to "
        "fit) and the operator asks for a 4 MiB receive buffer (so that a frame's datagrams arriving faster than they "
        "are decoded are not dropped); the datagrams lost are counted per condition\n"
     << "- **bandwidth**: per frame, what the service handed to its UDP socket (each datagram's payload: the chunk, "
        "fovea's header and authentication tag) plus 28 bytes of IPv4 and UDP headers per datagram, which is what a "
        "packet capture such as the paper's Wireshark counts (Ethernet framing aside; the 1 Hz status datagrams are "
        "left out); MB/s = bytes per frame x the frames' capture rate\n"
     << "- **latency**: from the moment the camera call returned the frame (capture) to the moment the operator had "
        "received and decoded it, on the one host's clock; per stage from the service's timing log; the last stage is "
        "the rest (the network, receiving and decoding). The camera's own exposure and read-out are not in it: the "
        "mock camera renders, TUM frames are read from disk\n"
     << "- reductions are against FREF of the same dataset; p: Welch's t-test (two-sided) between the condition's "
        "per-position means and FREF's (tools/eval/statistics.h: the t distribution from the regularised incomplete "
        "beta function, DLMF 8.17.22)\n\n";
}

// Each dataset's scene and HMD positions.
void writeDatasetsMarkdown(std::ostream& md, const ReportInput& in) {
  md << "## Datasets and HMD positions\n\n"
     << "| dataset | paper | camera | scene centre [m] | position | eye [m] | distance to centre [m] | fixations |\n"
     << "|---|---|---|---|---:|---|---:|---:|\n";
  for (const ReportDataset& d : in.datasets) {
    for (const HmdPosition& p : d.positions) {
      md << "| " << d.dataset.name << " | " << (d.dataset.paper_name.empty() ? "-" : d.dataset.paper_name) << " | `"
         << d.dataset.camera_spec << "` | " << vec(d.geometry.centre_m) << " | " << p.index << " | " << vec(p.eye_m)
         << " | " << fixed(p.distance_m, 2) << " | " << p.targets_m.size() << " |\n";
    }
  }
  md << "\nThe gaze of each position: `fovea-operator --gaze scan:EYE>T1;...@400/50`, fixations of 400 ms on the "
        "scene's centre and four seeded points within 0.5 m of it, saccades of 50 ms between them (runs/*/operator.log "
        "and the positions above).\n\n";
}

// Table II per dataset: bandwidth and latency, their reductions against FREF.
void writeTableIIMarkdown(std::ostream& md, const ReportInput& in, const std::vector<ConditionSummary>& summary,
                          bool have_bw) {
  md << "## Table II: bandwidth and latency\n\n"
     << "Mean over the HMD positions (SD across positions); latency p99 over every frame of the condition.\n\n";
  for (const ReportDataset& d : in.datasets) {
    md << "### " << d.dataset.name << (d.dataset.paper_name.empty() ? "" : " (the paper's " + d.dataset.paper_name + ")")
       << "\n\n| condition | MB/s | reduction | p | latency [ms] | p99 [ms] | reduction | p | points / frame | frames cut short | datagrams lost |\n"
       << "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    for (const Condition& c : in.conditions) {
      const ConditionSummary* s = find(summary, d.dataset.name, c.name);
      if (!s) continue;
      md << "| " << c.name << " | " << fixed(s->mb_per_s_mean, 3) << " (" << fixed(s->mb_per_s_sd, 3) << ") | "
         << (std::isnan(s->bandwidth_reduction) ? "-" : fixed(s->bandwidth_reduction, 1) + " %") << " | "
         << pValue(s->bandwidth_p) << " | " << fixed(s->latency_mean_ms, 1) << " (" << fixed(s->latency_sd_ms, 1) << ") | "
         << fixed(s->latency_p99_ms, 1) << " | "
         << (std::isnan(s->latency_reduction) ? "-" : fixed(s->latency_reduction, 1) + " %") << " | "
         << pValue(s->latency_p) << " | " << fixed(s->points_per_frame, 0) << " | " << s->incomplete << " | "
         << s->datagrams_lost << " of " << s->datagrams << " |\n";
    }
    md << "\n";
  }
  if (have_bw) md << "![bandwidth per condition](bandwidth.png)\n\n";
}

// The paper's own Table II beside fovea's reductions.
void writePaperMarkdown(std::ostream& md, const ReportInput& in, const std::vector<ConditionSummary>& summary) {
  md << "### Beside the paper's (theirs: different hardware, a different encoder, a different network)\n\n"
     << "The paper's Table II as published (MB/s; ms), and the reductions against its FREF, with fovea's reductions "
        "on the matching dataset:\n\n"
     << "| dataset | condition | paper MB/s | paper ms | paper: bandwidth reduction | paper: latency reduction | "
        "fovea: bandwidth reduction | fovea: latency reduction | fovea MB/s | fovea ms |\n"
     << "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const char* paper : {"LIV", "BAL"}) {
    const ReportDataset* ours = nullptr;
    for (const ReportDataset& d : in.datasets) {
      if (d.dataset.paper_name == paper) ours = &d;
    }
    const PaperFigures ref = paperTableII(paper, "FREF");
    for (const char* cond : {"F1", "F2", "F3", "FREF"}) {
      const PaperFigures p = paperTableII(paper, cond);
      const ConditionSummary* s = ours ? find(summary, ours->dataset.name, cond) : nullptr;
      const bool is_ref = std::string(cond) == "FREF";
      md << "| " << paper << " | " << cond << " | " << fixed(p.mb_per_s, 2) << " | " << fixed(p.latency_ms, 0) << " | "
         << (is_ref ? "-" : fixed(100.0 * (1.0 - p.mb_per_s / ref.mb_per_s), 1) + " %") << " | "
         << (is_ref ? "-" : fixed(100.0 * (1.0 - p.latency_ms / ref.latency_ms), 1) + " %") << " | "
         << (s && !is_ref ? fixed(s->bandwidth_reduction, 1) + " %" : "-") << " | "
         << (s && !is_ref ? fixed(s->latency_reduction, 1) + " %" : "-") << " | "
         << (s ? fixed(s->mb_per_s_mean, 3) : "-") << " | " << (s ? fixed(s->latency_mean_ms, 1) : "-") << " |\n";
    }
  }
  md << "\n";
}

// The latency of each stage per dataset and condition.
void writeStagesMarkdown(std::ostream& md, const ReportInput& in, const std::vector<ConditionSummary>& summary,
                         bool have_st) {
  md << "## Latency per stage\n\n"
     << "Mean (p99) per frame, ms. *acquire* is the camera call, which waits for the next frame at 30 fps: it comes "
        "before capture and is not part of the end-to-end latency. The rest add up to capture-to-decoded.\n\n";
  for (const ReportDataset& d : in.datasets) {
    md << "### " << d.dataset.name << "\n\n| stage |";
    for (const Condition& c : in.conditions) md << " " << c.name << " |";
    md << "\n|---|";
    for (std::size_t k = 0; k < in.conditions.size(); ++k) md << "---:|";
    md << "\n";
    for (std::size_t st = 0; st < kStageCount; ++st) {
      md << "| " << kStageTitles[st] << " |";
      for (const Condition& c : in.conditions) {
        const ConditionSummary* s = find(summary, d.dataset.name, c.name);
        md << " " << (s ? fixed(s->stage_mean_ms[st], 2) + " (" + fixed(s->stage_p99_ms[st], 2) + ")" : "-") << " |";
      }
      md << "\n";
    }
    md << "| **capture to decoded** |";
    for (const Condition& c : in.conditions) {
      const ConditionSummary* s = find(summary, d.dataset.name, c.name);
      md << " **" << (s ? fixed(s->latency_mean_ms, 2) + " (" + fixed(s->latency_p99_ms, 2) + ")" : "-") << "** |";
    }
    md << "\n\n";
  }
  if (have_st) md << "![latency per stage](stages.png)\n\n";
}

// The quality measures: what they are, and their means per dataset and condition.
void writeQualityMarkdown(std::ostream& md, const ReportInput& in) {
  const std::vector<double>& edges = in.quality_options.ring_edges_deg;
  md << "## Visual quality: an objective stand-in for the paper's user study\n\n"
     << "**These are objective proxies, not a user study.** The paper asked 24 people to rate each condition against "
        "FREF (DSIS, a 5-point impairment scale). Here, for frame " << in.quality_frame << " of each dataset (with "
        "MAP-DELTA: the frame its operator saved, in the `frame` column) and each HMD position measured, every condition's cloud (foveated with that position's gaze on the scene's centre, "
        "through the stream's codec and back) is drawn by a deterministic software renderer (tools/eval/quality/: "
        "z-buffered square splats, a raw point as large as the camera pixel it came from, a voxel-sampled one as "
        "large as its voxel or, when that is finer, as that pixel) from the HMD's eye at "
     << in.quality_options.width << "x" << in.quality_options.height << " pixels and a "
     << fixed(in.quality_options.horizontal_fov_deg, 0) << "-degree horizontal field of view, and compared with FREF "
        "drawn from the same eye:\n\n"
     << "- **PSNR and SSIM per eccentricity ring** around the gaze (rings at";
  for (std::size_t k = 0; k < edges.size(); ++k) md << (k ? ", " : " ") << fixed(edges[k], 1);
  md << " degrees); SSIM after Wang et al. (2004) on luma with an 11x11 Gaussian window;\n"
     << "- **weighted by acuity**: each ring weighs its pixel count over MAR(E) at its middle (m = "
     << fixed(in.quality_options.slope, 3) << "), so an error where the eye resolves finely counts more; the weighted "
        "PSNR is that of the weighted mean squared error;\n"
     << "- **above MAR**: the share of input points displaced, seen from the eye, by more than the MAR at their "
        "eccentricity (the speed-against-error report's measure, docs/report/).\n\n"
     << "Means over the positions measured (FREF against itself: PSNR inf, SSIM 1):\n\n";
  if (std::any_of(in.conditions.begin(), in.conditions.end(), [](const Condition& c) { return c.map_delta; })) {
    md << "MAP-DELTA is drawn from what its run's operator held (`fovea-operator --save-held`, docs/eval.md): the "
          "live points of the first frame from the quality frame on that arrived whole, and every map brick it held "
          "then; every condition of that position is drawn from that frame (the camera's sequence number, the "
          "`frame` column). Its *above MAR* judges each FREF input point inside the eye's image against the nearest "
          "point drawn, not against its own representative (there is none): not the same measure as the other "
          "rows'. A position whose operator saved nothing is *not measured*.\n\n";
  }
  for (const ReportDataset& d : in.datasets) {
    md << "### " << d.dataset.name << "\n\n| condition | positions | frame | points drawn | weighted PSNR [dB] | weighted SSIM | "
          "PSNR, whole image [dB] | SSIM, whole image | above MAR |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    for (const Condition& c : in.conditions) {
      const QualityMean q = qualityMean(in.quality, d.dataset.name, c.name);
      if (q.positions == 0 && q.not_measured == 0) continue;
      if (q.positions == 0) {
        md << "| " << c.name << " | 0 of " << q.not_measured << " | - | not measured | not measured | not measured | "
           << "not measured | not measured | not measured |\n";
        continue;
      }
      md << "| " << c.name << " | " << q.positions << (q.not_measured ? " of " + std::to_string(q.positions + q.not_measured) : "")
         << " | " << q.frames << " | " << fixed(q.points, 0) << " | " << fixed(q.weighted_psnr, 2)
         << " | " << fixed(q.weighted_ssim, 4) << " | " << fixed(q.psnr, 2) << " | " << fixed(q.ssim, 4) << " | "
         << (std::isnan(q.above_mar) ? std::string("n/a") : fixed(100.0 * q.above_mar, 1) + " %")
         << (c.map_delta ? " (nearest point)" : "") << " |\n";
    }
    md << "\n";
  }
}

// Per ring, the first dataset's first position.
void writeRingsMarkdown(std::ostream& md, const ReportInput& in) {
  if (!in.quality.empty()) {
    const QualityRow& first = in.quality.front();
    md << "Per ring, " << first.dataset << " position " << first.position << " (PSNR dB / SSIM; the ring's weight):\n\n"
       << "| condition |";
    const std::vector<Ring>& rings = first.quality.rings;
    for (const Ring& r : rings) md << " " << fixed(r.inner_deg, 1) << "-" << fixed(r.outer_deg, 1) << " deg |";
    md << "\n|---|";
    for (std::size_t k = 0; k < rings.size(); ++k) md << "---:|";
    md << "\n| (weight) |";
    for (const Ring& r : rings) md << " " << fixed(r.weight, 3) << " |";
    md << "\n";
    for (const QualityRow& q : in.quality) {
      if (q.dataset != first.dataset || q.position != first.position) continue;
      md << "| " << q.condition << " |";
      for (const Ring& r : q.quality.rings) md << " " << fixed(r.psnr_db, 1) << " / " << fixed(r.ssim, 3) << " |";
      md << "\n";
    }
    md << "\n";
  }
}

// The side-by-side images, listed, and F1's shown.
void writeSideBySideMarkdown(std::ostream& md, const ReportInput& in) {
  md << "### Side by side\n\nReference (FREF) | condition | difference x4, from position 1's eye (4x smaller than "
        "rendered). On the difference: the condition's region borders (its cones, those within 90 degrees) in cyan, or "
        "for ACUITY, which has none, the measuring rings; the gaze is the magenta cross.\n\n";
  for (const QualityRow& q : in.quality) {
    if (q.image.empty() || q.condition == "FREF") continue;
    md << "- " << q.dataset << ", " << q.condition << ": [" << q.image << "](" << q.image << ")\n";
  }
  md << "\n";
  // The first F1 image shown, when F1 was run (no empty image link otherwise).
  const auto f1 = std::find_if(in.quality.begin(), in.quality.end(),
                               [](const QualityRow& q) { return !q.image.empty() && q.condition == "F1"; });
  if (f1 != in.quality.end()) md << "![" << f1->dataset << " F1](" << f1->image << ")\n\n";
}

// How a real study like the paper's would be run.
void writeStudyMarkdown(std::ostream& md) {
  md << "### A real study\n\n"
     << "A DSIS study like the paper's can be run with fovea's browser viewer (docs/viewer.md): `fovead serve` streams "
        "the dataset, `fovea-operator --view 8080` serves the page, and each subject watches the FREF stream, then "
        "after a 3-second grey pause the same scene with the condition's preset (restart the service with "
        "`--preset`), in randomised order, and rates the second on the 5-point impairment scale (ITU-R BT.500). The "
        "viewer's cursor (or an eye tracker feeding `--gaze csv:`) supplies the gaze. Nothing here replaces that: the "
        "measures above say where the images differ and by how much, not whether people mind.\n";
}

}  // namespace

Status writeReport(const std::string& dir, const ReportInput& in, bool plot) {
  const std::vector<ConditionSummary> summary = summarise(in.runs);
  if (Status s = writeCsvFiles(dir, in, summary); !s) return s;
  bool have_bw = false, have_st = false;
  if (Status s = writePlots(dir, in, summary, plot, have_bw, have_st); !s) return s;
  std::ostringstream md;
  writeIntroMarkdown(md, in);
  writeDatasetsMarkdown(md, in);
  writeTableIIMarkdown(md, in, summary, have_bw);
  writePaperMarkdown(md, in, summary);
  writeStagesMarkdown(md, in, summary, have_st);
  writeQualityMarkdown(md, in);
  writeRingsMarkdown(md, in);
  writeSideBySideMarkdown(md, in);
  writeStudyMarkdown(md);
  return writeFile(dir + "/report.md", md.str());
}

}  // namespace fovea::tools::eval
