// fovea-map-delta: the bytes a stream of map changes (pipeline/map/map_delta.h:
// bricks at the level the eye needs, sent once and again only when due) would
// send, against the frame-by-frame streams FREF and F1, on the mock camera with
// a scripted gaze, and how close what the operator then holds lies to the true
// surface. One process, no sockets, no loss: every stream is encoded by the
// same codec (net/codec.h) and counted in datagram bytes (payload plus the
// datagram's header and tag); the map's bricks carry their brick tag and are
// decoded into the operator's cache (net/brick_cache.h).
//
//   fovea-map-delta [--scene living-room] [--path static] [--frames 90] [--size 640x480]
//                   [--budget-mbps 12.5] [--fps 30] [--dwell-frames 9] [--eval-every 15]
//
// The gaze: the operator's eye at the camera, fixating the scene's focus point
// and four points 0.25-0.4 m around it in turn, --dwell-frames frames each
// (9: 300 ms at 30 fps), with an instant saccade between.
//
// MAP-DELTA each frame: the bricks the plan makes due in the fovea, then the
// frame's points the map does not explain (ACUITY-foveated, as today's
// chunks), then the other due bricks, while the frame's share of the budget
// lasts; the rest waits.
//
// Quality, every --eval-every frames from the second second on and at the
// last: for each point of the true surface the frame sees (the mock camera's
// noiseless twin, back-projected), the nearest point of what the operator
// draws (FREF's or F1's decoded frame; for MAP-DELTA the cache's bricks and the
// frame's live points), and whether it is displaced, seen from the eye, by more
// than the MAR at the true point's eccentricity (Eq. 1, m = 0.022). A
// nearest-point measure, unlike fovea-eval's (each input point against its own
// representative). An evaluation tool: it allocates freely.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Geometry>

#include "bench/bench_input.h"
#include "hal/camera.h"
#include "net/brick_cache.h"
#include "net/codec.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/map/brick_batch.h"
#include "pipeline/map/map_delta.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/voxel_sampler.h"

namespace {

using namespace fovea;
using bench::option;

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// Datagram bytes of the encoder's last encode.
std::size_t datagramBytes(const net::ChunkEncoder& encoder) {
  std::size_t bytes = 0;
  for (std::size_t i = 0; i < encoder.chunkCount(); ++i) bytes += encoder.chunk(i).size() + net::kDatagramOverhead;
  return bytes;
}

// Decodes every chunk of the encoder's last encode: brick chunks into `cache`,
// frame chunks appended to `held` (world positions).
void decodeAll(const net::ChunkEncoder& encoder, net::BrickCache* cache, std::vector<Eigen::Vector3d>* held,
               pipeline::FoveatedCloud& scratch, int64_t now_ns) {
  alignas(16) static uint8_t aligned[net::kMaxMtu];
  for (std::size_t i = 0; i < encoder.chunkCount(); ++i) {
    const std::span<const uint8_t> c = encoder.chunk(i);
    std::memcpy(aligned, c.data(), c.size());
    scratch.clear();
    fovea::Result<net::DecodedChunk> d = net::decodeChunk(std::span<const uint8_t>(aligned, c.size()), scratch);
    if (!d) {
      std::fprintf(stderr, "fovea-map-delta: a chunk did not decode: %s\n", d.status().message().c_str());
      std::exit(1);
    }
    if (cache) cache->add(d.value(), scratch, 0, now_ns);
    if (held) {
      for (std::size_t p = 0; p < scratch.size(); ++p) held->push_back(scratch.points.world(p));
    }
  }
}

// The share of the true surface's points (a noiseless frame's) whose nearest
// point of `held` is displaced, seen from the eye, by more than the MAR at the
// point's eccentricity (Eq. 1, slope m). A true point with no held point within
// 10 cm counts as displaced (`missing`).
double shareAboveMar(const std::vector<Eigen::Vector3d>& held, const pipeline::PointCloud& truth,
                     const pipeline::Gaze& gaze, double slope, std::size_t& missing) {
  constexpr double kCell = 0.02;
  constexpr int kRings = 5;
  auto cellOf = [](const Eigen::Vector3d& p) {
    return Eigen::Vector3i(static_cast<int>(std::floor(p.x() / kCell)), static_cast<int>(std::floor(p.y() / kCell)),
                           static_cast<int>(std::floor(p.z() / kCell)));
  };
  auto key = [](const Eigen::Vector3i& c) {
    return (static_cast<int64_t>(c.x() & 0x1fffff) << 42) | (static_cast<int64_t>(c.y() & 0x1fffff) << 21) |
           static_cast<int64_t>(c.z() & 0x1fffff);
  };
  std::unordered_map<int64_t, std::vector<uint32_t>> grid;
  for (std::size_t i = 0; i < held.size(); ++i) grid[key(cellOf(held[i]))].push_back(static_cast<uint32_t>(i));
  const Eigen::Vector3d l = gaze.direction.normalized();
  std::size_t above = 0, seen = 0;
  missing = 0;
  for (std::size_t t = 0; t < truth.size(); ++t) {
    const Eigen::Vector3d p = truth.world(t);
    const Eigen::Vector3i c = cellOf(p);
    double best = std::numeric_limits<double>::infinity();
    int nearest = -1;
    for (int r = 0; r <= kRings && !(best <= (r - 1) * kCell); ++r) {
      for (int dx = -r; dx <= r; ++dx) {
        for (int dy = -r; dy <= r; ++dy) {
          for (int dz = -r; dz <= r; ++dz) {
            if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;  // the ring's shell only
            const auto it = grid.find(key(c + Eigen::Vector3i(dx, dy, dz)));
            if (it == grid.end()) continue;
            for (uint32_t i : it->second) {
              const double d = (held[i] - p).norm();
              if (d < best) {
                best = d;
                nearest = static_cast<int>(i);
              }
            }
          }
        }
      }
    }
    ++seen;
    if (nearest < 0 || best > kRings * kCell) {
      ++missing;
      ++above;
      continue;
    }
    const Eigen::Vector3d a = p - gaze.origin_m, b = held[static_cast<std::size_t>(nearest)] - gaze.origin_m;
    const double alpha = std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
    const double ecc = std::atan2(a.cross(l).norm(), a.dot(l)) * 180.0 / M_PI;
    above += alpha > slope * ecc + pipeline::kMar0Deg ? 1 : 0;
  }
  return seen > 0 ? static_cast<double>(above) / static_cast<double>(seen) : 0.0;
}

struct Stream {
  const char* name;
  std::size_t bytes = 0;         // all frames
  std::size_t bytes_steady = 0;  // after the first second
};

}  // namespace

int main(int argc, char** argv) {
  const std::string scene = option(argc, argv, "--scene", "living-room");
  const std::string path = option(argc, argv, "--path", "static");
  const std::string size = option(argc, argv, "--size", "640x480");
  const int frames = std::atoi(option(argc, argv, "--frames", "90").c_str());
  const double budget_mbps = std::atof(option(argc, argv, "--budget-mbps", "12.5").c_str());
  const int fps = std::atoi(option(argc, argv, "--fps", "30").c_str());
  const int dwell = std::atoi(option(argc, argv, "--dwell-frames", "9").c_str());
  const int eval_every = std::atoi(option(argc, argv, "--eval-every", "15").c_str());
  if (frames < 1 || fps < 1 || dwell < 1 || eval_every < 1 || !(budget_mbps > 0.0)) {
    std::fprintf(stderr,
                 "fovea-map-delta: --frames, --fps, --dwell-frames, --eval-every and --budget-mbps must be positive\n");
    return 2;
  }
  const std::string spec = "mock:" + scene + ",path=" + path + ",size=" + size;
  auto created_cam = hal::createCamera(spec);
  auto created_truth = hal::createCamera(spec + ",noise=off");  // the same path, noiseless: the true surface
  if (!created_cam || !created_truth) {
    std::fprintf(stderr, "fovea-map-delta: %s\n",
                 (created_cam ? created_truth.status() : created_cam.status()).message().c_str());
    return 2;
  }
  hal::Camera& camera = *created_cam.value();
  hal::Camera& truth_camera = *created_truth.value();
  if (!camera.open() || !camera.start() || !truth_camera.open() || !truth_camera.start()) {
    std::fprintf(stderr, "fovea-map-delta: the mock camera did not start\n");
    return 1;
  }
  const hal::CameraIntrinsics& k = camera.info().intrinsics;
  const std::size_t pixels = static_cast<std::size_t>(k.width) * k.height;
  const Eigen::Vector3d focus = camera.info().focus_point_m.value_or(Eigen::Vector3d(0, 0, 2));

  pipeline::map::SurfelMapConfig map_config;
  map_config.max_width = k.width;
  map_config.max_height = k.height;
  pipeline::map::SurfelMap map = pipeline::map::SurfelMap::create(map_config).value();
  const pipeline::map::MapDeltaConfig delta_config;
  pipeline::map::MapDelta delta = pipeline::map::MapDelta::create(delta_config, map_config.max_bricks).value();

  pipeline::PipelineCapacity capacity;
  capacity.max_points = capacity.max_voxels = pixels;
  pipeline::FoveationConfig f1;
  f1.acuity.preset = pipeline::Preset::kF1;
  pipeline::FoveationConfig acuity;
  acuity.acuity = delta_config.acuity;
  pipeline::Foveator f1_foveator = pipeline::Foveator::create(capacity, f1).value();
  pipeline::Foveator live_foveator = pipeline::Foveator::create(capacity, acuity).value();
  // A brick holds at most this many stable surfels here (the mock room's hold a few thousand).
  constexpr std::size_t kMaxBrickPoints = 1 << 18;
  net::ChunkEncoder encoder = net::ChunkEncoder::create(net::CodecConfig{}, std::max(pixels, kMaxBrickPoints)).value();
  pipeline::map::BrickSampler brick_sampler =
      pipeline::map::BrickSampler::create(delta_config.acuity, kMaxBrickPoints).value();
  pipeline::map::BrickBatch batch(kMaxBrickPoints, 1);
  pipeline::PointCloud cloud(pixels), live(pixels);
  pipeline::FoveatedCloud out(pixels);
  // The operator's side: the bricks it holds (no loss here), and the last
  // frame's decoded F1 and live points.
  net::BrickCacheConfig cache_config;
  cache_config.max_points = std::size_t{1} << 23;
  net::BrickCache cache = net::BrickCache::create(cache_config).value();
  pipeline::FoveatedCloud decoded(std::max(pixels, kMaxBrickPoints));
  std::vector<Eigen::Vector3d> f1_held, live_held;
  hal::RgbdFrame truth(k.width, k.height);
  pipeline::PointCloud truth_cloud(pixels);
  std::vector<double> above_mar[3], held_points, f1_points;  // FREF, F1, MAP-DELTA held
  std::size_t missing_points[3] = {};

  Stream fref{"FREF"}, f1_stream{"F1"}, bricks{"MAP-DELTA bricks"}, live_stream{"MAP-DELTA live"};
  const double budget_per_frame = budget_mbps * 1e6 / fps;
  std::vector<double> plan_ms, brick_encode_ms;
  std::size_t live_points = 0;  // after the first second
  std::size_t bricks_sent = 0, bricks_waited = 0, brick_points_sent = 0;
  hal::RgbdFrame frame(k.width, k.height);
  const Eigen::Vector3d offsets[5] = {{0, 0, 0}, {0.4, 0.25, 0}, {-0.4, 0.25, 0}, {-0.4, -0.25, 0}, {0.4, -0.25, 0}};
  for (int f = 0; f < frames; ++f) {
    if (!camera.acquire(frame, std::chrono::seconds(5)) || !truth_camera.acquire(truth, std::chrono::seconds(5))) {
      std::fprintf(stderr, "fovea-map-delta: frame %d did not arrive\n", f);
      return 1;
    }
    const bool steady = f >= fps;
    pipeline::Gaze gaze;
    gaze.origin_m = frame.T_world_cam.t_world_cam;
    const Eigen::Vector3d target = focus + frame.T_world_cam.R_world_cam * offsets[(f / dwell) % 5];
    gaze.direction = (target - gaze.origin_m).normalized();
    const auto frame_id = static_cast<uint32_t>(f);
    const int64_t now_ns = static_cast<int64_t>(f) * 1'000'000'000 / fps;
    auto count = [&](Stream& s, std::size_t bytes) {
      s.bytes += bytes;
      if (steady) s.bytes_steady += bytes;
    };

    // The frame-by-frame streams: FREF (every point) and F1.
    pipeline::BackprojectCounts bp;
    cloud.clear();
    if (!pipeline::backprojectRef(frame, map_config.depth, cloud, bp)) return 1;
    out.points.origin_m = cloud.origin_m;
    std::copy_n(cloud.x(), cloud.size(), out.points.x());
    std::copy_n(cloud.y(), cloud.size(), out.points.y());
    std::copy_n(cloud.z(), cloud.size(), out.points.z());
    std::copy_n(cloud.rgb(), cloud.size(), out.points.rgb());
    std::fill_n(out.region.begin(), cloud.size(), uint8_t{0});
    std::fill_n(out.weight.begin(), cloud.size(), 1u);
    if (!out.points.resize(cloud.size())) return 1;
    const double fovea_only[1] = {0.0};
    if (!encoder.encode(out, fovea_only, frame_id, 0)) return 1;
    count(fref, datagramBytes(encoder));
    pipeline::FoveationStats fs;
    if (!f1_foveator.foveate(cloud, gaze, out, fs)) return 1;
    double sizes[pipeline::kMaxRegions] = {};
    for (int r = 0; r < fs.region_count; ++r) sizes[r] = fs.regions[r].voxel_size_m;
    if (!encoder.encode(out, std::span<const double>(sizes, static_cast<std::size_t>(fs.region_count)), frame_id, 0)) {
      return 1;
    }
    count(f1_stream, datagramBytes(encoder));
    f1_held.clear();
    decodeAll(encoder, nullptr, &f1_held, decoded, now_ns);

    // MAP-DELTA.
    pipeline::map::FuseStats fuse;
    if (map.fuse(frame, fuse) != pipeline::map::FuseOutcome::kFused) {
      std::fprintf(stderr, "fovea-map-delta: frame %d: %s\n", f,
                   std::string(pipeline::map::fuseOutcomeName(fuse.outcome)).c_str());
      return 1;
    }
    pipeline::map::MapDeltaStats ds;
    auto plan = delta.plan(map, gaze, ds);
    if (!plan) return 1;
    plan_ms.push_back(static_cast<double>(ds.ns) * 1e-6);
    double left = budget_per_frame;
    bool live_sent = false;
    auto sendLive = [&] {
      live_sent = true;
      live_held.clear();
      live.clear();
      live.origin_m = cloud.origin_m;
      map.appendUnexplained(frame, live);
      if (steady) live_points += live.size();
      pipeline::FoveationStats ls;
      if (live.size() == 0 || !live_foveator.foveate(live, gaze, out, ls)) return;
      double live_sizes[pipeline::kMaxRegions] = {};
      for (int r = 0; r < ls.region_count; ++r) live_sizes[r] = ls.regions[r].voxel_size_m;
      if (!encoder.encode(out, std::span<const double>(live_sizes, static_cast<std::size_t>(ls.region_count)),
                          frame_id, 0)) {
        return;
      }
      const std::size_t bytes = datagramBytes(encoder);
      count(live_stream, bytes);
      left -= static_cast<double>(bytes);
      decodeAll(encoder, nullptr, &live_held, decoded, now_ns);
    };
    const auto encode_start = std::chrono::steady_clock::now();
    for (const pipeline::map::BrickDue& due : plan.value()) {
      if (!due.fovea && !live_sent) sendLive();
      if (left <= 0.0) {
        ++bricks_waited;
        continue;
      }
      // One brick at a time through the service's sampler (pipeline/map/brick_batch.h).
      uint32_t version = delta.version(due.brick) + 1;
      if (version == 0) version = 1;
      batch.clear(map.brickOrigin(due.brick));
      if (!brick_sampler.append(map, due.brick, due.level, version, due.fovea, batch)) return 1;
      const pipeline::map::BrickBatchEntry& e = batch.entries()[0];
      const net::BrickTag tag{e.key.x, e.key.y, e.key.z, e.version, e.level};
      if (!encoder.encode(batch.points, std::span<const double>(batch.level_step_m.data(), due.level + 1u), frame_id, 0,
                          &tag)) {
        return 1;
      }
      const std::size_t bytes = datagramBytes(encoder);
      decodeAll(encoder, &cache, nullptr, decoded, now_ns);
      count(bricks, bytes);
      left -= static_cast<double>(bytes);
      brick_points_sent += batch.points.size();
      ++bricks_sent;
      delta.markSent(map, due.brick, due.level);
    }
    if (!live_sent) sendLive();
    brick_encode_ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - encode_start).count());

    // Every --eval-every frames after the first second, and at the last: what
    // the operator holds when it draws this frame (its bricks and this frame's
    // live points), against the true surface the frame sees, from this gaze;
    // FREF's and F1's frame the same way.
    if ((f >= fps && (f - fps) % eval_every == 0) || f == frames - 1) {
      pipeline::BackprojectCounts truth_counts;
      truth_cloud.clear();
      if (!pipeline::backprojectRef(truth, map_config.depth, truth_cloud, truth_counts)) return 1;
      std::vector<Eigen::Vector3d> held = live_held;
      for (std::size_t s = 0; s < cache.slotCount(); ++s) {
        if (!cache.held(s)) continue;
        cache.forEachPoint(s, [&](const Eigen::Vector3d& p, uint32_t) { held.push_back(p); });
      }
      std::vector<Eigen::Vector3d> fref_held(cloud.size());
      for (std::size_t i = 0; i < cloud.size(); ++i) fref_held[i] = cloud.world(i);
      std::size_t missing = 0;
      above_mar[0].push_back(100.0 * shareAboveMar(fref_held, truth_cloud, gaze, pipeline::kDefaultSlope, missing));
      missing_points[0] += missing;
      above_mar[1].push_back(100.0 * shareAboveMar(f1_held, truth_cloud, gaze, pipeline::kDefaultSlope, missing));
      missing_points[1] += missing;
      above_mar[2].push_back(100.0 * shareAboveMar(held, truth_cloud, gaze, pipeline::kDefaultSlope, missing));
      missing_points[2] += missing;
      held_points.push_back(static_cast<double>(held.size()));
      f1_points.push_back(static_cast<double>(f1_held.size()));
    }
  }

  // The plan's worst case on the final map: an operator that holds nothing
  // (every brick due, all sorted), median of 21.
  std::vector<double> cold_ms;
  {
    pipeline::map::MapDelta cold = pipeline::map::MapDelta::create(delta_config, map_config.max_bricks).value();
    pipeline::Gaze gaze;
    gaze.origin_m = frame.T_world_cam.t_world_cam;
    gaze.direction = (focus - gaze.origin_m).normalized();
    for (int i = 0; i < 21; ++i) {
      cold.forgetAll();
      pipeline::map::MapDeltaStats ds;
      if (!cold.plan(map, gaze, ds)) return 1;
      cold_ms.push_back(static_cast<double>(ds.ns) * 1e-6);
    }
  }
  const double seconds = static_cast<double>(frames) / fps;
  const double steady_seconds = static_cast<double>(std::max(0, frames - fps)) / fps;
  std::printf("fovea-map-delta: %s, %d frames at %d fps, gaze: 5 fixations of %d frames, budget %.1f MB/s\n",
              spec.c_str(), frames, fps, dwell, budget_mbps);
  std::printf("  %-18s %10s %10s %16s %12s\n", "stream", "MB/s", "vs FREF", "MB/s after 1 s", "vs FREF");
  const Stream delta_total{"MAP-DELTA", bricks.bytes + live_stream.bytes, bricks.bytes_steady + live_stream.bytes_steady};
  for (const Stream* s : std::initializer_list<const Stream*>{&fref, &f1_stream, &delta_total, &bricks, &live_stream}) {
    const double rate = static_cast<double>(s->bytes) / seconds * 1e-6;
    const double steady_rate = steady_seconds > 0 ? static_cast<double>(s->bytes_steady) / steady_seconds * 1e-6 : 0.0;
    const double vs = 100.0 * (1.0 - static_cast<double>(s->bytes) / static_cast<double>(fref.bytes));
    const double vs_steady =
        fref.bytes_steady > 0 ? 100.0 * (1.0 - static_cast<double>(s->bytes_steady) / static_cast<double>(fref.bytes_steady))
                              : 0.0;
    std::printf("  %-18s %10.3f %9.1f%% %16.3f %11.1f%%\n", s->name, rate, vs, steady_rate, vs_steady);
  }
  std::printf("  live points after 1 s: %.0f a frame\n", frames > fps ? static_cast<double>(live_points) / (frames - fps) : 0.0);
  std::printf("  bricks sent %zu (%zu points), waited %zu brick-frames; map %zu surfels in %zu bricks\n",
              bricks_sent, brick_points_sent, bricks_waited, map.size(), map.brickCount());
  std::printf("  plan: median %.3f ms, max %.3f ms a frame; brick sampling and encoding: median %.3f ms a frame\n",
              median(plan_ms), *std::max_element(plan_ms.begin(), plan_ms.end()), median(brick_encode_ms));
  std::printf("  plan with every brick due (an operator that holds nothing): median %.3f ms\n", median(cold_ms));
  auto mean = [](const std::vector<double>& v) {
    double sum = 0.0;
    for (double x : v) sum += x;
    return v.empty() ? 0.0 : sum / static_cast<double>(v.size());
  };
  std::printf("  what the operator holds, against the true surface (the noiseless twin), %zu frames from the second on:\n",
              above_mar[0].size());
  std::printf("    share above the MAR (m %.3f), mean [min, max]: FREF %.2f %% [%.2f, %.2f], F1 %.2f %% [%.2f, %.2f], "
              "MAP-DELTA held %.2f %% [%.2f, %.2f]\n",
              pipeline::kDefaultSlope, mean(above_mar[0]), *std::min_element(above_mar[0].begin(), above_mar[0].end()),
              *std::max_element(above_mar[0].begin(), above_mar[0].end()), mean(above_mar[1]),
              *std::min_element(above_mar[1].begin(), above_mar[1].end()),
              *std::max_element(above_mar[1].begin(), above_mar[1].end()), mean(above_mar[2]),
              *std::min_element(above_mar[2].begin(), above_mar[2].end()),
              *std::max_element(above_mar[2].begin(), above_mar[2].end()));
  std::printf("    points drawn, mean: F1 %.0f, MAP-DELTA held %.0f; true points with nothing within 10 cm: FREF %zu, F1 %zu, "
              "MAP-DELTA %zu\n",
              mean(f1_points), mean(held_points), missing_points[0], missing_points[1], missing_points[2]);
  return 0;
}
