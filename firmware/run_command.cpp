// fovead run: camera -> back-projection -> foveation, with statistics.
#include <algorithm>
#include <array>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "core/clock.h"
#include "firmware/camera_setup.h"
#include "firmware/commands.h"
#include "firmware/frame_foveator.h"
#include "firmware/mcap_camera.h"
#include "firmware/options.h"
#include "firmware/report.h"
#include "firmware/stream_options.h"
#include "firmware/streamer.h"
#include "hal/camera.h"
#include "io/ply.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/quantile.h"

namespace fovea::firmware {

namespace {

const char* kRunHelp =
    "usage: fovead run [--camera SPEC] [--frames N] [--gaze MODE | --gaze-origin X,Y,Z --gaze-dir X,Y,Z]\n"
    "                  [--preset F1|F2|F3|FREF|ACUITY] [--m SLOPE] [--far-ecc DEG] [--fixation MODE]\n"
    "                  [--depth-min M] [--depth-max M] [--every N] [--save-ply FILE] [--threads N]\n"
    "                  [--calibration FILE] [--pose none|fixed:...|socket:PATH|track[+fixed:...|+socket:PATH]]\n"
    "                  [--source frame|map [--max-surfels N] [--brick-size M]]\n"
    "                  [--listen ADDR:PORT (--key-file FILE | --insecure) [stream options]]\n"
    "\n"
    "Runs the foveation pipeline on a camera and prints, per frame and for the run,\n"
    "the points per region in and out, the voxel size per region, d0, and the time\n"
    "per stage. With --listen it streams the foveated frames to the operator that\n"
    "says hello (fovea-operator), foveated for the gaze the operator sends.\n"
    "\n"
    "  --camera SPEC            camera backend (default mock:living-room), see below\n"
    "  --frames N               frames to process (default 30; with --listen 0: until SIGINT/SIGTERM)\n"
    "  --duration S             stop after S seconds (default: no limit)\n"
    "  --gaze MODE              scene-centre: from the camera towards the scene's focus point (default\n"
    "                           when the camera has one); axis: along the optical axis;\n"
    "                           target:X,Y,Z: from the camera towards a world point\n"
    "  --gaze-origin X,Y,Z      eye position in world coordinates (metres), with --gaze-dir\n"
    "  --gaze-dir X,Y,Z         gaze direction in world coordinates (any length > 0)\n"
    "  --depth-min M, --depth-max M   valid depth range (default 0.1 .. 10 m)\n"
    "  --every N                print every Nth frame (default 1; 0: summary only)\n"
    "  --save-ply FILE          write the last foveated frame (world coordinates, region per point);\n"
    "                           with --listen, the last frame sent whole to the operator\n"
    "  --calibration FILE       a calibration file (ROS camera_info, OpenCV FileStorage or fovea YAML,\n"
    "                           docs/calibration.md), as camera.calibration_file\n"
    "  --pose SPEC              where the camera is (docs/pose.md), as [camera.pose]: none (default: the\n"
    "                           camera's own), fixed:X,Y,Z[,QX,QY,QZ,QW] (metres; quaternion x y z w), or\n"
    "                           socket:PATH (the robot's poses as datagrams; --pose-max-age-ms MS, default 100);\n"
    "                           with --source map also track (the map's tracker alone), track+fixed:...,\n"
    "                           track+socket:PATH, track+camera (the outside pose, or the camera's own, as\n"
    "                           the prior; docs/tracking.md)\n"
    "  --threads N              threads per frame for back-projection and partition (default 1, up to 64;\n"
    "                           SIMD kernels only; the output does not depend on it)\n"
    "  --source frame|map       what is foveated (foveation.source, docs/map.md): each frame's own points\n"
    "                           (default), or the surfel map fused from the posed frames as the eye sees it,\n"
    "                           with the frame's points the map does not explain yet\n"
    "  --max-surfels N          the map's pool (default 1048576, at most 16777215; 38 bytes a surfel)\n"
    "  --brick-size M           the map's bricks' edge in metres (default 0.5)\n"
    "\n"
    "\n"
    "streaming (docs/protocol.md):\n"
    "  --listen ADDR:PORT       serve one operator over UDP: 127.0.0.1:7000, [::1]:7000, 0.0.0.0:7000...\n"
    "  --key-file FILE          the pre-shared key (64 hex characters; fovead keygen FILE makes one)\n"
    "  --insecure               no key: the fixed all-zero key, anyone can read and forge (logged loudly)\n"
    "  --budget MBPS            the most any operator may ask for, MB/s (default 12.5 = 100 Mbit/s)\n"
    "  --max-mtu BYTES          the largest UDP payload granted (default 1200, 256 .. 8952)\n"
    "  --gaze-timeout-ms MS     gaze older than this selects the fallback (default 100)\n"
    "  --fallback-voxel M       the fallback's uniform voxel size (default 0.05 m)\n"
    "  --fovea-step M           quantization step in the fovea (default 0.001 m)\n"
    "  --chroma full|half       half: chroma shared by pairs of points outside the fovea (default full)\n"
    "  --entropy on|off         zstd per chunk where it pays (default off: on our chunks it rarely does)\n"
    "\n"
    "FOVEA_FORCE_KERNEL=ref runs the scalar reference kernels instead of the SIMD ones.\n";

enum class GazeMode { kSceneCentre, kAxis, kTarget, kWorld };

struct GazeChoice {
  GazeMode mode = GazeMode::kSceneCentre;
  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d vector = Eigen::Vector3d::UnitZ();  // direction (kWorld) or target (kTarget)
};

Result<GazeChoice> gazeFromArgs(const Args& args, const hal::CameraInfo& info) {
  GazeChoice choice;
  if (args.has("--gaze-origin") || args.has("--gaze-dir")) {
    if (args.has("--gaze")) return Result<GazeChoice>(ErrorCode::kInvalidArgument, "--gaze: not together with --gaze-origin/--gaze-dir");
    if (!args.has("--gaze-origin") || !args.has("--gaze-dir")) {
      return Result<GazeChoice>(ErrorCode::kInvalidArgument, "--gaze-origin and --gaze-dir go together");
    }
    Result<Eigen::Vector3d> origin = parseVector3("--gaze-origin", *args.get("--gaze-origin"));
    if (!origin) return origin.status();
    Result<Eigen::Vector3d> dir = parseVector3("--gaze-dir", *args.get("--gaze-dir"));
    if (!dir) return dir.status();
    if (!(dir->norm() > 1e-12)) return Result<GazeChoice>(ErrorCode::kInvalidArgument, "--gaze-dir: has zero length");
    choice.mode = GazeMode::kWorld;
    choice.origin_m = origin.value();
    choice.vector = dir.value();
    return choice;
  }
  const std::string mode = args.getOr("--gaze", info.focus_point_m ? "scene-centre" : "axis");
  if (mode == "scene-centre") {
    if (!info.focus_point_m) {
      return Result<GazeChoice>(ErrorCode::kInvalidArgument, "--gaze scene-centre: camera " + info.name + " knows no scene centre; use axis or target:X,Y,Z");
    }
    choice.mode = GazeMode::kSceneCentre;
    choice.vector = *info.focus_point_m;
  } else if (mode == "axis") {
    choice.mode = GazeMode::kAxis;
  } else if (mode.rfind("target:", 0) == 0) {
    Result<Eigen::Vector3d> target = parseVector3("--gaze target:", mode.substr(7));
    if (!target) return target.status();
    choice.mode = GazeMode::kTarget;
    choice.vector = target.value();
  } else {
    return Result<GazeChoice>(ErrorCode::kInvalidArgument, "--gaze: '" + mode + "' is not scene-centre, axis or target:X,Y,Z");
  }
  return choice;
}

// The eye sits at the camera (an operator looking through the robot's eyes)
// unless the gaze was given in world coordinates.
pipeline::Gaze gazeForFrame(const GazeChoice& choice, const hal::Pose& pose) {
  pipeline::Gaze gaze;
  gaze.origin_m = pose.t_world_cam;
  switch (choice.mode) {
    case GazeMode::kSceneCentre:
    case GazeMode::kTarget: gaze.direction = choice.vector - pose.t_world_cam; break;
    case GazeMode::kAxis: gaze.direction = pose.R_world_cam.col(2); break;
    case GazeMode::kWorld:
      gaze.origin_m = choice.origin_m;
      gaze.direction = choice.vector;
      break;
  }
  return gaze;
}

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// Copies the points of a foveated cloud (not its whole capacity).
void copyFoveated(const pipeline::FoveatedCloud& from, pipeline::FoveatedCloud& to) {
  const std::size_t n = from.size();
  to.clear();
  if (!to.points.resize(n)) return;
  to.points.origin_m = from.points.origin_m;
  to.points.has_color = from.points.has_color;
  std::copy_n(from.points.x(), n, to.points.x());
  std::copy_n(from.points.y(), n, to.points.y());
  std::copy_n(from.points.z(), n, to.points.z());
  std::copy_n(from.points.rgb(), n, to.points.rgb());
  std::copy_n(from.region.begin(), n, to.region.begin());
  if (to.hasWeights() && from.hasWeights()) std::copy_n(from.weight.begin(), n, to.weight.begin());
}

// SIGINT/SIGTERM end the run loop cleanly (the link says Bye on the way out).
volatile std::sig_atomic_t g_stop = 0;
extern "C" void onStopSignal(int) { g_stop = 1; }

// A step that ends the command returns its exit code; nullopt: carry on.
using Exit = std::optional<int>;

int usage(const Status& s) {
  std::fprintf(stderr, "fovead run: %s\n", s.message().c_str());
  return kExitUsage;
}

// A start-up failure is the user's (bad arguments) or the machine's.
int startFailure(const Status& s) {
  std::fprintf(stderr, "fovead run: %s\n", s.message().c_str());
  return s.code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
}

std::vector<std::string> runFlags() {
  std::vector<std::string> flags = {"--frames", "--duration", "--gaze", "--gaze-origin", "--gaze-dir",
                                    "--depth-min", "--depth-max", "--every", "--save-ply", "--threads"};
  flags.insert(flags.end(), kCameraFlags.begin(), kCameraFlags.end());
  flags.insert(flags.end(), kFoveationFlags.begin(), kFoveationFlags.end());
  flags.insert(flags.end(), kStreamFlags.begin(), kStreamFlags.end());
  flags.insert(flags.end(), kMapFlags.begin(), kMapFlags.end());
  flags.push_back("--source");
  return flags;
}

// What fovead run takes from its flags, checked before the camera opens.
struct RunOptions {
  pipeline::FoveationConfig foveation;
  std::optional<StreamConfig> stream;  // with --listen
  std::size_t frames = 0;              // 0: until stopped
  double duration_s = 0.0;             // 0: no limit
  long every = 1;                      // 0: summary only
  int threads = 1;
  pipeline::DepthRange range;
  CameraSettings camera;
  std::optional<std::string> save_ply;
  MapSettings map;  // --source, --max-surfels, --brick-size
};

// In the order the flags were always checked: the first bad one is the one reported.
Result<RunOptions> runOptionsFromArgs(const Args& args) {
  RunOptions options;
  Result<pipeline::FoveationConfig> config = foveationConfigFromArgs(args);
  if (!config) return config.status();
  options.foveation = std::move(config.value());
  Result<std::optional<StreamConfig>> stream = streamConfigFromArgs(args);
  if (!stream) return stream.status();
  options.stream = std::move(stream.value());
  const bool streaming = options.stream.has_value();
  Result<long> frames =
      parseInteger("--frames", args.getOr("--frames", streaming ? "0" : "30"), streaming ? 0 : 1, 100000000);
  if (!frames) return frames.status();
  options.frames = static_cast<std::size_t>(frames.value());
  Result<double> duration = durationFromArgs(args);
  if (!duration) return duration.status();
  options.duration_s = duration.value();
  Result<long> every = parseInteger("--every", args.getOr("--every", "1"), 0, 100000000);
  if (!every) return every.status();
  options.every = every.value();
  Result<long> threads = parseInteger("--threads", args.getOr("--threads", "1"), 1, 64);
  if (!threads) return threads.status();
  options.threads = static_cast<int>(threads.value());
  Result<pipeline::DepthRange> range = depthRangeFromArgs(args);
  if (!range) return range.status();
  options.range = range.value();
  Result<CameraSettings> camera = cameraSettingsFromArgs(args);
  if (!camera) return camera.status();
  options.camera = std::move(camera.value());
  if (const std::string* path = args.get("--save-ply")) options.save_ply = *path;
  Result<MapSettings> map = mapSettingsFromArgs(args);
  if (!map) return map.status();
  options.map = map.value();
  return options;
}

// The service's own set-up (firmware/camera_setup.h): calibration before open, then the pose source.
Exit openCamera(const CameraSettings& settings, OpenedCamera& out) {
  Result<OpenedCamera> opened = openConfiguredCamera(settings);
  if (!opened) {
    std::fprintf(stderr, "fovead run: %s\n", opened.status().message().c_str());
    return opened.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
  }
  out = std::move(opened.value());
  return std::nullopt;
}

Result<GazeChoice> gazeChoiceForRun(const Args& args, const RunOptions& options, const hal::CameraInfo& info) {
  if (options.stream && (args.has("--gaze") || args.has("--gaze-origin") || args.has("--gaze-dir"))) {
    return Result<GazeChoice>(ErrorCode::kInvalidArgument, "--gaze: not with --listen (the operator sends the gaze)");
  }
  return gazeFromArgs(args, info);
}

// The run's figures; the samples keep the first `capacity` frames of an endless run.
struct RunStats {
  explicit RunStats(std::size_t capacity)
      : capture_ms(capacity), backproject_ms(capacity), partition_ms(capacity), fixation_ms(capacity),
        sample_ms(capacity), foveate_ms(capacity), points_in(capacity), points_out(capacity), d0_m(capacity),
        encode_ms(capacity), send_ms(capacity), fuse_ms(capacity), eye_ms(capacity) {}

  Samples capture_ms, backproject_ms, partition_ms, fixation_ms, sample_ms, foveate_ms;
  Samples points_in, points_out, d0_m;
  Samples encode_ms, send_ms;
  Samples fuse_ms, eye_ms;  // the map source: fusion, and the eye's view of the map
  RegionTotals totals;
  uint64_t failed_frames = 0, attempted_frames = 0, fallback_frames = 0, frames_streamed = 0, stale_pose_frames = 0;
};

// With --listen --save-ply: a copy of the last frame that went out whole.
struct LastStreamed {
  explicit LastStreamed(std::size_t max_points) : cloud(max_points) {}
  pipeline::FoveatedCloud cloud;
  uint64_t id = 0;
  std::array<double, pipeline::kMaxRegions> voxel_m{};
  int regions = 0;
};

// Capture-to-sent latency of the frames of the current status second (fixed room).
struct StatusWindow {
  std::array<double, 256> latency_ms{};
  std::size_t count = 0;
  int64_t next_ns = 0;  // when the next status report is due
};

// One frame's figures, as the loop's steps fill them in.
struct FrameFigures {
  double capture_ms = 0.0;
  double backproject_ms = 0.0;
  int64_t capture_ns = 0;
  pipeline::Gaze gaze;
  GazeSource source = GazeSource::kOperator;
  pipeline::FoveationStats stats;
  FrameSendReport sent;
};

// One run: the buffers sized from the camera, the stream (with --listen), and
// the figures the frame loop's steps share.
class Run {
 public:
  Run(const RunOptions& options, OpenedCamera& camera, const GazeChoice& gaze_choice, FrameFoveator& stage,
      fovea::KernelSet kernels)
      : options_(options),
        camera_(*camera.camera),
        info_(camera_.info()),
        calibrated_(camera.calibrated),
        pose_source_(*camera.pose_source),
        gaze_choice_(gaze_choice),
        stage_(stage),
        kernels_(kernels),
        max_points_(stage.cloud().capacity()),
        period_ns_(info_.fps > 0 ? static_cast<int64_t>(1e9 / info_.fps) : 33'333'333),
        keep_streamed_(options.stream && options.save_ply),
        frame_(info_.intrinsics.width, info_.intrinsics.height),
        out_(max_points_),
        model_(stage.foveator().model()),
        stats_(options.frames > 0 ? options.frames : 100000),
        last_streamed_(keep_streamed_ ? max_points_ : 0) {}

  // Starts the camera and the stream; prints the start-up lines.
  Exit start();
  // Frames until --frames, --duration or SIGINT/SIGTERM.
  Exit loop();
  // Stops the camera, prints the summary and writes --save-ply; the exit code.
  int finish();

 private:
  void printStartup() const;
  Exit startStream();
  void printFrameHeader() const;
  bool capture(std::size_t i, int64_t slot_start_ns, FrameFigures& f);
  bool backproject(std::size_t i, FrameFigures& f);
  bool chooseGaze(FrameFigures& f);
  bool foveate(std::size_t i, FrameFigures& f);
  void send(std::size_t i, int64_t slot_start_ns, FrameFigures& f);
  void record(const FrameFigures& f);
  void printFrame(const FrameFigures& f) const;
  void sendStatusIfDue();
  void printSummary() const;
  Exit saveLastFrame() const;
  void printStreamSummary() const;

  const RunOptions& options_;
  hal::Camera& camera_;
  const hal::CameraInfo& info_;
  const std::string& calibrated_;
  hal::PoseSource& pose_source_;
  const GazeChoice& gaze_choice_;
  FrameFoveator& stage_;
  bool pose_fresh_ = true;  // the pose source had a pose for the current frame
  const fovea::KernelSet kernels_;
  const std::size_t max_points_;
  const int64_t period_ns_;
  const bool keep_streamed_;
  hal::RgbdFrame frame_;
  pipeline::FoveatedCloud out_;
  std::unique_ptr<Streamer> streamer_;
  std::optional<GazePolicy> gaze_policy_;  // the operator's gaze while fresh, else the fallback
  // The run's own region model (the stream's fallback swaps the foveator's).
  const pipeline::RegionModel model_;
  RunStats stats_;
  int64_t run_end_ns_ = INT64_MAX;
  StatusWindow status_;
  uint64_t last_frame_id_ = 0;
  LastStreamed last_streamed_;
  pipeline::Gaze last_gaze_;
  GazeSource last_source_ = GazeSource::kOperator;
};

Exit Run::start() {
  if (Status s = camera_.start(); !s) {
    std::fprintf(stderr, "fovead run: camera %s: %s\n", info_.name.c_str(), s.message().c_str());
    return kExitFailure;
  }
  printStartup();
  if (options_.stream) {
    if (Exit e = startStream()) return e;
  }
  std::signal(SIGINT, onStopSignal);
  std::signal(SIGTERM, onStopSignal);
  printFrameHeader();
  return std::nullopt;
}

void Run::printStartup() const {
  std::printf("fovead run: camera %s %dx%d @ %g fps, depth %g..%g m\n", info_.name.c_str(), info_.intrinsics.width,
              info_.intrinsics.height, info_.fps, options_.range.min_m, options_.range.max_m);
  std::printf("foveation: %s\n", describeFoveation(options_.foveation).c_str());
  if (!calibrated_.empty()) std::printf("camera: %s\n", calibrated_.c_str());
  std::printf("pose: %s\n", describePose(options_.camera, pose_source_).c_str());
  if (kernels_ == fovea::KernelSet::kSimd) {
    std::printf("kernels: simd, target %s, %d thread%s (FOVEA_FORCE_KERNEL=ref for the references)\n",
                pipeline::simdTargetName(pipeline::activeSimdTarget()), options_.threads,
                options_.threads == 1 ? "" : "s");
  } else {
    std::printf("kernels: ref (scalar references, one thread)\n");
  }
}

Exit Run::startStream() {
  const StreamConfig& config = *options_.stream;
  Result<std::unique_ptr<Streamer>> created = Streamer::create(config, max_points_);
  if (!created) return startFailure(created.status());
  streamer_ = std::move(created.value());
  gaze_policy_.emplace(config.gaze, options_.foveation);
  if (!streamer_->notice().empty()) std::fprintf(stderr, "fovead run: *** %s ***\n", streamer_->notice().c_str());
  const net::RobotLinkConfig& link = config.link;
  std::printf("streaming: listening on %s (%s), budget up to %.2f MB/s, MTU up to %u, gaze timeout %lld ms, "
              "fallback voxel %g m\n",
              streamer_->localEndpoint().toString().c_str(), link.insecure ? "INSECURE" : "authenticated",
              static_cast<double>(link.max_budget_bytes_per_s) / 1e6, link.max_mtu_bytes,
              static_cast<long long>(config.gaze.timeout_ns / 1'000'000), config.gaze.fallback_voxel_m);
  std::fflush(stdout);
  return std::nullopt;
}

void Run::printFrameHeader() const {
  if (options_.every > 0 && streamer_) {
    std::printf("%5s %-22s %8s %6s %6s %5s %8s | ms: %7s %8s %7s %7s\n", "frame", "gaze", "out", "chunks", "sent",
                "cut", "kB", "capture", "foveate", "encode", "send");
  } else if (options_.every > 0) {
    std::printf("%5s %7s %7s %-8s", "frame", "valid", "d0[m]", "d0 from");
    for (int r = 0; r < model_.regionCount(); ++r) std::printf(" %15.15s", model_.regionName(r));
    std::printf(" %8s %6s | ms: %7s %8s %8s %8s %7s\n", "out", "kept", "capture", "backproj", "partition", "fixation",
                "sample");
  }
}

Exit Run::loop() {
  const std::size_t n = options_.frames;  // 0: until stopped
  const int64_t run_start_ns = monotonicNs();
  if (options_.duration_s > 0) run_end_ns_ = run_start_ns + static_cast<int64_t>(options_.duration_s * 1e9);
  status_.next_ns = run_start_ns + 1'000'000'000;
  for (std::size_t i = 0; n == 0 || i < n; ++i) {
    // The frame slot starts before acquire: a camera that paces itself (realtime)
    // waits inside acquire, and the idle below must not push the next acquire late.
    const int64_t slot_start_ns = monotonicNs();
    if (g_stop != 0 || slot_start_ns >= run_end_ns_) break;
    ++stats_.attempted_frames;
    FrameFigures f;
    if (!capture(i, slot_start_ns, f) || !backproject(i, f)) continue;
    if (!chooseGaze(f)) return kExitFailure;
    if (!foveate(i, f)) continue;
    if (streamer_) send(i, slot_start_ns, f);
    record(f);
    if (options_.every > 0 && i % static_cast<std::size_t>(options_.every) == 0) printFrame(f);
    if (streamer_) {
      sendStatusIfDue();
      // Gaze keeps coming in while the next frame is awaited; frames go out at the camera's rate.
      streamer_->idleUntil(std::min(slot_start_ns + period_ns_, run_end_ns_));
    }
  }
  return std::nullopt;
}

bool Run::capture(std::size_t i, int64_t slot_start_ns, FrameFigures& f) {
  const auto t0 = std::chrono::steady_clock::now();
  if (Status s = camera_.acquire(frame_, std::chrono::seconds(2)); !s) {
    std::fprintf(stderr, "frame %zu: capture: %s\n", i, s.toString().c_str());
    ++stats_.failed_frames;
    // A camera that fails at once (unplugged) must not spin the loop: wait out the
    // frame slot (still serving the link). The service's runtime retries with backoff.
    if (streamer_) {
      streamer_->idleUntil(std::min(slot_start_ns + period_ns_, run_end_ns_));
    } else {
      std::this_thread::sleep_until(std::chrono::steady_clock::now() +
                                    std::chrono::nanoseconds(std::max<int64_t>(0, slot_start_ns + period_ns_ - monotonicNs())));
    }
    return false;
  }
  pose_fresh_ = pose_source_.apply(frame_);
  if (!pose_fresh_) ++stats_.stale_pose_frames;
  f.capture_ms = msSince(t0);
  f.capture_ns = monotonicNs();
  return true;
}

bool Run::backproject(std::size_t i, FrameFigures& f) {
  const auto t0 = std::chrono::steady_clock::now();
  pipeline::BackprojectCounts counts;
  // With --pose track... the map's tracker poses the frame first.
  if (Status s = stage_.backproject(frame_, counts, pose_fresh_); !s) {
    std::fprintf(stderr, "frame %zu: backproject: %s\n", i, s.toString().c_str());
    ++stats_.failed_frames;
    return false;
  }
  f.backproject_ms = msSince(t0);
  if (stage_.map() != nullptr && stage_.mapFigures().fused()) {
    stats_.fuse_ms.add(static_cast<double>(stage_.mapFigures().fuse.fuse_ns) * 1e-6);
  }
  return true;
}

// The run's gaze, or with --listen the operator's (or the fallback); false when
// the foveation for it cannot be set (the run ends).
bool Run::chooseGaze(FrameFigures& f) {
  f.gaze = gazeForFrame(gaze_choice_, frame_.T_world_cam);
  f.source = GazeSource::kOperator;
  if (!streamer_) return true;
  streamer_->poll();
  OperatorGaze operator_gaze;
  (void)streamer_->operatorGaze(operator_gaze);
  const GazePolicy::Decision decision = gaze_policy_->decide(operator_gaze, f.capture_ns, frame_.T_world_cam);
  if (decision.changed) {
    std::printf("gaze: %s\n", std::string(gazeSourceName(decision.source)).c_str());
    std::fflush(stdout);
  }
  if (Status s = stage_.use(decision.foveation); !s) {
    std::fprintf(stderr, "fovead run: foveation config: %s\n", s.message().c_str());
    return false;
  }
  f.gaze = decision.gaze;
  f.source = decision.source;
  return true;
}

bool Run::foveate(std::size_t i, FrameFigures& f) {
  if (Status s = stage_.foveate(f.gaze, out_, f.stats); !s) {
    std::fprintf(stderr, "frame %zu: foveate: %s\n", i, s.toString().c_str());
    ++stats_.failed_frames;
    return false;
  }
  if (stage_.map() != nullptr) stats_.eye_ms.add(static_cast<double>(stage_.mapFigures().eye.ns) * 1e-6);
  return true;
}

void Run::send(std::size_t i, int64_t slot_start_ns, FrameFigures& f) {
  // A frame must be out before the next one is due; what is not goes unsent.
  const int64_t deadline_ns = slot_start_ns + period_ns_ - std::min<int64_t>(period_ns_ / 10, 2'000'000);
  Result<FrameSendReport> result = streamer_->sendFrame(out_, f.stats, static_cast<uint32_t>(frame_.sequence),
                                                        f.capture_ns, deadline_ns, period_ns_);
  if (!result) {
    std::fprintf(stderr, "frame %zu: send: %s\n", i, result.status().toString().c_str());
  } else {
    f.sent = result.value();
  }
  if (f.sent.had_session) {
    if (status_.count < status_.latency_ms.size()) {
      status_.latency_ms[status_.count++] = static_cast<double>(monotonicNs() - f.capture_ns) * 1e-6;
    }
    ++stats_.frames_streamed;
    stats_.encode_ms.add(static_cast<double>(f.sent.encode_ns) * 1e-6);
    stats_.send_ms.add(static_cast<double>(f.sent.send_ns) * 1e-6);
  }
  if (f.source != GazeSource::kOperator) ++stats_.fallback_frames;
  if (keep_streamed_ && f.sent.completed) {
    copyFoveated(out_, last_streamed_.cloud);
    last_streamed_.id = frame_.sequence;
    last_streamed_.regions = f.stats.region_count;
    for (int r = 0; r < f.stats.region_count; ++r) last_streamed_.voxel_m[r] = f.stats.regions[r].voxel_size_m;
  }
}

void Run::record(const FrameFigures& f) {
  const pipeline::FoveationStats& stats = f.stats;
  last_frame_id_ = frame_.sequence;
  last_gaze_ = f.gaze;
  last_source_ = f.source;
  stats_.capture_ms.add(f.capture_ms);
  stats_.backproject_ms.add(f.backproject_ms);
  stats_.partition_ms.add(static_cast<double>(stats.partition_ns) * 1e-6);
  stats_.fixation_ms.add(static_cast<double>(stats.fixation_ns) * 1e-6);
  stats_.sample_ms.add(static_cast<double>(stats.sample_ns) * 1e-6);
  stats_.foveate_ms.add(static_cast<double>(stats.partition_ns + stats.fixation_ns + stats.sample_ns) * 1e-6 +
                        f.backproject_ms);
  stats_.points_in.add(stats.points_in);
  stats_.points_out.add(stats.points_out);
  stats_.d0_m.add(stats.fixation.d0_m);
  if (f.source == GazeSource::kOperator) stats_.totals.add(stats);
}

void Run::printFrame(const FrameFigures& f) const {
  const pipeline::FoveationStats& stats = f.stats;
  if (streamer_) {
    const FrameSendReport& sent = f.sent;
    std::printf("%5llu %-22s %8u %6u %6u %5u %8.1f | ms: %7.2f %8.2f %7.2f %7.2f\n",
                static_cast<unsigned long long>(frame_.sequence),
                sent.had_session ? std::string(gazeSourceName(f.source)).c_str() : "(no operator)", stats.points_out,
                sent.chunks, sent.chunks_sent, sent.chunks_cut, static_cast<double>(sent.bytes_sent) / 1e3,
                f.capture_ms,
                f.backproject_ms + static_cast<double>(stats.partition_ns + stats.fixation_ns + stats.sample_ns) * 1e-6,
                static_cast<double>(sent.encode_ns) * 1e-6, static_cast<double>(sent.send_ns) * 1e-6);
    std::fflush(stdout);
    return;
  }
  std::printf("%5llu %7u %7.3f %-8s", static_cast<unsigned long long>(frame_.sequence), stats.points_in,
              stats.fixation.d0_m, std::string(pipeline::fixationSourceName(stats.fixation.source)).c_str());
  for (int r = 0; r < model_.regionCount(); ++r) {
    std::printf(" %7u>%-7u", stats.regions[r].points_in, stats.regions[r].points_out);
  }
  std::printf(" %8u %5.1f%% | ms: %7.2f %8.2f %8.2f %8.2f %7.2f\n", stats.points_out,
              stats.points_in ? 100.0 * stats.points_out / stats.points_in : 0.0, f.capture_ms, f.backproject_ms,
              stats.partition_ns * 1e-6, stats.fixation_ns * 1e-6, stats.sample_ns * 1e-6);
}

void Run::sendStatusIfDue() {
  const int64_t now = monotonicNs();
  if (now < status_.next_ns) return;
  net::StatusReport status =
      streamer_->statusReport(stats_.attempted_frames, stats_.frames_streamed, stats_.failed_frames, now);
  if (status_.count > 0) {
    const std::span<double> window(status_.latency_ms.data(), status_.count);
    status.latency_p50_ns = static_cast<int64_t>(pipeline::nearestRankQuantile(window, 0.5) * 1e6);
    status.latency_p99_ns = static_cast<int64_t>(pipeline::nearestRankQuantile(window, 0.99) * 1e6);
    status_.count = 0;
  }
  streamer_->sendStatus(status);
  status_.next_ns += 1'000'000'000 * ((now - status_.next_ns) / 1'000'000'000 + 1);
}

int Run::finish() {
  camera_.stop();
  if (g_stop != 0) {
    std::printf("\nstopped by a signal after %llu frames\n", static_cast<unsigned long long>(stats_.attempted_frames));
  }
  printSummary();
  if (Exit e = saveLastFrame()) return *e;
  if (streamer_) printStreamSummary();
  return stats_.failed_frames == stats_.attempted_frames && stats_.attempted_frames > 0 ? kExitFailure : kExitOk;
}

void Run::printSummary() const {
  const RunStats& s = stats_;
  std::printf("\nsummary: %zu frames foveated, %llu failed; per frame on average:\n", s.points_in.count(),
              static_cast<unsigned long long>(s.failed_frames));
  if (pose_source_.config().kind == hal::PoseSourceConfig::Kind::kSocket) {
    const hal::PoseCounters pc = pose_source_.counters();
    std::printf("pose: %llu frames with a stale pose (kept with the nearest pose); %llu poses received, %llu malformed, "
                "%llu out of order, %llu dropped from the ring\n",
                static_cast<unsigned long long>(s.stale_pose_frames), static_cast<unsigned long long>(pc.received),
                static_cast<unsigned long long>(pc.malformed), static_cast<unsigned long long>(pc.out_of_order),
                static_cast<unsigned long long>(pc.overwritten));
  }
  printRegionTable(stdout, model_, s.totals);
  std::printf("  d0 median %.3f m; valid points median %.0f, output median %.0f (%.2f%%)\n", s.d0_m.median(),
              s.points_in.median(), s.points_out.median(),
              s.points_in.median() > 0 ? 100.0 * s.points_out.median() / s.points_in.median() : 0.0);
  std::printf("time per frame [ms] over %zu frames:  %8s %8s %8s\n", s.capture_ms.count(), "median", "p90", "max");
  auto row = [](const char* name, const Samples& samples) {
    std::printf("  %-30s %8.2f %8.2f %8.2f\n", name, samples.median(), samples.quantile(0.9), samples.max());
  };
  row("capture (camera acquire)", s.capture_ms);
  row("back-projection", s.backproject_ms);
  row("partition", s.partition_ms);
  row("fixation d0", s.fixation_ms);
  row("voxel sampling", s.sample_ms);
  row("foveation total (no capture)", s.foveate_ms);
  if (const pipeline::map::SurfelMap* map = stage_.map()) {
    row("map: fusion (in back-projection)", s.fuse_ms);
    row("map: the eye's view (in total)", s.eye_ms);
    const pipeline::map::SurfelMapCounters& c = map->counters();
    const MapFrameFigures& last = stage_.mapFigures();
    std::printf("map: %zu surfels (%llu evicted); %llu frames fused, refused %llu without a pose, %llu for another "
                "reason; last frame: %u of the frame's points unexplained, %u map surfels sent, %u hidden from the eye\n",
                map->size(), static_cast<unsigned long long>(c.evicted), static_cast<unsigned long long>(c.frames_fused),
                static_cast<unsigned long long>(c.refused_no_pose),
                static_cast<unsigned long long>(c.refused() - c.refused_no_pose), last.frame_points, last.eye.appended,
                last.eye.hidden);
    if (stage_.hasFusionBudget()) {
      std::printf(
          "map: %llu frames left unfused by map.fuse_budget_ms (sent without what the last fused view explained)\n",
          static_cast<unsigned long long>(stage_.fusionSkipped()));
    }
  }
}

// --save-ply: the last foveated frame, or with --listen the last one streamed whole.
Exit Run::saveLastFrame() const {
  if (!options_.save_ply) return std::nullopt;
  const std::string& path = *options_.save_ply;
  const pipeline::FoveatedCloud& cloud = keep_streamed_ ? last_streamed_.cloud : out_;
  if (cloud.size() == 0) return std::nullopt;
  io::PlyWriteOptions ply;
  ply.double_coords = true;
  if (Status s = io::writePly(path, cloud.points, cloud.region.data(), ply); !s) {
    std::fprintf(stderr, "fovead run: %s\n", s.message().c_str());
    return kExitFailure;
  }
  if (!keep_streamed_) {
    std::printf("wrote the last foveated frame (%zu points) to %s\n", cloud.size(), path.c_str());
    return std::nullopt;
  }
  std::printf("wrote the last streamed frame %llu (%zu points) to %s; voxel sizes [m]:",
              static_cast<unsigned long long>(last_streamed_.id), cloud.size(), path.c_str());
  for (int r = 0; r < last_streamed_.regions; ++r) std::printf(" %.9g", last_streamed_.voxel_m[r]);
  std::printf("\n");
  return std::nullopt;
}

void Run::printStreamSummary() const {
  const net::UplinkCounters& up = streamer_->uplinkCounters();
  const net::RobotLinkCounters& lc = streamer_->link().counters();
  std::printf("stream: %llu frames streamed (%llu on the fallback gaze), %llu sessions\n",
              static_cast<unsigned long long>(stats_.frames_streamed),
              static_cast<unsigned long long>(stats_.fallback_frames),
              static_cast<unsigned long long>(lc.sessions_accepted));
  std::printf("  uplink: %llu chunks sent, %llu cut for the budget, %llu superseded, %.2f MB sent\n",
              static_cast<unsigned long long>(up.chunks_sent), static_cast<unsigned long long>(up.chunks_cut),
              static_cast<unsigned long long>(up.chunks_superseded), static_cast<double>(up.bytes_sent) / 1e6);
  std::printf("  link: %llu datagrams in, %llu dropped, %llu refusals, %llu gaze samples accepted\n",
              static_cast<unsigned long long>(lc.datagrams_received), static_cast<unsigned long long>(lc.dropped.total()),
              static_cast<unsigned long long>(lc.refusals), static_cast<unsigned long long>(lc.gaze_accepted));
  for (std::size_t r = 0; r < net::kDropReasonCount; ++r) {
    if (lc.dropped.by_reason[r] > 0) {
      std::printf("    dropped %-20s %llu\n", net::dropReasonName(static_cast<net::DropReason>(r)),
                  static_cast<unsigned long long>(lc.dropped.by_reason[r]));
    }
  }
  if (stats_.encode_ms.count() > 0) {
    std::printf("  encode median %.2f ms, send median %.2f ms per frame\n", stats_.encode_ms.median(),
                stats_.send_ms.median());
  }
  // The last frame's gaze, for comparison with what the operator sent.
  std::printf("last frame %llu: gaze %s origin %.6f,%.6f,%.6f direction %.6f,%.6f,%.6f\n",
              static_cast<unsigned long long>(last_frame_id_), std::string(gazeSourceName(last_source_)).c_str(),
              last_gaze_.origin_m.x(), last_gaze_.origin_m.y(), last_gaze_.origin_m.z(), last_gaze_.direction.x(),
              last_gaze_.direction.y(), last_gaze_.direction.z());
}

}  // namespace

int runCommand(int argc, char** argv) {
  Result<Args> args = Args::parse(argc, argv, 2, runFlags(), {"--help", "-h", "--insecure"});
  if (!args) return usage(args.status());
  if (args->has("--help") || args->has("-h")) {
    std::printf("%s%s\ncameras:\n%s\n", kRunHelp, foveationFlagsHelp().c_str(), cameraSpecHelp().c_str());
    return kExitOk;
  }
  Result<RunOptions> options = runOptionsFromArgs(args.value());
  if (!options) return usage(options.status());
  OpenedCamera camera;
  if (Exit e = openCamera(options->camera, camera)) return *e;
  Result<GazeChoice> gaze_choice = gazeChoiceForRun(args.value(), options.value(), camera.camera->info());
  if (!gaze_choice) return usage(gaze_choice.status());
  // Start-up: every buffer sized from the camera's resolution.
  const hal::CameraInfo& info = camera.camera->info();
  const std::size_t max_points = static_cast<std::size_t>(info.intrinsics.width) * info.intrinsics.height;
  const fovea::KernelSet kernels = fovea::defaultKernelSet();
  MapSettings map_settings = options->map;
  map_settings.tracking = poseTracking(options->camera);
  if (map_settings.tracking != pipeline::map::PoseTracking::kOff && map_settings.source != FoveationSource::kMap) {
    return usage(invalidArgument("--pose track... tracks the camera against the map: add --source map"));
  }
  Result<FrameFoveator> stage =
      FrameFoveator::create({max_points, max_points, kernels, options->threads}, options->foveation, options->range,
                            map_settings, info.intrinsics.width, info.intrinsics.height);
  if (!stage) return usage(stage.status());
  Run run(options.value(), camera, gaze_choice.value(), stage.value(), kernels);
  if (Exit e = run.start()) return *e;
  if (Exit e = run.loop()) return *e;
  return run.finish();
}

}  // namespace fovea::firmware
