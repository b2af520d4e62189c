// fovea-error-report's measurement, step by step: set-up (every buffer sized
// once), the camera started, the map's warm-up, the measured frames, the
// figures over time.
#include "tools/error_report/measure.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <utility>

#include <unistd.h>

#include "firmware/frame_foveator.h"
#include "firmware/mcap_camera.h"
#include "net/codec.h"
#include "pipeline/backproject.h"
#include "pipeline/error_metrics.h"
#include "pipeline/foveator.h"
#include "tools/common/host.h"
#include "tools/error_report/exit_code.h"
#include "tools/error_report/frame_measurer.h"
#include "tools/error_report/gaze.h"
#include "tools/error_report/surface_error.h"

namespace fovea::tools {
namespace {

// The map source (--sources with map): the service's map at its defaults, fed
// the same frames; its cloud (and so the output) holds the map's surfels too.
firmware::MapSettings reportMapSettings() {
  firmware::MapSettings map_settings;
  map_settings.source = firmware::FoveationSource::kMap;
  map_settings.map.kernels = fovea::KernelSet::kRef;  // the report times the scalar references throughout
  return map_settings;
}

// One measurement on an open camera: what it uses, sized once at start-up (one
// Foveator reconfigured per configuration), and its steps in order. Each step
// returns kExitOk or the exit code of a run that cannot go on, having said why
// on standard error.
class MeasurementRun {
 public:
  MeasurementRun(const Options& options, hal::Camera& camera, Measurement& result)
      : options_(options),
        camera_(camera),
        result_(result),
        info_(camera.info()),
        width_(info_.intrinsics.width),
        height_(info_.intrinsics.height),
        max_points_(static_cast<std::size_t>(width_) * height_),
        map_settings_(reportMapSettings()),
        cloud_points_(options.hasMap() ? firmware::FrameFoveator::cloudCapacity(max_points_, map_settings_)
                                       : max_points_),
        truth_frame_(width_, height_),
        truth_cloud_(max_points_),
        // The true surface for the nearest-point measure (only with the map source: it
        // costs a nearest-neighbour search per true point and configuration).
        surface_cloud_(options.hasMap() ? max_points_ : 0),
        surface_evaluator_(options.hasMap() ? cloud_points_ : 0),
        raw_range_(pipeline::rawDepthRange(pipeline::DepthRange{}, info_.depth_scale_m)),
        frame_(width_, height_),
        cloud_(max_points_),
        out_(cloud_points_),
        representative_(cloud_points_) {}
  MeasurementRun(const MeasurementRun&) = delete;
  MeasurementRun& operator=(const MeasurementRun&) = delete;

  // The configurations, the foveators, the evaluators, the codec and the noiseless twin.
  int setUp() {
    result_.runs = planRuns(options_);
    if (const int code = createFoveator(); code != kExitOk) return code;
    if (const int code = createMap(); code != kExitOk) return code;
    if (const int code = createEvaluators(); code != kExitOk) return code;
    openTwin();
    return kExitOk;
  }

  // Says what is measured, and starts the camera.
  int start() {
    result_.gaze = describeGaze(options_, info_);
    std::printf("fovea-error-report: camera %s %dx%d, %ld frames, %zu configurations; gaze %s\n", info_.name.c_str(),
                width_, height_, options_.frames, result_.runs.size(), result_.gaze.c_str());
    if (Status s = camera_.start(); !s) {
      std::fprintf(stderr, "fovea-error-report: camera %s: %s\n", info_.name.c_str(), s.message().c_str());
      return kExitFailure;
    }
    result_.load_before = loadAverage();
    interactive_ = isatty(STDOUT_FILENO) != 0;  // progress only on a terminal
    return kExitOk;
  }

  // The map's warm-up: the camera's first frames fused into it (the twin kept in
  // step), none measured.
  int warmUpMap() {
    for (long f = 0; map_ && f < options_.map_warmup; ++f) {
      if (Status s = camera_.acquire(frame_, std::chrono::seconds(2)); !s) {
        std::fprintf(stderr, "fovea-error-report: map warm-up frame %ld: capture: %s\n", f, s.toString().c_str());
        return kExitFailure;
      }
      if (truth_camera_ && !truth_camera_->acquire(truth_frame_, std::chrono::seconds(2))) {
        std::fprintf(stderr, "fovea-error-report: map warm-up frame %ld: the noiseless twin gave no frame\n", f);
        return kExitFailure;
      }
      pipeline::BackprojectCounts counts;
      if (Status s = map_->backproject(frame_, counts); !s) {
        std::fprintf(stderr, "fovea-error-report: map warm-up frame %ld: %s\n", f, s.toString().c_str());
        return kExitFailure;
      }
      if (interactive_) {
        std::printf("\rmap warm-up %ld/%ld", f + 1, options_.map_warmup);
        std::fflush(stdout);
      }
    }
    if (map_) {
      if (interactive_) std::printf("\n");
      const pipeline::map::SurfelMapCounters& counters = map_->map()->counters();
      std::printf("fovea-error-report: map warmed up over %ld frames: %llu fused, %llu refused\n", options_.map_warmup,
                  static_cast<unsigned long long>(counters.frames_fused),
                  static_cast<unsigned long long>(counters.refused()));
    }
    return kExitOk;
  }

  // Every configuration on each measured frame; a frame the camera does not
  // deliver is counted and skipped.
  int measureFrames() {
    // The range: the same as fovead's defaults.
    Measurer measurer{*foveator_, *evaluator_, *encoder_, surface_evaluator_, cloud_, out_, representative_,
                      pipeline::DepthRange{}, options_.reference_slope};
    for (long f = 0; f < options_.frames; ++f) {
      if (Status s = camera_.acquire(frame_, std::chrono::seconds(2)); !s) {
        std::fprintf(stderr, "frame %ld: capture: %s\n", f, s.toString().c_str());
        ++failed_;
        continue;
      }
      if (const int code = measureFrame(measurer, f); code != kExitOk) return code;
      if (interactive_) {
        std::printf("\rframe %ld/%ld", f + 1, options_.frames);
        std::fflush(stdout);
      }
    }
    if (interactive_) std::printf("\n");
    if (truth_camera_) truth_camera_->stop();
    return kExitOk;
  }

  // The figures over time, on the camera's next frames (unless none was captured).
  int measureOverTime() {
    if (options_.dynamics.stability_frames <= 0 || failed_ >= options_.frames) return kExitOk;
    DynamicsOptions d = options_.dynamics;
    if (info_.fps > 0) d.fps = info_.fps;
    d.eye_offset_cam = options_.eye_offset_cam;
    Result<DynamicsReport> measured = measureDynamics(
        camera_,
        dynamicsConfigs(options_.slopes.front(), acuityFloors(options_.acuity_floors_mm, options_.acuity_noise_floors_mm),
                        options_.acuity_refined),
        d);
    if (!measured) {
      std::fprintf(stderr, "fovea-error-report: temporal figures: %s\n", measured.status().toString().c_str());
      return kExitFailure;
    }
    result_.dynamics = std::move(measured.value());
    return kExitOk;
  }

  long failed() const { return failed_; }

 private:
  // The scalar reference kernels: the report's time column says so. Every
  // configuration is tried on it here, before any frame.
  int createFoveator() {
    Result<pipeline::Foveator> foveator =
        pipeline::Foveator::create({max_points_, max_points_, fovea::KernelSet::kRef, 1}, result_.runs.front().config);
    if (!foveator) {
      std::fprintf(stderr, "fovea-error-report: %s\n", foveator.status().message().c_str());
      return kExitUsage;
    }
    for (const ConfigRun& r : result_.runs) {
      if (Status s = foveator->setConfig(r.config); !s) {
        std::fprintf(stderr, "fovea-error-report: %s\n", s.message().c_str());
        return kExitUsage;
      }
    }
    foveator_.emplace(std::move(foveator.value()));
    return kExitOk;
  }

  // The map source's stage, with every map configuration tried on it (--sources with map).
  int createMap() {
    if (!options_.hasMap()) return kExitOk;
    const auto first = std::find_if(result_.runs.begin(), result_.runs.end(),
                                    [](const ConfigRun& r) { return r.source == firmware::FoveationSource::kMap; });
    Result<firmware::FrameFoveator> created_map = firmware::FrameFoveator::create(
        {max_points_, max_points_, fovea::KernelSet::kRef, 1}, first->config, pipeline::DepthRange{}, map_settings_,
        width_, height_);
    if (!created_map) {
      std::fprintf(stderr, "fovea-error-report: map: %s\n", created_map.status().message().c_str());
      return kExitFailure;
    }
    map_ = std::make_unique<firmware::FrameFoveator>(std::move(created_map.value()));
    for (const ConfigRun& r : result_.runs) {
      if (r.source != firmware::FoveationSource::kMap) continue;
      if (Status s = map_->use(&r.config); !s) {
        std::fprintf(stderr, "fovea-error-report: map: %s\n", s.message().c_str());
        return kExitUsage;
      }
    }
    return kExitOk;
  }

  // The error evaluator, and the stream's codec at its defaults (1200-byte
  // datagrams), for the bytes columns.
  int createEvaluators() {
    Result<pipeline::ErrorEvaluator> evaluator = pipeline::ErrorEvaluator::create(cloud_points_);
    Result<net::ChunkEncoder> encoder = net::ChunkEncoder::create(net::CodecConfig{}, cloud_points_);
    for (const Status& s : {evaluator.status(), encoder.status()}) {
      if (!s) {
        std::fprintf(stderr, "fovea-error-report: %s\n", s.message().c_str());
        return kExitFailure;
      }
    }
    evaluator_.emplace(std::move(evaluator.value()));
    encoder_.emplace(std::move(encoder.value()));
    return kExitOk;
  }

  // The true surface: the mock scene without sensor noise, frame for frame. A
  // camera without such a twin has no true-surface columns.
  void openTwin() {
    if (options_.camera.rfind("mock:", 0) == 0 && options_.camera.find("noise=off") == std::string::npos) {
      Result<std::unique_ptr<hal::Camera>> t = firmware::createCamera(options_.camera + ",noise=off");
      if (t && t.value()->open() && t.value()->start()) truth_camera_ = std::move(t.value());
      if (!truth_camera_) {
        std::printf("fovea-error-report: no noiseless twin of %s: no true-surface columns\n", options_.camera.c_str());
      }
    }
    surface_ = truth_camera_ && options_.hasMap() ? &surface_cloud_ : nullptr;
  }

  // The map source: this frame fused into the map once, timed (thread CPU time
  // and wall clock), for all its rows.
  int fuseIntoMap(long f, double& fuse_cpu_ms, double& fuse_wall_ms) {
    pipeline::BackprojectCounts counts;
    const double cpu0 = threadCpuMs();
    const auto t0 = std::chrono::steady_clock::now();
    const Status s = map_->backproject(frame_, counts);
    fuse_wall_ms = msBetween(t0, std::chrono::steady_clock::now());
    fuse_cpu_ms = threadCpuMs() - cpu0;
    if (!s) {
      std::fprintf(stderr, "frame %ld, map: %s\n", f, s.toString().c_str());
      return kExitFailure;
    }
    return kExitOk;
  }

  // Every configuration on the frame just captured, f-th of the measured ones.
  int measureFrame(Measurer& measurer, long f) {
    const bool have_truth = truth_camera_ && backprojectTruth(*truth_camera_, frame_, raw_range_, measurer.range,
                                                              truth_frame_, truth_cloud_, surface_);
    const pipeline::Gaze gaze = gazeOn(frame_, options_, info_);
    double fuse_cpu_ms = 0.0, fuse_wall_ms = 0.0;
    if (map_) {
      if (const int code = fuseIntoMap(f, fuse_cpu_ms, fuse_wall_ms); code != kExitOk) return code;
    }
    // Side by side: every configuration on this frame, starting with a different
    // one each frame so that no configuration always runs first (cold caches).
    std::vector<ConfigRun>& runs = result_.runs;
    for (std::size_t k = 0; k < runs.size(); ++k) {
      ConfigRun& r = runs[(k + static_cast<std::size_t>(f)) % runs.size()];
      const Status s =
          r.source == firmware::FoveationSource::kMap
              ? measurer.measureMap(*map_, gaze, have_truth ? surface_ : nullptr, fuse_cpu_ms, fuse_wall_ms, r)
              : measurer.measure(frame_, gaze, have_truth ? &truth_cloud_ : nullptr, have_truth ? surface_ : nullptr, r);
      if (!s) {
        std::fprintf(stderr, "frame %ld, %s %s m %.3f: %s\n", f, firmware::foveationSourceName(r.source).data(),
                     configName(r.config.acuity).c_str(), r.config.acuity.slope, s.toString().c_str());
        return kExitFailure;
      }
    }
    return kExitOk;
  }

  const Options& options_;
  hal::Camera& camera_;
  Measurement& result_;
  const hal::CameraInfo& info_;
  const int width_, height_;
  const std::size_t max_points_;
  const firmware::MapSettings map_settings_;
  const std::size_t cloud_points_;  // the output's room: the map's surfels too, with the map source
  std::optional<pipeline::Foveator> foveator_;
  std::unique_ptr<firmware::FrameFoveator> map_;  // with --sources map
  std::optional<pipeline::ErrorEvaluator> evaluator_;
  std::optional<net::ChunkEncoder> encoder_;
  std::unique_ptr<hal::Camera> truth_camera_;  // the noiseless twin, when the camera has one
  hal::RgbdFrame truth_frame_;
  pipeline::PointCloud truth_cloud_;
  pipeline::PointCloud surface_cloud_;
  pipeline::PointCloud* surface_ = nullptr;  // &surface_cloud_ when measured
  SurfaceErrorEvaluator surface_evaluator_;
  pipeline::RawDepthRange raw_range_;
  hal::RgbdFrame frame_;
  pipeline::PointCloud cloud_;
  pipeline::FoveatedCloud out_;
  std::vector<uint32_t> representative_;
  bool interactive_ = false;
  long failed_ = 0;  // measured frames the camera did not deliver
};

}  // namespace

int measure(const Options& options, Measurement& measurement) {
  Result<std::unique_ptr<hal::Camera>> created = firmware::createCamera(options.camera);
  if (!created) {
    std::fprintf(stderr, "fovea-error-report: --camera: %s\n", created.status().message().c_str());
    return kExitUsage;
  }
  hal::Camera& camera = *created.value();
  if (Status s = camera.open(); !s) {
    std::fprintf(stderr, "fovea-error-report: camera %s: %s\n", options.camera.c_str(), s.message().c_str());
    return kExitFailure;
  }
  measurement.info = camera.info();
  MeasurementRun run(options, camera, measurement);
  if (const int code = run.setUp(); code != kExitOk) return code;
  if (const int code = run.start(); code != kExitOk) return code;
  if (const int code = run.warmUpMap(); code != kExitOk) return code;
  if (const int code = run.measureFrames(); code != kExitOk) return code;
  if (const int code = run.measureOverTime(); code != kExitOk) return code;
  camera.stop();
  if (run.failed() == options.frames) {
    std::fprintf(stderr, "fovea-error-report: no frame could be captured\n");
    return kExitFailure;
  }
  measurement.frames = options.frames - run.failed();
  return kExitOk;
}

}  // namespace fovea::tools
