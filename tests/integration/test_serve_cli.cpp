// fovead serve as a process: the memory line and status lines, SIGTERM and
// SIGINT stop it with exit 0 within a second, SIGHUP applies a new preset.
#include <signal.h>

#include <chrono>
#include <fstream>
#include <regex>
#include <string>

#include <gtest/gtest.h>

#include "tests/support/process.h"
#include "tests/support/programs.h"
#include "tests/support/test_time.h"

namespace fovea {
namespace {

std::string fovead() { return test::program(FOVEAD_PATH); }

const std::string kSmallCamera = " --camera mock:living-room,size=160x120,realtime=on,fps=30";

void writeFile(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

// The wait is an upper bound, scaled as test_time.h's waits (a bare 5 s was shorter
// than the scaled "within a second" the tests check, and failed under TSan in a
// loaded CI); how long the stop took is what the tests bound.
double stopSeconds(test::BackgroundProcess& process, int signal_number, int& exit_code) {
  const auto t0 = std::chrono::steady_clock::now();
  exit_code = process.stop(signal_number, 5.0);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

TEST(FoveadServe, PrintsMemoryAndStatusThenStopsOnSigtermWithinASecond) {
  test::BackgroundProcess serve(fovead() + " serve" + kSmallCamera + " --status-interval-ms 200");
  ASSERT_TRUE(serve.started());
  ASSERT_TRUE(serve.waitFor("running", 20.0)) << serve.output();
  ASSERT_TRUE(serve.waitFor("status: fps in ", 10.0)) << serve.output();
  int exit_code = -1;
  const double seconds = stopSeconds(serve, SIGTERM, exit_code);
  EXPECT_EQ(exit_code, 0) << serve.output();
  EXPECT_LT(seconds, 1.0 * test::timeScale()) << serve.output();  // slower under sanitizers and emulators
  EXPECT_NE(serve.output().find("memory: "), std::string::npos);
  EXPECT_NE(serve.output().find(" MiB in "), std::string::npos);
  EXPECT_NE(serve.output().find("frame slots"), std::string::npos);
  EXPECT_NE(serve.output().find("stopped after"), std::string::npos);
}

TEST(FoveadServe, SigintStopsItToo) {
  test::BackgroundProcess serve(fovead() + " serve" + kSmallCamera);
  ASSERT_TRUE(serve.waitFor("running", 20.0)) << serve.output();
  int exit_code = -1;
  const double seconds = stopSeconds(serve, SIGINT, exit_code);
  EXPECT_EQ(exit_code, 0) << serve.output();
  EXPECT_LT(seconds, 1.0 * test::timeScale());
}

TEST(FoveadServe, SighupReadsTheConfigurationFileAgain) {
  test::TempDir dir;
  const std::string config = dir.file("fovea.toml");
  writeFile(config, "[foveation]\npreset = \"F1\"\n");
  test::BackgroundProcess serve(fovead() + " serve" + kSmallCamera + " --config " + config);
  ASSERT_TRUE(serve.waitFor("running", 20.0)) << serve.output();
  EXPECT_NE(serve.output().find("foveation F1"), std::string::npos);
  writeFile(config, "[foveation]\npreset = \"F3\"\nslope = 0.03\n");
  ASSERT_TRUE(serve.signal(SIGHUP));
  ASSERT_TRUE(serve.waitFor("reload (SIGHUP): foveation F3 (m 0.03", 5.0)) << serve.output();
  // A broken file keeps the running configuration, and says where it is broken.
  writeFile(config, "[foveation]\npreset = \"F9\"\n");
  ASSERT_TRUE(serve.signal(SIGHUP));
  ASSERT_TRUE(serve.waitFor("the running configuration stays", 5.0)) << serve.output();
  EXPECT_NE(serve.output().find("fovea.toml:2: foveation.preset"), std::string::npos) << serve.output();
  int exit_code = -1;
  stopSeconds(serve, SIGTERM, exit_code);
  EXPECT_EQ(exit_code, 0) << serve.output();
  EXPECT_NE(serve.output().find("1 reloads applied"), std::string::npos) << serve.output();
}

TEST(FoveadServe, BoardProfileAndSetApply) {
  test::BackgroundProcess serve(fovead() + " serve" + kSmallCamera +
                                " --board host-mock --set foveation.preset=F2 --set runtime.ring_depth=3");
  ASSERT_TRUE(serve.waitFor("running", 20.0)) << serve.output();
  EXPECT_NE(serve.output().find("board host-mock"), std::string::npos) << serve.output();
  EXPECT_NE(serve.output().find("foveation F2"), std::string::npos) << serve.output();
  EXPECT_NE(serve.output().find("ring depth 3"), std::string::npos) << serve.output();
  int exit_code = -1;
  stopSeconds(serve, SIGTERM, exit_code);
  EXPECT_EQ(exit_code, 0) << serve.output();
  const test::ProcessResult unknown = test::runCommand(fovead() + " serve --board no-such-board --frames 1");
  EXPECT_EQ(unknown.exit_code, 2) << unknown.output;
  EXPECT_NE(unknown.output.find("unknown board 'no-such-board'"), std::string::npos) << unknown.output;
}

// Starts `fovead serve` on the small mock camera with `flags`, expects `line`
// in what it prints by the time it runs, and stops it cleanly.
void expectServeStartsSaying(const std::string& flags, const std::string& line) {
  test::BackgroundProcess serve(fovead() + " serve" + kSmallCamera + " " + flags);
  ASSERT_TRUE(serve.waitFor("running", 20.0)) << serve.output();
  EXPECT_NE(serve.output().find(line), std::string::npos) << serve.output();
  int exit_code = -1;
  stopSeconds(serve, SIGTERM, exit_code);
  EXPECT_EQ(exit_code, 0) << serve.output();
}

TEST(FoveadServe, FoveationFlagsKeepWhatSetSays) {
  // --preset names the mode; the floor comes from --set and must survive it.
  expectServeStartsSaying("--set foveation.floor_per_m2=0.002 --preset ACUITY --m 0.028",
                          "foveation ACUITY floor 2 mm x s^2 (m 0.028");
}

// --listen and the other stream flags go over the configuration's stream
// section: what --set (or the profile) says of it stays (the stream was rebuilt
// from the defaults, so the README demo's wider gaze timeout under the
// sanitizers never applied).
TEST(FoveadServe, TheStreamFlagsKeepWhatSetSays) {
  expectServeStartsSaying("--board host-mock --set stream.budget_mbps=20 --listen 127.0.0.1:0 --insecure",
                          "budget up to 20.00 MB/s");
}

std::string foveaOperator() { return test::program(FOVEA_OPERATOR_PATH); }

// The stream end to end through the service's threads: fovea-operator decodes
// what fovead serve sends for its gaze.
TEST(FoveadServe, StreamsToFoveaOperator) {
  test::BackgroundProcess serve(fovead() + " serve" + kSmallCamera +
                                " --listen 127.0.0.1:0 --insecure --status-interval-ms 500");
  ASSERT_TRUE(serve.waitFor("running", 20.0)) << serve.output();
  std::smatch port;
  const std::string out = serve.output();
  ASSERT_TRUE(std::regex_search(out, port, std::regex("listening on 127\\.0\\.0\\.1:([0-9]+)"))) << out;
  const test::ProcessResult op = test::runCommand(foveaOperator() + " --connect 127.0.0.1:" + port[1].str() +
                                                  " --insecure --gaze 'fixed:3,0.35,1.55>3,2.25,1.35' --duration " +
                                                  std::to_string(test::repetitions(3, 8)));
  EXPECT_EQ(op.exit_code, 0) << op.output;
  std::smatch frames;
  ASSERT_TRUE(std::regex_search(op.output, frames, std::regex("summary: ([0-9]+) frames"))) << op.output;
  // 30 fps for 3 s; a sanitizer, an emulator or a loaded CI host (other stages beside
  // it) is slower, and how much is timing, which tests do not bound: frames flowed.
  EXPECT_GE(std::stoi(frames[1].str()), 5) << op.output;
  EXPECT_NE(op.output.find(" 0 bad"), std::string::npos) << op.output;
  ASSERT_TRUE(serve.waitFor("out ", 5.0));
  int exit_code = -1;
  stopSeconds(serve, SIGTERM, exit_code);
  EXPECT_EQ(exit_code, 0) << serve.output();
  EXPECT_NE(serve.output().find("gaze: operator"), std::string::npos) << serve.output();
  // Each frame counted once: never more than the service sent. (The operator
  // used to count a frame again for every status datagram, one a second, that
  // came after it; the soak test's totals showed it.)
  std::smatch stopped;
  const std::string serve_out = serve.output();
  ASSERT_TRUE(std::regex_search(serve_out, stopped, std::regex("stopped: [0-9]+ frames captured, [0-9]+ foveated, ([0-9]+) sent")))
      << serve_out;
  EXPECT_LE(std::stoi(frames[1].str()), std::stoi(stopped[1].str())) << op.output << serve_out;
}

// foveation.source = map: the service fuses the mock orbit into its map and
// streams the map's bricks (map.delta, the default) beside the live points; the
// operator keeps them and acknowledges them; the status line and the stop line
// carry the map's figures, the operator's summary what it holds.
TEST(FoveadServe, StreamsTheMapToFoveaOperator) {
  test::BackgroundProcess serve(fovead() +
                                " serve --camera mock:living-room,path=orbit,size=160x120,realtime=on,fps=30"
                                " --set foveation.source=map --set map.max_surfels=65536"
                                // Settled after 2 frames, not 10: the ASan tree fuses 3 frames a second.
                                " --set map.settle_frames=2"
                                " --listen 127.0.0.1:0 --insecure --status-interval-ms 500");
  ASSERT_TRUE(serve.waitFor("running", 20.0)) << serve.output();
  std::smatch port;
  const std::string out = serve.output();
  ASSERT_TRUE(std::regex_search(out, port, std::regex("listening on 127\\.0\\.0\\.1:([0-9]+)"))) << out;
  // The map's parts, each a line; with bricks the eye's depth buffer is not needed.
  EXPECT_NE(out.find("map: surfel pool (32 B a surfel, 6 B its links)"), std::string::npos) << out;
  EXPECT_NE(out.find("map: bricks the operator holds, plan, sampler"), std::string::npos) << out;
  EXPECT_EQ(out.find("map: eye depth buffer"), std::string::npos) << out;
  const test::ProcessResult op = test::runCommand(foveaOperator() + " --connect 127.0.0.1:" + port[1].str() +
                                                  " --insecure --gaze 'fixed:3,0.35,1.55>3,2.25,1.35' --duration " +
                                                  std::to_string(test::repetitions(3, 8)));
  EXPECT_EQ(op.exit_code, 0) << op.output;
  std::smatch frames;
  ASSERT_TRUE(std::regex_search(op.output, frames, std::regex("summary: ([0-9]+) frames"))) << op.output;
  EXPECT_GE(std::stoi(frames[1].str()), 3) << op.output;
  EXPECT_NE(op.output.find(" 0 bad"), std::string::npos) << op.output;
  std::smatch held;
  ASSERT_TRUE(std::regex_search(op.output, held,
                                std::regex("map: ([0-9]+) bricks and ([0-9]+) points held; [0-9]+ brick parts taken "
                                           "\\([0-9]+ duplicate, [0-9]+ stale, 0 bad, 0 no room\\), ([0-9]+) versions completed")))
      << op.output;
  EXPECT_GT(std::stoul(held[1].str()), 3u) << op.output;
  EXPECT_GT(std::stoul(held[2].str()), 1000u) << op.output;
  EXPECT_GT(std::stoul(held[3].str()), 3u) << op.output;
  ASSERT_TRUE(serve.waitFor(" surfels, fuse ", 5.0)) << serve.output();
  int exit_code = -1;
  stopSeconds(serve, SIGTERM, exit_code);
  EXPECT_EQ(exit_code, 0) << serve.output();
  std::smatch map;
  const std::string serve_out = serve.output();
  ASSERT_TRUE(std::regex_search(serve_out, map,
                                std::regex("map: ([0-9]+) surfels from ([0-9]+) fused frames; [0-9]+ evicted; 0 new "
                                           "surfels dropped \\(0 for want of a brick\\); 0 empty bricks reused; refused 0 frames without "
                                           "a pose, 0 for another reason")))
      << serve_out;
  EXPECT_GT(std::stoul(map[1].str()), 5000u) << serve_out;
  EXPECT_GT(std::stoul(map[2].str()), 3u) << serve_out;
  std::smatch bricks;
  ASSERT_TRUE(std::regex_search(serve_out, bricks,
                                std::regex("map bricks: ([0-9]+) planned; ([0-9]+) versions in [0-9]+ parts sent, [0-9]+ "
                                           "parts resent; ([0-9]+) versions acknowledged whole")))
      << serve_out;
  EXPECT_GT(std::stoul(bricks[3].str()), 3u) << serve_out;  // the operator's acknowledgements reached the robot
  EXPECT_LE(std::stoul(bricks[3].str()), std::stoul(bricks[2].str())) << serve_out;
}

// Fusion slowed on purpose against its time budget (a microsecond a frame):
// the frames it leaves unfused are counted in the status line and at the stop,
// and still foveated. The first fusion spends the budget of thousands of
// frames, so every frame after it is left unfused; the service runs until the
// status line says so (a slow build, sanitizers on a loaded machine, lets few
// frames through: a fixed --frames 12 once saw only three, fused one and left
// two unfused while the fusion thread was busy).
TEST(FoveadServe, FramesOverTheFusionBudgetAreCountedAndStillFoveated) {
  test::BackgroundProcess serve(fovead() + " serve" + kSmallCamera +
                                " --set foveation.source=map --set map.max_surfels=65536 --set map.fuse_budget_ms=0.001"
                                " --status-interval-ms 100");
  ASSERT_TRUE(serve.started());
  ASSERT_TRUE(serve.waitForMatch(std::regex("unfused [1-9][0-9]* \\(budget\\)"), 5.0)) << serve.output();
  int exit_code = -1;
  stopSeconds(serve, SIGTERM, exit_code);
  EXPECT_EQ(exit_code, 0) << serve.output();
  const std::string out = serve.output();
  std::smatch unfused;
  ASSERT_TRUE(std::regex_search(out, unfused, std::regex("map: ([0-9]+) frames left unfused by map.fuse_budget_ms")))
      << out;
  EXPECT_GE(std::stoul(unfused[1].str()), 1u) << out;
  std::smatch fused;
  ASSERT_TRUE(std::regex_search(out, fused, std::regex("map: [0-9]+ surfels from ([0-9]+) fused frames"))) << out;
  EXPECT_GE(std::stoul(fused[1].str()), 1u) << out;
  std::smatch foveated;
  ASSERT_TRUE(std::regex_search(out, foveated, std::regex("stopped after ([0-9]+) frames foveated"))) << out;
  EXPECT_GE(std::stoul(foveated[1].str()), std::stoul(fused[1].str()) + std::stoul(unfused[1].str())) << out;
}

TEST(FoveadServe, FrameLimitAndBadFlags) {
  const test::ProcessResult done = test::runCommand(fovead() + " serve" + kSmallCamera + " --frames 10");
  EXPECT_EQ(done.exit_code, 0) << done.output;
  // Ten frames captured, drained through the stages (a drop, if any, is counted).
  EXPECT_NE(done.output.find("stopped: 10 frames captured"), std::string::npos) << done.output;
  EXPECT_NE(done.output.find("fovead serve: stopped after "), std::string::npos) << done.output;
  const test::ProcessResult bad = test::runCommand(fovead() + " serve --ring-depth 0");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("--ring-depth"), std::string::npos) << bad.output;
  const test::ProcessResult bad_source = test::runCommand(fovead() + " serve --set foveation.source=mesh");
  EXPECT_EQ(bad_source.exit_code, 2) << bad_source.output;
  EXPECT_NE(bad_source.output.find("foveation.source"), std::string::npos) << bad_source.output;
  const test::ProcessResult no_key = test::runCommand(fovead() + " serve --listen 127.0.0.1:0");
  EXPECT_EQ(no_key.exit_code, 2) << no_key.output;
  EXPECT_EQ(test::runCommand(fovead() + " serve --help").exit_code, 0);
}

}  // namespace
}  // namespace fovea
