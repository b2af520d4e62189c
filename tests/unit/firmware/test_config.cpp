// The configuration file, --set, validation, printing and the board profiles
// (firmware/config.h): the exact messages users see, and round trips.
#include "firmware/config.h"

#include <algorithm>
#include <cstdlib>
#include <set>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "firmware/options.h"
#include "hal/camera.h"
#include "pipeline/map/pose_tracking.h"
#include "tests/support/process.h"
#include "tests/support/programs.h"

namespace fovea::firmware {
namespace {

// FOVEA_BOARD_DIR for a scope, then what was there before (CTest sets it for
// every test, tests/CMakeLists.txt, and fovead subprocesses read it).
class ScopedBoardDir {
 public:
  explicit ScopedBoardDir(const std::string& dir) {
    if (const char* old = std::getenv("FOVEA_BOARD_DIR")) saved_ = old;
    setenv("FOVEA_BOARD_DIR", dir.c_str(), 1);
  }
  ~ScopedBoardDir() {
    if (saved_) {
      setenv("FOVEA_BOARD_DIR", saved_->c_str(), 1);
    } else {
      unsetenv("FOVEA_BOARD_DIR");
    }
  }
  ScopedBoardDir(const ScopedBoardDir&) = delete;
  ScopedBoardDir& operator=(const ScopedBoardDir&) = delete;

 private:
  std::optional<std::string> saved_;
};

using test::TempDir;

std::string write(const TempDir& dir, const std::string& name, const std::string& text) {
  const std::string path = dir.file(name);
  std::ofstream(path) << text;
  return path;
}

// The error of loading `text` as a file (over the defaults), with the file's
// path replaced by "fovea.toml".
std::string loadError(const std::string& text) {
  TempDir dir;
  const std::string path = write(dir, "fovea.toml", text);
  Result<ServiceConfig> config = loadServiceConfig(path, ServiceConfig{});
  if (config) return "(loaded)";
  std::string message = config.status().message();
  if (const std::size_t at = message.find(path); at != std::string::npos) message.replace(at, path.size(), "fovea.toml");
  return message;
}

std::string setError(const std::string& assignment) {
  ServiceConfig config;
  const Status s = applyOverride(config, assignment);
  return s ? "(applied)" : s.message();
}

// Two configurations are the same when every key prints the same.
void expectSame(const ServiceConfig& a, const ServiceConfig& b) {
  EXPECT_EQ(formatServiceConfig(a), formatServiceConfig(b));
}

TEST(Config, DefaultConfigurationIsValid) {
  const Status s = validate(ServiceConfig{});
  EXPECT_TRUE(s.isOk()) << s.message();
}

TEST(Config, MissingFile) {
  Result<ServiceConfig> config = loadServiceConfig("/nonexistent/x.toml", ServiceConfig{});
  ASSERT_FALSE(config.isOk());
  EXPECT_EQ(config.status().message(), "cannot open '/nonexistent/x.toml': No such file or directory");
}

TEST(Config, UnknownKeyWithSuggestion) {
  EXPECT_EQ(loadError("board = \"host-mock\"\n\n[camera]\nsepc = \"mock:balloon\"\n"),
            "fovea.toml:4: unknown key 'camera.sepc' (did you mean 'camera.spec'?)");
  EXPECT_EQ(loadError("[stream]\nbudget = 3\n"), "fovea.toml:2: unknown key 'stream.budget' (did you mean 'stream.budget_mbps'?)");
  EXPECT_EQ(loadError("[stream]\nfrobnicate = 3\n"), "fovea.toml:2: unknown key 'stream.frobnicate'");
  EXPECT_EQ(loadError("bord = \"x\"\n"), "fovea.toml:1: unknown key 'bord' (did you mean 'board'?)");
}

TEST(Config, UnknownSection) {
  EXPECT_EQ(loadError("[camra]\nspec = \"mock\"\n"), "fovea.toml:1: unknown section 'camra' (did you mean 'camera'?)");
  EXPECT_EQ(loadError("[runtime.capture]\ncore = 1\n"),
            "fovea.toml:1: unknown section 'runtime.capture' (did you mean 'runtime.capture_thread'?)");
  EXPECT_EQ(loadError("camera = 3\n"), "fovea.toml:1: camera: expected a table (a [camera] section), got an integer");
}

TEST(Config, WrongType) {
  EXPECT_EQ(loadError("[pipeline]\n\n\n\n\n\nmax_points = \"big\"\n"),
            "fovea.toml:7: pipeline.max_points: expected an integer, got a string");
  EXPECT_EQ(loadError("[pipeline]\nmax_points = 1.5\n"), "fovea.toml:2: pipeline.max_points: expected an integer, got a float");
  EXPECT_EQ(loadError("[stream]\ninsecure = 1\n"), "fovea.toml:2: stream.insecure: expected a boolean, got an integer");
  EXPECT_EQ(loadError("[stream]\nbudget_mbps = \"fast\"\n"), "fovea.toml:2: stream.budget_mbps: expected a number, got a string");
  EXPECT_EQ(loadError("[foveation]\ncustom_bounds_deg = [5, \"8\"]\n"),
            "fovea.toml:2: foveation.custom_bounds_deg: expected an array of numbers, got an array holding a string");
  EXPECT_EQ(loadError("[camera.spec]\nx = 1\n"), "fovea.toml:1: camera.spec: expected a string, got a table");
}

TEST(Config, OutOfRange) {
  EXPECT_EQ(loadError("[stream]\nbudget_mbps = -3\n"), "fovea.toml:2: stream.budget_mbps: must be within 0.01 .. 10000 (got -3)");
  EXPECT_EQ(loadError("[pipeline]\nthreads = 0\n"), "fovea.toml:2: pipeline.threads: must be within 1 .. 64 (got 0)");
  EXPECT_EQ(loadError("[stream]\nmax_mtu_bytes = 9000\n"),
            "fovea.toml:2: stream.max_mtu_bytes: must be within 256 .. 8952 (got 9000)");
  // The map's brick lists link slots in 24 bits (pipeline/map/surfel_links.h).
  EXPECT_EQ(loadError("[map]\nmax_surfels = 16777216\n"),
            "fovea.toml:2: map.max_surfels: must be within 1 .. 16777215 (got 16777216)");
  EXPECT_EQ(loadError("[foveation]\npreset = \"F9\"\n"),
            "fovea.toml:2: foveation.preset: must be one of \"F1\", \"F2\", \"F3\", \"FREF\", \"ACUITY\", \"custom\" (got \"F9\")");
  EXPECT_EQ(loadError("[runtime]\nlog_level = \"loud\"\n"),
            "fovea.toml:2: runtime.log_level: must be one of \"error\", \"warning\", \"notice\", \"info\", \"debug\" "
            "(got \"loud\")");
  EXPECT_EQ(loadError("[foveation]\ncustom_bounds_deg = [5, 200]\n"),
            "fovea.toml:2: foveation.custom_bounds_deg: each must be within 0 .. 180 (got 200)");
  EXPECT_EQ(loadError("[stream]\nlisten = \"nowhere\"\n").rfind("fovea.toml:2: stream.listen: ", 0), 0u);
  EXPECT_EQ(loadError("[camera]\nspec = \"\"\n"), "fovea.toml:2: camera.spec: must name a backend, as backend[:args]");
}

TEST(Config, SyntaxErrorsGiveToml11sLine) {
  const std::string unquoted = loadError("[camera]\nspec = mock\n");
  EXPECT_EQ(unquoted.rfind("fovea.toml:2: syntax error: ", 0), 0u) << unquoted;
  EXPECT_GT(unquoted.size(), std::string("fovea.toml:2: syntax error: ").size());
  EXPECT_EQ(unquoted.find('\n'), std::string::npos) << "one line: " << unquoted;
  const std::string twice = loadError("[camera]\nspec = \"a\"\nspec = \"b\"\n");
  EXPECT_EQ(twice.rfind("fovea.toml:3: syntax error: ", 0), 0u) << twice;
}

TEST(Config, OddFilesGiveMessagesNotCrashes) {
  EXPECT_EQ(loadError(""), "(loaded)");
  EXPECT_EQ(loadError("# only a comment\n\n"), "(loaded)");
  EXPECT_EQ(loadError("[stream]\nbudget_mbps = nan\n"), "fovea.toml:2: stream.budget_mbps: must be within 0.01 .. 10000 (got nan)");
  EXPECT_EQ(loadError("[stream]\nbudget_mbps = inf\n"), "fovea.toml:2: stream.budget_mbps: must be within 0.01 .. 10000 (got inf)");
  EXPECT_EQ(loadError("[camera]\nspec = 2024-01-01\n"), "fovea.toml:2: camera.spec: expected a string, got a date or time");
  EXPECT_EQ(loadError("[[camera]]\nspec = \"mock\"\n"), "fovea.toml:1: camera: expected a table (a [camera] section), got an array");
  EXPECT_EQ(loadError("[camera]\nspec = \"mock\"\n[camera.sub]\nx = 1\n"), "fovea.toml:3: unknown section 'camera.sub'");
  // toml11 3.7 saturates an integer too large for 64 bits; the range still rejects it.
  const std::string huge = loadError("[pipeline]\nmax_points = 99999999999999999999999\n");
  EXPECT_EQ(huge.rfind("fovea.toml:2: pipeline.max_points: must be within 1 .. 50000000 (got ", 0), 0u) << huge;
  const std::string binary = loadError(std::string("\0\x01\xff[camera", 10));
  EXPECT_EQ(binary.rfind("fovea.toml:1: syntax error: ", 0), 0u) << binary;
  // The first error by line wins, whatever the table order.
  EXPECT_EQ(loadError("[stream]\nbudget_mbps = -1\n[camera]\nsepc = 1\n"),
            "fovea.toml:2: stream.budget_mbps: must be within 0.01 .. 10000 (got -1)");
  EXPECT_EQ(loadError("[stream]\nbudget_mbps = 1\n[camra]\n[pipeline]\nthreads = 0\n"),
            "fovea.toml:3: unknown section 'camra' (did you mean 'camera'?)");
  TempDir dir;
  Result<ServiceConfig> directory = loadServiceConfig(dir.path(), ServiceConfig{});
  ASSERT_FALSE(directory.isOk());
  EXPECT_EQ(directory.status().message(), "cannot read '" + dir.path() + "': Is a directory");
}

TEST(Config, RulesBetweenFields) {
  EXPECT_EQ(loadError("[pipeline]\nmax_points = 1000\nmax_voxels = 2000\n"),
            "fovea.toml:3: pipeline.max_voxels: must be at most pipeline.max_points (got 2000 > 1000)");
  // Only max_points in the file: the message points at it.
  EXPECT_EQ(loadError("[pipeline]\nmax_points = 1000\n"),
            "fovea.toml:2: pipeline.max_voxels: must be at most pipeline.max_points (got 307200 > 1000)");
  EXPECT_EQ(loadError("[pipeline]\nmax_points = 1000\nmax_voxels = 500\nmax_output_points = 2000\n"),
            "fovea.toml:4: pipeline.max_output_points: must be at most pipeline.max_points (got 2000 > 1000)");
  EXPECT_EQ(loadError("[gpio]\nheartbeat_line = 4\nstreaming_line = 5\nfault_line = 4\n"),
            "fovea.toml:4: gpio.fault_line: line 4 is already used by gpio.heartbeat_line");
  EXPECT_EQ(loadError("[stream]\nlisten = \"0.0.0.0:7000\"\n"),
            "fovea.toml:2: stream.key_file: needed when stream.listen is set (fovead keygen FILE makes one), or "
            "stream.insecure = true on a trusted test host, or stream.listen = \"\" not to stream");
  EXPECT_EQ(loadError("[stream]\nlisten = \"0.0.0.0:7000\"\nkey_file = \"k\"\ninsecure = true\n"),
            "fovea.toml:4: stream.insecure: not together with stream.key_file (set stream.key_file = \"\")");
  EXPECT_EQ(loadError("[camera]\ndepth_min_m = 3\ndepth_max_m = 2\n"),
            "fovea.toml:3: camera.depth_max_m: must be more than camera.depth_min_m (got 2 <= 3)");
  EXPECT_EQ(loadError("[camera]\nretry_initial_ms = 1000\nretry_max_ms = 10\n"),
            "fovea.toml:3: camera.retry_max_ms: must be at least camera.retry_initial_ms (got 10 < 1000)");
  EXPECT_EQ(loadError("[foveation]\ncustom_bounds_deg = [5, 8]\n"),
            "fovea.toml:2: foveation.custom_bounds_deg: only with foveation.preset = \"custom\" (clear it, or set the "
            "preset)");
  EXPECT_EQ(loadError("[map]\nconfidence_cap = 10\nstable_confidence = 12\n"),
            "fovea.toml:3: map.stable_confidence: must be at most map.confidence_cap (got 12 > 10)");
  EXPECT_EQ(loadError("[foveation]\nsource = \"mesh\"\n").rfind("fovea.toml:2: foveation.source: ", 0), 0u);
  const std::string decreasing = loadError("[foveation]\npreset = \"custom\"\ncustom_bounds_deg = [8, 5]\n");
  EXPECT_EQ(decreasing.rfind("fovea.toml:3: foveation.custom_bounds_deg: ", 0), 0u) << decreasing;

  // Without a file, the message starts with the field.
  ServiceConfig config;
  config.pipeline.max_voxels = config.pipeline.max_points + 1;
  EXPECT_EQ(validate(config).message(), "pipeline.max_voxels: must be at most pipeline.max_points (got 307201 > 307200)");
  config = ServiceConfig{};
  config.stream.link.max_budget_bytes_per_s = 0;
  EXPECT_EQ(validate(config).message(), "stream.budget_mbps: must be within 0.01 .. 10000 (got 0)");
  config = ServiceConfig{};
  config.gpio.lines.privacy_line = 7;
  config.gpio.lines.heartbeat_line = 7;
  EXPECT_EQ(validate(config).message(), "gpio.privacy_line: line 7 is already used by gpio.heartbeat_line");
}

TEST(Config, FileOverridesOnlyWhatItSays) {
  TempDir dir;
  ServiceConfig base;
  base.camera.spec = "mock:balloon";
  base.pipeline.threads = 3;
  const std::string path = write(dir, "fovea.toml",
                                 "# a comment\n[pipeline]\nthreads = 2\n[stream]\nbudget_mbps = 125\n"
                                 "[runtime.send_thread]\ncore = 3\n");
  Result<ServiceConfig> config = loadServiceConfig(path, base);
  ASSERT_TRUE(config.isOk()) << config.status().message();
  EXPECT_EQ(config->camera.spec, "mock:balloon");
  EXPECT_EQ(config->pipeline.threads, 2);
  EXPECT_EQ(config->stream.link.max_budget_bytes_per_s, 125'000'000u);
  EXPECT_EQ(config->runtime.send_thread.core, 3);
  EXPECT_EQ(config->runtime.capture_thread.core, -1);
}

// Every key with a value other than its default.
const std::vector<std::string> kEveryKeyChanged = {
    "board=lab-bench",
    "camera.spec=mock:balloon,seed=3",
    "camera.depth_min_m=0.3",
    "camera.depth_max_m=7.25",
    "camera.retry_initial_ms=50",
    "camera.retry_max_ms=2000",
    "camera.stall_timeout_ms=250",
    "camera.calibration_file=/etc/fovea/d435.yaml",
    "camera.extrinsics.rotation_xyzw=[0, 0, 0.0087265, 0.9999619]",
    "camera.extrinsics.translation_m=[0.015, -0.0001, 0.0002]",
    "camera.pose.source=socket",
    "camera.pose.translation_m=[0.2, 0.0, 0.45]",
    "camera.pose.rotation_xyzw=[-0.5, 0.5, -0.5, 0.5]",
    "camera.pose.socket=/run/fovea/robot-pose.sock",
    "camera.pose.max_age_ms=250",
    "camera.pose.buffer_poses=512",
    "pipeline.max_points=100000",
    "pipeline.max_voxels=90000",
    "pipeline.max_output_points=95000",
    "pipeline.kernels=ref",
    "pipeline.threads=4",
    "pipeline.max_coarsenings=5",
    "foveation.preset=custom",
    "foveation.custom_bounds_deg=[2.5, 7, 19.125]",
    "foveation.slope=0.031",
    "foveation.far_ecc_deg=75.5",
    "foveation.level_voxel_m=0.004",
    "foveation.floor_m=0.016",
    "foveation.floor_per_m2=0.0025",
    "foveation.level_margin=0.7",
    "foveation.refine_passes=3",
    "foveation.view_cull=\"drop\"",
    "foveation.view_cull_deg=65.0",
    "foveation.source=map",
    "foveation.fixation.mode=fixed",
    "foveation.fixation.fixed_m=1.75",
    "foveation.fixation.hit_cone_deg=0.5",
    "foveation.fixation.hit_percentile=0.1",
    "foveation.fixation.fallback_m=3",
    "foveation.fixation.min_m=0.1",
    "map.max_surfels=250000",
    "map.max_bricks=4096",
    "map.brick_size_m=0.25",
    "map.depth_tolerance_sigmas=2.5",
    "map.normal_tolerance_deg=20.0",
    "map.confidence_cap=12.0",
    "map.stable_confidence=2.5",
    "map.unstable_max_frames=45",
    "map.settle_frames=4",
    "map.delta=false",
    "map.change_fraction=0.05",
    "map.growth_fraction=0.5",
    "map.churn_fraction=0.3",
    "map.explain_held_only=false",
    "map.max_brick_surfels=4096",
    "map.max_frame_brick_points=100000",
    "map.max_live_points=20000",
    "map.fuse_budget_ms=12.5",
    "map.fusion_thread=false",
    "map.carve_weight=1.5",
    "map.max_pose_jump_m=0.5",
    "map.eye_face_cells=192",
    "map.occlusion_margin=0.08",
    "stream.listen=[::1]:7001",
    "stream.key_file=\"/etc/fovea/robot key\\\"quoted\\\".key\"",
    "stream.insecure=false",
    "stream.max_mtu_bytes=1400",
    "stream.budget_mbps=33.333333",
    "stream.session_timeout_ms=2500",
    "stream.burst_ms=7.5",
    "stream.gaze_timeout_ms=80",
    "stream.fallback_voxel_m=0.04",
    "stream.gaze_growth_max_deg=12.5",
    "stream.gaze_lead_ms=25",
    "stream.fovea_step_m=0.0005",
    "stream.periphery_step_ratio=0.25",
    "stream.chroma=half",
    "stream.entropy=true",
    "stream.zstd_level=3",
    "gpio.spec=gpiod:gpiochip4",
    "gpio.heartbeat_line=17",
    "gpio.streaming_line=27",
    "gpio.fault_line=22",
    "gpio.privacy_line=23",
    "gpio.privacy_active_low=true",
    "gpio.heartbeat_period_ms=250",
    "gpio.consumer=fovead-test",
    "runtime.ring_depth=3",
    "runtime.memory_lock=true",
    "runtime.log_level=debug",
    "runtime.status_interval_ms=2000",
    "runtime.systemd_notify=false",
    "runtime.capture_thread.core=1",
    "runtime.capture_thread.realtime_priority=50",
    "runtime.foveation_thread.core=2",
    "runtime.foveation_thread.realtime_priority=40",
    "runtime.send_thread.core=3",
    "runtime.send_thread.realtime_priority=45",
    "runtime.map_thread.core=1",
    "runtime.map_thread.realtime_priority=30",
    "runtime.capture_thread.nice=-5",
    "runtime.foveation_thread.nice=-3",
    "runtime.send_thread.nice=-4",
    "runtime.map_thread.nice=7",
};

TEST(Config, EveryKeyRoundTrips) {
  ServiceConfig changed;
  for (const std::string& assignment : kEveryKeyChanged) {
    const Status s = applyOverride(changed, assignment);
    ASSERT_TRUE(s.isOk()) << assignment << ": " << s.message();
  }
  ASSERT_TRUE(validate(changed).isOk()) << validate(changed).message();
  // Every key was changed: each line of the printed config differs from the default's.
  const std::string text = formatServiceConfig(changed);
  const std::string defaults = formatServiceConfig(ServiceConfig{});
  std::size_t keys = 0;
  for (std::size_t a = 0, b = 0; a < text.size() && b < defaults.size(); ++keys) {
    const std::size_t ea = text.find('\n', a), eb = defaults.find('\n', b);
    const std::string la = text.substr(a, ea - a), lb = defaults.substr(b, eb - b);
    // stream.insecure stays false beside a key file; kernels=ref is the default under FOVEA_FORCE_KERNEL=ref.
    const bool may_stay = la.rfind("insecure = ", 0) == 0 || la.rfind("kernels = ", 0) == 0;
    if (may_stay) {
      // either
    } else if (la.find(" = ") != std::string::npos) {
      EXPECT_NE(la, lb) << "not changed by kEveryKeyChanged";
    } else {
      EXPECT_EQ(la, lb);
    }
    a = ea + 1;
    b = eb + 1;
  }
  EXPECT_GT(keys, kEveryKeyChanged.size());

  TempDir dir;
  const std::string path = write(dir, "printed.toml", text);
  Result<ServiceConfig> loaded = loadServiceConfig(path, ServiceConfig{});
  ASSERT_TRUE(loaded.isOk()) << loaded.status().message() << "\n" << text;
  expectSame(*loaded, changed);
  EXPECT_EQ(loaded->key_file, "/etc/fovea/robot key\"quoted\".key");
  EXPECT_EQ(loaded->stream.link.listen, "[::1]:7001");
  EXPECT_EQ(loaded->stream.link.max_budget_bytes_per_s, 33'333'333u);
  EXPECT_EQ(loaded->stream.gaze.timeout_ns, 80'000'000);
  EXPECT_EQ(loaded->gpio.lines.heartbeat_period_ns, 250'000'000);
  EXPECT_EQ(loaded->foveation.acuity.custom_bounds_deg, (std::vector<double>{2.5, 7.0, 19.125}));
  EXPECT_EQ(loaded->foveation.acuity.preset, pipeline::Preset::kCustom);
  EXPECT_EQ(loaded->pipeline.kernels, fovea::KernelSet::kRef);
  EXPECT_EQ(loaded->runtime.log_level, LogLevel::kDebug);
  EXPECT_TRUE(loaded->stream.codec.halve_peripheral_chroma);
  EXPECT_EQ(loaded->camera.depth.max_m, 7.25);
  // And printing again gives the same text.
  EXPECT_EQ(formatServiceConfig(*loaded), text);
}

TEST(Config, AwkwardNumbersRoundTripExactly) {
  ServiceConfig config;
  config.foveation.acuity.slope = 0.1 + 0.2;  // 0.30000000000000004
  config.foveation.fixation.min_m = 1.0 / 3;
  config.camera.depth.max_m = 100.0;          // prints as 100.0, a float
  config.stream.link.max_budget_bytes_per_s = 123'456'789;
  TempDir dir;
  Result<ServiceConfig> loaded = loadServiceConfig(write(dir, "a.toml", formatServiceConfig(config)), ServiceConfig{});
  ASSERT_TRUE(loaded.isOk()) << loaded.status().message();
  EXPECT_EQ(loaded->foveation.acuity.slope, 0.1 + 0.2);
  EXPECT_EQ(loaded->foveation.fixation.min_m, 1.0 / 3);
  EXPECT_EQ(loaded->camera.depth.max_m, 100.0);
  EXPECT_EQ(loaded->stream.link.max_budget_bytes_per_s, 123'456'789u);
}

TEST(Config, SetOverrides) {
  ServiceConfig config;
  ASSERT_TRUE(applyOverride(config, "camera.spec=mock:balloon,seed=7").isOk());  // bare text for a string
  EXPECT_EQ(config.camera.spec, "mock:balloon,seed=7");
  ASSERT_TRUE(applyOverride(config, "camera.spec=\"tum:/data/x\"").isOk());  // or TOML
  EXPECT_EQ(config.camera.spec, "tum:/data/x");
  ASSERT_TRUE(applyOverride(config, "stream.budget_mbps=25").isOk());  // an integer for a number
  EXPECT_EQ(config.stream.link.max_budget_bytes_per_s, 25'000'000u);
  ASSERT_TRUE(applyOverride(config, "foveation.preset=F3").isOk());
  EXPECT_EQ(config.foveation.acuity.preset, pipeline::Preset::kF3);
  ASSERT_TRUE(applyOverride(config, "stream.listen=").isOk());
  EXPECT_EQ(config.stream.link.listen, "");
  ASSERT_TRUE(applyOverride(config, "gpio.privacy_line=-1").isOk());
  // A key short of its outer section, when only one key ends so (the "pose.source").
  ASSERT_TRUE(applyOverride(config, "pose.source=track").isOk());
  EXPECT_EQ(config.camera.pose.source, "track");
  EXPECT_EQ(setError("pose.source=gps"), "--set: camera.pose.source: must be one of \"none\", \"fixed\", \"socket\", "
                                         "\"track\", \"track+fixed\", \"track+socket\", \"track+camera\" (got \"gps\")");
  // The tracker refining the camera's own pose (a mock's path, a recording's ground truth).
  ASSERT_TRUE(applyOverride(config, "pose.source=track+camera").isOk());
  EXPECT_EQ(config.camera.pose.source, "track+camera");
  const std::optional<pipeline::map::PoseSourceChoice> own = pipeline::map::parsePoseSourceChoice("track+camera");
  ASSERT_TRUE(own.has_value());
  EXPECT_EQ(own->outside, "none");
  EXPECT_EQ(own->tracking, pipeline::map::PoseTracking::kRefine);
  EXPECT_FALSE(pipeline::map::parsePoseSourceChoice("track+none").has_value());
  EXPECT_NE(setError("source=map").find("unknown key 'source'"), std::string::npos);  // no section at all: not guessed

  EXPECT_EQ(setError("camera.sepc=mock"), "--set: unknown key 'camera.sepc' (did you mean 'camera.spec'?)");
  EXPECT_EQ(setError("stream.budget_mbps=-3"), "--set: stream.budget_mbps: must be within 0.01 .. 10000 (got -3)");
  EXPECT_EQ(setError("stream.budget_mbps=fast"), "--set: stream.budget_mbps: 'fast' is not a TOML value");
  EXPECT_EQ(setError("pipeline.threads=2.5"), "--set: pipeline.threads: expected an integer, got a float");
  EXPECT_EQ(setError("stream.entropy=on"), "--set: stream.entropy: 'on' is not a TOML value");
  EXPECT_EQ(setError("pipeline"), "--set: 'pipeline' is not section.key=value");
  EXPECT_EQ(setError("runtime.capture_thread=1"), "--set: 'runtime.capture_thread' is a section; set one of its keys");
}

// Found by tests/fuzz/fuzz_config: --set's bare text took any bytes, and
// print-config then wrote a file that does not load (TOML is UTF-8).
TEST(Config, StringsAreUtf8WithoutControlCharacters) {
  EXPECT_EQ(setError("camera.spec=mock:ball\xa6n"), "--set: camera.spec: must be UTF-8 text (byte 9 is not)");
  EXPECT_EQ(setError(std::string("camera.spec=mock:ball\0n", 23)),
            "--set: camera.spec: must not contain control characters (byte 9 is 0x00)");
  EXPECT_EQ(setError("stream.key_file=/etc/\xc0\xafkey"), "--set: stream.key_file: must be UTF-8 text (byte 5 is not)");
  EXPECT_EQ(setError("stream.key_file=/etc/\xed\xa0\x80"), "--set: stream.key_file: must be UTF-8 text (byte 5 is not)");
  EXPECT_EQ(setError("stream.key_file=/etc/\xe2\x82"), "--set: stream.key_file: must be UTF-8 text (byte 5 is not)");
  EXPECT_EQ(loadError("[camera]\nspec = \"mock:a\\u0007\"\n"),
            "fovea.toml:2: camera.spec: must not contain control characters (byte 6 is 0x07)");
  // Text that is UTF-8 still goes, and prints to a file that loads back.
  ServiceConfig config;
  ASSERT_TRUE(applyOverride(config, "camera.calibration_file=/home/zoë/カメラ.yaml").isOk());
  ASSERT_TRUE(applyOverride(config, "stream.key_file=/etc/fovea/\xf0\x9f\x94\x91.key").isOk());
  Result<ServiceConfig> again = parseServiceConfig(formatServiceConfig(config), "printed.toml", ServiceConfig{});
  ASSERT_TRUE(again.isOk()) << again.status().message();
  expectSame(config, *again);
}

std::string boardDir() { return test::sourceDir() + "/board"; }

std::vector<std::filesystem::path> boardProfiles() {
  std::vector<std::filesystem::path> profiles;
  for (const auto& entry : std::filesystem::directory_iterator(boardDir())) {
    if (entry.path().extension() == ".toml") profiles.push_back(entry.path());
  }
  std::sort(profiles.begin(), profiles.end());
  return profiles;
}

// The foveation flags change only what they name: a floor, a level margin or a view
// cull from the configuration file or --set survive --preset ACUITY (fovead serve
// once replaced the whole section, so --set foveation.floor_per_m2 did nothing there).
Result<pipeline::FoveationConfig> flagsOver(const pipeline::FoveationConfig& base, std::vector<std::string> words) {
  words.insert(words.begin(), {"fovead", "serve"});
  std::vector<char*> argv;
  for (std::string& w : words) argv.push_back(w.data());
  Result<Args> args = Args::parse(static_cast<int>(argv.size()), argv.data(), 2, kFoveationFlags, {});
  if (!args) return args.status();
  return foveationConfigFromArgs(args.value(), base);
}

TEST(FoveationFlags, ChangeOnlyWhatTheyName) {
  pipeline::FoveationConfig base;
  base.acuity.slope = 0.028;
  base.acuity.floor_m = 0.003;
  base.acuity.floor_per_m2 = 0.002;
  base.acuity.level_margin = 0.7;
  base.acuity.refine_passes = 3;
  base.acuity.view_cull = pipeline::ViewCull::kDrop;
  base.fixation.fixed_m = 2.5;
  Result<pipeline::FoveationConfig> acuity = flagsOver(base, {"--preset", "ACUITY"});
  ASSERT_TRUE(acuity) << acuity.status().toString();
  EXPECT_EQ(acuity->acuity.preset, pipeline::Preset::kAcuity);
  EXPECT_EQ(acuity->acuity.slope, 0.028);
  EXPECT_EQ(acuity->acuity.floor_m, 0.003);
  EXPECT_EQ(acuity->acuity.floor_per_m2, 0.002);
  EXPECT_EQ(acuity->acuity.level_margin, 0.7);
  EXPECT_EQ(acuity->acuity.refine_passes, 3);
  EXPECT_EQ(acuity->acuity.view_cull, pipeline::ViewCull::kDrop);
  EXPECT_EQ(describeFoveation(acuity.value()).rfind("ACUITY floor 3 mm floor 2 mm x s^2 margin 0.7 refined 3 passes (m 0.028, ", 0), 0u)
      << describeFoveation(acuity.value());
  pipeline::FoveationConfig one_pass = acuity.value();
  one_pass.acuity.refine_passes = 1;
  EXPECT_NE(describeFoveation(one_pass).find(" refined 1 pass ("), std::string::npos) << describeFoveation(one_pass);
  Result<pipeline::FoveationConfig> slope = flagsOver(acuity.value(), {"--m", "0.034"});
  ASSERT_TRUE(slope);
  EXPECT_EQ(slope->acuity.slope, 0.034);
  EXPECT_EQ(slope->acuity.preset, pipeline::Preset::kAcuity);
  EXPECT_EQ(slope->acuity.floor_per_m2, 0.002);
  Result<pipeline::FoveationConfig> fixed = flagsOver(base, {"--fixation", "centroid"});
  ASSERT_TRUE(fixed);
  EXPECT_EQ(fixed->fixation.mode, pipeline::FixationMode::kCentroid);
  EXPECT_EQ(fixed->fixation.fixed_m, 2.5);
  // The paper's presets say no floor, whatever the base holds (they ignore it).
  Result<pipeline::FoveationConfig> f1 = flagsOver(base, {"--preset", "F1"});
  ASSERT_TRUE(f1);
  EXPECT_EQ(describeFoveation(f1.value()).rfind("F1 (m 0.028, ", 0), 0u) << describeFoveation(f1.value());
}

// ACUITY's own settings have flags too (fovead run and foveate read no
// configuration file), and they are refused where they would do nothing.
TEST(FoveationFlags, AcuitySettingsHaveFlags) {
  Result<pipeline::FoveationConfig> set =
      flagsOver(pipeline::FoveationConfig{}, {"--preset", "ACUITY", "--floor-m", "0.004", "--floor-per-m2", "0.001",
                                              "--level-margin", "0.3", "--refine-passes", "2", "--view-cull", "drop",
                                              "--level-voxel-m", "0.003", "--view-cull-deg", "55"});
  ASSERT_TRUE(set) << set.status().toString();
  EXPECT_EQ(set->acuity.level_voxel_m, 0.003);
  EXPECT_EQ(set->acuity.view_cull_deg, 55.0);
  EXPECT_EQ(set->acuity.floor_m, 0.004);
  EXPECT_EQ(set->acuity.floor_per_m2, 0.001);
  EXPECT_EQ(set->acuity.level_margin, 0.3);
  EXPECT_EQ(set->acuity.refine_passes, 2);
  EXPECT_EQ(set->acuity.view_cull, pipeline::ViewCull::kDrop);
  // Over a base that is already ACUITY, no --preset is needed.
  Result<pipeline::FoveationConfig> over = flagsOver(set.value(), {"--refine-passes", "0"});
  ASSERT_TRUE(over) << over.status().toString();
  EXPECT_EQ(over->acuity.refine_passes, 0);
  EXPECT_EQ(over->acuity.level_margin, 0.3);

  // Every ACUITY flag is refused with another preset (it would silently do nothing).
  for (const char* flag : {"--level-voxel-m", "--floor-m", "--floor-per-m2", "--level-margin", "--refine-passes",
                           "--view-cull", "--view-cull-deg"}) {
    const char* value = std::string_view(flag) == "--view-cull" ? "drop" : "1";
    Result<pipeline::FoveationConfig> f1 = flagsOver(pipeline::FoveationConfig{}, {flag, value});
    ASSERT_FALSE(f1) << flag;
    EXPECT_NE(f1.status().message().find("say --preset ACUITY (the foveation is F1)"), std::string::npos)
        << f1.status().message();
    EXPECT_EQ(f1.status().message().rfind(std::string(flag) + ": ", 0), 0u) << f1.status().message();
  }
  for (const std::vector<std::string>& bad :
       {std::vector<std::string>{"--refine-passes", "8"}, {"--refine-passes", "1.5"}, {"--level-margin", "0.01"},
        {"--floor-m", "nan"}, {"--floor-per-m2", "-1"}, {"--view-cull", "sideways"}, {"--level-margin", "x"},
        {"--level-voxel-m", "0"}, {"--level-voxel-m", "2"}, {"--view-cull-deg", "0"}, {"--view-cull-deg", "181"},
        {"--view-cull-deg", "inf"}}) {
    std::vector<std::string> words = {"--preset", "ACUITY"};
    words.insert(words.end(), bad.begin(), bad.end());
    Result<pipeline::FoveationConfig> refused = flagsOver(pipeline::FoveationConfig{}, words);
    ASSERT_FALSE(refused) << bad[0] << " " << bad[1];
    EXPECT_EQ(refused.status().code(), ErrorCode::kInvalidArgument) << refused.status().toString();
  }
}

TEST(FoveationFlags, CustomRegionsFromTheBaseNeedNoBoundsFlag) {
  pipeline::FoveationConfig base;
  base.acuity.preset = pipeline::Preset::kCustom;
  base.acuity.custom_bounds_deg = {5, 20};
  Result<pipeline::FoveationConfig> slope = flagsOver(base, {"--m", "0.03"});
  ASSERT_TRUE(slope) << slope.status().toString();
  EXPECT_EQ(slope->acuity.custom_bounds_deg, (std::vector<double>{5, 20}));
  Result<pipeline::FoveationConfig> bare = flagsOver(pipeline::FoveationConfig{}, {"--preset", "custom"});
  ASSERT_FALSE(bare);
  EXPECT_NE(bare.status().message().find("needs --bounds"), std::string::npos) << bare.status().message();
  Result<pipeline::FoveationConfig> both = flagsOver(base, {"--preset", "F2", "--bounds", "3,9"});
  ASSERT_FALSE(both);
  EXPECT_NE(both.status().message().find("--bounds"), std::string::npos) << both.status().message();
}

TEST(BoardProfiles, EveryProfileLoadsAndValidates) {
  const std::vector<std::filesystem::path> profiles = boardProfiles();
  ASSERT_GE(profiles.size(), 4u);
  const ScopedBoardDir board_dir(boardDir());
  for (const std::filesystem::path& profile : profiles) {
    SCOPED_TRACE(profile.string());
    Result<ServiceConfig> config = loadServiceConfig(profile.string(), ServiceConfig{});
    ASSERT_TRUE(config.isOk()) << config.status().message();
    EXPECT_EQ(config->board, profile.stem().string()) << "a profile's board key is its file name";
    // A profile says what it is and why its values, in a comment header.
    std::ifstream in(profile);
    std::string first_line;
    std::getline(in, first_line);
    EXPECT_EQ(first_line.rfind("# " + profile.stem().string() + ": ", 0), 0u) << first_line;
    // By name, as fovead serve --board NAME loads it.
    Result<ServiceConfig> resolved = resolveServiceConfig(profile.stem().string(), std::nullopt, {});
    ASSERT_TRUE(resolved.isOk()) << resolved.status().message();
    expectSame(*resolved, *config);
    // And what print-config shows for it loads back the same.
    TempDir dir;
    Result<ServiceConfig> printed =
        loadServiceConfig(write(dir, "printed.toml", formatServiceConfig(*config)), ServiceConfig{});
    ASSERT_TRUE(printed.isOk()) << printed.status().message();
    expectSame(*printed, *config);
  }
}

TEST(BoardProfiles, DefaultIsHostMock) {
  const ScopedBoardDir board_dir(boardDir());
  Result<ServiceConfig> config = resolveServiceConfig(std::nullopt, std::nullopt, {});
  ASSERT_TRUE(config.isOk()) << config.status().message();
  EXPECT_EQ(config->board, "host-mock");
  EXPECT_EQ(config->camera.spec.rfind("mock:", 0), 0u);
  EXPECT_EQ(config->gpio.spec, "mock");
  EXPECT_TRUE(missingBackends(*config).empty());
}

// `fovead serve --set pose.source=track`: tracking implies the map unless
// foveation.source was set; set to the frame, it is an error naming both.
TEST(BoardProfiles, TrackingImpliesTheMapUnlessTheSourceIsSet) {
  const ScopedBoardDir board_dir(boardDir());
  const std::vector<std::string> track = {"pose.source=track"};
  Result<ServiceConfig> config = resolveServiceConfig(std::nullopt, std::nullopt, track);
  ASSERT_TRUE(config.isOk()) << config.status().message();
  EXPECT_EQ(config->camera.pose.source, "track");
  EXPECT_EQ(config->map.source, FoveationSource::kMap);
  const std::vector<std::string> frame = {"foveation.source=frame", "camera.pose.source=track+fixed"};
  config = resolveServiceConfig(std::nullopt, std::nullopt, frame);
  ASSERT_FALSE(config.isOk());
  EXPECT_NE(config.status().message().find("--set: camera.pose.source: \"track+fixed\" tracks the camera against the "
                                           "map: needs foveation.source = \"map\""),
            std::string::npos)
      << config.status().message();
}

TEST(BoardProfiles, MissingCameraBackendIsReportedButTheProfileValidates) {
  TempDir dir;
  ServiceConfig config;
  config.camera.spec = "nosuch:/dev/video9";
  EXPECT_TRUE(validate(config).isOk());
  std::string built;
  for (std::string_view name : hal::cameraBackendNames()) built += (built.empty() ? "" : ", ") + std::string(name);
  const std::vector<std::string> missing = missingBackends(config);
  ASSERT_EQ(missing.size(), 1u);
  EXPECT_EQ(missing[0], "camera.spec: backend 'nosuch' is not in this build (built: " + built + ")");

  // The Raspberry Pi 5 profile names the V4L2 backend and a calibration file.
  Result<ServiceConfig> rpi5 = loadServiceConfig(boardDir() + "/rpi5-usb-rgbd.toml", ServiceConfig{});
  ASSERT_TRUE(rpi5.isOk()) << rpi5.status().message();
  EXPECT_EQ(rpi5->camera.spec.rfind("v4l2:auto,", 0), 0u) << rpi5->camera.spec;
  EXPECT_EQ(rpi5->camera.calibration_file, "/etc/fovea/camera.yaml");
  // With the map source, fusion under the send thread's SCHED_FIFO on core 3 (docs/map.md).
  EXPECT_EQ(rpi5->runtime.map_thread.core, 3);
  EXPECT_EQ(rpi5->runtime.map_thread.realtime_priority, 0);
  // A build with V4L2 (every toolchain/ build: FOVEA_REQUIRE_BACKENDS) misses
  // nothing the profile names; one without it names the backend. Either way
  // the check runs.
  const std::vector<std::string_view> names = hal::cameraBackendNames();
  const std::vector<std::string> rpi5_missing = missingBackends(*rpi5);
  if (std::find(names.begin(), names.end(), "v4l2") != names.end()) {
    EXPECT_TRUE(rpi5_missing.empty()) << rpi5_missing.front();
  } else {
    ASSERT_FALSE(rpi5_missing.empty());
    EXPECT_EQ(rpi5_missing[0], "camera.spec: backend 'v4l2' is not in this build (built: " + built + ")");
  }
}

TEST(Resolve, BoardThenFileThenSet) {
  TempDir dir;
  const ScopedBoardDir board_dir(boardDir());
  const std::string file = write(dir, "fovea.toml", "[pipeline]\nthreads = 1\n[stream]\nbudget_mbps = 50\n");
  const std::vector<std::string> sets = {"stream.budget_mbps=25", "foveation.preset=F2"};
  Result<ServiceConfig> config = resolveServiceConfig("rpi5-usb-rgbd", file, sets);
  ASSERT_TRUE(config.isOk()) << config.status().message();
  EXPECT_EQ(config->board, "rpi5-usb-rgbd");
  EXPECT_EQ(config->gpio.spec, "gpiod:gpiochip4");              // the board
  EXPECT_EQ(config->pipeline.threads, 1);                        // the file over the board
  EXPECT_EQ(config->stream.link.max_budget_bytes_per_s, 25'000'000u);  // --set over the file
  EXPECT_EQ(config->foveation.acuity.preset, pipeline::Preset::kF2);

  // The file's board key picks the profile; --board must agree with it.
  const std::string jetson = write(dir, "jetson.toml", "board = \"jetson-orin-nano\"\n[pipeline]\nthreads = 2\n");
  Result<ServiceConfig> picked = resolveServiceConfig(std::nullopt, jetson, {});
  ASSERT_TRUE(picked.isOk()) << picked.status().message();
  EXPECT_EQ(picked->gpio.spec, "gpiod:gpiochip0");
  EXPECT_EQ(picked->pipeline.threads, 2);
  Result<ServiceConfig> clash = resolveServiceConfig("rk3588", jetson, {});
  ASSERT_FALSE(clash.isOk());
  EXPECT_EQ(clash.status().message(), jetson + ":1: board: the file is for 'jetson-orin-nano', --board says 'rk3588'");

  // An error names where the value came from: here the board's max_voxels
  // against --set's max_points.
  const std::vector<std::string> small = {"pipeline.max_points=1000"};
  Result<ServiceConfig> bad = resolveServiceConfig("host-mock", std::nullopt, small);
  ASSERT_FALSE(bad.isOk());
  EXPECT_EQ(bad.status().message(), boardDir() + "/host-mock.toml:20: pipeline.max_voxels: must be at most "
                                                  "pipeline.max_points (got 92160 > 1000)");
  const std::vector<std::string> listen = {"stream.listen=0.0.0.0:7000"};
  Result<ServiceConfig> unkeyed = resolveServiceConfig("host-mock", std::nullopt, listen);
  ASSERT_FALSE(unkeyed.isOk());
  EXPECT_EQ(unkeyed.status().message().rfind("--set: stream.key_file: needed when stream.listen is set", 0), 0u)
      << unkeyed.status().message();

  const std::vector<std::string> rename = {"board=rk3588"};
  Result<ServiceConfig> renamed = resolveServiceConfig(std::nullopt, std::nullopt, rename);
  ASSERT_FALSE(renamed.isOk());
  EXPECT_EQ(renamed.status().message(), "--set: board: pick a profile with --board NAME");

  Result<ServiceConfig> unknown = resolveServiceConfig("nope", std::nullopt, {});
  ASSERT_FALSE(unknown.isOk());
  EXPECT_EQ(unknown.status().message(), "unknown board 'nope': no nope.toml in " + boardDir() +
                                            " (boards: host-mock, jetson-orin-nano, rk3588, rpi5-usb-rgbd)");
}

TEST(Resolve, BoardDirectoryFromTheEnvironment) {
  TempDir dir;
  write(dir, "bench.toml", "# bench: a test bench\nboard = \"bench\"\n[pipeline]\nthreads = 5\n");
  write(dir, "wrong.toml", "board = \"other\"\n");
  const ScopedBoardDir board_dir(dir.path());
  EXPECT_EQ(boardDirectory(), dir.path());
  Result<ServiceConfig> config = resolveServiceConfig("bench", std::nullopt, {});
  ASSERT_TRUE(config.isOk()) << config.status().message();
  EXPECT_EQ(config->pipeline.threads, 5);
  Result<ServiceConfig> wrong = resolveServiceConfig("wrong", std::nullopt, {});
  ASSERT_FALSE(wrong.isOk());
  EXPECT_EQ(wrong.status().message(), dir.file("wrong.toml") + ":1: board: 'other' in wrong.toml (they must match)");
}

std::string fovead() { return test::program(FOVEAD_PATH); }

TEST(PrintConfig, PrintsTheEffectiveConfigurationAsLoadableToml) {
  TempDir dir;
  const std::string printed = dir.file("printed.toml");
  // stdout alone (the note about the missing v4l2 backend goes to stderr).
  const test::ProcessResult r = test::runCommand("(FOVEA_BOARD_DIR=" + boardDir() + " " + fovead() +
                                                 " --print-config --board rpi5-usb-rgbd --set stream.budget_mbps=25"
                                                 " --set pipeline.threads=1 > " + printed + " 2>/dev/null)");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  Result<ServiceConfig> loaded = loadServiceConfig(printed, ServiceConfig{});
  ASSERT_TRUE(loaded.isOk()) << loaded.status().message();
  const ScopedBoardDir board_dir(boardDir());
  const std::vector<std::string> sets = {"stream.budget_mbps=25", "pipeline.threads=1"};
  Result<ServiceConfig> expected = resolveServiceConfig("rpi5-usb-rgbd", std::nullopt, sets);
  ASSERT_TRUE(expected.isOk()) << expected.status().message();
  expectSame(*loaded, *expected);

  // FOVEA_FORCE_KERNEL beats the configuration, as it does everywhere.
  const test::ProcessResult forced =
      test::runCommand("FOVEA_FORCE_KERNEL=ref " + fovead() + " print-config --set pipeline.kernels=simd");
  ASSERT_EQ(forced.exit_code, 0) << forced.output;
  EXPECT_NE(forced.output.find("kernels = \"ref\""), std::string::npos) << forced.output;

  // The command form, and the default board.
  const test::ProcessResult host = test::runCommand(fovead() + " print-config");
  ASSERT_EQ(host.exit_code, 0) << host.output;
  EXPECT_NE(host.output.find("board = \"host-mock\""), std::string::npos) << host.output;
  EXPECT_NE(host.output.find("[runtime.send_thread]"), std::string::npos) << host.output;
}

TEST(PrintConfig, ErrorsExitWithStatus2AndTheMessage) {
  TempDir dir;
  const std::string file = write(dir, "fovea.toml", "[camera]\nsepc = \"mock\"\n");
  test::ProcessResult r = test::runCommand(fovead() + " --print-config --config " + file);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.output, "fovead print-config: " + file + ":2: unknown key 'camera.sepc' (did you mean 'camera.spec'?)\n");
  r = test::runCommand(fovead() + " print-config --config " + dir.file("missing.toml"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.output, "fovead print-config: cannot open '" + dir.file("missing.toml") + "': No such file or directory\n");
  r = test::runCommand(fovead() + " print-config --set stream.budget_mbps=-3");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.output, "fovead print-config: --set: stream.budget_mbps: must be within 0.01 .. 10000 (got -3)\n");
  r = test::runCommand(fovead() + " print-config --frobnicate");
  EXPECT_EQ(r.exit_code, 2);
  // A board whose camera backend this build lacks still prints, with a note.
  r = test::runCommand("FOVEA_BOARD_DIR=" + boardDir() + " " + fovead() + " print-config --board rpi5-usb-rgbd");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

}  // namespace
}  // namespace fovea::firmware

namespace fovea::firmware {
namespace {

TEST(Config, CameraGeometryKeysAreChecked) {
  EXPECT_EQ(loadError("[camera.extrinsics]\nrotation_xyzw = [0, 0, 0, 1]\n"),
            "fovea.toml:2: camera.extrinsics.translation_m: give camera.extrinsics.rotation_xyzw and translation_m "
            "together (or neither)");
  EXPECT_EQ(loadError("[camera.pose]\nsource = \"fixed\"\nrotation_xyzw = [0, 0, 0, 0]\n"),
            "fovea.toml:3: camera.pose.rotation_xyzw: not a rotation quaternion (x, y, z, w with length near 1; got "
            "length 0; the identity is [0, 0, 0, 1])");
  EXPECT_EQ(loadError("[camera.pose]\ntranslation_m = [1, 2]\n"),
            "fovea.toml:2: camera.pose.translation_m: a translation is 3 numbers x, y, z in metres (got 2)");
  EXPECT_EQ(loadError("[camera.pose]\nsource = \"socket\"\nsocket = \"\"\n"),
            "fovea.toml:3: camera.pose.socket: must name the socket's path with camera.pose.source = \"socket\"");
  EXPECT_EQ(loadError("[camera.pose]\nsource = \"gps\"\n"),
            "fovea.toml:2: camera.pose.source: must be one of \"none\", \"fixed\", \"socket\", \"track\", \"track+fixed\", "
            "\"track+socket\", \"track+camera\" (got \"gps\")");
  EXPECT_EQ(loadError("[camera.pose]\nmax_age_ms = 0\n"),
            "fovea.toml:2: camera.pose.max_age_ms: must be within 1 .. 60000 (got 0)");
  EXPECT_EQ(loadError("[camera]\ncalibration_file = \"d435.yaml\"\n[camera.pose]\nsource = \"fixed\"\n"
                      "translation_m = [1.5, 0, 0.8]\nrotation_xyzw = [0, 0, 0, 1]\n"),
            "(loaded)");  // the file is read at start-up, not by the configuration
}

TEST(Config, PrintConfigShowsTheCameraGeometry) {
  ServiceConfig config;
  ASSERT_TRUE(applyOverride(config, "camera.pose.source=fixed").isOk());
  ASSERT_TRUE(applyOverride(config, "camera.pose.translation_m=[1.5, 0, 0.8]").isOk());
  ASSERT_TRUE(applyOverride(config, "camera.calibration_file=/etc/fovea/cal.yaml").isOk());
  const std::string text = formatServiceConfig(config);
  EXPECT_NE(text.find("calibration_file = \"/etc/fovea/cal.yaml\"\n\n[camera.extrinsics]\nrotation_xyzw = []\n"
                      "translation_m = []\n\n[camera.pose]\nsource = \"fixed\"\ntranslation_m = [1.5, 0.0, 0.8]\n"),
            std::string::npos)
      << text;
  // And it loads back the same.
  TempDir dir;
  Result<ServiceConfig> back = loadServiceConfig(write(dir, "printed.toml", text), ServiceConfig{});
  ASSERT_TRUE(back.isOk()) << back.status().message();
  expectSame(back.value(), config);
}

}  // namespace
}  // namespace fovea::firmware
