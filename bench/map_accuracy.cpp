// fovea-map-accuracy: how close the surfel map (pipeline/map/) lies to the true
// surface, against a single noisy frame, on the mock camera, whose noiseless
// twin (noise=off, the same path and poses) gives the truth.
//
//   fovea-map-accuracy [--scene living-room] [--path orbit] [--frames 60] [--size 640x480] [--every 10]
//
// Every --every frames (and at the last) the map's stable surfels are drawn
// into that frame's view (z-buffered: only the visible ones) and compared with
// the noiseless depth at each pixel, along the pixel's ray (the surfel's plane
// met by the ray); the noisy frame is compared the same way. Printed: the RMS
// of each and their ratio, and the share of the true surface in view that has
// a surfel within 1 cm. An evaluation tool: it allocates freely.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "hal/camera.h"
#include "pipeline/map/surfel_map.h"

namespace {

using fovea::hal::RgbdFrame;
using fovea::pipeline::map::SurfelMap;

struct Totals {
  double map_sq = 0.0, frame_sq = 0.0;
  std::size_t map_n = 0, frame_n = 0;
  std::size_t true_pixels = 0, covered = 0;
  std::vector<float> map_abs, frame_abs;  // |error| of every compared pixel, for the median
};

float median(std::vector<float>& v) {
  if (v.empty()) return 0.0f;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// The depth of each valid pixel of `truth` against the noisy frame and the map.
void evaluate(const SurfelMap& map, const RgbdFrame& noisy, const RgbdFrame& truth, Totals& t) {
  const int w = truth.width(), h = truth.height();
  const fovea::hal::CameraIntrinsics& k = truth.intrinsics;
  const Eigen::Matrix3d R_cw = truth.T_world_cam.R_world_cam.transpose();
  const Eigen::Vector3d& cam = truth.T_world_cam.t_world_cam;
  std::vector<double> seen(static_cast<std::size_t>(w) * h, std::numeric_limits<double>::infinity());
  for (std::size_t slot = 0; slot < map.slotCount(); ++slot) {
    if (!map.live(slot) || !(map.surfel(slot).flags & fovea::pipeline::map::kSurfelStable)) continue;
    const Eigen::Vector3d p = R_cw * (map.worldPosition(slot) - cam);
    if (p.z() < 0.05) continue;
    const long u = std::lround(k.fx * p.x() / p.z() + k.cx), v = std::lround(k.fy * p.y() / p.z() + k.cy);
    if (u < 0 || v < 0 || u >= w || v >= h) continue;
    // The surfel's disc over its footprint (at most 2 pixels around, as the map
    // draws it), at the depth where each pixel's ray meets its plane.
    const Eigen::Vector3d n = R_cw * fovea::pipeline::map::surfelNormal(map.surfel(slot)).cast<double>();
    const double footprint = 0.5 * (k.fx + k.fy) * fovea::pipeline::map::surfelRadius(map.surfel(slot)) / p.z();
    const long reach = std::min(2L, static_cast<long>(footprint));
    for (long dv = -reach; dv <= reach; ++dv) {
      for (long du = -reach; du <= reach; ++du) {
        const long x = u + du, y = v + dv;
        if (x < 0 || y < 0 || x >= w || y >= h || du * du + dv * dv > reach * reach) continue;
        const Eigen::Vector3d ray((static_cast<double>(x) - k.cx) / k.fx, (static_cast<double>(y) - k.cy) / k.fy, 1.0);
        const double along = n.dot(ray);
        const double z = std::abs(along) > 0.2 * ray.norm() ? n.dot(p) / along : p.z();
        double& held = seen[static_cast<std::size_t>(y) * w + static_cast<std::size_t>(x)];
        if (z < held) held = z;
      }
    }
  }
  for (std::size_t i = 0; i < seen.size(); ++i) {
    const uint16_t raw_true = truth.depth()[i];
    if (raw_true == 0) continue;
    const double z_true = raw_true * truth.depth_scale_m;
    ++t.true_pixels;
    if (std::isfinite(seen[i])) {
      const double e = seen[i] - z_true;
      t.map_sq += e * e;
      ++t.map_n;
      t.map_abs.push_back(static_cast<float>(std::abs(e)));
      if (std::abs(e) <= 0.01) ++t.covered;
    }
    if (const uint16_t raw = noisy.depth()[i]; raw != 0) {
      const double e = raw * noisy.depth_scale_m - z_true;
      t.frame_sq += e * e;
      ++t.frame_n;
      t.frame_abs.push_back(static_cast<float>(std::abs(e)));
    }
  }
}

std::string option(int argc, char** argv, const char* name, const char* fallback) {
  for (int i = 1; i + 1 < argc; ++i) {
    if (std::strcmp(argv[i], name) == 0) return argv[i + 1];
  }
  return fallback;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string scene = option(argc, argv, "--scene", "living-room");
  const std::string path = option(argc, argv, "--path", "orbit");
  const std::string size = option(argc, argv, "--size", "640x480");
  const int frames = std::atoi(option(argc, argv, "--frames", "60").c_str());
  const int every = std::atoi(option(argc, argv, "--every", "10").c_str());
  if (frames < 1 || every < 1) {
    std::fprintf(stderr, "fovea-map-accuracy: --frames and --every must be at least 1\n");
    return 2;
  }
  const std::string spec = "mock:" + scene + ",path=" + path + ",size=" + size;
  auto noisy_cam = fovea::hal::createCamera(spec);
  auto truth_cam = fovea::hal::createCamera(spec + ",noise=off");
  if (!noisy_cam || !truth_cam) {
    std::fprintf(stderr, "fovea-map-accuracy: %s\n", (noisy_cam ? truth_cam.status() : noisy_cam.status()).message().c_str());
    return 2;
  }
  fovea::hal::Camera& a = *noisy_cam.value();
  fovea::hal::Camera& b = *truth_cam.value();
  if (!a.open() || !a.start() || !b.open() || !b.start()) {
    std::fprintf(stderr, "fovea-map-accuracy: the mock camera did not start\n");
    return 1;
  }
  const fovea::hal::CameraIntrinsics& k = a.info().intrinsics;
  fovea::pipeline::map::SurfelMapConfig config;
  config.max_width = k.width;
  config.max_height = k.height;
  SurfelMap map = SurfelMap::create(config).value();
  RgbdFrame noisy(k.width, k.height), truth(k.width, k.height);
  Totals totals;
  std::vector<double> fuse_ms;
  for (int i = 0; i < frames; ++i) {
    if (!a.acquire(noisy, std::chrono::seconds(5)) || !b.acquire(truth, std::chrono::seconds(5))) {
      std::fprintf(stderr, "fovea-map-accuracy: frame %d did not arrive\n", i);
      return 1;
    }
    fovea::pipeline::map::FuseStats stats;
    if (map.fuse(noisy, stats) != fovea::pipeline::map::FuseOutcome::kFused) {
      std::fprintf(stderr, "fovea-map-accuracy: frame %d: %s\n", i,
                   std::string(fovea::pipeline::map::fuseOutcomeName(stats.outcome)).c_str());
      return 1;
    }
    fuse_ms.push_back(static_cast<double>(stats.fuse_ns) * 1e-6);
    if ((i + 1) % every == 0 || i + 1 == frames) evaluate(map, noisy, truth, totals);
  }
  const double map_rms = totals.map_n ? std::sqrt(totals.map_sq / static_cast<double>(totals.map_n)) : 0.0;
  const double frame_rms = totals.frame_n ? std::sqrt(totals.frame_sq / static_cast<double>(totals.frame_n)) : 0.0;
  std::printf("%s: %d frames, evaluated every %d; map %zu surfels\n", spec.c_str(), frames, every, map.size());
  std::printf("depth error against the noiseless twin, RMS [mm]: map %.2f (%zu pixels), single frame %.2f (%zu pixels), "
              "ratio %.3f\n", map_rms * 1e3, totals.map_n, frame_rms * 1e3, totals.frame_n,
              frame_rms > 0.0 ? map_rms / frame_rms : 0.0);
  std::printf("median |depth error| [mm]: map %.2f, single frame %.2f\n", median(totals.map_abs) * 1e3,
              median(totals.frame_abs) * 1e3);
  std::printf("true surface in view with a stable surfel within 1 cm: %.1f %% (%zu of %zu pixels)\n",
              totals.true_pixels ? 100.0 * static_cast<double>(totals.covered) / static_cast<double>(totals.true_pixels) : 0.0,
              totals.covered, totals.true_pixels);
  std::sort(fuse_ms.begin(), fuse_ms.end());
  std::printf("fusion time per frame [ms]: median %.2f (scalar reference, one thread)\n", fuse_ms[fuse_ms.size() / 2]);
  return 0;
}
