// The operator's gaze, scripted (fovea-operator --gaze SCRIPT): where a VR
// front end would read the eye tracker, the test operator reads a script.
//
//   fixed:EYE>TARGET                  one fixation, e.g. fixed:3,0.35,1.55>3,2.25,1.35
//   scan:EYE>T1;T2;...[@DWELL_MS[/SACCADE_MS]]
//                                     fixations on T1, T2, ... in a loop, each held
//                                     DWELL_MS (default 400), moving between them in
//                                     SACCADE_MS (default 50) along the great circle
//   csv:FILE                          a recorded trace: lines "t_s,ox,oy,oz,dx,dy,dz"
//                                     (a header line and '#' comments are skipped);
//                                     each sample holds until the next, the last one
//                                     to the end
// Coordinates are world metres; directions any non-zero length.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"

namespace fovea::tools {

struct GazePoint {
  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  // unit length
};

class GazeScript {
 public:
  // Parses a script; errors name the part that is wrong (and the CSV line).
  static Result<GazeScript> parse(std::string_view text);

  // The gaze t_ns after the script started (t_ns < 0 counts as 0).
  GazePoint at(int64_t t_ns) const;

 private:
  // parse's steps: fixed: and scan: (EYE>TARGETS, after a scan's timing), csv:FILE.
  static Result<GazeScript> parseFixations(std::string_view kind, std::string_view body);
  Status takeScanTiming(std::string_view timing);  // a scan's DWELL_MS[/SACCADE_MS]
  static Result<GazeScript> parseTrace(const std::string& path);

  struct Key {
    int64_t t_ns;
    GazePoint gaze;
  };
  enum class Kind { kFixed, kScan, kTrace };
  Kind kind_ = Kind::kFixed;
  std::vector<Key> keys_;  // fixed: one; scan: the fixations; trace: the samples
  int64_t dwell_ns_ = 400'000'000;
  int64_t saccade_ns_ = 50'000'000;
};

}  // namespace fovea::tools
