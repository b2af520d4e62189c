// fovea-track: the map's camera tracker (pipeline/map/tracker.h, docs/tracking.md)
// against ground truth: the absolute trajectory error after TUM's rigid
// alignment (pipeline/map/trajectory_error.h), the tracking time per frame
// (median, p90; one thread), the model's build after each fused frame (median),
// and the hard cases with their outcome frame by
// frame. The ground truth is each camera's own pose (a TUM sequence's
// groundtruth.txt, interpolated at the depth stamp; the mock camera's path),
// which the tracker never sees unless a case gives it as the prior.
//
//   fovea-track                      the suite: TUM teddy, mock orbit and dolly, the hard cases
//   fovea-track --camera SPEC [--frames N] [--case NAME] [--kernels ref|simd] [--every K] [--moving on|off]
//               [--robust on|off] [--carried on|off] [--verbose on]
//
// The mock scenes with movers (hal/camera/mock/built_in_scenes.cpp): the
// balloon, the walker (a person crossing the orbit's view), the carried block.
// "moving %" is the largest share of a frame's pixels found moving, "mov. ms"
// the median time of track ms spent finding them, "carried %" the largest
// share found carried with the camera (of the moving ones; carried_pixels.h)
// and "carr. ms" the median time spent finding those.
// --moving off: every pixel fused, as before the moving pixels were left out;
// --robust off: least squares, as before Cauchy's weights; --carried off:
// nothing found carried with the camera (the suite runs the movers as before,
// with none of the three).
// Cases (--case): plain; skip (every other frame dropped: twice the motion a
// frame); invalid (frame 30 has no valid depth); wall (frames 30-34 are a flat
// textureless wall at 1.2 m); object (from frame 20 a box a third of the view
// wide moves across it at 0.8 m); small (the same box a tenth of the view wide); jump (track+socket: the ground truth as the
// prior, shifted 0.5 m from frame 30 on, as a socket's pose that jumps);
// drift (track+socket: the ground truth plus a drift of 1 cm a frame as the
// prior). An evaluation tool: it allocates freely.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "bench/bench_input.h"
#include "core/kernel_set.h"
#include "hal/camera.h"
#include "pipeline/map/mapper.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/map/tracker.h"
#include "pipeline/map/trajectory_error.h"

namespace {

using fovea::KernelSet;
using fovea::hal::RgbdFrame;
using namespace fovea::pipeline::map;

struct RunOptions {
  std::string name;
  std::string camera;
  int frames = 60;
  int every = 1;  // keep frame i when i % every == 0
  std::string hard = "plain";
  KernelSet kernels = fovea::defaultKernelSet();
  std::array<int, 3> iterations = TrackerConfig{}.iterations;  // Gauss-Newton's per level, finest first
  bool moving = true;  // the moving pixels left out of fusion (pipeline/map/moving_pixels.h)
  bool robust = true;  // Cauchy's weights on the residuals (TrackerConfig::icp_robust_scale_m)
  bool carried = true;  // what is still while the view changes left out (pipeline/map/carried_pixels.h)
  bool verbose = false;  // a line a frame: outcome, inliers, moving share, error
};

struct RunResult {
  bool ok = false;
  std::string error;
  int frames = 0, tracked = 0, lost = 0, relocalised = 0;
  std::optional<TrajectoryError> ate;
  double track_median_ms = 0, track_p90_ms = 0, model_median_ms = 0, fuse_median_ms = 0;
  double moving_median_ms = 0;  // of track ms: finding the moving pixels
  double carried_median_ms = 0;  // ... and the carried ones
  double iterations_median = 0;  // Gauss-Newton iterations a frame, all levels and attempts
  double moving_max = 0;         // the largest share of a frame's pixels found moving
  double carried_max = 0;        // ... found carried with the camera
  double max_disagreement_m = 0;
  std::string events;  // the hard case's frames: "30 lost(no-valid-depth) 31 relocalised"
};

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
}

// The hard cases' changes to a frame before the tracker sees it.
void applyHardCase(const std::string& hard, int index, RgbdFrame& frame) {
  const int w = frame.width(), h = frame.height();
  const auto raw = [&](double metres) { return static_cast<uint16_t>(std::lround(metres / frame.depth_scale_m)); };
  if (hard == "invalid" && index == 30) {
    std::fill(frame.depth(), frame.depth() + frame.pixelCount(), uint16_t{0});
  } else if (hard == "wall" && index >= 30 && index <= 34) {
    std::fill(frame.depth(), frame.depth() + frame.pixelCount(), raw(1.2));
    std::fill(frame.rgb(), frame.rgb() + 3 * frame.pixelCount(), uint8_t{200});
  } else if ((hard == "object" || hard == "small") && index >= 20) {
    // A third of the view wide (small: a tenth), the full height, moving 6 pixels a frame, textured.
    const int box = hard == "object" ? w / 3 : w / 10;
    const int x0 = ((index - 20) * 6) % (w - box);
    for (int v = 0; v < h; ++v) {
      for (int u = x0; u < x0 + box; ++u) {
        const std::size_t i = static_cast<std::size_t>(v) * w + u;
        frame.depth()[i] = raw(0.8 + 0.0005 * (u - x0));
        const bool check = ((u - x0) / 16 + v / 16) % 2 == 0;
        frame.rgb()[3 * i] = check ? 220 : 40;
        frame.rgb()[3 * i + 1] = 60;
        frame.rgb()[3 * i + 2] = check ? 40 : 200;
      }
    }
  }
}

// A frame's outcome into the counts and the events: every frame not tracked
// (after the first), and in the hard case's frames (19-40) the first and last
// and the jump.
void countOutcome(const RunOptions& o, int i, const TrackStats& stats, RunResult& r) {
  const bool hard_frames = o.hard != "plain" && o.hard != "skip" && o.hard != "drift" && i >= 19 && i <= 40;
  if (stats.outcome == TrackOutcome::kLost) {
    ++r.lost;
  } else {
    ++r.tracked;
    if (stats.outcome == TrackOutcome::kRelocalised) ++r.relocalised;
  }
  const bool untracked = stats.outcome != TrackOutcome::kTracked && stats.outcome != TrackOutcome::kFirstFrame;
  if (untracked || (hard_frames && (i == 19 || i == 40 || (o.hard == "jump" && i == 30)))) {
    char event[160];
    std::snprintf(event, sizeof event, "%s%d %s%s%s%s", r.events.empty() ? "" : ", ", i,
                  std::string(trackOutcomeName(stats.outcome)).c_str(),
                  stats.outcome == TrackOutcome::kLost ? "(" : "",
                  stats.outcome == TrackOutcome::kLost ? std::string(lostReasonName(stats.lost_reason)).c_str() : "",
                  stats.outcome == TrackOutcome::kLost ? ")" : "");
    r.events += event;
    if (o.hard == "jump" && i == 30) {
      std::snprintf(event, sizeof event, " (prior off by %.3f m)", stats.prior_disagreement_m);
      r.events += event;
    }
  }
}

// The trajectory's error after the alignment, and the times' quantiles.
void finishResult(const std::vector<Eigen::Vector3d>& estimated, const std::vector<Eigen::Vector3d>& truth,
                  const std::vector<double>& track_ms, const std::vector<double>& model_ms,
                  const std::vector<double>& fuse_ms, RunResult& r) {
  fovea::Result<TrajectoryError> ate = absoluteTrajectoryError(estimated, truth);
  if (ate) r.ate = ate.value();
  r.track_median_ms = quantile(track_ms, 0.5);
  r.track_p90_ms = quantile(track_ms, 0.9);
  r.model_median_ms = quantile(model_ms, 0.5);
  r.fuse_median_ms = quantile(fuse_ms, 0.5);
  r.ok = true;
}

RunResult run(const RunOptions& o) {
  RunResult r;
  fovea::Result<std::unique_ptr<fovea::hal::Camera>> created = fovea::hal::createCamera(o.camera);
  if (!created) {
    r.error = created.status().message();
    return r;
  }
  fovea::hal::Camera& camera = *created.value();
  if (fovea::Status s = camera.open(); !s) {
    r.error = s.message();
    return r;
  }
  const fovea::hal::CameraIntrinsics& k = camera.info().intrinsics;
  MapperConfig config;
  config.map.max_width = k.width;
  config.map.max_height = k.height;
  config.map.kernels = o.kernels;
  config.tracker.kernels = o.kernels;
  config.tracker.iterations = o.iterations;
  config.tracker.moving.enabled = o.moving;
  config.tracker.carried.enabled = o.carried;
  if (!o.robust) config.tracker.icp_robust_scale_m = config.tracker.photometric_robust_scale = 0.0;
  const bool prior = o.hard == "jump" || o.hard == "drift";
  config.tracking = prior ? PoseTracking::kRefine : PoseTracking::kAlone;
  fovea::Result<Mapper> mapper = Mapper::create(config);
  if (!mapper) {
    r.error = mapper.status().message();
    return r;
  }
  if (fovea::Status s = camera.start(); !s) {
    r.error = s.message();
    return r;
  }
  RgbdFrame frame(k.width, k.height);
  std::vector<Eigen::Vector3d> estimated, truth;
  std::vector<double> track_ms, model_ms, fuse_ms, iterations, moving_ms, carried_ms;
  for (int i = 0; r.frames < o.frames; ++i) {
    if (fovea::Status s = camera.acquire(frame, std::chrono::seconds(5)); !s) break;  // a recording's end
    if (i % o.every != 0) continue;
    const fovea::hal::Pose gt = frame.T_world_cam;
    applyHardCase(o.hard, i, frame);
    if (o.hard == "jump" && i >= 30) frame.T_world_cam.t_world_cam += Eigen::Vector3d(0.5, 0.0, 0.0);
    if (o.hard == "drift") frame.T_world_cam.t_world_cam += Eigen::Vector3d(0.01 * i, 0.0, 0.0);
    ++r.frames;
    MapperFrame figures;
    const bool fused = mapper->addFrame(frame, /*outside_pose_valid=*/true, figures);
    track_ms.push_back(static_cast<double>(figures.track.track_ns) * 1e-6);
    moving_ms.push_back(static_cast<double>(figures.track.moving_ns) * 1e-6);
    carried_ms.push_back(static_cast<double>(figures.track.carried_ns) * 1e-6);
    iterations.push_back(figures.track.iterations);
    r.max_disagreement_m = std::max(r.max_disagreement_m, figures.track.prior_disagreement_m);
    r.moving_max = std::max(r.moving_max, static_cast<double>(figures.track.moving_share));
    const double carried_share = figures.track.valid_pixels > 0
                                     ? static_cast<double>(figures.track.carried_pixels) / figures.track.valid_pixels
                                     : 0.0;
    r.carried_max = std::max(r.carried_max, carried_share);
    countOutcome(o, i, figures.track, r);
    if (o.verbose) {
      std::printf("  frame %3d %-11s inliers %u/%u %5.1f %% moving %5.1f %% carried %5.1f %% changed %5.1f %% rms %.4f m error %.1f mm\n", i,
                  std::string(trackOutcomeName(figures.track.outcome)).c_str(), figures.track.inliers, figures.track.valid_pixels, 100.0 * figures.track.inlier_fraction,
                  100.0 * figures.track.moving_share, 100.0 * carried_share, 100.0 * figures.track.changed_share, figures.track.icp_rms_m,
                  1e3 * (frame.T_world_cam.t_world_cam - gt.t_world_cam).norm());
    }
    if (!figures.pose_usable) continue;  // lost: not fused, not in the trajectory
    estimated.push_back(frame.T_world_cam.t_world_cam);
    truth.push_back(gt.t_world_cam);
    if (fused) {
      fuse_ms.push_back(static_cast<double>(figures.fuse.fuse_ns) * 1e-6);
      model_ms.push_back(static_cast<double>(figures.track.model_ns) * 1e-6);
    }
  }
  camera.stop();
  finishResult(estimated, truth, track_ms, model_ms, fuse_ms, r);
  r.iterations_median = quantile(iterations, 0.5);
  r.moving_median_ms = quantile(moving_ms, 0.5);
  r.carried_median_ms = quantile(carried_ms, 0.5);
  return r;
}

void printHeader() {
  std::printf("%-28s %6s %7s %5s %6s %9s %9s %9s %9s %6s %9s %9s %9s %8s %9s %8s\n", "run", "frames", "tracked", "lost",
              "reloc", "ATE mm", "max mm", "track ms", "p90 ms", "iters", "model ms", "fuse ms", "moving %", "mov. ms",
              "carried %", "carr. ms");
}

void printRow(const RunOptions& o, const RunResult& r) {
  if (!r.ok) {
    std::printf("%-28s failed: %s\n", o.name.c_str(), r.error.c_str());
    return;
  }
  std::printf("%-28s %6d %7d %5d %6d %9.2f %9.2f %9.2f %9.2f %6.0f %9.2f %9.2f %9.1f %8.2f %9.1f %8.2f\n", o.name.c_str(),
              r.frames, r.tracked, r.lost, r.relocalised, r.ate ? r.ate->rmse_m * 1e3 : NAN,
              r.ate ? r.ate->max_m * 1e3 : NAN, r.track_median_ms, r.track_p90_ms, r.iterations_median,
              r.model_median_ms, r.fuse_median_ms, 100.0 * r.moving_max, r.moving_median_ms, 100.0 * r.carried_max,
              r.carried_median_ms);
  if (!r.events.empty()) std::printf("    %s\n", r.events.c_str());
  if (o.hard == "jump" || o.hard == "drift") {
    std::printf("    largest disagreement with the prior: %.3f m\n", r.max_disagreement_m);
  }
}

std::string teddyPath() {
  if (const char* shared = std::getenv("FOVEA_SHARED_DIR")) return std::string(shared) + "/data/tum-fr3-teddy";
  return "../shared/data/tum-fr3-teddy";
}

// The options every run takes (a switch off turns it off in every run of the suite).
struct Switches {
  KernelSet kernels = fovea::defaultKernelSet();
  std::array<int, 3> iterations = TrackerConfig{}.iterations;
  bool moving = true, robust = true, carried = true;
};

std::optional<Switches> parseSwitches(int argc, char** argv) {
  Switches w;
  const std::optional<KernelSet> kernels = fovea::parseKernelSet(fovea::bench::option(argc, argv, "--kernels", "simd"));
  if (!kernels) {
    std::fprintf(stderr, "fovea-track: --kernels ref|simd\n");
    return std::nullopt;
  }
  w.kernels = *kernels;
  const std::string iteration_text = fovea::bench::option(argc, argv, "--iterations", "");
  if (!iteration_text.empty() &&
      std::sscanf(iteration_text.c_str(), "%d,%d,%d", &w.iterations[0], &w.iterations[1], &w.iterations[2]) != 3) {
    std::fprintf(stderr, "fovea-track: --iterations FINE,MID,COARSE (three counts, as TrackerConfig::iterations)\n");
    return std::nullopt;
  }
  const std::string moving = fovea::bench::option(argc, argv, "--moving", "on");
  const std::string robust = fovea::bench::option(argc, argv, "--robust", "on");
  const std::string carried = fovea::bench::option(argc, argv, "--carried", "on");
  if ((moving != "on" && moving != "off") || (robust != "on" && robust != "off") ||
      (carried != "on" && carried != "off")) {
    std::fprintf(stderr, "fovea-track: --moving on|off, --robust on|off, --carried on|off\n");
    return std::nullopt;
  }
  w.moving = moving == "on", w.robust = robust == "on", w.carried = carried == "on";
  return w;
}

// One run of the camera the command line names.
int runOne(int argc, char** argv, const std::string& camera, const Switches& w) {
  RunOptions o;
  o.camera = camera;
  o.name = camera.substr(0, 28);
  o.frames = std::atoi(fovea::bench::option(argc, argv, "--frames", "60").c_str());
  o.every = std::max(1, std::atoi(fovea::bench::option(argc, argv, "--every", "1").c_str()));
  o.hard = fovea::bench::option(argc, argv, "--case", "plain");
  o.kernels = w.kernels;
  o.iterations = w.iterations;
  o.moving = w.moving, o.robust = w.robust, o.carried = w.carried;
  o.verbose = fovea::bench::option(argc, argv, "--verbose", "off") == "on";
  const RunResult r = run(o);
  printRow(o, r);
  return r.ok ? 0 : 1;
}

// The suite: TUM teddy, the mock orbit and dolly, the hard cases (each mover
// also "as before": without the moving pixels, the robust weights and the
// carried pixels).
std::vector<RunOptions> suiteRuns(const std::string& tum_dir, KernelSet k) {
  const std::string tum = "tum:" + tum_dir + ",loop=off";
  const std::string orbit = "mock:living-room,size=640x480,path=orbit";
  const std::string dolly = "mock:living-room,size=640x480,path=dolly";
  const std::string balloon = "mock:balloon,size=640x480,path=orbit";
  const std::string walker = "mock:walker,size=640x480,path=orbit";    // a person crossing a third of the view
  const std::string carried = "mock:carried,size=640x480,path=orbit";  // a block carried with the camera
  const std::string carried_dolly = "mock:carried,size=640x480,path=dolly";  // ... starting slowly
  return {
      {"tum-fr3-teddy", tum, 60, 1, "plain", k},
      {"tum-fr3-teddy (ref kernels)", tum, 60, 1, "plain", KernelSet::kRef},
      {"mock orbit", orbit, 90, 1, "plain", k},
      {"mock dolly", dolly, 90, 1, "plain", k},
      {"hard: orbit, every 2nd", orbit, 45, 2, "skip", k},
      {"hard: tum, every 2nd", tum, 30, 2, "skip", k},
      {"hard: invalid depth @30", orbit, 60, 1, "invalid", k},
      {"hard: wall @30-34", orbit, 60, 1, "wall", k},
      {"hard: moving object", orbit, 60, 1, "object", k},
      {"hard: moving object, as before", orbit, 60, 1, "object", k, {}, false, false, false},
      {"hard: small moving object", orbit, 60, 1, "small", k},
      {"hard: small object, as before", orbit, 60, 1, "small", k, {}, false, false, false},
      {"hard: balloon, orbit", balloon, 60, 1, "plain", k},
      {"hard: balloon, as before", balloon, 60, 1, "plain", k, {}, false, false, false},
      {"hard: walker, orbit", walker, 90, 1, "plain", k},
      {"hard: walker, as before", walker, 90, 1, "plain", k, {}, false, false, false},
      {"hard: carried block, orbit", carried, 60, 1, "plain", k},
      {"hard: carried, as before", carried, 60, 1, "plain", k, {}, false, false, false},
      {"hard: carried block, dolly", carried_dolly, 60, 1, "plain", k},
      {"hard: carried dolly, before", carried_dolly, 60, 1, "plain", k, {}, false, false, false},
      {"hard: socket jump @30", orbit, 60, 1, "jump", k},
      {"hard: socket drift 1cm/f", orbit, 60, 1, "drift", k},
  };
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::puts("usage: fovea-track [--camera SPEC] [--frames N] [--every K] [--case plain|skip|invalid|wall|object|small|jump|drift]\n"
                "                   [--kernels ref|simd] [--tum PATH] [--iterations FINE,MID,COARSE] [--moving on|off]\n"
                "                   [--robust on|off] [--carried on|off] [--verbose on]\n"
                "Without --camera: the suite (TUM teddy, mock orbit and dolly at 640x480, the hard cases).");
      return 0;
    }
  }
  const std::optional<Switches> switches = parseSwitches(argc, argv);
  if (!switches) return 2;
  const std::string camera = fovea::bench::option(argc, argv, "--camera", "");
  printHeader();
  if (!camera.empty()) return runOne(argc, argv, camera, *switches);
  int failed = 0;
  for (RunOptions& o : suiteRuns(fovea::bench::option(argc, argv, "--tum", teddyPath().c_str()), switches->kernels)) {
    o.iterations = switches->iterations;
    o.moving = o.moving && switches->moving;
    o.robust = o.robust && switches->robust;
    o.carried = o.carried && switches->carried;
    const RunResult r = run(o);
    printRow(o, r);
    failed += r.ok ? 0 : 1;
    std::fflush(stdout);
  }
  return failed == 0 ? 0 : 1;
}
