// fovea-map-accuracy: how close the surfel map (pipeline/map/) lies to the true
// surface, against a single noisy frame, on the mock camera, whose noiseless
// twin (noise=off, the same path and poses) gives the truth.
//
//   fovea-map-accuracy [--scene living-room] [--path orbit] [--frames 60] [--size 640x480] [--every 10]
//                      [--stable C] [--cap C] [--unstable-frames N] [--kernels ref|simd] [--pose truth|track]
//                      [--carried on|off]
//                      (SurfelMapConfig's stable_confidence, confidence_cap, unstable_max_frames, kernels;
//                      the kernels' default is defaultKernelSet(): simd unless FOVEA_FORCE_KERNEL=ref)
//
// It also prints the fusion time per frame, median over the frames, and its
// steps' medians (FuseStats' *_ns).
//
// Every --every frames (and at the last) the map is compared with that frame's
// noiseless view: the depth error along the ray through each stable surfel's
// centre, against the depth error of each pixel of the noisy frame (their RMS,
// medians and ratio), the share of the true surface in view that has a stable
// surfel within 1 cm, and (at the last frame) the stable surfels in view that
// lie in free space, more than 5 cm in front of the true surface: on the balloon
// scene, ghosts of where the balloon was. An evaluation tool: it allocates freely.
//
// --pose truth (the default) fuses each frame at the camera's true pose, every
// pixel. --pose track fuses as the service does with camera.pose.source=track+camera:
// through a Mapper whose tracker takes the first frame's true pose and tracks
// the rest, leaving out the pixels it finds moving (issue 42); it also prints
// the tracker's outcomes, its error against the true path, and the moving share.
// --carried off: nothing found carried with the camera (pipeline/map/carried_pixels.h).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "bench/bench_input.h"
#include "bench/mock_scene.h"
#include "hal/camera.h"
#include "pipeline/map/mapper.h"
#include "pipeline/map/surfel_map.h"

namespace {

using fovea::bench::option;
using fovea::bench::trueDepthAt;
using fovea::hal::RgbdFrame;
using fovea::pipeline::map::SurfelMap;

struct Totals {
  double map_sq = 0.0, frame_sq = 0.0;
  std::size_t map_n = 0, frame_n = 0;
  std::size_t true_pixels = 0, covered = 0;
  std::vector<float> map_abs, frame_abs;  // |error| of every compared pixel, for the median
  // At the last evaluation: stable surfels in view, and those more than 5 cm in
  // front of the true surface (in free space: ghosts of what moved, or outliers).
  std::size_t in_view = 0, ghosts = 0;
};

float median(std::vector<float>& v) {
  if (v.empty()) return 0.0f;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

std::int64_t cellKey(const Eigen::Vector3d& p, double cell) {
  const auto c = (p / cell).array().floor().cast<std::int64_t>();
  return ((c.x() & 0x1fffff) << 42) | ((c.y() & 0x1fffff) << 21) | (c.z() & 0x1fffff);
}

// The map's stable surfels and the noisy frame against the noiseless view:
//  - depth error along the ray through each surfel's centre (the true depth
//    interpolated there; surfels more than 5 cm behind the true surface are
//    hidden by it and not counted; one in front of it, a ghost, is);
//  - depth error of each pixel of the noisy frame;
//  - coverage: the true surface points of the view with a stable surfel within 1 cm.
void evaluate(const SurfelMap& map, const RgbdFrame& noisy, const RgbdFrame& truth, Totals& t) {
  const int w = truth.width(), h = truth.height();
  const fovea::hal::CameraIntrinsics& k = truth.intrinsics;
  const Eigen::Matrix3d& R_wc = truth.T_world_cam.R_world_cam;
  const Eigen::Matrix3d R_cw = R_wc.transpose();
  const Eigen::Vector3d& cam = truth.T_world_cam.t_world_cam;
  constexpr double kCell = 0.01;
  std::unordered_map<std::int64_t, std::vector<Eigen::Vector3d>> cells;
  t.in_view = t.ghosts = 0;
  for (std::size_t slot = 0; slot < map.slotCount(); ++slot) {
    if (!map.live(slot) || !(map.surfel(slot).flags & fovea::pipeline::map::kSurfelStable)) continue;
    const Eigen::Vector3d world = map.worldPosition(slot);
    cells[cellKey(world, kCell)].push_back(world);
    const Eigen::Vector3d p = R_cw * (world - cam);
    if (p.z() < 0.05) continue;
    const double z_true = trueDepthAt(truth, k.fx * p.x() / p.z() + k.cx, k.fy * p.y() / p.z() + k.cy);
    if (!std::isfinite(z_true) || p.z() > z_true + 0.05) continue;
    const double e = p.z() - z_true;
    ++t.in_view;
    t.ghosts += e < -0.05;
    t.map_sq += e * e;
    ++t.map_n;
    t.map_abs.push_back(static_cast<float>(std::abs(e)));
  }
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      const uint16_t raw_true = truth.depth()[i];
      if (raw_true == 0) continue;
      const double z_true = raw_true * truth.depth_scale_m;
      if (const uint16_t raw = noisy.depth()[i]; raw != 0) {
        const double e = raw * noisy.depth_scale_m - z_true;
        t.frame_sq += e * e;
        ++t.frame_n;
        t.frame_abs.push_back(static_cast<float>(std::abs(e)));
      }
      ++t.true_pixels;
      const Eigen::Vector3d point = R_wc * Eigen::Vector3d((u - k.cx) / k.fx * z_true, (v - k.cy) / k.fy * z_true, z_true) + cam;
      bool near = false;
      for (int dx = -1; dx <= 1 && !near; ++dx) {
        for (int dy = -1; dy <= 1 && !near; ++dy) {
          for (int dz = -1; dz <= 1 && !near; ++dz) {
            const auto it = cells.find(cellKey(point + Eigen::Vector3d(dx, dy, dz) * kCell, kCell));
            if (it == cells.end()) continue;
            for (const Eigen::Vector3d& q : it->second) {
              if ((q - point).squaredNorm() <= kCell * kCell) {
                near = true;
                break;
              }
            }
          }
        }
      }
      t.covered += near;
    }
  }
}

// Each frame's fusion time and its steps' (FuseStats' *_ns), in ms.
struct FuseTimes {
  std::vector<double> fuse_ms, vertices_ms, index_map_ms, associate_ms, add_ms;
  void add(const fovea::pipeline::map::FuseStats& stats) {
    fuse_ms.push_back(static_cast<double>(stats.fuse_ns) * 1e-6);
    vertices_ms.push_back(static_cast<double>(stats.vertices_ns) * 1e-6);
    index_map_ms.push_back(static_cast<double>(stats.index_map_ns) * 1e-6);
    associate_ms.push_back(static_cast<double>(stats.associate_ns) * 1e-6);
    add_ms.push_back(static_cast<double>(stats.add_ns) * 1e-6);
  }
};

// --stable, --cap, --unstable-frames and --kernels onto the map's configuration.
// Returns 0, or the exit status 2 after printing why.
int readMapOptions(int argc, char** argv, fovea::pipeline::map::SurfelMapConfig& config) {
  if (const std::string c = option(argc, argv, "--stable", ""); !c.empty()) config.stable_confidence = std::atof(c.c_str());
  if (const std::string c = option(argc, argv, "--cap", ""); !c.empty()) config.confidence_cap = std::atof(c.c_str());
  if (const std::string n = option(argc, argv, "--unstable-frames", ""); !n.empty()) {
    config.unstable_max_frames = static_cast<uint32_t>(std::atoi(n.c_str()));
  }
  if (const std::string kernels = option(argc, argv, "--kernels", ""); !kernels.empty()) {
    const std::optional<fovea::KernelSet> set = fovea::parseKernelSet(kernels);
    if (!set) {
      std::fprintf(stderr, "fovea-map-accuracy: --kernels must be ref or simd\n");
      return 2;
    }
    config.kernels = *set;
  }
  return 0;
}

// --pose track's figures: the tracker's outcomes, its position error against
// the true path (no alignment: the first frame's pose is the truth), the
// moving share a frame.
struct TrackFigures {
  int tracked = 0, lost = 0;
  double error_sq = 0.0, error_max = 0.0;
  std::vector<double> moving_share;
};

// Fuses `frames` frames of the noisy camera, comparing the map with the twin's
// view every `every` frames and at the last. With tracking, the first frame
// gives the tracker its true pose and a lost frame is not fused. Returns 0, or
// the exit status 1.
int fuseFrames(fovea::hal::Camera& a, fovea::hal::Camera& b, fovea::pipeline::map::Mapper& mapper, bool tracking,
               int frames, int every, Totals& totals, FuseTimes& times, TrackFigures& track) {
  const fovea::hal::CameraIntrinsics& k = a.info().intrinsics;
  RgbdFrame noisy(k.width, k.height), truth(k.width, k.height);
  for (int i = 0; i < frames; ++i) {
    if (!a.acquire(noisy, std::chrono::seconds(5)) || !b.acquire(truth, std::chrono::seconds(5))) {
      std::fprintf(stderr, "fovea-map-accuracy: frame %d did not arrive\n", i);
      return 1;
    }
    fovea::pipeline::map::MapperFrame figures;
    const bool fused = mapper.addFrame(noisy, /*outside_pose_valid=*/!tracking || i == 0, figures);
    if (tracking && i > 0) {
      const bool lost = figures.track.outcome == fovea::pipeline::map::TrackOutcome::kLost;
      (lost ? track.lost : track.tracked) += 1;
      track.moving_share.push_back(figures.track.moving_share);
      const double e = (noisy.T_world_cam.t_world_cam - truth.T_world_cam.t_world_cam).norm();
      if (!lost) track.error_sq += e * e, track.error_max = std::max(track.error_max, e);
    }
    if (fused) {
      times.add(figures.fuse);
    } else if (!tracking) {
      std::fprintf(stderr, "fovea-map-accuracy: frame %d: %s\n", i,
                   std::string(fovea::pipeline::map::fuseOutcomeName(figures.fuse.outcome)).c_str());
      return 1;
    }
    if ((i + 1) % every == 0 || i + 1 == frames) evaluate(mapper.map(), noisy, truth, totals);
  }
  return 0;
}

void printTracking(const TrackFigures& t) {
  std::vector<double> shares = t.moving_share;
  std::sort(shares.begin(), shares.end());
  const double median = shares.empty() ? 0.0 : shares[shares.size() / 2];
  const double most = shares.empty() ? 0.0 : shares.back();
  std::printf("tracking: %d tracked, %d lost; position error against the true path: RMS %.2f mm, max %.2f mm; "
              "moving share a frame: median %.1f %%, max %.1f %%\n",
              t.tracked, t.lost, t.tracked ? 1e3 * std::sqrt(t.error_sq / t.tracked) : 0.0, 1e3 * t.error_max,
              100.0 * median, 100.0 * most);
}

// The map's surfels, and its depth error and coverage against the single frame's.
void printAccuracy(const std::string& spec, int frames, int every, const SurfelMap& map, Totals& totals) {
  const double map_rms = totals.map_n ? std::sqrt(totals.map_sq / static_cast<double>(totals.map_n)) : 0.0;
  const double frame_rms = totals.frame_n ? std::sqrt(totals.frame_sq / static_cast<double>(totals.frame_n)) : 0.0;
  double confidence = 0.0;
  std::size_t stable = 0;
  for (std::size_t slot = 0; slot < map.slotCount(); ++slot) {
    if (!map.live(slot) || !(map.surfel(slot).flags & fovea::pipeline::map::kSurfelStable)) continue;
    confidence += fovea::pipeline::map::decodeConfidence(map.surfel(slot).confidence);
    ++stable;
  }
  std::printf("%s: %d frames, evaluated every %d; map %zu surfels, %zu stable (mean confidence %.1f)\n", spec.c_str(),
              frames, every, map.size(), stable, stable ? confidence / static_cast<double>(stable) : 0.0);
  std::printf("depth error against the noiseless twin, RMS [mm]: map %.2f (%zu surfels), single frame %.2f (%zu pixels), "
              "ratio %.3f\n", map_rms * 1e3, totals.map_n, frame_rms * 1e3, totals.frame_n,
              frame_rms > 0.0 ? map_rms / frame_rms : 0.0);
  std::printf("median |depth error| [mm]: map %.2f, single frame %.2f\n", median(totals.map_abs) * 1e3,
              median(totals.frame_abs) * 1e3);
  std::printf("true surface in view with a stable surfel within 1 cm: %.1f %% (%zu of %zu pixels)\n",
              totals.true_pixels ? 100.0 * static_cast<double>(totals.covered) / static_cast<double>(totals.true_pixels) : 0.0,
              totals.covered, totals.true_pixels);
  std::printf("stable surfels in the last view more than 5 cm in front of the true surface: %.3f %% (%zu of %zu)\n",
              totals.in_view ? 100.0 * static_cast<double>(totals.ghosts) / static_cast<double>(totals.in_view) : 0.0,
              totals.ghosts, totals.in_view);
}

void printFuseTimes(FuseTimes& times, fovea::KernelSet kernels) {
  auto middle = [](std::vector<double>& v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  std::printf("fusion time per frame [ms]: median %.2f (kernels %s, one thread); steps' medians: vertices %.2f, "
              "index map %.2f, associate %.2f, evict and add %.2f\n",
              middle(times.fuse_ms), std::string(fovea::kernelSetName(kernels)).c_str(), middle(times.vertices_ms),
              middle(times.index_map_ms), middle(times.associate_ms), middle(times.add_ms));
}

}  // namespace

int main(int argc, char** argv) {
  const std::string spec = fovea::bench::mockSceneSpec(argc, argv, "orbit");
  const int frames = std::atoi(option(argc, argv, "--frames", "60").c_str());
  const int every = std::atoi(option(argc, argv, "--every", "10").c_str());
  if (frames < 1 || every < 1) {
    std::fprintf(stderr, "fovea-map-accuracy: --frames and --every must be at least 1\n");
    return 2;
  }
  fovea::bench::MockTwins twins;
  if (int status = fovea::bench::openMockTwins("fovea-map-accuracy", spec, twins); status != 0) return status;
  const fovea::hal::CameraIntrinsics& k = twins.noisy->info().intrinsics;
  const std::string pose = option(argc, argv, "--pose", "truth");
  if (pose != "truth" && pose != "track") {
    std::fprintf(stderr, "fovea-map-accuracy: --pose must be truth or track\n");
    return 2;
  }
  const bool tracking = pose == "track";
  const std::string carried = option(argc, argv, "--carried", "on");
  if (carried != "on" && carried != "off") {
    std::fprintf(stderr, "fovea-map-accuracy: --carried must be on or off\n");
    return 2;
  }
  fovea::pipeline::map::MapperConfig config;
  config.map.max_width = k.width;
  config.map.max_height = k.height;
  if (int status = readMapOptions(argc, argv, config.map); status != 0) return status;
  config.tracking = tracking ? fovea::pipeline::map::PoseTracking::kRefine : fovea::pipeline::map::PoseTracking::kOff;
  config.tracker.max_width = k.width;
  config.tracker.max_height = k.height;
  config.tracker.kernels = config.map.kernels;
  config.tracker.carried.enabled = carried == "on";
  fovea::Result<fovea::pipeline::map::Mapper> created = fovea::pipeline::map::Mapper::create(config);
  if (!created) {
    std::fprintf(stderr, "fovea-map-accuracy: %s\n", created.status().message().c_str());
    return 2;
  }
  fovea::pipeline::map::Mapper& mapper = created.value();
  Totals totals;
  FuseTimes times;
  TrackFigures track;
  if (int status = fuseFrames(*twins.noisy, *twins.truth, mapper, tracking, frames, every, totals, times, track);
      status != 0) {
    return status;
  }
  printAccuracy(spec, frames, every, mapper.map(), totals);
  if (tracking) printTracking(track);
  printFuseTimes(times, config.map.kernels);
  return 0;
}
