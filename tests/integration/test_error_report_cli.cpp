// fovea-error-report as a user runs it, on a tiny camera: the files it writes and
// the rows of its CSV. No timing is asserted.
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/process.h"
#include "tests/support/programs.h"

namespace fovea {
namespace {

using test::ProcessResult;
using test::TempDir;
ProcessResult run(const std::string& command) { return test::runCommand(command); }

std::vector<std::string> splitCsvLine(const std::string& line) {
  std::vector<std::string> fields;
  std::stringstream in(line);
  std::string field;
  while (std::getline(in, field, ',')) fields.push_back(field);
  if (!line.empty() && line.back() == ',') fields.emplace_back();
  return fields;
}

std::string readAll(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Cross builds run the tool through the same emulator as the tests.
const std::string kTool =
    test::program(FOVEA_ERROR_REPORT_PATH);

// A CSV's column index by name.
using Columns = std::map<std::string, std::size_t>;

// Regions per preset, plus one "all" row: F1 4, F2 5, F3 6, FREF 1; ACUITY's 8
// levels once per default level margin and per default refined row.
const std::map<std::string, int> kTinyRunRegions = {{"F1", 4},
                                                    {"F2", 5},
                                                    {"F3", 6},
                                                    {"FREF", 1},
                                                    {"ACUITY k=1.73", 8},
                                                    {"ACUITY k=0.70", 8},
                                                    {"ACUITY k=0.50", 8},
                                                    {"ACUITY k=0.42", 8},
                                                    {"ACUITY k=0.30 refined 1", 8},
                                                    {"ACUITY k=0.12 refined 2", 8},
                                                    {"ACUITY k=0.15 refined 7", 8}};

// What the tiny run's rows add up to.
struct TinyRunRows {
  std::set<std::string> seen;
  std::map<std::string, double> fref_rms, f1_points, fref_points;
  std::map<std::string, double> all_bytes, region_bytes_sum;  // per preset/m
};

// The header's columns, every one the report promises among them.
void readTinyRunHeader(std::ifstream& csv, std::vector<std::string>& header, Columns& column) {
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  header = splitCsvLine(line);
  for (std::size_t i = 0; i < header.size(); ++i) column[header[i]] = i;
  for (const char* name : {"preset", "m", "region", "region_name", "points_out", "bytes_per_frame", "raw_bytes_per_frame", "time_ms_median",
                           "rms_mm", "max_mm", "rms_over_voxel", "share_above_mar", "ratio_median"}) {
    ASSERT_TRUE(column.count(name)) << "missing column " << name << " in " << line;
  }
}

// One row: its sizes and, for a frame's "all" row, its time and errors; what
// the totals need is added to `rows`.
void checkTinyRunRow(const std::string& line, std::size_t header_size, Columns& column, TinyRunRows& rows) {
  const std::vector<std::string> f = splitCsvLine(line);
  ASSERT_EQ(f.size(), header_size) << line;
  const std::string key = f[column["preset"]] + "/" + f[column["m"]] + "/" + f[column["region"]];
  EXPECT_TRUE(rows.seen.insert(key).second) << "duplicate row " << key;
  ASSERT_TRUE(kTinyRunRegions.count(f[column["preset"]])) << line;
  const std::string config = f[column["preset"]] + "/" + f[column["m"]];
  const double bytes = std::stod(f[column["bytes_per_frame"]]);
  const double points_out = std::stod(f[column["points_out"]]);
  EXPECT_DOUBLE_EQ(std::stod(f[column["raw_bytes_per_frame"]]), 15.0 * points_out) << line;
  // On the wire: the codec's few bytes a point plus 36 bytes of framing per 1200-byte
  // datagram, and at least one chunk's table (about 100 bytes) for a region of a few
  // points (ACUITY's sparse levels).
  if (points_out > 0) {
    EXPECT_GT(bytes, 1.0 * points_out) << line;
    EXPECT_LT(bytes, 15.0 * points_out + 200.0) << line;
  }
  if (f[column["region"]] == "all") {
    rows.all_bytes[config] = bytes;
  } else {
    rows.region_bytes_sum[config] += bytes;
  }
  if (f[column["region"]] == "all") {
    EXPECT_FALSE(f[column["time_ms_median"]].empty()) << line;
    const double points = points_out;
    if (f[column["preset"]] == "FREF") {
      rows.fref_rms[f[column["m"]]] = std::stod(f[column["rms_mm"]]);
      rows.fref_points[f[column["m"]]] = points;
      EXPECT_EQ(std::stod(f[column["share_above_mar"]]), 0.0) << line;
    }
    if (f[column["preset"]] == "F1") rows.f1_points[f[column["m"]]] = points;
    // The diagonal margin keeps every point under its MAR, and so does refinement to the end.
    if (f[column["preset"]] == "ACUITY k=1.73" || f[column["preset"]] == "ACUITY k=0.15 refined 7") {
      EXPECT_EQ(std::stod(f[column["share_above_mar"]]), 0.0) << line;
    }
  } else {
    EXPECT_LT(std::stoi(f[column["region"]]), kTinyRunRegions.at(f[column["preset"]])) << line;
  }
}

// Every preset's rows once per slope, a frame's bytes its regions' bytes, and
// FREF exact with more points than F1.
void expectEveryRowOnce(TinyRunRows& rows) {
  // A frame's bytes are its regions' bytes.
  for (const auto& [config, bytes] : rows.all_bytes) EXPECT_NEAR(rows.region_bytes_sum[config], bytes, 1e-6 * bytes) << config;
  std::size_t expected_rows = 0;
  for (const auto& [preset, count] : kTinyRunRegions) expected_rows += 3 * static_cast<std::size_t>(count + 1);
  EXPECT_EQ(rows.seen.size(), expected_rows);
  for (const char* m : {"0.022", "0.028", "0.034"}) {
    for (const auto& [preset, count] : kTinyRunRegions) {
      EXPECT_TRUE(rows.seen.count(preset + "/" + m + "/all")) << preset << " m " << m;
      for (int r = 0; r < count; ++r) EXPECT_TRUE(rows.seen.count(preset + "/" + m + "/" + std::to_string(r)));
    }
    EXPECT_EQ(rows.fref_rms[m], 0.0);
    EXPECT_GT(rows.fref_points[m], 1000.0);
    EXPECT_LT(rows.f1_points[m], rows.fref_points[m]);
  }
}

// --replot-from writes the same plot files again from report.csv and report.md alone.
void expectReplotWritesTheSamePlots(const TempDir& dir) {
  const std::vector<std::string> plot_files = {"report.gp", "report_plot.dat", "report_acuity.gp", "report_acuity_plot.dat"};
  std::string plots_before;
  for (const std::string& name : plot_files) {
    plots_before += readAll(dir.file(name));
    std::filesystem::remove(dir.file(name));
  }
  const ProcessResult replot = run(kTool + " --replot-from " + dir.path() + " --no-plot");
  ASSERT_EQ(replot.exit_code, 0) << replot.output;
  std::string plots_after;
  for (const std::string& name : plot_files) plots_after += readAll(dir.file(name));
  EXPECT_EQ(plots_after, plots_before);
  EXPECT_EQ(run(kTool + " --replot-from " + dir.path() + "/nowhere --no-plot").exit_code, 1);
}

// report.md's tables and text; the frame is the only source by default: no map
// section, no nearest-point columns.
void expectTheFrameAloneReported(const TempDir& dir, std::size_t header_size, Columns& column) {
  const std::string md = readAll(dir.file("report.md"));
  for (const char* expected : {"| F1 | 0.022 |", "| FREF | 0.034 |", "scalar reference", "fovea's chunk codec", "15 bytes per output point",
                               "Steps at region borders", "--frames 1"}) {
    EXPECT_NE(md.find(expected), std::string::npos) << "missing '" << expected << "' in report.md";
  }
  // The frame is the only source by default: no map section, no nearest-point columns.
  EXPECT_EQ(md.find("Frame against map"), std::string::npos);
  std::ifstream again(dir.file("report.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(again, line));
  ASSERT_TRUE(column.count("source") && column.count("share_above_mar_surface")) << line;
  while (std::getline(again, line)) {
    const std::vector<std::string> f = splitCsvLine(line);
    ASSERT_EQ(f.size(), header_size) << line;
    EXPECT_EQ(f[column["source"]], "frame") << line;
    EXPECT_EQ(f[column["share_above_mar_surface"]], "") << line;
  }
}

TEST(ErrorReportCli, TinyRunWritesTheExpectedRows) {
  TempDir dir;
  const ProcessResult r =
      run(kTool + " --camera mock:living-room,size=160x120 --frames 1 --dynamics-frames 0 --out-dir " + dir.path());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* name : {"report.csv", "report.md", "report.gp", "report_plot.dat"}) {
    EXPECT_TRUE(std::filesystem::exists(dir.file(name))) << name << "\n" << r.output;
  }
  // The plot is optional at run time: either drawn or the program says why not.
  EXPECT_TRUE(std::filesystem::exists(dir.file("report.png")) ||
              r.output.find("gnuplot not found") != std::string::npos)
      << r.output;

  std::ifstream csv(dir.file("report.csv"));
  std::vector<std::string> header;
  Columns column;
  ASSERT_NO_FATAL_FAILURE(readTinyRunHeader(csv, header, column));
  TinyRunRows rows;
  for (std::string line; std::getline(csv, line);) ASSERT_NO_FATAL_FAILURE(checkTinyRunRow(line, header.size(), column, rows));
  expectEveryRowOnce(rows);
  ASSERT_NO_FATAL_FAILURE(expectReplotWritesTheSamePlots(dir));
  ASSERT_NO_FATAL_FAILURE(expectTheFrameAloneReported(dir, header.size(), column));
}

// --sources frame,map on a tiny orbit: the map's rows beside the frame's, both
// judged against the true surface by the nearest sent point.
TEST(ErrorReportCli, MapSourceRowsBesideTheFrame) {
  TempDir dir;
  const ProcessResult r = run(kTool + " --camera mock:living-room,size=160x120,path=orbit --frames 3 --map-warmup 10 "
                                      "--sources frame,map --presets F1,ACUITY --slopes 0.022 --acuity-margins 0.5 "
                                      "--acuity-refined none --dynamics-frames 0 --no-plot --out-dir " + dir.path());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("map warmed up over 10 frames: 10 fused, 0 refused"), std::string::npos) << r.output;
  std::ifstream csv(dir.file("report.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  const std::vector<std::string> header = splitCsvLine(line);
  std::map<std::string, std::size_t> column;
  for (std::size_t i = 0; i < header.size(); ++i) column[header[i]] = i;
  for (const char* name : {"source", "share_above_mar_surface", "share_above_reference_mar_surface", "rms_mm_surface",
                           "fuse_ms_median", "map_frame_points", "map_surfels"}) {
    ASSERT_TRUE(column.count(name)) << "missing column " << name << " in " << line;
  }
  std::map<std::string, std::vector<std::string>> all;  // "source/preset" -> its all row
  std::set<std::string> keys;
  while (std::getline(csv, line)) {
    const std::vector<std::string> f = splitCsvLine(line);
    ASSERT_EQ(f.size(), header.size()) << line;
    EXPECT_TRUE(keys.insert(f[column["source"]] + "/" + f[column["preset"]] + "/" + f[column["region"]]).second) << line;
    if (f[column["region"]] == "all") all[f[column["source"]] + "/" + f[column["preset"]]] = f;
  }
  ASSERT_EQ(all.size(), 4u);
  const auto value = [&](const std::string& row, const char* name) {
    const std::string& text = all.at(row)[column.at(name)];
    EXPECT_FALSE(text.empty()) << row << " " << name;
    return text.empty() ? -1.0 : std::stod(text);
  };
  for (const char* source : {"frame", "map"}) {
    for (const char* preset : {"F1", "ACUITY k=0.50"}) {
      const std::string row = std::string(source) + "/" + preset;
      ASSERT_TRUE(all.count(row)) << row;
      const double points = value(row, "points_out"), bytes = value(row, "bytes_per_frame");
      EXPECT_GT(points, 1000.0) << row;
      EXPECT_GT(bytes, points) << row;
      EXPECT_LT(bytes, 15.0 * points + 200.0) << row;
      // Against the true surface, every row: a share, some of it above (the sensor's
      // noise, F1's coarse periphery), and F1's coarse periphery worse than ACUITY's levels.
      const double share = value(row, "share_above_mar_surface");
      EXPECT_GT(share, 0.0) << row;
      EXPECT_LT(share, 1.0) << row;
      EXPECT_GT(value(row, "rms_mm_surface"), 0.0) << row;
      EXPECT_GT(value(row, "time_ms_median"), 0.0) << row;
    }
    EXPECT_GT(value(std::string(source) + "/F1", "share_above_mar_surface"),
              2.0 * value(std::string(source) + "/ACUITY k=0.50", "share_above_mar_surface"))
        << source;
  }
  for (const char* preset : {"F1", "ACUITY k=0.50"}) {
    const std::string row = std::string("map/") + preset;
    // The map's cloud is its surfels the eye sees and the frame's unexplained points.
    const double surfels = value(row, "map_surfels"), unexplained = value(row, "map_frame_points");
    EXPECT_GT(surfels, 1000.0) << row;
    EXPECT_GE(unexplained, 0.0) << row;
    EXPECT_NEAR(value(row, "points_in"), surfels + unexplained, 0.01) << row;
    // Its time includes the frame's fusion (each frame's time is its fusion's and more).
    const double fuse = value(row, "fuse_ms_median");
    EXPECT_GT(fuse, 0.0) << row;
    EXPECT_GE(value(row, "time_ms_median"), fuse) << row;
    // The frame's rows have no map columns.
    EXPECT_EQ(all.at(std::string("frame/") + preset)[column.at("fuse_ms_median")], "") << preset;
    EXPECT_EQ(all.at(std::string("frame/") + preset)[column.at("map_surfels")], "") << preset;
  }
  const std::string md = readAll(dir.file("report.md"));
  for (const char* expected : {"## Frame against map", "warmed up over 10 frames", "| map | F1 | 0.022 |",
                               "| frame | ACUITY k=0.50 | 0.022 |"}) {
    EXPECT_NE(md.find(expected), std::string::npos) << "missing '" << expected << "' in report.md";
  }
}

TEST(ErrorReportCli, SubsetOfPresetsAndSlopes) {
  TempDir dir;
  const ProcessResult r = run(kTool + " --camera mock:balloon,size=96x72 --frames 2 --presets F3,FREF --slopes 0.03 "
                                      "--no-plot --dynamics-frames 0 --out-dir " + dir.path());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir.file("report.png")));
  const std::string csv = readAll(dir.file("report.csv"));
  std::size_t rows = 0;
  for (char c : csv) rows += c == '\n';
  EXPECT_EQ(rows, 1u + 7u + 2u) << csv;  // header, F3's 6 regions + all, FREF's 1 + all
  EXPECT_NE(csv.find("\nF3,0.03,5,far-periphery,"), std::string::npos) << csv;
}

TEST(ErrorReportCli, HelpAndBadArguments) {
  EXPECT_EQ(run(kTool + " --help").exit_code, 0);
  EXPECT_EQ(run(kTool + " --frames 0").exit_code, 2);
  EXPECT_EQ(run(kTool + " --frames").exit_code, 2);
  EXPECT_EQ(run(kTool + " --presets F9").exit_code, 2);
  EXPECT_EQ(run(kTool + " --slopes -0.1").exit_code, 2);
  EXPECT_EQ(run(kTool + " --camera mock:nowhere-scene-x,size=1x").exit_code, 2);
  EXPECT_EQ(run(kTool + " --bogus").exit_code, 2);
  EXPECT_EQ(run(kTool + " --eye-offset 1,2").exit_code, 2);
  EXPECT_EQ(run(kTool + " --dynamics-frames -1").exit_code, 2);
  EXPECT_EQ(run(kTool + " --acuity-noise-floors 0").exit_code, 2);
  for (const char* refined : {"0.15", "0.15:0", "0.15:8", "0.05:2", "0.15:2x", "x:2", "0.15:"}) {
    EXPECT_EQ(run(kTool + " --acuity-refined " + refined).exit_code, 2) << refined;
  }
  EXPECT_EQ(run(kTool + " --growth-lead-ms -5").exit_code, 2);
  EXPECT_EQ(run(kTool + " --growth-lead-ms 2000").exit_code, 2);
  for (const char* sources : {"frame,frame", "map,map", "fram", "frame,", "''"}) {
    EXPECT_EQ(run(kTool + " --sources " + sources).exit_code, 2) << sources;
  }
  for (const char* warmup : {"-1", "1.5", "x", "100001"}) {
    EXPECT_EQ(run(kTool + " --map-warmup " + warmup).exit_code, 2) << warmup;
  }
}

// The figures over time on a scene with nothing moving and no sensor noise: a
// fixed gaze gives the same output every frame (0 changed) in every configuration;
// a drifting gaze changes something; the fovea's growth never coarsens, so its
// coverage is at least that without it; and with no noise there is no true-surface
// twin (with noise there is).
TEST(ErrorReportCli, DynamicsFiguresOnANoiselessStaticScene) {
  TempDir dir;
  const ProcessResult r = run(kTool + " --camera mock:living-room,size=160x120,noise=off --frames 1 --presets F1,ACUITY "
                                      "--slopes 0.022 --acuity-margins 0.5 --acuity-noise-floors 1 --dynamics-frames 4 "
                                      "--coverage-seconds 0.6 "
                                      "--out-dir " + dir.path());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream csv(dir.file("dynamics.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  const std::vector<std::string> header = splitCsvLine(line);
  std::map<std::string, std::size_t> column;
  for (std::size_t i = 0; i < header.size(); ++i) column[header[i]] = i;
  for (const char* name : {"configuration", "changed_fixed", "changed_drift", "coverage_all", "coverage_moving",
                           "moving_frames", "frames", "bytes_per_frame"}) {
    ASSERT_TRUE(column.count(name)) << "missing column " << name << " in " << line;
  }
  std::map<std::string, std::vector<std::string>> rows;
  while (std::getline(csv, line)) {
    const std::vector<std::string> f = splitCsvLine(line);
    ASSERT_EQ(f.size(), header.size()) << line;
    rows[f[0]] = f;
  }
  for (const char* name : {"F1", "F2", "F3", "ACUITY k=0.50", "ACUITY k=0.50 growth", "ACUITY k=0.50 growth floor 1mm*r^2"}) {
    ASSERT_TRUE(rows.count(name)) << name;
  }
  const auto value = [&](const std::string& row, const char* col) { return std::stod(rows[row][column[col]]); };
  double drift_changed = 0.0;
  for (const auto& [name, f] : rows) {
    EXPECT_EQ(value(name, "changed_fixed"), 0.0) << name;
    drift_changed += value(name, "changed_drift");
    EXPECT_GT(value(name, "moving_frames"), 0.0) << name;
    EXPECT_GT(value(name, "coverage_all"), 0.0) << name;
    EXPECT_LE(value(name, "coverage_all"), 1.0) << name;
    EXPECT_GT(value(name, "bytes_per_frame"), 0.0) << name;
  }
  EXPECT_GT(drift_changed, 0.0);
  EXPECT_GE(value("ACUITY k=0.50 growth", "coverage_moving"), value("ACUITY k=0.50", "coverage_moving"));
  EXPECT_GE(value("ACUITY k=0.50 growth", "bytes_per_frame"), value("ACUITY k=0.50", "bytes_per_frame"));
  const std::string md = readAll(dir.file("report.md"));
  EXPECT_NE(md.find("## Temporal stability"), std::string::npos);
  EXPECT_NE(md.find("## Latency-corrected fovea coverage"), std::string::npos);
  EXPECT_EQ(md.find("true surface |"), std::string::npos);

  // With sensor noise: the true-surface columns; --dynamics-frames 0: no figures over time.
  TempDir noisy;
  const ProcessResult n = run(kTool + " --camera mock:living-room,size=160x120 --frames 1 --presets FREF --slopes 0.022 "
                                      "--dynamics-frames 0 --eye-offset 0.5,0,0 --out-dir " + noisy.path());
  ASSERT_EQ(n.exit_code, 0) << n.output;
  const std::string noisy_md = readAll(noisy.file("report.md"));
  EXPECT_NE(noisy_md.find("true surface |"), std::string::npos);
  EXPECT_EQ(noisy_md.find("## Temporal stability"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(noisy.file("dynamics.csv")));
  // FREF sends every reading as it is: against its own readings nothing is
  // displaced; against the true surface, seen from beside the camera, the noise is.
  std::ifstream noisy_csv(noisy.file("report.csv"));
  ASSERT_TRUE(std::getline(noisy_csv, line));
  const std::vector<std::string> h = splitCsvLine(line);
  std::size_t share = 0, share_true = 0;
  for (std::size_t i = 0; i < h.size(); ++i) {
    if (h[i] == "share_above_mar") share = i;
    if (h[i] == "share_above_mar_true_surface") share_true = i;
  }
  ASSERT_GT(share_true, 0u);
  bool saw_all = false;
  while (std::getline(noisy_csv, line)) {
    const std::vector<std::string> f = splitCsvLine(line);
    if (f[2] != "all") continue;
    saw_all = true;
    EXPECT_EQ(std::stod(f[share]), 0.0);
    EXPECT_GT(std::stod(f[share_true]), 0.0);
  }
  EXPECT_TRUE(saw_all);
}

}  // namespace
}  // namespace fovea
