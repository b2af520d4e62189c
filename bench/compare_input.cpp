// fovea-compare's input: loading the frame or cloud the command line names.
#include "bench/compare_input.h"

#include <cstdio>
#include <utility>

#include "bench/bench_input.h"
#include "io/ply.h"

namespace fovea::bench::compare {
namespace {

// The PLY cloud, or the frame (the mock living room or a TUM frame) with its gaze
// (not yet normalised).
int loadCloudOrFrame(const CompareOptions& options, Input& input, pipeline::Gaze& gaze) {
  if (!options.ply_path.empty()) {
    Result<io::PlyCloud> ply = io::readPly(options.ply_path);
    if (!ply) {
      std::fprintf(stderr, "fovea-compare: %s\n", ply.status().toString().c_str());
      return 1;
    }
    input.cloud = std::move(ply.value().points);
    input.description = options.ply_path + " (" + std::to_string(input.cloud.size()) + " points; no back-projection)";
    return 0;
  }
  Result<FrameInput> frame =
      options.tum_path.empty() ? mockLivingRoom() : tumFrame(options.tum_path, options.frame_index);
  if (!frame) {
    std::fprintf(stderr, "fovea-compare: %s\n", frame.status().toString().c_str());
    return 1;
  }
  input.has_frame = true;
  input.frame = std::move(frame.value().frame);
  input.description = frame.value().description;
  gaze = frame.value().gaze;
  return 0;
}

// The valid points after back-projection (a PLY cloud's are all valid).
int countInputPoints(Input& input) {
  if (input.has_frame) {
    pipeline::PointCloud probe(input.frame.pixelCount());
    pipeline::BackprojectCounts counts;
    if (Status s = pipeline::backprojectRef(input.frame, input.range, probe, counts); !s) {
      std::fprintf(stderr, "fovea-compare: %s\n", s.toString().c_str());
      return 1;
    }
    input.input_points = counts.valid;
  } else {
    input.input_points = input.cloud.size();
  }
  if (input.input_points == 0) {
    std::fprintf(stderr, "fovea-compare: the input has no valid points\n");
    return 1;
  }
  return 0;
}

}  // namespace

int loadInput(const CompareOptions& options, Input& input) {
  input.config.acuity.preset = options.preset;
  input.acuity_floor_per_m2 = options.acuity_floor_mm * 1e-3;
  input.pyramid_margin = options.pyramid_margin;
  pipeline::Gaze gaze;
  if (int status = loadCloudOrFrame(options, input, gaze); status != 0) return status;
  if (options.gaze_origin) gaze.origin_m = *options.gaze_origin;
  if (options.gaze_dir) gaze.direction = *options.gaze_dir;
  Result<pipeline::Gaze> unit = pipeline::normalizeGaze(gaze);
  if (!unit) {
    std::fprintf(stderr, "fovea-compare: %s\n", unit.status().toString().c_str());
    return 1;
  }
  input.gaze = unit.value();
  return countInputPoints(input);
}

}  // namespace fovea::bench::compare
