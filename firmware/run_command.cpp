// fovead run: camera -> back-projection -> foveation, with statistics.
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

#include "firmware/commands.h"
#include "firmware/options.h"
#include "firmware/report.h"
#include "hal/camera.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/io/ply.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/kernels/foveation_simd.h"

namespace fovea::firmware {

namespace {

const char* kRunHelp =
    "usage: fovead run [--camera SPEC] [--frames N] [--gaze MODE | --gaze-origin X,Y,Z --gaze-dir X,Y,Z]\n"
    "                  [--preset F1|F2|F3|FREF] [--m SLOPE] [--far-ecc DEG] [--fixation MODE]\n"
    "                  [--depth-min M] [--depth-max M] [--every N] [--save-ply FILE] [--threads N]\n"
    "\n"
    "Runs the foveation pipeline on a camera and prints, per frame and for the run,\n"
    "the points per region in and out, the voxel size per region, d0, and the time\n"
    "per stage.\n"
    "\n"
    "  --camera SPEC            camera backend (default mock:living-room), see below\n"
    "  --frames N               frames to process (default 30)\n"
    "  --gaze MODE              scene-centre: from the camera towards the scene's focus point (default\n"
    "                           when the camera has one); axis: along the optical axis;\n"
    "                           target:X,Y,Z: from the camera towards a world point\n"
    "  --gaze-origin X,Y,Z      eye position in world coordinates (metres), with --gaze-dir\n"
    "  --gaze-dir X,Y,Z         gaze direction in world coordinates (any length > 0)\n"
    "  --depth-min M, --depth-max M   valid depth range (default 0.1 .. 10 m)\n"
    "  --every N                print every Nth frame (default 1; 0: summary only)\n"
    "  --save-ply FILE          write the last foveated frame (world coordinates, region per point)\n"
    "  --threads N              threads per frame for back-projection and partition (default 1, up to 64;\n"
    "                           SIMD kernels only; the output does not depend on it)\n"
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

}  // namespace

int runCommand(int argc, char** argv) {
  std::vector<std::string> flags = {"--camera", "--frames", "--gaze", "--gaze-origin", "--gaze-dir",
                                    "--depth-min", "--depth-max", "--every", "--save-ply", "--threads"};
  flags.insert(flags.end(), kFoveationFlags.begin(), kFoveationFlags.end());
  Result<Args> args = Args::parse(argc, argv, 2, flags, {"--help", "-h"});
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
  Result<long> frames = parseInteger("--frames", args->getOr("--frames", "30"), 1, 100000000);
  if (!frames) return usage(frames.status());
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

  Result<std::unique_ptr<hal::Camera>> created = hal::createCamera(args->getOr("--camera", "mock:living-room"));
  if (!created) return usage(created.status());
  hal::Camera& camera = *created.value();
  if (Status s = camera.open(); !s) {
    std::fprintf(stderr, "fovead run: camera %s: %s\n", camera.info().name.c_str(), s.message().c_str());
    return kExitFailure;
  }
  const hal::CameraInfo& info = camera.info();
  Result<GazeChoice> gaze_choice = gazeFromArgs(args.value(), info);
  if (!gaze_choice) return usage(gaze_choice.status());

  // Start-up: every buffer sized from the camera's resolution.
  const int width = info.intrinsics.width, height = info.intrinsics.height;
  const std::size_t max_points = static_cast<std::size_t>(width) * height;
  hal::RgbdFrame frame(width, height);
  pipeline::PointCloud cloud(max_points);
  pipeline::FoveatedCloud out(max_points);
  const pipeline::KernelSet kernels = pipeline::defaultKernelSet();
  const int thread_count = static_cast<int>(threads.value());
  Result<pipeline::Foveator> foveator =
      pipeline::Foveator::create({max_points, max_points, kernels, thread_count}, config.value());
  pipeline::Backprojector backprojector(thread_count, kernels);
  if (!foveator) return usage(foveator.status());
  if (Status s = camera.start(); !s) {
    std::fprintf(stderr, "fovead run: camera %s: %s\n", info.name.c_str(), s.message().c_str());
    return kExitFailure;
  }

  std::printf("fovead run: camera %s %dx%d @ %g fps, depth %g..%g m\n", info.name.c_str(), width, height, info.fps,
              range.min_m, range.max_m);
  std::printf("foveation: %s\n", describeFoveation(config.value()).c_str());
  if (kernels == pipeline::KernelSet::kSimd) {
    std::printf("kernels: simd, target %s, %d thread%s (FOVEA_FORCE_KERNEL=ref for the references)\n",
                pipeline::simdTargetName(pipeline::activeSimdTarget()), thread_count, thread_count == 1 ? "" : "s");
  } else {
    std::printf("kernels: ref (scalar references, one thread)\n");
  }
  const pipeline::RegionModel& model = foveator->model();
  if (every.value() > 0) {
    std::printf("%5s %7s %7s %-8s", "frame", "valid", "d0[m]", "d0 from");
    for (int r = 0; r < model.regionCount(); ++r) std::printf(" %15.15s", model.regionName(r));
    std::printf(" %8s %6s | ms: %7s %8s %8s %8s %7s\n", "out", "kept", "capture", "backproj", "partition", "fixation",
                "sample");
  }

  const auto n = static_cast<std::size_t>(frames.value());
  Samples capture_ms(n), backproject_ms(n), partition_ms(n), fixation_ms(n), sample_ms(n), foveate_ms(n);
  Samples points_in(n), points_out(n), d0_m(n);
  RegionTotals totals;
  uint64_t failed_frames = 0;
  for (std::size_t i = 0; i < n; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    if (Status s = camera.acquire(frame, std::chrono::seconds(2)); !s) {
      std::fprintf(stderr, "frame %zu: capture: %s\n", i, s.toString().c_str());
      ++failed_frames;
      continue;
    }
    const double t_capture = msSince(t0);
    t0 = std::chrono::steady_clock::now();
    pipeline::BackprojectCounts bc;
    if (Status s = backprojector.run(frame, range, cloud, bc); !s) {
      std::fprintf(stderr, "frame %zu: backproject: %s\n", i, s.toString().c_str());
      ++failed_frames;
      continue;
    }
    const double t_backproject = msSince(t0);
    pipeline::FoveationStats stats;
    if (Status s = foveator->foveate(cloud, gazeForFrame(gaze_choice.value(), frame.T_world_cam), out, stats); !s) {
      std::fprintf(stderr, "frame %zu: foveate: %s\n", i, s.toString().c_str());
      ++failed_frames;
      continue;
    }
    capture_ms.add(t_capture);
    backproject_ms.add(t_backproject);
    partition_ms.add(static_cast<double>(stats.partition_ns) * 1e-6);
    fixation_ms.add(static_cast<double>(stats.fixation_ns) * 1e-6);
    sample_ms.add(static_cast<double>(stats.sample_ns) * 1e-6);
    foveate_ms.add(static_cast<double>(stats.partition_ns + stats.fixation_ns + stats.sample_ns) * 1e-6 + t_backproject);
    points_in.add(stats.points_in);
    points_out.add(stats.points_out);
    d0_m.add(stats.fixation.d0_m);
    totals.add(stats);
    if (every.value() > 0 && i % static_cast<std::size_t>(every.value()) == 0) {
      std::printf("%5llu %7u %7.3f %-8s", static_cast<unsigned long long>(frame.sequence), stats.points_in,
                  stats.fixation.d0_m, std::string(pipeline::fixationSourceName(stats.fixation.source)).c_str());
      for (int r = 0; r < model.regionCount(); ++r) {
        std::printf(" %7u>%-7u", stats.regions[r].points_in, stats.regions[r].points_out);
      }
      std::printf(" %8u %5.1f%% | ms: %7.2f %8.2f %8.2f %8.2f %7.2f\n", stats.points_out,
                  stats.points_in ? 100.0 * stats.points_out / stats.points_in : 0.0, t_capture, t_backproject,
                  stats.partition_ns * 1e-6, stats.fixation_ns * 1e-6, stats.sample_ns * 1e-6);
    }
  }
  camera.stop();

  std::printf("\nsummary: %zu frames foveated, %llu failed; per frame on average:\n", points_in.count(),
              static_cast<unsigned long long>(failed_frames));
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

  if (const std::string* path = args->get("--save-ply"); path && out.size() > 0) {
    pipeline::PlyWriteOptions options;
    options.double_coords = true;
    if (Status s = pipeline::writePly(*path, out.points, out.region.data(), options); !s) {
      std::fprintf(stderr, "fovead run: %s\n", s.message().c_str());
      return kExitFailure;
    }
    std::printf("wrote the last foveated frame (%zu points) to %s\n", out.size(), path->c_str());
  }
  return failed_frames == n ? kExitFailure : kExitOk;
}

}  // namespace fovea::firmware
