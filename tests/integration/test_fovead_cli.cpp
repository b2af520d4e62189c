// fovead run and fovead foveate, as separate processes, the way users call them.
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "tests/support/process.h"
#include "tests/support/programs.h"
#include "tests/support/test_time.h"

#include "io/ply.h"
#include "pipeline/foveator.h"
#include "pipeline/map/trajectory_error.h"
#include "tests/support/clouds.h"
#include "tests/support/tum_frames.h"

namespace fovea {
namespace {

using test::ProcessResult;
using test::TempDir;
ProcessResult run(const std::string& command) { return test::runCommand(command); }

std::string fovead() { return test::program(FOVEAD_PATH); }

TEST(FoveadCli, ReadmeRunCommandWorks) {
  if (test::emulated()) GTEST_SKIP() << "run-demo runs host binaries; this build is cross-compiled";
  // The README's first command, on the build tree under test (setup and build are no-ops here).
  const ProcessResult r = run("FOVEA_BUILD_DIR=" + test::buildDir() + " " + test::sourceDir() +
                    "/toolchain/run-demo --camera mock:living-room --preset F1 --frames 3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* expected : {"fovea", "parafovea", "perifovea", "rest", "summary: 3 frames foveated, 0 failed",
                               "d0 median", "voxel sampling", "back-projection"}) {
    EXPECT_NE(r.output.find(expected), std::string::npos) << "missing '" << expected << "' in:\n" << r.output;
  }
}

TEST(FoveadCli, RunReducesThePointCountAndSavesAPly) {
  TempDir dir;
  const std::string ply = dir.file("last.ply");
  const ProcessResult r = run(fovead() + " run --camera mock:balloon --preset F3 --frames 2 --every 0 --save-ply " + ply);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  Result<io::PlyCloud> saved = io::readPly(ply);
  ASSERT_TRUE(saved.isOk()) << saved.status().toString();
  EXPECT_TRUE(saved->has_region);
  EXPECT_GT(saved->points.size(), 1000u);
  EXPECT_LT(saved->points.size(), 640u * 480u / 2);
}

// fovead cameras, as a new user runs it: every backend fovea knows is either
// listed as compiled in or named with what its build lacked, each compiled
// backend that can enumerate says what it found, and no camera is an answer
// (exit 0), not a failure.
TEST(FoveadCli, CamerasListsBackendsAndExitsZeroWithoutACamera) {
  const ProcessResult r = run(fovead() + " cameras");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::size_t backends = r.output.find("\nbackends:");
  ASSERT_NE(backends, std::string::npos) << r.output;
  const std::string compiled = r.output.substr(backends, r.output.find('\n', backends + 1) - backends);
  for (const char* name : {"mock", "tum", "openni2", "v4l2", "libcamera"}) {
    const bool listed_compiled = compiled.find(std::string(" ") + name) != std::string::npos;
    const bool listed_missing = r.output.find(std::string("  ") + name + ": not compiled in: ") != std::string::npos;
    EXPECT_NE(listed_compiled, listed_missing) << name << " must be listed exactly once, in:\n" << r.output;
  }
  // Every enumerating backend that is compiled in answers on a line of its own:
  // a count, "no camera found", or why it cannot list.
  const std::string text = "\n" + r.output;
  bool any_found = false;
  for (const char* name : {"openni2", "v4l2", "libcamera"}) {
    if (compiled.find(std::string(" ") + name) == std::string::npos) continue;
    const std::size_t line = text.find("\n" + std::string(name) + ": ");
    ASSERT_NE(line, std::string::npos) << name << " did not answer, in:\n" << r.output;
    const std::string answer = text.substr(line + 1, text.find('\n', line + 1) - line - 1);
    const bool none = answer.find(": no camera found") != std::string::npos;
    const bool cannot = answer.find(": cannot list cameras: ") != std::string::npos;
    const bool count = answer.find(" camera") != std::string::npos && !none;
    EXPECT_TRUE(none || cannot || count) << answer;
    any_found = any_found || (count && !cannot);
  }
  EXPECT_EQ(r.output.find("No camera found.") != std::string::npos, !any_found) << r.output;

  const ProcessResult extra = run(fovead() + " cameras --bogus");
  EXPECT_EQ(extra.exit_code, 2) << extra.output;
  EXPECT_EQ(run(fovead() + " cameras --help").exit_code, 0);
  // The udev rules a user installs by hand: Orbbec's and Intel's ids, for both
  // the USB device node and its V4L2 nodes.
  const ProcessResult rules = run(fovead() + " cameras --udev-rules");
  ASSERT_EQ(rules.exit_code, 0) << rules.output;
  for (const char* expected : {"SUBSYSTEM==\"usb\"", "SUBSYSTEM==\"video4linux\"", "\"2bc5\"", "\"8086\"", "\"0b07\""}) {
    EXPECT_NE(rules.output.find(expected), std::string::npos) << expected << " missing in:\n" << rules.output;
  }
}

// A V4L2 camera that is not there: a message saying what to do, exit 1, no crash.
TEST(FoveadCli, RunWithAMissingV4l2CameraSaysWhatToDo) {
  const ProcessResult cameras = run(fovead() + " cameras");
  const std::size_t backends = cameras.output.find("\nbackends:");
  ASSERT_NE(backends, std::string::npos) << cameras.output;
  if (cameras.output.substr(backends, cameras.output.find('\n', backends + 1) - backends).find(" v4l2") ==
      std::string::npos) {
    GTEST_SKIP() << "this build has no v4l2 backend";
  }
  struct Case {
    const char* spec;
    const char* message;
  };
  const Case cases[] = {
      {"v4l2:/dev/video-fovea-missing", "/dev/video-fovea-missing does not exist: is the camera plugged in?"},
      {"v4l2:serial=fovea-no-such-serial,hfov_deg=60", "no depth node with serial=fovea-no-such-serial"},
  };
  for (const Case& c : cases) {
    const ProcessResult r = run(fovead() + " run --frames 1 --camera " + c.spec);
    EXPECT_EQ(r.exit_code, 1) << c.spec << "\n" << r.output;
    EXPECT_NE(r.output.find(c.message), std::string::npos) << c.spec << "\n" << r.output;
  }
}

TEST(FoveadCli, HelpAndBadArguments) {
  EXPECT_EQ(run(fovead() + " --help").exit_code, 0);
  EXPECT_EQ(run(fovead() + " run --help").exit_code, 0);
  const ProcessResult foveate_help = run(fovead() + " foveate --help");
  EXPECT_EQ(foveate_help.exit_code, 0);
  EXPECT_NE(foveate_help.output.find("--fixation"), std::string::npos);

  struct Bad {
    const char* args;
    const char* message;
  };
  const Bad bad[] = {{"", "usage"},
                     {"fly", "unknown command"},
                     {"run --frames -3", "--frames"},
                     {"run --duration 1e300", "--duration"},
                     {"run --preset F9", "F9"},
                     {"run --m -1", "slope"},
                     {"run --bounds 5,3", "bounds_deg[1]"},
                     {"run --camera mock:kitchen", "kitchen"},
                     {"run --camera usb:0", "usb"},
                     {"run --gaze sideways", "--gaze"},
                     {"run --gaze-origin 1,2,3", "--gaze-dir"},
                     {"run --fixation fixed:abc", "--fixation"},
                     {"run --bogus 1", "--bogus"},
                     {"run --source mesh", "--source"},
                     {"run --source map --max-surfels 0", "--max-surfels"},
                     {"map --frames 3", "--out"},
                     {"map --out m.ply --max-surfels 0", "--max-surfels"},
                     {"map --out m.ply --brick-size 100", "brick_size_m"},
                     {"map --out m.ply --camera mock:kitchen", "kitchen"},
                     {"map --trajectory t.txt --pose track+gps:1", "--pose"},
                     {"run --pose track", "--source map"},
                     {"foveate --in a.ply", "required"},
                     {"foveate --in a.ply --out b.ply --gaze-origin 0,0,0 --gaze-dir 0,0,0", "zero length"},
                     {"foveate --in a.ply --out b.ply --gaze-origin 0,nan,0 --gaze-dir 0,0,1", "--gaze-origin"}};
  for (const Bad& b : bad) {
    const ProcessResult r = run(fovead() + " " + b.args);
    EXPECT_EQ(r.exit_code, 2) << b.args << "\n" << r.output;
    EXPECT_NE(r.output.find(b.message), std::string::npos) << b.args << "\n" << r.output;
  }
}

// fovead map on the mock camera's orbit: the map it writes is a PLY of stable
// surfels that readPly reads back, with the figures the summary promises.
TEST(FoveadCli, MapFusesAMockOrbitIntoAPly) {
  TempDir dir;
  const std::string ply = dir.file("map.ply");
  const ProcessResult r =
      run(fovead() + " map --camera mock:living-room,path=orbit,size=160x120 --frames 12 --out " + ply);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* expected : {"frames: 12 read, 12 fused", "surfels in", "32 bytes a surfel", "fusion time [ms]: median",
                               "wrote the stable surfels"}) {
    EXPECT_NE(r.output.find(expected), std::string::npos) << "missing '" << expected << "' in:\n" << r.output;
  }
  Result<io::PlyCloud> map = io::readPly(ply);
  ASSERT_TRUE(map.isOk()) << map.status().toString();
  EXPECT_TRUE(map->coords_were_double);
  EXPECT_TRUE(map->has_color);
  EXPECT_GT(map->points.size(), 5000u);
  EXPECT_LT(map->points.size(), 12u * 160 * 120);
}

// The same on the TUM recording with its ground-truth poses (../shared/data).
TEST(FoveadCli, MapFusesTheTumRecordingWithItsGroundTruth) {
  FOVEA_REQUIRE_TUM_TEDDY(path);
  TempDir dir;
  const std::string ply = dir.file("teddy.ply");
  // A 640x480 frame's fusion takes 1.2 s under ASan: two frames there.
  const std::string frames = std::to_string(test::repetitions(6, 2));
  const ProcessResult r =
      run(fovead() + " map --camera tum:" + path + ",loop=off --frames " + frames + " --all-surfels --out " + ply);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("frames: " + frames + " read, " + frames + " fused"), std::string::npos) << r.output;
  Result<io::PlyCloud> map = io::readPly(ply);
  ASSERT_TRUE(map.isOk()) << map.status().toString();
  EXPECT_GT(map->points.size(), 50000u);
}

// fovead map --pose track: the map tracks the camera, the recording's own poses
// unseen; the trajectory file is TUM's format, a line a frame, and lies within
// a few centimetres of the ground truth (which fovead map writes too without
// --pose track) after TUM's alignment. bench/fovea-track measures the figure.
TEST(FoveadCli, MapTracksTheTumRecordingAndWritesItsTrajectory) {
  FOVEA_REQUIRE_TUM_TEDDY(path);
  TempDir dir;
  const std::string frames = std::to_string(test::repetitions(30, 5));
  const std::string tracked = dir.file("tracked.txt"), truth = dir.file("truth.txt");
  ProcessResult r = run(fovead() + " map --camera tum:" + path + " --pose track --frames " + frames +
                        " --trajectory " + tracked);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string tracked_frames = std::to_string(std::stoi(frames) - 1);
  EXPECT_NE(r.output.find("tracking: " + frames + " frames (the first sets the world), " + tracked_frames +
                          " tracked, 0 lost"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("wrote " + frames + " poses to"), std::string::npos) << r.output;
  r = run(fovead() + " map --camera tum:" + path + ",loop=off --frames " + frames + " --trajectory " + truth);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto readTrajectory = [](const std::string& file) {
    std::ifstream in(file);
    std::vector<std::pair<std::string, Eigen::Vector3d>> poses;
    std::string line;
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream fields(line);
      std::string stamp;
      double x, y, z, qx, qy, qz, qw;
      fields >> stamp >> x >> y >> z >> qx >> qy >> qz >> qw;
      EXPECT_TRUE(fields) << line;
      EXPECT_NEAR(qx * qx + qy * qy + qz * qz + qw * qw, 1.0, 1e-5) << line;
      poses.emplace_back(stamp, Eigen::Vector3d(x, y, z));
    }
    return poses;
  };
  const auto a = readTrajectory(tracked), b = readTrajectory(truth);
  ASSERT_EQ(a.size(), static_cast<std::size_t>(std::stoi(frames)));
  ASSERT_EQ(b.size(), a.size());
  std::vector<Eigen::Vector3d> pa, pb;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].first, b[i].first) << "the same frames, the recording's stamps";
    pa.push_back(a[i].second);
    pb.push_back(b[i].second);
  }
  EXPECT_EQ(a[0].first.substr(0, 11), "1341841873.") << "the TUM sequence's own clock";
  Result<pipeline::map::TrajectoryError> ate = pipeline::map::absoluteTrajectoryError(pa, pb);
  ASSERT_TRUE(ate.isOk()) << ate.status().message();
  EXPECT_LT(ate->rmse_m, 0.03) << "ATE " << ate->rmse_m << " m";
}

// fovead run --source map: the frames fused into the map, the map foveated as
// the eye sees it; the summary has the map's figures.
TEST(FoveadCli, RunFoveatesTheMapOfAMockOrbit) {
  const ProcessResult r = run(fovead() +
                              " run --source map --max-surfels 65536 --camera mock:living-room,path=orbit,size=160x120"
                              " --frames 12 --every 0");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.output, m,
                                std::regex("map: ([0-9]+) surfels \\(([0-9]+) evicted\\); 12 frames fused, refused 0 "
                                           "without a pose, 0 for another reason; last frame: ([0-9]+) of the frame's "
                                           "points unexplained, ([0-9]+) map surfels sent")))
      << r.output;
  EXPECT_GT(std::stoul(m[1].str()), 5000u) << r.output;
  EXPECT_GT(std::stoul(m[4].str()), 5000u) << "the map reached the foveator:\n" << r.output;
  // A 160x120 frame has 19200 pixels: most of the last one is explained by the map by now.
  EXPECT_LT(std::stoul(m[3].str()), 19200u / 2) << r.output;
  EXPECT_NE(r.output.find("map: fusion (in back-projection)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("summary: 12 frames foveated, 0 failed"), std::string::npos) << r.output;
}

// A pose source with no pose: every frame is refused by the map, counted, and
// still foveated as it is (the operator keeps the live view).
TEST(FoveadCli, RunWithTheMapCountsFramesWithoutAPose) {
  TempDir dir;
  const ProcessResult r = run(fovead() + " run --source map --max-surfels 65536 --camera mock:living-room,size=160x120" +
                              " --pose socket:" + dir.file("pose.sock") + " --frames 5 --every 0");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("map: 0 surfels (0 evicted); 0 frames fused, refused 5 without a pose"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("summary: 5 frames foveated, 0 failed"), std::string::npos) << r.output;
}

// The same on the TUM recording with its ground-truth poses (../shared/data).
TEST(FoveadCli, RunFoveatesTheMapOfTheTumRecording) {
  FOVEA_REQUIRE_TUM_TEDDY(path);
  const ProcessResult r =
      run(fovead() + " run --source map --max-surfels 65536 --camera tum:" + path + ",loop=off --frames 3 --every 0");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // A pool smaller than a frame: eviction on every frame, as on a small board.
  EXPECT_NE(r.output.find("3 frames fused, refused 0 without a pose, 0 for another reason"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("summary: 3 frames foveated, 0 failed"), std::string::npos) << r.output;
}

TEST(FoveadCli, UnreadableAndMalformedFilesFailCleanly) {
  TempDir dir;
  const std::string args = " --out " + dir.file("out.ply") + " --gaze-origin 0,0,0 --gaze-dir 0,0,1";
  ProcessResult r = run(fovead() + " foveate --in " + dir.file("missing.ply") + args);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("missing.ply"), std::string::npos) << r.output;

  std::ofstream(dir.file("bad.ply")) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n";
  r = run(fovead() + " foveate --in " + dir.file("bad.ply") + args);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("bad.ply"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir.file("out.ply")));
}

// fovead foveate on a recorded cloud gives exactly what the library gives, and
// keeps double coordinates double far from the world origin.
// fovead foveate on a PLY file (10 km from the origin) against the library with
// the configuration the flags name.
void expectFoveateMatchesTheLibrary(const std::string& flags, const pipeline::FoveationConfig& config) {
  TempDir dir;
  const Eigen::Vector3d origin(10000.0, -2500.0, 3.0);
  pipeline::PointCloud cloud = test::randomCloud(30000, origin, 3.0f, 31);
  io::PlyWriteOptions write;
  write.double_coords = true;
  ASSERT_TRUE(io::writePly(dir.file("in.ply"), cloud, nullptr, write).isOk());

  const ProcessResult r = run(fovead() + " foveate --in " + dir.file("in.ply") + " --out " + dir.file("out.ply") +
                              " --gaze-origin 10000,-2500,3 --gaze-dir 0.3,0.1,1 " + flags);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(std::string(pipeline::fixationModeName(config.fixation.mode))), std::string::npos)
      << r.output;

  // The same through the library, from the cloud as the PLY reader sees it.
  Result<io::PlyCloud> input = io::readPly(dir.file("in.ply"));
  ASSERT_TRUE(input.isOk());
  pipeline::Foveator foveator = pipeline::Foveator::create({30000, 30000}, config).value();
  pipeline::FoveatedCloud expected(30000);
  pipeline::FoveationStats stats;
  pipeline::Gaze gaze;
  gaze.origin_m = origin;
  gaze.direction = Eigen::Vector3d(0.3, 0.1, 1);
  ASSERT_TRUE(foveator.foveate(input->points, gaze, expected, stats).isOk());

  Result<io::PlyCloud> output = io::readPly(dir.file("out.ply"));
  ASSERT_TRUE(output.isOk()) << output.status().toString();
  EXPECT_TRUE(output->coords_were_double);
  EXPECT_TRUE(output->has_color);
  ASSERT_TRUE(output->has_region);
  ASSERT_EQ(output->points.size(), expected.size());
  EXPECT_LT(expected.size(), cloud.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    ASSERT_EQ(output->region[i], expected.region[i]) << i;
    // Written in double; read back as float relative to the output's own origin.
    EXPECT_NEAR((output->points.world(i) - expected.points.world(i)).norm(), 0.0, 1e-6) << i;
    EXPECT_EQ(output->points.rgb()[i], expected.points.rgb()[i]) << i;
  }
}

TEST(FoveadCli, FoveatePlyRoundTripMatchesTheLibrary) {
  pipeline::FoveationConfig config;
  config.acuity.preset = pipeline::Preset::kF2;
  config.acuity.slope = 0.028;
  config.fixation.mode = pipeline::FixationMode::kCentroid;
  expectFoveateMatchesTheLibrary("--preset F2 --m 0.028 --fixation centroid", config);
}

// ACUITY's own flags reach the foveation (the refinement changes the output:
// checked below, so that a flag dropped on the way would fail).
TEST(FoveadCli, FoveateTakesAcuitysFlags) {
  pipeline::FoveationConfig config;
  config.acuity.preset = pipeline::Preset::kAcuity;
  config.acuity.level_margin = 0.3;
  config.acuity.refine_passes = 1;
  config.acuity.floor_m = 0.004;
  config.acuity.level_voxel_m = 0.0025;
  expectFoveateMatchesTheLibrary(
      "--preset ACUITY --level-margin 0.3 --refine-passes 1 --floor-m 0.004 --level-voxel-m 0.0025", config);

  pipeline::FoveationConfig unrefined = config;
  unrefined.acuity.refine_passes = 0;
  pipeline::PointCloud cloud = test::randomCloud(30000, Eigen::Vector3d(10000.0, -2500.0, 3.0), 3.0f, 31);
  pipeline::Gaze gaze;
  gaze.origin_m = Eigen::Vector3d(10000.0, -2500.0, 3.0);
  gaze.direction = Eigen::Vector3d(0.3, 0.1, 1);
  std::size_t sizes[2];
  int i = 0;
  for (const pipeline::FoveationConfig& c : {config, unrefined}) {
    pipeline::Foveator foveator = pipeline::Foveator::create({30000, 30000}, c).value();
    pipeline::FoveatedCloud out(30000);
    pipeline::FoveationStats stats;
    ASSERT_TRUE(foveator.foveate(cloud, gaze, out, stats).isOk());
    sizes[i++] = out.size();
  }
  EXPECT_NE(sizes[0], sizes[1]) << "one refinement pass changed nothing on this cloud";
  // ... and so does the finest voxel (a dropped --level-voxel-m would compare 2 mm's output).
  pipeline::FoveationConfig finer = config;
  finer.acuity.level_voxel_m = 0.002;
  pipeline::Foveator foveator = pipeline::Foveator::create({30000, 30000}, finer).value();
  pipeline::FoveatedCloud out(30000);
  pipeline::FoveationStats stats;
  ASSERT_TRUE(foveator.foveate(cloud, gaze, out, stats).isOk());
  EXPECT_NE(out.size(), sizes[0]) << "the level voxel changed nothing on this cloud";

  const ProcessResult refused = run(fovead() + " run --frames 1 --refine-passes 1");
  EXPECT_EQ(refused.exit_code, 2) << refused.output;
  EXPECT_NE(refused.output.find("--preset ACUITY"), std::string::npos) << refused.output;
}

}  // namespace
}  // namespace fovea
