// fovea-eval's plan (seeded HMD positions, gaze scripts, selections) and its
// reading of a run's logs (tools/eval/results.h) on logs written here by hand.
#include <algorithm>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "tools/eval/plan.h"
#include "tools/eval/results.h"
#include "tools/eval/statistics.h"
#include "tools/operator/gaze_script.h"

namespace fovea::tools::eval {
namespace {

SceneGeometry livingRoom() {
  SceneGeometry g;
  g.centre_m = {3.0, 2.25, 1.35};
  g.camera_m = {3.0, 0.35, 1.55};
  g.up = {0, 0, 1};
  return g;
}

TEST(EvalPlan, PositionsAreSeededSpreadAndOnTheCamerasSide) {
  const SceneGeometry g = livingRoom();
  const std::vector<HmdPosition> a = makePositions(g, 5, 7), b = makePositions(g, 5, 7), c = makePositions(g, 5, 8);
  ASSERT_EQ(a.size(), 5u);
  const double base = (g.camera_m - g.centre_m).norm();
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].eye_m, b[k].eye_m) << "same seed, same position";
    EXPECT_NE(a[k].eye_m, c[k].eye_m) << "another seed, another position";
    EXPECT_EQ(a[k].index, static_cast<int>(k) + 1);
    EXPECT_NEAR(a[k].distance_m, (a[k].eye_m - g.centre_m).norm(), 1e-12);
    EXPECT_GT(a[k].distance_m, 0.5 * base);
    EXPECT_LT(a[k].distance_m, 1.5 * base);
    // On the camera's side of the scene, within 30 degrees of its bearing (seen from above).
    Eigen::Vector3d to_eye = a[k].eye_m - g.centre_m, to_cam = g.camera_m - g.centre_m;
    to_eye.z() = to_cam.z() = 0;
    EXPECT_GT(to_eye.normalized().dot(to_cam.normalized()), std::cos(30.5 * M_PI / 180));
    ASSERT_EQ(a[k].targets_m.size(), 5u);
    EXPECT_EQ(a[k].targets_m[0], g.centre_m);
    for (const Eigen::Vector3d& t : a[k].targets_m) EXPECT_LT((t - g.centre_m).norm(), 0.6);
  }
  // "Varying distances": from near to far.
  EXPECT_LT(a.front().distance_m, a.back().distance_m - 0.5 * base);
}

TEST(EvalPlan, GazeScriptIsOneTheOperatorReads) {
  const HmdPosition p = makePositions(livingRoom(), 2, 1).front();
  const std::string text = gazeScript(p, 400, 50);
  EXPECT_EQ(text.rfind("scan:", 0), 0u) << text;
  Result<GazeScript> script = GazeScript::parse(text);
  ASSERT_TRUE(script) << script.status().message();
  const GazePoint g = script->at(0);
  EXPECT_LT((g.origin_m - p.eye_m).norm(), 1e-3);
  EXPECT_GT(g.direction.dot((p.targets_m[0] - p.eye_m).normalized()), 0.99999);
  // 400 ms later the eye is on its way to the second fixation.
  EXPECT_GT(script->at(430'000'000).direction.dot((p.targets_m[1] - p.eye_m).normalized()),
            g.direction.dot((p.targets_m[1] - p.eye_m).normalized()));
}

TEST(EvalPlan, SelectionsNameWhatIsUnknown) {
  ASSERT_TRUE(selectConditions("F1,FREF"));
  EXPECT_EQ(selectConditions("F1,FREF")->size(), 2u);
  Result<std::vector<Condition>> bad = selectConditions("F1,F9");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.status().message().find("F9"), std::string::npos);
  EXPECT_FALSE(selectConditions(""));
  const std::vector<Dataset> mock = defaultDatasets("");
  ASSERT_EQ(mock.size(), 3u);
  EXPECT_EQ(std::count_if(mock.begin(), mock.end(), [](const Dataset& d) { return d.by_default; }), 2);
  EXPECT_EQ(defaultDatasets("/data/tum")[2].camera_spec, "tum:/data/tum,realtime=on,loop=on");
  // TUM tracked, named only: played back and forth, so that the camera's path
  // has no jump for the tracker to lose.
  const Dataset tum_track = defaultDatasets("/data/tum").back();
  EXPECT_EQ(tum_track.name, "tum-track");
  EXPECT_FALSE(tum_track.by_default);
  EXPECT_EQ(tum_track.camera_spec, "tum:/data/tum,realtime=on,loop=bounce");
  EXPECT_EQ(tum_track.map_settings, std::vector<std::string>{"camera.pose.source=track+camera"});
  // The balloon with a moving camera, named only; its map conditions track the
  // camera (track+camera) so that the balloon is found moving (issue 42).
  const Dataset& orbit = mock.back();
  EXPECT_EQ(orbit.name, "balloon-orbit");
  EXPECT_FALSE(orbit.by_default);
  EXPECT_EQ(orbit.camera_spec, "mock:balloon,realtime=on,path=orbit");
  Result<std::vector<Condition>> f1_delta = selectConditions("F1,MAP-DELTA");
  ASSERT_TRUE(f1_delta);
  EXPECT_EQ(runSettings(orbit, (*f1_delta)[0]), std::vector<std::string>{});
  EXPECT_EQ(runSettings(orbit, (*f1_delta)[1]),
            (std::vector<std::string>{"foveation.source=map", "map.delta=true", "camera.pose.source=track+camera"}));
  EXPECT_EQ(runSettings(mock[1], (*f1_delta)[1]), conditionSettings((*f1_delta)[1]));
  EXPECT_TRUE(selectDatasets(mock, "balloon-orbit"));
  EXPECT_FALSE(selectDatasets(mock, "tum"));  // not there without a path
  EXPECT_TRUE(selectDatasets(mock, "balloon"));
  EXPECT_EQ(runName(mock[1], defaultConditions()[3], makePositions(livingRoom(), 2, 1)[1]), "balloon_FREF_p2");
}

TEST(EvalPlan, AcuityWithItsFloorIsAConditionOfItsOwn) {
  Result<std::vector<Condition>> both = selectConditions("ACUITY,ACUITY-2MM");
  ASSERT_TRUE(both);
  ASSERT_EQ(both->size(), 2u);
  EXPECT_EQ((*both)[0].preset, "ACUITY");
  EXPECT_EQ((*both)[0].floor_per_m2, 0.0);
  EXPECT_EQ((*both)[1].preset, "ACUITY");
  EXPECT_EQ((*both)[1].floor_per_m2, 0.002);
  for (const Condition& c : defaultConditions()) {
    if (c.name != "ACUITY-2MM") {
      EXPECT_EQ(c.floor_per_m2, 0.0) << c.name;
    }
    if (c.name != "ACUITY-REFINED") {
      EXPECT_EQ(c.level_margin, 0.0) << c.name;
      EXPECT_EQ(c.refine_passes, 0) << c.name;
    }
  }
  // What fovead is told beyond the preset.
  EXPECT_EQ(conditionSettings((*both)[0]), std::vector<std::string>{});
  EXPECT_EQ(conditionSettings((*both)[1]), std::vector<std::string>{"foveation.floor_per_m2=0.002"});
  Result<std::vector<Condition>> refined = selectConditions("ACUITY-REFINED");
  ASSERT_TRUE(refined);
  EXPECT_EQ((*refined)[0].preset, "ACUITY");
  EXPECT_EQ(conditionSettings((*refined)[0]),
            (std::vector<std::string>{"foveation.level_margin=0.3", "foveation.refine_passes=1"}));
  EXPECT_EQ(runName(defaultDatasets("")[0], (*both)[1], makePositions(livingRoom(), 2, 1)[0]),
            "living-room_ACUITY-2MM_p1");
  // fovead reads the floor back as the same number.
  EXPECT_EQ(shortestDecimal(0.002), "0.002");
  EXPECT_EQ(shortestDecimal(0.1 + 0.2), "0.30000000000000004");
  EXPECT_EQ(std::strtod(shortestDecimal(1.0 / 3.0).c_str(), nullptr), 1.0 / 3.0);
}

// MAP is ACUITY told to foveate the fused map; it can be named but is not run by
// default (its fusion makes every run slower, docs/eval.md).
TEST(EvalPlan, MapIsAcuityOnTheMapAndNotADefault) {
  Result<std::vector<Condition>> map = selectConditions("ACUITY,MAP");
  ASSERT_TRUE(map);
  ASSERT_EQ(map->size(), 2u);
  EXPECT_EQ((*map)[1].name, "MAP");
  EXPECT_EQ((*map)[1].preset, "ACUITY");
  EXPECT_EQ((*map)[1].source, "map");
  EXPECT_EQ(conditionSettings((*map)[1]), (std::vector<std::string>{"foveation.source=map", "map.delta=false"}));
  // ACUITY itself stays on the frame, and no default condition is on the map.
  EXPECT_EQ((*map)[0].source, "");
  EXPECT_EQ(conditionSettings((*map)[0]), std::vector<std::string>{});
  for (const Condition& c : defaultConditions()) {
    EXPECT_NE(c.name, "MAP");
    EXPECT_EQ(c.source, "") << c.name;
    for (const std::string& setting : conditionSettings(c)) EXPECT_EQ(setting.find("foveation.source"), std::string::npos) << c.name;
  }
  EXPECT_EQ(allConditions().size(), defaultConditions().size() + 2);  // MAP and MAP-DELTA
  EXPECT_EQ(runName(defaultDatasets("")[0], (*map)[1], makePositions(livingRoom(), 2, 1)[0]), "living-room_MAP_p1");
  Result<std::vector<Condition>> bad = selectConditions("map");  // names are upper case
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.status().message().find("MAP"), std::string::npos);
}

// MAP-DELTA is MAP with the map streamed as bricks the operator keeps
// (map.delta = true, said explicitly); named only, like MAP.
TEST(EvalPlan, MapDeltaIsTheMapStreamedAsBricksAndNotADefault) {
  Result<std::vector<Condition>> picked = selectConditions("F1,FREF,MAP,MAP-DELTA");
  ASSERT_TRUE(picked);
  ASSERT_EQ(picked->size(), 4u);
  const Condition& map = (*picked)[2];
  const Condition& delta = (*picked)[3];
  EXPECT_EQ(delta.name, "MAP-DELTA");
  EXPECT_EQ(delta.preset, "ACUITY");
  EXPECT_EQ(delta.source, "map");
  EXPECT_TRUE(delta.map_delta);
  EXPECT_FALSE(map.map_delta);
  EXPECT_EQ(delta.floor_per_m2, 0.0);
  EXPECT_EQ(delta.level_margin, 0.0);
  EXPECT_EQ(delta.refine_passes, 0);
  EXPECT_EQ(conditionSettings(delta), (std::vector<std::string>{"foveation.source=map", "map.delta=true"}));
  EXPECT_EQ(conditionSettings(map), (std::vector<std::string>{"foveation.source=map", "map.delta=false"}));
  for (const Condition& c : defaultConditions()) {
    EXPECT_NE(c.name, "MAP-DELTA");
    EXPECT_FALSE(c.map_delta) << c.name;
  }
  // The last of every condition, after MAP.
  ASSERT_GE(allConditions().size(), 2u);
  EXPECT_EQ(allConditions().back().name, "MAP-DELTA");
  EXPECT_EQ(allConditions()[allConditions().size() - 2].name, "MAP");
  EXPECT_EQ(runName(defaultDatasets("/data/tum")[2], delta, makePositions(livingRoom(), 2, 1)[1]), "tum_MAP-DELTA_p2");
  // Its images need a frame the operator received with the map settled: 90, not 30.
  EXPECT_EQ(defaultQualityFrame(picked.value()), 90);
  EXPECT_EQ(defaultQualityFrame(selectConditions("F1,FREF,MAP").value()), 30);
  EXPECT_EQ(defaultQualityFrame(defaultConditions()), 30);
  Result<std::vector<Condition>> bad = selectConditions("MAP_DELTA");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.status().message().find("MAP-DELTA"), std::string::npos);
}

// A run directory written by hand: the service logged frames 10..14, the operator
// decoded 9 (not logged: before the session), 10, 11 (latency unknown), 12, 13;
// the timing log's last line is cut short.
class EvalRunLogs : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("fovea_eval_run_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
    std::ofstream t(dir_ / "timing.csv");
    t << "frame_id,captured_ns,acquire_us,queue_us,backproject_us,partition_us,sample_us,handoff_us,encode_us,send_us,"
         "captured_to_sent_us,points_out,chunks_sent,bytes_sent,completed\n";
    for (int f = 10; f <= 13; ++f) {
      t << f << "," << (1'000'000'000LL + (f - 10) * 33'000'000LL) << ",33000,100,800,500,4000,300,1500,2000,"
        << (8000 + f) << ",36000," << 100 + f << "," << 140000 + f << "," << (f == 12 ? 0 : 1) << "\n";
    }
    t << "14,1132000000,33000,100";  // cut short
    std::ofstream o(dir_ / "frames.csv");
    o << "frame_id,capture_ns,decoded_ns,latency_us,points,chunks_received,chunks_expected,summary_received,"
         "map_bricks,map_points,brick_parts,brick_versions\n"
      << "9,0,0,9000,1,1,1,1,0,0,0,0\n10,0,0,9000,1,1,1,1,0,0,0,0\n11,0,0,,1,1,1,1,2,512,3,1\n12,0,0,10000,1,1,1,1,2,512,0,0\n"
      << "13,0,0,11000,1,1,1,1,2,512,0,0\n";
    std::ofstream(dir_ / "summary.json") << "{\n  \"datagrams\": 500,\n  \"datagrams_lost\": 3,\n}\n";
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

TEST_F(EvalRunLogs, ReadsTheFramesBothSidesLogged) {
  Result<RunResult> r = readRun(dir_.string(), 100);
  ASSERT_TRUE(r) << r.status().message();
  ASSERT_EQ(r->frames, 3);  // 10, 12, 13
  EXPECT_EQ(r->incomplete, 1);
  EXPECT_EQ(r->datagrams, 500);
  EXPECT_EQ(r->datagrams_lost, 3);
  // Bytes at the socket: payloads plus 28 bytes of headers per datagram (chunks and the summary).
  const double bytes = ((140010 + 28.0 * 111) + (140012 + 28.0 * 113) + (140013 + 28.0 * 114)) / 3;
  EXPECT_NEAR(r->bytes_per_frame, bytes, 1e-9);
  // Frames 10 and 13 were captured 99 ms apart: three intervals.
  EXPECT_NEAR(r->frames_per_s, 3 / 0.099, 1e-9);
  EXPECT_NEAR(r->mb_per_s, bytes * (3 / 0.099) / 1e6, 1e-9);
  EXPECT_EQ(r->end_to_end_ms, (std::vector<double>{9.0, 10.0, 11.0}));
  EXPECT_EQ(r->stage_ms[2], (std::vector<double>{0.8, 0.8, 0.8}));  // back-projection
  // The rest of the way: capture to decoded minus capture to the end of sending.
  EXPECT_NEAR(r->stage_ms[kStageCount - 1][0], 9.0 - 8.010, 1e-12);
  EXPECT_NEAR(r->stage_ms[kStageCount - 1][2], 11.0 - 8.013, 1e-12);
  // Fewer frames asked for: the first ones.
  EXPECT_EQ(readRun(dir_.string(), 2)->frames, 2);
}

TEST_F(EvalRunLogs, ErrorsNameTheFile) {
  std::ofstream(dir_ / "frames.csv") << "frame_id,latency\n1,2\n";
  Result<RunResult> r = readRun(dir_.string(), 10);
  ASSERT_FALSE(r);
  EXPECT_NE(r.status().message().find("frames.csv: no column 'latency_us'"), std::string::npos) << r.status().message();
  std::filesystem::remove(dir_ / "timing.csv");
  EXPECT_NE(readRun(dir_.string(), 10).status().message().find("timing.csv"), std::string::npos);
}

TEST(EvalSummary, ReductionsAndTestsAgainstFref) {
  std::vector<RunResult> runs;
  const auto run = [](const char* c, int p, double mbps, std::vector<double> latency) {
    RunResult r;
    r.dataset = "living-room";
    r.condition = c;
    r.position = p;
    r.frames = static_cast<int>(latency.size());
    r.mb_per_s = mbps;
    r.end_to_end_ms = latency;
    for (auto& s : r.stage_ms) s = latency;
    return r;
  };
  runs.push_back(run("F1", 1, 4.0, {10, 12}));
  runs.push_back(run("FREF", 1, 39.0, {20, 22}));
  runs.push_back(run("F1", 2, 5.0, {11, 13}));
  runs.push_back(run("FREF", 2, 39.2, {21, 23}));
  const std::vector<ConditionSummary> s = summarise(runs);
  ASSERT_EQ(s.size(), 2u);
  const ConditionSummary& f1 = s[0];
  EXPECT_EQ(f1.condition, "F1");
  EXPECT_EQ(f1.positions, 2);
  EXPECT_DOUBLE_EQ(f1.mb_per_s_mean, 4.5);
  EXPECT_DOUBLE_EQ(f1.latency_mean_ms, 11.5);
  EXPECT_NEAR(f1.bandwidth_reduction, 100 * (1 - 4.5 / 39.1), 1e-9);
  EXPECT_NEAR(f1.latency_reduction, 100 * (1 - 11.5 / 21.5), 1e-9);
  const std::vector<double> a = {4.0, 5.0}, b = {39.0, 39.2};
  EXPECT_DOUBLE_EQ(f1.bandwidth_p, welchTTest(a, b).p);
  EXPECT_EQ(f1.latency_p99_ms, 13.0);
  EXPECT_TRUE(std::isnan(s[1].bandwidth_reduction));  // FREF against itself
}

}  // namespace
}  // namespace fovea::tools::eval
