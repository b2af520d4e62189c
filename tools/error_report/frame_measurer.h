// fovea-error-report: one configuration measured on one frame. The part the
// service does per frame is timed (thread CPU time and wall clock); its error,
// against the input and the true surface, and its bytes on the wire are measured
// after, untimed, into the configuration's record (config_run.h).
#pragma once

#include <chrono>
#include <cstdint>
#include <vector>

#include "firmware/frame_foveator.h"
#include "hal/camera.h"
#include "net/codec.h"
#include "pipeline/backproject.h"
#include "pipeline/error_metrics.h"
#include "pipeline/foveator.h"
#include "tools/error_report/config_run.h"
#include "tools/error_report/surface_error.h"

namespace fovea::tools {

double msBetween(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b);

// CPU time of the calling thread, in ms: unlike the wall clock, it does not count
// the time other processes on a shared host take from us.
double threadCpuMs();

// The true position of every input point: the twin's frame (same pose and
// intrinsics) keeps its noiseless depth where both readings are valid and takes
// the noisy one elsewhere, so that its back-projection has the same points in
// the same order as the noisy frame's. `surface`, when given, receives the
// twin's own frame back-projected first: the true surface, every pixel in range
// (surface_error.h). False when the twin gave no frame.
bool backprojectTruth(hal::Camera& twin, const hal::RgbdFrame& frame, const pipeline::RawDepthRange& raw_range,
                      const pipeline::DepthRange& range, hal::RgbdFrame& truth_frame, pipeline::PointCloud& truth_cloud,
                      pipeline::PointCloud* surface);

// What measuring a configuration on a frame uses: sized once at start-up.
struct Measurer {
  pipeline::Foveator& foveator;
  pipeline::ErrorEvaluator& evaluator;
  net::ChunkEncoder& encoder;
  SurfaceErrorEvaluator& surface_evaluator;
  pipeline::PointCloud& cloud;
  pipeline::FoveatedCloud& out;
  std::vector<uint32_t>& representative;
  pipeline::DepthRange range;
  double reference_slope;

  // One configuration on one frame, added to its run: back-projection and
  // foveation timed (what the service does per frame), then, untimed, the same
  // foveation with each input point's representative, its error (and against
  // the true surface when `truth` is given) and the bytes the stream would send.
  Status measure(const hal::RgbdFrame& frame, const pipeline::Gaze& gaze, const pipeline::PointCloud* truth,
                 const pipeline::PointCloud* surface, ConfigRun& r);

  // The same for the map source, on the frame `map` fused last (fuse_cpu_ms and
  // fuse_wall_ms: that fusion's times, which every configuration's time
  // includes): the eye's view of the map and the foveation timed, then the
  // foveation again with representatives, untimed. The map's rows have no
  // per-pixel truth (their input is surfels, not the frame's pixels): `surface`
  // judges them.
  Status measureMap(firmware::FrameFoveator& map, const pipeline::Gaze& gaze, const pipeline::PointCloud* surface,
                    double fuse_cpu_ms, double fuse_wall_ms, ConfigRun& r);

  // The untimed part: the error of `out` against its input `in`, against the
  // true surface, and the bytes.
  Status record(pipeline::Foveator& used, const pipeline::PointCloud& in, const pipeline::Gaze& gaze,
                const pipeline::FoveationStats& stats, const pipeline::PointCloud* truth,
                const pipeline::PointCloud* surface, double cpu_ms, double wall_ms, ConfigRun& r);
};

}  // namespace fovea::tools
