// fovead map: posed frames of a camera (a recording, a mock path) fused into a
// surfel map offline (pipeline/map/surfel_map.h), written as PLY.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "firmware/camera_setup.h"
#include "firmware/commands.h"
#include "firmware/frame_foveator.h"
#include "firmware/options.h"
#include "firmware/report.h"
#include "hal/pose.h"
#include "hal/pose_source.h"
#include "io/ply.h"
#include "pipeline/map/mapper.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/map/tracker.h"

namespace fovea::firmware {

namespace {

const char* kMapHelp =
    "usage: fovead map [--out MAP.ply] [--trajectory FILE] [--camera SPEC] [--frames N] [--all-surfels]\n"
    "                  [--max-surfels N] [--brick-size M] [--depth-min M] [--depth-max M]\n"
    "                  [--calibration FILE]\n"
    "                  [--pose none|fixed:X,Y,Z[,QX,QY,QZ,QW]|socket:PATH|track|track+fixed:...|track+socket:PATH\n"
    "                          |track+camera]\n"
    "\n"
    "Fuses N posed frames of a camera into a surfel map (point-based fusion: docs/map.md)\n"
    "and writes it as binary PLY, one vertex a surfel: x y z (double, world), nx ny nz,\n"
    "red green blue, radius, confidence. Each frame's pose is the camera's own (a TUM\n"
    "recording's ground truth, the mock camera's path) unless --pose gives one; a frame\n"
    "without a usable pose is refused and counted. With --pose track the map tracks the\n"
    "camera itself (frame-to-model ICP and colour, docs/tracking.md): the camera's own\n"
    "poses are ignored; track+fixed, track+socket and track+camera (the camera's own)\n"
    "refine an outside pose. A lost frame is not fused. A recording ends the run at its\n"
    "end (tum:PATH,loop=off) or after N frames; with --pose track a recording plays once\n"
    "unless its spec says loop=on.\n"
    "\n"
    "  --out FILE          the map's PLY file\n"
    "  --trajectory FILE   the poses in TUM's format (timestamp tx ty tz qx qy qz qw, the frame's stamp\n"
    "                      in seconds: a TUM sequence's own), for evaluate_ate.py: with --pose track\n"
    "                      every frame's (a lost one's is the outside pose with track+X, else the\n"
    "                      last good one), else the fused frames'\n"
    "                      (one of --out and --trajectory is needed)\n"
    "  --camera SPEC       default mock:living-room,path=orbit ('fovead cameras' lists them)\n"
    "  --frames N          frames to fuse (default 100; with --pose track and a recording: all)\n"
    "  --all-surfels       write unstable surfels too (default: the stable ones, those the map shows)\n"
    "  --max-surfels N     the pool (default 1048576, at most 16777215; 38 bytes a surfel)\n"
    "  --brick-size M      the bricks' edge in metres (default 0.5)\n"
    "  --depth-min M, --depth-max M  the depth range fused (default 0.1 .. 10 m)\n";

int mapUsage(const Status& s) {
  std::fprintf(stderr, "fovead map: %s\n", s.message().c_str());
  return kExitUsage;
}

int mapFailure(const Status& s) {
  std::fprintf(stderr, "fovead map: %s\n", s.message().c_str());
  return kExitFailure;
}

void printSummary(const pipeline::map::SurfelMap& map, const Samples& fuse_ms, std::size_t frames_read) {
  const pipeline::map::SurfelMapCounters& c = map.counters();
  std::printf("frames: %zu read, %llu fused; refused: %llu without a usable pose, %llu pose jumps, "
              "%llu stamps not increasing, %llu too large\n",
              frames_read, static_cast<unsigned long long>(c.frames_fused),
              static_cast<unsigned long long>(c.refused_bad_pose + c.refused_no_pose),
              static_cast<unsigned long long>(c.refused_pose_jump),
              static_cast<unsigned long long>(c.refused_clock), static_cast<unsigned long long>(c.refused_size));
  std::printf("map: %zu surfels in %zu bricks (pool %zu, %zu bytes a surfel, %.1f MiB in all)\n", map.size(),
              map.brickCount(), map.capacity(), sizeof(pipeline::map::Surfel),
              static_cast<double>(map.memoryBytes()) / (1024.0 * 1024.0));
  std::printf("surfels: %llu added, %llu carved away, %llu unstable too long, %llu evicted, %llu not placed (pool or "
              "bricks full; %llu for want of a brick); %llu empty bricks reused\n",
              static_cast<unsigned long long>(c.added), static_cast<unsigned long long>(c.removed_carved),
              static_cast<unsigned long long>(c.removed_unstable), static_cast<unsigned long long>(c.evicted),
              static_cast<unsigned long long>(c.dropped_full), static_cast<unsigned long long>(c.dropped_no_brick),
              static_cast<unsigned long long>(c.bricks_reused));
  std::printf("fusion time [ms]: median %.2f, p90 %.2f, max %.2f (per-pixel kernels %s, one thread)\n",
              fuse_ms.median(), fuse_ms.quantile(0.9), fuse_ms.max(),
              std::string(kernelSetName(map.config().kernels)).c_str());
}

// With --pose track, a TUM recording plays once (mcap: plays once unless told
// to loop): looping back to its start is a jump the tracker would (rightly)
// call lost. loop=on in the spec still loops.
std::string playOnce(std::string spec) {
  if (spec.rfind("tum:", 0) == 0 && spec.find("loop") == std::string::npos) spec += ",loop=off";
  return spec;
}

void printTracking(const pipeline::map::FrameToModelTracker& tracker, const Samples& track_ms) {
  const pipeline::map::TrackerCounters& t = tracker.counters();
  std::printf("tracking: %llu frames (the first sets the world), %llu tracked, %llu lost (not fused), %llu relocalised; "
              "time [ms] median %.2f, "
              "p90 %.2f, max %.2f (kernels %s, one thread)\n",
              static_cast<unsigned long long>(t.frames), static_cast<unsigned long long>(t.tracked),
              static_cast<unsigned long long>(t.lost), static_cast<unsigned long long>(t.relocalised), track_ms.median(),
              track_ms.quantile(0.9), track_ms.max(), std::string(kernelSetName(tracker.config().kernels)).c_str());
}

// What the command line asks for: the map, the camera, the tracking and how
// many frames. Every error here is a usage error.
struct MapPlan {
  pipeline::map::SurfelMapConfig map;
  CameraSettings camera;
  pipeline::map::PoseTracking tracking = pipeline::map::PoseTracking::kOff;
  long frames = 0;
};

Result<MapPlan> mapPlanFromArgs(const Args& args) {
  MapPlan plan;
  Result<MapSettings> settings_map = mapSettingsFromArgs(args);
  if (!settings_map) return settings_map.status();
  Result<pipeline::DepthRange> range = depthRangeFromArgs(args);
  if (!range) return range.status();
  plan.map = settings_map->map;
  plan.map.depth = range.value();
  Result<CameraSettings> settings = cameraSettingsFromArgs(args);
  if (!settings) return settings.status();
  plan.camera = std::move(settings.value());
  if (!args.has("--camera")) plan.camera.spec = "mock:living-room,path=orbit";
  plan.tracking = poseTracking(plan.camera);
  const bool tracked = plan.tracking != pipeline::map::PoseTracking::kOff;
  if (tracked) plan.camera.spec = playOnce(plan.camera.spec);
  // A recording tracked plays to its end unless --frames says otherwise.
  const bool recording = plan.camera.spec.rfind("tum:", 0) == 0 || plan.camera.spec.rfind("mcap:", 0) == 0;
  const char* default_frames = tracked && recording ? "100000000" : "100";
  Result<long> frames = parseInteger("--frames", args.getOr("--frames", default_frames), 1, 100000000);
  if (!frames) return frames.status();
  plan.frames = frames.value();
  return plan;
}

// --trajectory FILE, open for the run's poses and closed at the end.
class TrajectoryFile {
 public:
  TrajectoryFile() = default;
  TrajectoryFile(const TrajectoryFile&) = delete;
  TrajectoryFile& operator=(const TrajectoryFile&) = delete;
  ~TrajectoryFile() {
    if (file_) std::fclose(file_);
  }

  // Opens `path` and writes the header line.
  Status open(const std::string& path) {
    path_ = path;
    file_ = std::fopen(path.c_str(), "w");
    if (file_ == nullptr) return cannotWrite();
    std::fputs("# timestamp tx ty tz qx qy qz qw (fovead map: camera to world, one line a frame)\n", file_);
    return Status::ok();
  }
  bool isOpen() const { return file_ != nullptr; }
  const std::string& path() const { return path_; }
  std::size_t lines() const { return lines_; }

  Status write(const hal::RgbdFrame& frame) {
    char line[192];
    const std::size_t n = hal::formatTumPose(frame.stamp_ns, frame.T_world_cam, line, sizeof line);
    if (n == 0 || std::fwrite(line, 1, n, file_) != n) return cannotWrite();
    ++lines_;
    return Status::ok();
  }
  Status flush() { return std::fflush(file_) != 0 ? cannotWrite() : Status::ok(); }

 private:
  Status cannotWrite() const { return Status(ErrorCode::kIoError, "--trajectory: cannot write " + path_); }

  std::FILE* file_ = nullptr;
  std::string path_;
  std::size_t lines_ = 0;
};

// What the fusion loop measured.
struct MapFusion {
  explicit MapFusion(std::size_t expected) : fuse_ms(expected), track_ms(expected) {}
  Samples fuse_ms;
  Samples track_ms;
  std::size_t read = 0;
};

// Poses one frame (the pose source, then the mapper's tracker) and fuses it; true when fused.
bool poseAndFuse(hal::RgbdFrame& frame, hal::PoseSource& poses, pipeline::map::Mapper& mapper, MapFusion& fusion) {
  const bool outside_pose_valid = poses.apply(frame);
  pipeline::map::MapperFrame figures;
  const bool fused = mapper.addFrame(frame, outside_pose_valid, figures);
  if (mapper.poseEstimator()) fusion.track_ms.add(static_cast<double>(figures.track.track_ns) * 1e-6);
  if (fused) fusion.fuse_ms.add(static_cast<double>(figures.fuse.fuse_ns) * 1e-6);
  return fused;
}

// Reads up to `frames` frames of the started camera into the map; a recording
// that ends early ends the run. The error of a camera or of the trajectory file.
Status fuseMapFrames(hal::Camera& camera, hal::PoseSource& poses, pipeline::map::Mapper& mapper, long frames,
                     TrajectoryFile& trajectory, MapFusion& fusion) {
  const hal::CameraIntrinsics& k = camera.info().intrinsics;
  hal::RgbdFrame frame(k.width, k.height);
  for (long i = 0; i < frames; ++i) {
    if (Status s = camera.acquire(frame, std::chrono::seconds(5)); !s) {
      if (s.code() == ErrorCode::kUnavailable && fusion.read > 0) {
        std::printf("camera: %s after %zu frames\n", s.message().c_str(), fusion.read);
        break;
      }
      return Status(s.code(), "camera " + camera.info().name + ": " + s.message());
    }
    ++fusion.read;
    const bool fused = poseAndFuse(frame, poses, mapper, fusion);
    // Tracked: every frame's pose, a lost one's too (the last good: its error
    // counts, as a tracker's failures should); otherwise the fused frames'.
    if (trajectory.isOpen() && (fused || mapper.poseEstimator())) {
      if (Status s = trajectory.write(frame); !s) return s;
    }
  }
  return Status::ok();
}

// What the run made: the camera, the map's counters, the tracking, the files written.
void printMapReport(const Args& args, const hal::Camera& camera, const pipeline::map::Mapper& mapper,
                    const MapFusion& fusion, const TrajectoryFile& trajectory) {
  const hal::CameraIntrinsics& k = camera.info().intrinsics;
  std::printf("camera: %s (%dx%d)\n", camera.info().name.c_str(), k.width, k.height);
  printSummary(mapper.map(), fusion.fuse_ms, fusion.read);
  if (const pipeline::map::PoseEstimator* poser = mapper.poseEstimator()) printTracking(poser->tracker(), fusion.track_ms);
  if (const std::string* out_path = args.get("--out")) {
    std::printf("wrote %s surfels to %s\n", args.has("--all-surfels") ? "all" : "the stable", out_path->c_str());
  }
  if (trajectory.isOpen()) std::printf("wrote %zu poses to %s\n", trajectory.lines(), trajectory.path().c_str());
}

}  // namespace

int mapCommand(int argc, char** argv) {
  std::vector<std::string> flags = {"--out", "--trajectory", "--frames", "--depth-min", "--depth-max"};
  flags.insert(flags.end(), kCameraFlags.begin(), kCameraFlags.end());
  flags.insert(flags.end(), kMapFlags.begin(), kMapFlags.end());
  Result<Args> args = Args::parse(argc, argv, 2, flags, {"--help", "-h", "--all-surfels"});
  if (!args) return mapUsage(args.status());
  if (args->has("--help") || args->has("-h")) {
    std::fputs(kMapHelp, stdout);
    return kExitOk;
  }
  if (!args->has("--out") && !args->has("--trajectory")) {
    return mapUsage(invalidArgument("--out or --trajectory is required (see --help)"));
  }
  Result<MapPlan> plan = mapPlanFromArgs(args.value());
  if (!plan) return mapUsage(plan.status());
  TrajectoryFile trajectory;
  if (const std::string* path = args->get("--trajectory")) {
    if (Status s = trajectory.open(*path); !s) return mapFailure(s);
  }

  Result<OpenedCamera> opened = openConfiguredCamera(plan->camera);
  if (!opened) {
    return opened.status().code() == ErrorCode::kInvalidArgument ? mapUsage(opened.status()) : mapFailure(opened.status());
  }
  hal::Camera& camera = *opened->camera;
  const hal::CameraIntrinsics& k = camera.info().intrinsics;
  pipeline::map::MapperConfig config;
  config.map = plan->map;
  config.map.max_width = k.width;
  config.map.max_height = k.height;
  config.tracking = plan->tracking;
  Result<pipeline::map::Mapper> created = pipeline::map::Mapper::create(config);
  if (!created) return mapUsage(created.status());
  pipeline::map::Mapper& mapper = created.value();
  if (Status s = camera.start(); !s) return mapFailure(s);

  // Samples are sized up front: a recording's frame count when it is known.
  MapFusion fusion(static_cast<std::size_t>(std::min<long>(plan->frames, 100000)));
  const Status fused = fuseMapFrames(camera, *opened->pose_source, mapper, plan->frames, trajectory, fusion);
  camera.stop();
  if (!fused) return mapFailure(fused);
  if (trajectory.isOpen()) {
    if (Status s = trajectory.flush(); !s) return mapFailure(s);
  }

  if (const std::string* out_path = args->get("--out")) {
    if (Status s = io::writeSurfelPly(*out_path, mapper.map(), !args->has("--all-surfels")); !s) return mapFailure(s);
  }
  printMapReport(args.value(), camera, mapper, fusion, trajectory);
  return mapper.map().counters().frames_fused > 0 ? kExitOk : mapFailure(invalidArgument("no frame was fused (see the refusals above)"));
}

}  // namespace fovea::firmware
