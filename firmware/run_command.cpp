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
    "                  [--calibration FILE] [--pose none|fixed:X,Y,Z[,QX,QY,QZ,QW]|socket:PATH]\n"
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
    "                           socket:PATH (the robot's poses as datagrams; --pose-max-age-ms MS, default 100)\n"
    "  --threads N              threads per frame for back-projection and partition (default 1, up to 64;\n"
    "                           SIMD kernels only; the output does not depend on it)\n"
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
  std::copy_n(from.weight.begin(), n, to.weight.begin());
}

// [camera] settings from --camera, --calibration, --pose and --pose-max-age-ms.
Result<CameraSettings> cameraSettingsFromArgs(const Args& args) {
  CameraSettings settings;
  settings.spec = args.getOr("--camera", "mock:living-room");
  settings.calibration_file = args.getOr("--calibration", "");
  const std::string pose = args.getOr("--pose", "none");
  if (pose == "none") {
    settings.pose.source = "none";
  } else if (pose.rfind("fixed:", 0) == 0) {
    Result<std::vector<double>> values = parseDoubleList("--pose fixed:", pose.substr(6));
    if (!values) return values.status();
    if (values->size() != 3 && values->size() != 7) {
      return Result<CameraSettings>(ErrorCode::kInvalidArgument, "--pose fixed: expects X,Y,Z or X,Y,Z,QX,QY,QZ,QW");
    }
    settings.pose.source = "fixed";
    settings.pose.translation_m.assign(values->begin(), values->begin() + 3);
    if (values->size() == 7) settings.pose.rotation_xyzw.assign(values->begin() + 3, values->end());
  } else if (pose.rfind("socket:", 0) == 0 && pose.size() > 7) {
    settings.pose.source = "socket";
    settings.pose.socket = pose.substr(7);
  } else {
    return Result<CameraSettings>(ErrorCode::kInvalidArgument,
                                  "--pose: '" + pose + "' is not none, fixed:X,Y,Z[,QX,QY,QZ,QW] or socket:PATH");
  }
  if (const std::string* v = args.get("--pose-max-age-ms")) {
    Result<long> ms = parseInteger("--pose-max-age-ms", *v, 1, 60'000);
    if (!ms) return ms.status();
    settings.pose.max_age_ms = ms.value();
  }
  if (Status s = checkCameraGeometry(settings); !s) return s;
  return settings;
}

// SIGINT/SIGTERM end the run loop cleanly (the link says Bye on the way out).
volatile std::sig_atomic_t g_stop = 0;
extern "C" void onStopSignal(int) { g_stop = 1; }


}  // namespace

int runCommand(int argc, char** argv) {
  std::vector<std::string> flags = {"--camera", "--frames", "--duration", "--gaze", "--gaze-origin", "--gaze-dir",
                                    "--depth-min", "--depth-max", "--every", "--save-ply", "--threads",
                                    "--calibration", "--pose", "--pose-max-age-ms"};
  flags.insert(flags.end(), kFoveationFlags.begin(), kFoveationFlags.end());
  flags.insert(flags.end(), kStreamFlags.begin(), kStreamFlags.end());
  Result<Args> args = Args::parse(argc, argv, 2, flags, {"--help", "-h", "--insecure"});
  if (!args) {
    std::fprintf(stderr, "fovead run: %s\n", args.status().message().c_str());
    return kExitUsage;
  }
  if (args->has("--help") || args->has("-h")) {
    std::printf("%s%s\ncameras:\n%s\n", kRunHelp, foveationFlagsHelp().c_str(), hal::cameraSpecHelp().c_str());
    return kExitOk;
  }
  auto usage = [](const Status& s) {
    std::fprintf(stderr, "fovead run: %s\n", s.message().c_str());
    return kExitUsage;
  };
  Result<pipeline::FoveationConfig> config = foveationConfigFromArgs(args.value());
  if (!config) return usage(config.status());
  Result<std::optional<StreamConfig>> stream_config = streamConfigFromArgs(args.value());
  if (!stream_config) return usage(stream_config.status());
  const bool streaming = stream_config->has_value();
  Result<long> frames = parseInteger("--frames", args->getOr("--frames", streaming ? "0" : "30"), streaming ? 0 : 1,
                                     100000000);
  if (!frames) return usage(frames.status());
  Result<double> duration = durationFromArgs(args.value());
  if (!duration) return usage(duration.status());
  const double duration_s = duration.value();
  Result<long> every = parseInteger("--every", args->getOr("--every", "1"), 0, 100000000);
  if (!every) return usage(every.status());
  Result<long> threads = parseInteger("--threads", args->getOr("--threads", "1"), 1, 64);
  if (!threads) return usage(threads.status());
  pipeline::DepthRange range;
  if (const std::string* v = args->get("--depth-min")) {
    Result<double> d = parseDouble("--depth-min", *v);
    if (!d) return usage(d.status());
    range.min_m = d.value();
  }
  if (const std::string* v = args->get("--depth-max")) {
    Result<double> d = parseDouble("--depth-max", *v);
    if (!d) return usage(d.status());
    range.max_m = d.value();
  }
  if (Status s = range.validate(); !s) return usage(s);

  Result<CameraSettings> camera_settings = cameraSettingsFromArgs(args.value());
  if (!camera_settings) return usage(camera_settings.status());
  Result<std::unique_ptr<hal::Camera>> created = hal::createCamera(camera_settings->spec);
  if (!created) return usage(created.status());
  hal::Camera& camera = *created.value();
  // The service's own set-up (firmware/camera_setup.h): calibration before open, then the pose source.
  Result<std::string> calibrated = applyCameraCalibration(camera, camera_settings.value());
  if (!calibrated) return usage(calibrated.status());
  Result<std::unique_ptr<hal::PoseSource>> pose_source = createPoseSource(camera_settings.value());
  if (!pose_source) {
    std::fprintf(stderr, "fovead run: %s\n", pose_source.status().message().c_str());
    return pose_source.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
  }
  if (Status s = camera.open(); !s) {
    std::fprintf(stderr, "fovead run: camera %s: %s\n", camera.info().name.c_str(), s.message().c_str());
    return kExitFailure;
  }
  const hal::CameraInfo& info = camera.info();
  if (streaming && (args->has("--gaze") || args->has("--gaze-origin") || args->has("--gaze-dir"))) {
    return usage({ErrorCode::kInvalidArgument, "--gaze: not with --listen (the operator sends the gaze)"});
  }
  Result<GazeChoice> gaze_choice = gazeFromArgs(args.value(), info);
  if (!gaze_choice) return usage(gaze_choice.status());

  // Start-up: every buffer sized from the camera's resolution.
  const int width = info.intrinsics.width, height = info.intrinsics.height;
  const std::size_t max_points = static_cast<std::size_t>(width) * height;
  hal::RgbdFrame frame(width, height);
  pipeline::FoveatedCloud out(max_points);
  const fovea::KernelSet kernels = fovea::defaultKernelSet();
  const int thread_count = static_cast<int>(threads.value());
  Result<FrameFoveator> stage =
      FrameFoveator::create({max_points, max_points, kernels, thread_count}, config.value(), range);
  if (!stage) return usage(stage.status());
  if (Status s = camera.start(); !s) {
    std::fprintf(stderr, "fovead run: camera %s: %s\n", info.name.c_str(), s.message().c_str());
    return kExitFailure;
  }

  std::printf("fovead run: camera %s %dx%d @ %g fps, depth %g..%g m\n", info.name.c_str(), width, height, info.fps,
              range.min_m, range.max_m);
  std::printf("foveation: %s\n", describeFoveation(config.value()).c_str());
  if (!calibrated->empty()) std::printf("camera: %s\n", calibrated->c_str());
  std::printf("pose: %s\n", pose_source.value()->describe().c_str());
  if (kernels == fovea::KernelSet::kSimd) {
    std::printf("kernels: simd, target %s, %d thread%s (FOVEA_FORCE_KERNEL=ref for the references)\n",
                pipeline::simdTargetName(pipeline::activeSimdTarget()), thread_count, thread_count == 1 ? "" : "s");
  } else {
    std::printf("kernels: ref (scalar references, one thread)\n");
  }
  std::unique_ptr<Streamer> streamer;
  std::optional<GazePolicy> gaze_policy;  // the operator's gaze while fresh, else the fallback
  if (streaming) {
    Result<std::unique_ptr<Streamer>> created_streamer = Streamer::create(**stream_config, max_points);
    if (!created_streamer) {
      std::fprintf(stderr, "fovead run: %s\n", created_streamer.status().message().c_str());
      return created_streamer.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
    }
    streamer = std::move(created_streamer.value());
    gaze_policy.emplace((*stream_config)->gaze, config.value());
    if (!streamer->notice().empty()) std::fprintf(stderr, "fovead run: *** %s ***\n", streamer->notice().c_str());
    const net::RobotLinkConfig& link = (*stream_config)->link;
    std::printf("streaming: listening on %s (%s), budget up to %.2f MB/s, MTU up to %u, gaze timeout %lld ms, "
                "fallback voxel %g m\n",
                streamer->localEndpoint().toString().c_str(), link.insecure ? "INSECURE" : "authenticated",
                static_cast<double>(link.max_budget_bytes_per_s) / 1e6, link.max_mtu_bytes,
                static_cast<long long>((*stream_config)->gaze.timeout_ns / 1'000'000), (*stream_config)->gaze.fallback_voxel_m);
    std::fflush(stdout);
  }
  std::signal(SIGINT, onStopSignal);
  std::signal(SIGTERM, onStopSignal);

  // The run's own region model (the stream's fallback swaps the foveator's).
  const pipeline::RegionModel model = stage->foveator().model();
  if (every.value() > 0 && streaming) {
    std::printf("%5s %-22s %8s %6s %6s %5s %8s | ms: %7s %8s %7s %7s\n", "frame", "gaze", "out", "chunks", "sent",
                "cut", "kB", "capture", "foveate", "encode", "send");
  } else if (every.value() > 0) {
    std::printf("%5s %7s %7s %-8s", "frame", "valid", "d0[m]", "d0 from");
    for (int r = 0; r < model.regionCount(); ++r) std::printf(" %15.15s", model.regionName(r));
    std::printf(" %8s %6s | ms: %7s %8s %8s %8s %7s\n", "out", "kept", "capture", "backproj", "partition", "fixation",
                "sample");
  }

  const auto n = static_cast<std::size_t>(frames.value());  // 0: until stopped
  // Statistics keep the first sample_capacity frames of an endless run.
  const std::size_t sample_capacity = n > 0 ? n : 100000;
  Samples capture_ms(sample_capacity), backproject_ms(sample_capacity), partition_ms(sample_capacity),
      fixation_ms(sample_capacity), sample_ms(sample_capacity), foveate_ms(sample_capacity);
  Samples points_in(sample_capacity), points_out(sample_capacity), d0_m(sample_capacity);
  Samples encode_ms(sample_capacity), send_ms(sample_capacity);
  RegionTotals totals;
  uint64_t failed_frames = 0, attempted_frames = 0, fallback_frames = 0, frames_streamed = 0, stale_pose_frames = 0;
  const int64_t period_ns = info.fps > 0 ? static_cast<int64_t>(1e9 / info.fps) : 33'333'333;
  const int64_t run_start_ns = monotonicNs();
  const int64_t run_end_ns = duration_s > 0 ? run_start_ns + static_cast<int64_t>(duration_s * 1e9) : INT64_MAX;
  int64_t next_status_ns = run_start_ns + 1'000'000'000;
  // Capture-to-sent latency of the frames of the current status second (fixed room).
  std::array<double, 256> status_latency_ms{};
  std::size_t status_latency_count = 0;
  uint64_t last_frame_id = 0;
  // With --listen --save-ply: a copy of the last frame that went out whole.
  const bool keep_streamed = streaming && args->has("--save-ply");
  pipeline::FoveatedCloud last_streamed(keep_streamed ? max_points : 0);
  uint64_t last_streamed_id = 0;
  std::array<double, pipeline::kMaxRegions> last_streamed_voxel_m{};
  int last_streamed_regions = 0;
  pipeline::Gaze last_gaze;
  GazeSource last_source = GazeSource::kOperator;
  for (std::size_t i = 0; n == 0 || i < n; ++i) {
    // The frame slot starts before acquire: a camera that paces itself (realtime)
    // waits inside acquire, and the idle below must not push the next acquire late.
    const int64_t slot_start_ns = monotonicNs();
    if (g_stop != 0 || slot_start_ns >= run_end_ns) break;
    ++attempted_frames;
    auto t0 = std::chrono::steady_clock::now();
    if (Status s = camera.acquire(frame, std::chrono::seconds(2)); !s) {
      std::fprintf(stderr, "frame %zu: capture: %s\n", i, s.toString().c_str());
      ++failed_frames;
      // A camera that fails at once (unplugged) must not spin the loop: wait out the
      // frame slot (still serving the link). The service's runtime retries with backoff.
      if (streamer) {
        streamer->idleUntil(std::min(slot_start_ns + period_ns, run_end_ns));
      } else {
        std::this_thread::sleep_until(std::chrono::steady_clock::now() + std::chrono::nanoseconds(std::max<int64_t>(
                                                                             0, slot_start_ns + period_ns - monotonicNs())));
      }
      continue;
    }
    if (!pose_source.value()->apply(frame)) ++stale_pose_frames;
    const double t_capture = msSince(t0);
    const int64_t capture_ns = monotonicNs();
    t0 = std::chrono::steady_clock::now();
    pipeline::BackprojectCounts bc;
    if (Status s = stage->backproject(frame, bc); !s) {
      std::fprintf(stderr, "frame %zu: backproject: %s\n", i, s.toString().c_str());
      ++failed_frames;
      continue;
    }
    const double t_backproject = msSince(t0);
    pipeline::Gaze gaze = gazeForFrame(gaze_choice.value(), frame.T_world_cam);
    GazeSource source = GazeSource::kOperator;
    if (streamer) {
      streamer->poll();
      OperatorGaze operator_gaze;
      (void)streamer->operatorGaze(operator_gaze);
      const GazePolicy::Decision decision = gaze_policy->decide(operator_gaze, capture_ns, frame.T_world_cam);
      if (decision.changed) {
        std::printf("gaze: %s\n", std::string(gazeSourceName(decision.source)).c_str());
        std::fflush(stdout);
      }
      if (Status s = stage->use(decision.foveation); !s) {
        std::fprintf(stderr, "fovead run: foveation config: %s\n", s.message().c_str());
        return kExitFailure;
      }
      gaze = decision.gaze;
      source = decision.source;
    }
    pipeline::FoveationStats stats;
    if (Status s = stage->foveate(gaze, out, stats); !s) {
      std::fprintf(stderr, "frame %zu: foveate: %s\n", i, s.toString().c_str());
      ++failed_frames;
      continue;
    }
    FrameSendReport sent;
    if (streamer) {
      // A frame must be out before the next one is due; what is not goes unsent.
      const int64_t deadline_ns = slot_start_ns + period_ns - std::min<int64_t>(period_ns / 10, 2'000'000);
      Result<FrameSendReport> result =
          streamer->sendFrame(out, stats, static_cast<uint32_t>(frame.sequence), capture_ns, deadline_ns, period_ns);
      if (!result) {
        std::fprintf(stderr, "frame %zu: send: %s\n", i, result.status().toString().c_str());
      } else {
        sent = result.value();
      }
      if (sent.had_session) {
        if (status_latency_count < status_latency_ms.size()) {
          status_latency_ms[status_latency_count++] = static_cast<double>(monotonicNs() - capture_ns) * 1e-6;
        }
        ++frames_streamed;
        encode_ms.add(static_cast<double>(sent.encode_ns) * 1e-6);
        send_ms.add(static_cast<double>(sent.send_ns) * 1e-6);
      }
      if (source != GazeSource::kOperator) ++fallback_frames;
      if (keep_streamed && sent.completed) {
        copyFoveated(out, last_streamed);
        last_streamed_id = frame.sequence;
        last_streamed_regions = stats.region_count;
        for (int r = 0; r < stats.region_count; ++r) last_streamed_voxel_m[r] = stats.regions[r].voxel_size_m;
      }
    }
    last_frame_id = frame.sequence;
    last_gaze = gaze;
    last_source = source;
    capture_ms.add(t_capture);
    backproject_ms.add(t_backproject);
    partition_ms.add(static_cast<double>(stats.partition_ns) * 1e-6);
    fixation_ms.add(static_cast<double>(stats.fixation_ns) * 1e-6);
    sample_ms.add(static_cast<double>(stats.sample_ns) * 1e-6);
    foveate_ms.add(static_cast<double>(stats.partition_ns + stats.fixation_ns + stats.sample_ns) * 1e-6 + t_backproject);
    points_in.add(stats.points_in);
    points_out.add(stats.points_out);
    d0_m.add(stats.fixation.d0_m);
    if (source == GazeSource::kOperator) totals.add(stats);
    if (streamer && every.value() > 0 && i % static_cast<std::size_t>(every.value()) == 0) {
      std::printf("%5llu %-22s %8u %6u %6u %5u %8.1f | ms: %7.2f %8.2f %7.2f %7.2f\n",
                  static_cast<unsigned long long>(frame.sequence),
                  sent.had_session ? std::string(gazeSourceName(source)).c_str() : "(no operator)", stats.points_out,
                  sent.chunks, sent.chunks_sent, sent.chunks_cut, static_cast<double>(sent.bytes_sent) / 1e3, t_capture,
                  t_backproject + static_cast<double>(stats.partition_ns + stats.fixation_ns + stats.sample_ns) * 1e-6,
                  static_cast<double>(sent.encode_ns) * 1e-6, static_cast<double>(sent.send_ns) * 1e-6);
      std::fflush(stdout);
    } else if (every.value() > 0 && i % static_cast<std::size_t>(every.value()) == 0) {
      std::printf("%5llu %7u %7.3f %-8s", static_cast<unsigned long long>(frame.sequence), stats.points_in,
                  stats.fixation.d0_m, std::string(pipeline::fixationSourceName(stats.fixation.source)).c_str());
      for (int r = 0; r < model.regionCount(); ++r) {
        std::printf(" %7u>%-7u", stats.regions[r].points_in, stats.regions[r].points_out);
      }
      std::printf(" %8u %5.1f%% | ms: %7.2f %8.2f %8.2f %8.2f %7.2f\n", stats.points_out,
                  stats.points_in ? 100.0 * stats.points_out / stats.points_in : 0.0, t_capture, t_backproject,
                  stats.partition_ns * 1e-6, stats.fixation_ns * 1e-6, stats.sample_ns * 1e-6);
    }
    if (streamer) {
      if (const int64_t now = monotonicNs(); now >= next_status_ns) {
        net::StatusReport status = streamer->statusReport(attempted_frames, frames_streamed, failed_frames, now);
        if (status_latency_count > 0) {
          const std::span<double> window(status_latency_ms.data(), status_latency_count);
          status.latency_p50_ns = static_cast<int64_t>(pipeline::nearestRankQuantile(window, 0.5) * 1e6);
          status.latency_p99_ns = static_cast<int64_t>(pipeline::nearestRankQuantile(window, 0.99) * 1e6);
          status_latency_count = 0;
        }
        streamer->sendStatus(status);
        next_status_ns += 1'000'000'000 * ((now - next_status_ns) / 1'000'000'000 + 1);
      }
      // Gaze keeps coming in while the next frame is awaited; frames go out at the camera's rate.
      streamer->idleUntil(std::min(slot_start_ns + period_ns, run_end_ns));
    }
  }
  camera.stop();
  if (g_stop != 0) std::printf("\nstopped by a signal after %llu frames\n", static_cast<unsigned long long>(attempted_frames));

  std::printf("\nsummary: %zu frames foveated, %llu failed; per frame on average:\n", points_in.count(),
              static_cast<unsigned long long>(failed_frames));
  if (pose_source.value()->config().kind == hal::PoseSourceConfig::Kind::kSocket) {
    const hal::PoseCounters pc = pose_source.value()->counters();
    std::printf("pose: %llu frames with a stale pose (kept with the nearest pose); %llu poses received, %llu malformed, "
                "%llu out of order, %llu dropped from the ring\n",
                static_cast<unsigned long long>(stale_pose_frames), static_cast<unsigned long long>(pc.received),
                static_cast<unsigned long long>(pc.malformed), static_cast<unsigned long long>(pc.out_of_order),
                static_cast<unsigned long long>(pc.overwritten));
  }
  printRegionTable(stdout, model, totals);
  std::printf("  d0 median %.3f m; valid points median %.0f, output median %.0f (%.2f%%)\n", d0_m.median(),
              points_in.median(), points_out.median(),
              points_in.median() > 0 ? 100.0 * points_out.median() / points_in.median() : 0.0);
  std::printf("time per frame [ms] over %zu frames:  %8s %8s %8s\n", capture_ms.count(), "median", "p90", "max");
  auto row = [](const char* name, const Samples& s) {
    std::printf("  %-30s %8.2f %8.2f %8.2f\n", name, s.median(), s.quantile(0.9), s.max());
  };
  row("capture (camera acquire)", capture_ms);
  row("back-projection", backproject_ms);
  row("partition", partition_ms);
  row("fixation d0", fixation_ms);
  row("voxel sampling", sample_ms);
  row("foveation total (no capture)", foveate_ms);

  if (const std::string* path = args->get("--save-ply"); path && !keep_streamed && out.size() > 0) {
    io::PlyWriteOptions options;
    options.double_coords = true;
    if (Status s = io::writePly(*path, out.points, out.region.data(), options); !s) {
      std::fprintf(stderr, "fovead run: %s\n", s.message().c_str());
      return kExitFailure;
    }
    std::printf("wrote the last foveated frame (%zu points) to %s\n", out.size(), path->c_str());
  }
  if (const std::string* path = args->get("--save-ply"); path && keep_streamed && last_streamed.size() > 0) {
    io::PlyWriteOptions options;
    options.double_coords = true;
    if (Status s = io::writePly(*path, last_streamed.points, last_streamed.region.data(), options); !s) {
      std::fprintf(stderr, "fovead run: %s\n", s.message().c_str());
      return kExitFailure;
    }
    std::printf("wrote the last streamed frame %llu (%zu points) to %s; voxel sizes [m]:",
                static_cast<unsigned long long>(last_streamed_id), last_streamed.size(), path->c_str());
    for (int r = 0; r < last_streamed_regions; ++r) std::printf(" %.9g", last_streamed_voxel_m[r]);
    std::printf("\n");
  }
  if (streamer) {
    const net::UplinkCounters& up = streamer->uplinkCounters();
    const net::RobotLinkCounters& lc = streamer->link().counters();
    std::printf("stream: %llu frames streamed (%llu on the fallback gaze), %llu sessions\n",
                static_cast<unsigned long long>(frames_streamed), static_cast<unsigned long long>(fallback_frames),
                static_cast<unsigned long long>(lc.sessions_accepted));
    std::printf("  uplink: %llu chunks sent, %llu cut for the budget, %llu superseded, %.2f MB sent\n",
                static_cast<unsigned long long>(up.chunks_sent), static_cast<unsigned long long>(up.chunks_cut),
                static_cast<unsigned long long>(up.chunks_superseded), static_cast<double>(up.bytes_sent) / 1e6);
    std::printf("  link: %llu datagrams in, %llu dropped, %llu refusals, %llu gaze samples accepted\n",
                static_cast<unsigned long long>(lc.datagrams_received),
                static_cast<unsigned long long>(lc.dropped.total()), static_cast<unsigned long long>(lc.refusals),
                static_cast<unsigned long long>(lc.gaze_accepted));
    for (std::size_t r = 0; r < net::kDropReasonCount; ++r) {
      if (lc.dropped.by_reason[r] > 0) {
        std::printf("    dropped %-20s %llu\n", net::dropReasonName(static_cast<net::DropReason>(r)),
                    static_cast<unsigned long long>(lc.dropped.by_reason[r]));
      }
    }
    if (encode_ms.count() > 0) {
      std::printf("  encode median %.2f ms, send median %.2f ms per frame\n", encode_ms.median(), send_ms.median());
    }
    // The last frame's gaze, for comparison with what the operator sent.
    std::printf("last frame %llu: gaze %s origin %.6f,%.6f,%.6f direction %.6f,%.6f,%.6f\n",
                static_cast<unsigned long long>(last_frame_id), std::string(gazeSourceName(last_source)).c_str(),
                last_gaze.origin_m.x(), last_gaze.origin_m.y(), last_gaze.origin_m.z(), last_gaze.direction.x(),
                last_gaze.direction.y(), last_gaze.direction.z());
  }
  return failed_frames == attempted_frames && attempted_frames > 0 ? kExitFailure : kExitOk;
}

}  // namespace fovea::firmware
