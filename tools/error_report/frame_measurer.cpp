// fovea-error-report: one configuration on one frame, timed, then its error and
// bytes into its record; and the true surface of a frame from the noiseless twin.
#include "tools/error_report/frame_measurer.h"

#include <array>
#include <span>

#include <time.h>

namespace fovea::tools {

double msBetween(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

bool backprojectTruth(hal::Camera& twin, const hal::RgbdFrame& frame, const pipeline::RawDepthRange& raw_range,
                      const pipeline::DepthRange& range, hal::RgbdFrame& truth_frame, pipeline::PointCloud& truth_cloud,
                      pipeline::PointCloud* surface) {
  if (!twin.acquire(truth_frame, std::chrono::seconds(2))) return false;
  if (surface != nullptr) {
    pipeline::BackprojectCounts surface_counts;
    if (!pipeline::backprojectRef(truth_frame, range, *surface, surface_counts)) return false;
  }
  const auto valid = [&](uint16_t raw) { return raw >= raw_range.min && raw <= raw_range.max; };
  const uint16_t* noisy = frame.depth();
  uint16_t* clean = truth_frame.depth();
  for (std::size_t i = 0; i < frame.pixelCount(); ++i) {
    if (!valid(noisy[i]) || !valid(clean[i])) clean[i] = noisy[i];
  }
  pipeline::BackprojectCounts truth_counts;
  return pipeline::backprojectRef(truth_frame, range, truth_cloud, truth_counts).isOk();
}

Status Measurer::measure(const hal::RgbdFrame& frame, const pipeline::Gaze& gaze, const pipeline::PointCloud* truth,
                         const pipeline::PointCloud* surface, ConfigRun& r) {
  if (Status s = foveator.setConfig(r.config); !s) return s;
  pipeline::BackprojectCounts counts;
  pipeline::FoveationStats stats;
  const double cpu0 = threadCpuMs();
  const auto t0 = std::chrono::steady_clock::now();
  Status s = pipeline::backprojectRef(frame, range, cloud, counts);
  if (s) s = foveator.foveate(cloud, gaze, out, stats);
  const auto t1 = std::chrono::steady_clock::now();
  const double cpu1 = threadCpuMs();
  if (s) s = foveator.foveate(cloud, gaze, out, stats, representative.data());
  if (!s) return s;
  return record(foveator, cloud, gaze, stats, truth, surface, cpu1 - cpu0, msBetween(t0, t1), r);
}

Status Measurer::measureMap(firmware::FrameFoveator& map, const pipeline::Gaze& gaze, const pipeline::PointCloud* surface,
                            double fuse_cpu_ms, double fuse_wall_ms, ConfigRun& r) {
  if (Status s = map.use(&r.config); !s) return s;
  pipeline::FoveationStats stats;
  const double cpu0 = threadCpuMs();
  const auto t0 = std::chrono::steady_clock::now();
  Status s = map.foveate(gaze, out, stats);
  const auto t1 = std::chrono::steady_clock::now();
  const double cpu1 = threadCpuMs();
  if (s) s = map.foveator().foveate(map.cloud(), gaze, out, stats, representative.data());
  if (!s) return s;
  r.fuse_ms.push_back(fuse_cpu_ms);
  r.map_frame_points += map.mapFigures().frame_points;
  r.map_surfels += map.mapFigures().eye.appended;
  return record(map.foveator(), map.cloud(), gaze, stats, nullptr, surface, fuse_cpu_ms + cpu1 - cpu0,
                fuse_wall_ms + msBetween(t0, t1), r);
}

Status Measurer::record(pipeline::Foveator& used, const pipeline::PointCloud& in, const pipeline::Gaze& gaze,
                        const pipeline::FoveationStats& stats, const pipeline::PointCloud* truth,
                        const pipeline::PointCloud* surface, double cpu_ms, double wall_ms, ConfigRun& r) {
  pipeline::ErrorModel error_model{&used.model(), {}, reference_slope};
  for (int reg = 0; reg < stats.region_count; ++reg) error_model.voxel_size_m[reg] = stats.regions[reg].voxel_size_m;
  pipeline::ErrorMetrics metrics;
  Status s = evaluator.evaluate(in, used.lastRegions(), representative.data(), out.points, gaze, error_model, metrics);
  std::array<uint64_t, pipeline::kMaxRegions> wire_bytes{};
  uint64_t wire_total = 0;
  if (s) {
    std::array<double, pipeline::kMaxRegions> voxel_m{};
    for (int reg = 0; reg < stats.region_count; ++reg) voxel_m[reg] = stats.regions[reg].voxel_size_m;
    s = encoder.encode(out, std::span<const double>(voxel_m.data(), stats.region_count), 0, 0);
    for (std::size_t i = 0; s && i < encoder.chunkCount(); ++i) {
      wire_bytes[encoder.chunkRegion(i)] += encoder.chunk(i).size() + net::kDatagramOverhead;
      wire_total += encoder.chunk(i).size() + net::kDatagramOverhead;
    }
  }
  SurfaceError surface_error;
  if (s && surface != nullptr) {
    s = surface_evaluator.evaluate(*surface, out.points, gaze, used.model().slope(), reference_slope, surface_error);
  }
  if (!s) return s;
  r.time_ms.push_back(cpu_ms);
  r.wall_ms.push_back(wall_ms);
  // (ACUITY has no d0: its column says "-".)
  if (stats.fixation.source != pipeline::FixationSource::kNone) r.d0_m.push_back(stats.fixation.d0_m);
  for (int reg = 0; reg < stats.region_count; ++reg) {
    r.regions[reg].add(metrics.regions[reg], stats.regions[reg].points_in, stats.regions[reg].points_out,
                       stats.regions[reg].voxel_size_m, wire_bytes[reg]);
  }
  r.all.add(metrics.all, stats.points_in, stats.points_out, 0.0, wire_total);
  if (truth != nullptr) {
    pipeline::ErrorMetrics truth_metrics;
    if (evaluator.evaluate(*truth, used.lastRegions(), representative.data(), out.points, gaze, error_model,
                           truth_metrics)) {
      r.truth.add(truth_metrics.all, 0, 0, 0.0, 0);
    }
  }
  if (surface != nullptr) {
    r.surface.add(surface_error);
    ++r.surface_frames;
  }
  r.at_eye += metrics.at_eye;
  r.no_representative += metrics.no_representative;
  ++r.frames;
  return Status::ok();
}

}  // namespace fovea::tools
