// fovea-error-report's plots (tools/error_report/report.h): report.gp names the
// paper's presets and at most three ACUITY settings, the ones the docs quote;
// report_acuity.gp has every ACUITY setting; the CSV read back draws the same plots.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/process.h"
#include "tools/error_report/report.h"

namespace fovea::tools {
namespace {

std::string readAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The legend entries ("title '...'") of a gnuplot script that name an ACUITY setting.
std::vector<std::string> acuityTitles(const std::string& script) {
  std::vector<std::string> titles;
  const std::string tag = "title 'ACUITY";
  for (std::size_t at = script.find(tag); at != std::string::npos; at = script.find(tag, at + 1)) {
    const std::size_t start = at + std::string("title '").size();
    titles.push_back(script.substr(start, script.find('\'', start) - start));
  }
  return titles;
}

ConfigSummary config(const std::string& preset, double slope, double bytes, double share) {
  ConfigSummary c;
  c.preset = preset;
  c.slope = slope;
  c.frames = 3;
  c.time_ms_median = 12.5;
  c.all.name = "all";
  c.all.points_out = bytes / 4.0;
  c.all.wire_bytes = bytes;
  c.all.rms_mm = 20.0;
  c.all.share_above_mar = share;
  c.all.share_above_reference_mar = share;
  return c;
}

// The main run's settings: 4 margins x 3 floors and 3 refined rows, at two slopes.
std::vector<ConfigSummary> mainRun() {
  std::vector<ConfigSummary> configs;
  for (double m : {0.022, 0.028}) {
    for (const char* preset : {"F1", "F2", "F3", "FREF"}) configs.push_back(config(preset, m, 150000.0, 0.4));
    for (const char* k : {"1.73", "0.70", "0.50", "0.42"}) {
      for (const char* floor : {"", " floor 1mm*r^2", " floor 2mm*r^2"}) {
        configs.push_back(config(std::string("ACUITY k=") + k + floor, m, 180000.0, 0.02));
      }
    }
    for (const char* refined : {"k=0.30 refined 1", "k=0.12 refined 2", "k=0.15 refined 7"}) {
      configs.push_back(config(std::string("ACUITY ") + refined, m, 200000.0, 0.003));
    }
  }
  return configs;
}

ReportContext context() {
  ReportContext c;
  c.camera = "mock:living-room 640x480";
  c.frames = 3;
  return c;
}

TEST(ErrorReportPlot, TheMainPlotNamesTheQuotedAcuitySettingsOnly) {
  const std::vector<ConfigSummary> configs = mainRun();
  EXPECT_EQ(mainPlotAcuitySettings(configs),
            (std::vector<std::string>{"ACUITY k=0.50", "ACUITY k=0.50 floor 1mm*r^2", "ACUITY k=0.30 refined 1"}));
  test::TempDir dir;
  Result<std::vector<PlotFiles>> written = writePlotFiles(dir.path(), context(), configs);
  ASSERT_TRUE(written) << written.status().toString();
  ASSERT_EQ(written->size(), 2u);
  EXPECT_EQ(std::string(written->at(0).script), kMainPlot.script);
  EXPECT_EQ(std::string(written->at(1).script), kAcuityPlot.script);

  const std::string main_script = readAll(dir.file(kMainPlot.script));
  const std::vector<std::string> main_titles = acuityTitles(main_script);
  EXPECT_EQ(main_titles, mainPlotAcuitySettings(configs)) << main_script;
  EXPECT_LE(main_titles.size(), kMainPlotAcuitySettings);
  // No ACUITY point is labelled on the main plot: only the first slope's presets are.
  EXPECT_EQ(main_script.find("k=0.70"), std::string::npos) << main_script;
  EXPECT_NE(main_script.find("title 'F1, F2, F3, FREF, m = 0.022'"), std::string::npos) << main_script;

  // The second plot names every ACUITY setting but the margin, once per slope (a
  // row of panels each); every ACUITY row of the run is in its data.
  const std::string acuity_script = readAll(dir.file(kAcuityPlot.script));
  std::vector<std::string> acuity_titles = acuityTitles(acuity_script);
  const std::vector<std::string> expected = {"ACUITY", "ACUITY floor 1mm*r^2", "ACUITY floor 2mm*r^2",
                                             "ACUITY k=0.30 refined 1", "ACUITY k=0.12 refined 2",
                                             "ACUITY k=0.15 refined 7"};
  ASSERT_EQ(acuity_titles.size(), 2 * expected.size()) << acuity_script;
  EXPECT_TRUE(std::equal(expected.begin(), expected.end(), acuity_titles.begin())) << acuity_script;
  const std::string acuity_data = readAll(dir.file(kAcuityPlot.data));
  for (const ConfigSummary& c : configs) {
    if (c.preset.rfind("ACUITY", 0) != 0) continue;
    const std::string row = "\"" + c.preset.substr(7) + "\" " + (c.slope == 0.022 ? "0.022 " : "0.028 ");
    EXPECT_NE(acuity_data.find(row), std::string::npos) << row;
  }
}

TEST(ErrorReportPlot, OtherSettingsFillTheMainPlotUpToThree) {
  // No setting the docs quote: the run's first three, in its order.
  std::vector<ConfigSummary> configs = {config("F1", 0.022, 150000.0, 0.4)};
  for (const char* k : {"0.90", "0.80", "0.70", "0.60"}) configs.push_back(config(std::string("ACUITY k=") + k, 0.022, 1e5, 0.0));
  EXPECT_EQ(mainPlotAcuitySettings(configs),
            (std::vector<std::string>{"ACUITY k=0.90", "ACUITY k=0.80", "ACUITY k=0.70"}));
  // A quoted one goes first, the others fill up.
  configs.push_back(config("ACUITY k=0.30 refined 1", 0.022, 1e5, 0.0));
  EXPECT_EQ(mainPlotAcuitySettings(configs),
            (std::vector<std::string>{"ACUITY k=0.30 refined 1", "ACUITY k=0.90", "ACUITY k=0.80"}));
  // Without ACUITY rows: no ACUITY on the plot, and no second plot.
  const std::vector<ConfigSummary> presets = {config("F1", 0.022, 150000.0, 0.4), config("FREF", 0.022, 1.2e6, 0.0)};
  EXPECT_TRUE(mainPlotAcuitySettings(presets).empty());
  test::TempDir dir;
  Result<std::vector<PlotFiles>> written = writePlotFiles(dir.path(), context(), presets);
  ASSERT_TRUE(written);
  EXPECT_EQ(written->size(), 1u);
  EXPECT_TRUE(acuityTitles(readAll(dir.file(kMainPlot.script))).empty());
}

// --replot-from's route: the CSV and report.md a run wrote, read back, give the
// plot files that run wrote, byte for byte.
TEST(ErrorReportPlot, TheCsvReadBackGivesTheSamePlotFiles) {
  std::vector<ConfigSummary> configs = mainRun();
  // Figures with more digits than the CSV keeps.
  for (std::size_t i = 0; i < configs.size(); ++i) {
    configs[i].all.wire_bytes = 123456.789012345 + 1000.0 * static_cast<double>(i) / 3.0;
    configs[i].all.share_above_mar = 0.0123456789012 * static_cast<double>(i % 7);
    configs[i].time_ms_median = 14.923961234;
  }
  test::TempDir dir;
  ASSERT_TRUE(writeCsv(dir.file("report.csv"), configs));
  ASSERT_TRUE(writeMarkdown(dir.file("report.md"), context(), configs, true));
  ASSERT_TRUE(writePlotFiles(dir.path(), context(), configs));
  const std::string main_before = readAll(dir.file(kMainPlot.data)) + readAll(dir.file(kMainPlot.script));
  const std::string acuity_before = readAll(dir.file(kAcuityPlot.data)) + readAll(dir.file(kAcuityPlot.script));

  Result<std::vector<ConfigSummary>> read = readCsvSummaries(dir.file("report.csv"));
  ASSERT_TRUE(read) << read.status().toString();
  EXPECT_EQ(read->size(), configs.size());
  Result<std::string> camera = readMarkdownCamera(dir.file("report.md"));
  ASSERT_TRUE(camera) << camera.status().toString();
  EXPECT_EQ(*camera, "mock:living-room 640x480");
  ReportContext replotted;
  replotted.camera = *camera;
  replotted.frames = 3;
  ASSERT_TRUE(writePlotFiles(dir.path(), replotted, *read));
  EXPECT_EQ(readAll(dir.file(kMainPlot.data)) + readAll(dir.file(kMainPlot.script)), main_before);
  EXPECT_EQ(readAll(dir.file(kAcuityPlot.data)) + readAll(dir.file(kAcuityPlot.script)), acuity_before);

  // The page shows both plots.
  const std::string md = readAll(dir.file("report.md"));
  EXPECT_NE(md.find("](report.png)"), std::string::npos);
  EXPECT_NE(md.find("](report_acuity.png)"), std::string::npos);
}

TEST(ErrorReportPlot, ReadingBackRejectsWhatARunDidNotWrite) {
  test::TempDir dir;
  EXPECT_EQ(readCsvSummaries(dir.file("missing.csv")).status().code(), ErrorCode::kIoError);
  std::ofstream(dir.file("bad.csv")) << "preset,m,region\nF1,0.022,all\n";
  EXPECT_EQ(readCsvSummaries(dir.file("bad.csv")).status().code(), ErrorCode::kParseError);
  std::ofstream(dir.file("report.md")) << "# no camera line\n";
  EXPECT_EQ(readMarkdownCamera(dir.file("report.md")).status().code(), ErrorCode::kParseError);
}

}  // namespace
}  // namespace fovea::tools
