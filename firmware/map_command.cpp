// fovead map: posed frames of a camera (a recording, a mock path) fused into a
// surfel map offline (pipeline/map/surfel_map.h), written as PLY.
#include <chrono>
#include <cstdio>
#include <string>

#include "firmware/camera_setup.h"
#include "firmware/commands.h"
#include "firmware/frame_foveator.h"
#include "firmware/options.h"
#include "firmware/report.h"
#include "io/ply.h"
#include "pipeline/map/surfel_map.h"

namespace fovea::firmware {

namespace {

const char* kMapHelp =
    "usage: fovead map --out MAP.ply [--camera SPEC] [--frames N] [--all-surfels]\n"
    "                  [--max-surfels N] [--brick-size M] [--depth-min M] [--depth-max M]\n"
    "                  [--calibration FILE] [--pose none|fixed:X,Y,Z[,QX,QY,QZ,QW]|socket:PATH]\n"
    "\n"
    "Fuses N posed frames of a camera into a surfel map (point-based fusion: docs/map.md)\n"
    "and writes it as binary PLY, one vertex a surfel: x y z (double, world), nx ny nz,\n"
    "red green blue, radius, confidence. Each frame's pose is the camera's own (a TUM\n"
    "recording's ground truth, the mock camera's path) unless --pose gives one; a frame\n"
    "without a usable pose is refused and counted. A recording ends the run at its end\n"
    "(tum:PATH,loop=off) or after N frames.\n"
    "\n"
    "  --out FILE          the map's PLY file\n"
    "  --camera SPEC       default mock:living-room,path=orbit ('fovead cameras' lists them)\n"
    "  --frames N          frames to fuse (default 100)\n"
    "  --all-surfels       write unstable surfels too (default: the stable ones, those the map shows)\n"
    "  --max-surfels N     the pool (default 1048576; 32 bytes a surfel)\n"
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
  std::printf("surfels: %llu added, %llu carved away, %llu unstable too long, %llu evicted, %llu not placed (pool or bricks full)\n",
              static_cast<unsigned long long>(c.added), static_cast<unsigned long long>(c.removed_carved),
              static_cast<unsigned long long>(c.removed_unstable), static_cast<unsigned long long>(c.evicted),
              static_cast<unsigned long long>(c.dropped_full));
  std::printf("fusion time [ms]: median %.2f, p90 %.2f, max %.2f (per-pixel kernels %s, one thread)\n",
              fuse_ms.median(), fuse_ms.quantile(0.9), fuse_ms.max(),
              std::string(kernelSetName(map.config().kernels)).c_str());
}

}  // namespace

int mapCommand(int argc, char** argv) {
  std::vector<std::string> flags = {"--out", "--frames", "--depth-min", "--depth-max"};
  flags.insert(flags.end(), kCameraFlags.begin(), kCameraFlags.end());
  flags.insert(flags.end(), kMapFlags.begin(), kMapFlags.end());
  Result<Args> args = Args::parse(argc, argv, 2, flags, {"--help", "-h", "--all-surfels"});
  if (!args) return mapUsage(args.status());
  if (args->has("--help") || args->has("-h")) {
    std::fputs(kMapHelp, stdout);
    return kExitOk;
  }
  if (!args->has("--out")) return mapUsage(invalidArgument("--out is required (see --help)"));
  Result<long> frames = parseInteger("--frames", args->getOr("--frames", "100"), 1, 100000000);
  if (!frames) return mapUsage(frames.status());
  Result<MapSettings> settings_map = mapSettingsFromArgs(args.value());
  if (!settings_map) return mapUsage(settings_map.status());
  Result<pipeline::DepthRange> range = depthRangeFromArgs(args.value());
  if (!range) return mapUsage(range.status());
  pipeline::map::SurfelMapConfig config = settings_map->map;
  config.depth = range.value();
  Result<CameraSettings> settings = cameraSettingsFromArgs(args.value());
  if (!settings) return mapUsage(settings.status());
  if (!args->has("--camera")) settings->spec = "mock:living-room,path=orbit";

  Result<OpenedCamera> opened = openConfiguredCamera(settings.value());
  if (!opened) {
    return opened.status().code() == ErrorCode::kInvalidArgument ? mapUsage(opened.status()) : mapFailure(opened.status());
  }
  hal::Camera& camera = *opened->camera;
  const hal::CameraIntrinsics& k = camera.info().intrinsics;
  config.max_width = k.width;
  config.max_height = k.height;
  Result<pipeline::map::SurfelMap> created = pipeline::map::SurfelMap::create(config);
  if (!created) return mapUsage(created.status());
  pipeline::map::SurfelMap& map = created.value();
  if (Status s = camera.start(); !s) return mapFailure(s);

  hal::RgbdFrame frame(k.width, k.height);
  Samples fuse_ms(static_cast<std::size_t>(frames.value()));
  std::size_t read = 0;
  for (long i = 0; i < frames.value(); ++i) {
    if (Status s = camera.acquire(frame, std::chrono::seconds(5)); !s) {
      if (s.code() == ErrorCode::kUnavailable && read > 0) {
        std::printf("camera: %s after %zu frames\n", s.message().c_str(), read);
        break;
      }
      camera.stop();
      return mapFailure(Status(s.code(), "camera " + camera.info().name + ": " + s.message()));
    }
    ++read;
    const bool pose_fresh = opened->pose_source->apply(frame);
    pipeline::map::FuseStats stats;
    if (map.fuse(frame, stats, pose_fresh) == pipeline::map::FuseOutcome::kFused) fuse_ms.add(static_cast<double>(stats.fuse_ns) * 1e-6);
  }
  camera.stop();

  const std::string& out_path = *args->get("--out");
  if (Status s = io::writeSurfelPly(out_path, map, !args->has("--all-surfels")); !s) return mapFailure(s);
  std::printf("camera: %s (%dx%d)\n", camera.info().name.c_str(), k.width, k.height);
  printSummary(map, fuse_ms, read);
  std::printf("wrote %s surfels to %s\n", args->has("--all-surfels") ? "all" : "the stable", out_path.c_str());
  return map.counters().frames_fused > 0 ? kExitOk : mapFailure(invalidArgument("no frame was fused (see the refusals above)"));
}

}  // namespace fovea::firmware
