// The baselines of fovea-bench-codec, each in its own translation unit so its
// headers stay out of the rest (Draco, PCL's octree codec). Start-up code.
#pragma once

#include <chrono>
#include <cstddef>
#include <ctime>
#include <string>
#include <vector>

#include "pipeline/point_cloud.h"

namespace fovea::bench {

// CPU time of the calling thread: on a shared machine, time the scheduler gives
// to other processes does not count (every codec here runs on one thread).
struct ThreadCpuClock {
  using duration = std::chrono::nanoseconds;
  using rep = duration::rep;
  using period = duration::period;
  using time_point = std::chrono::time_point<ThreadCpuClock>;
  static constexpr bool is_steady = true;
  static time_point now() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return time_point(duration(static_cast<rep>(ts.tv_sec) * 1000000000 + ts.tv_nsec));
  }
};

// Medians over the runs. Encode and decode are timed on the codec's own data
// structures: converting fovea's cloud to them (and back) is not timed.
struct CodecRun {
  std::size_t bytes = 0;       // one frame's compressed size
  std::size_t points_out = 0;  // points the decoder returned
  double encode_ms = 0.0;
  double decode_ms = 0.0;
  double max_error_m = 0.0;    // the configuration's bound on the position error, per axis
  std::string error;           // empty on success
};

// Draco: kd-tree encoding, position_bits-bit positions over the cloud's bounding
// box, 8-bit colour (uint8 attribute, unquantized), encoding and decoding speed 10.
// Whole-frame stream: one buffer, not decodable in parts.
bool haveDraco();
CodecRun runDraco(const pipeline::FoveatedCloud& cloud, int position_bits, int runs);
// The step of Draco's position grid for this cloud and bit count:
// max extent of the bounding box / (2^bits - 1); the error is at most half of it.
double dracoStep(const pipeline::FoveatedCloud& cloud, int position_bits);

// PCL 1.13's octree codec (OctreePointCloudCompression<PointXYZRGB>), manual
// profile: octree leaf octree_resolution_m, per-point detail point_resolution_m
// (positions are truncated to it: error < point_resolution_m), 8-bit colour, no
// voxel-grid downsampling, every frame an I-frame (a fresh encoder per run).
bool havePclOctree();
CodecRun runPclOctree(const pipeline::FoveatedCloud& cloud, double point_resolution_m, double octree_resolution_m,
                      int runs);

double median(std::vector<double> values);

}  // namespace fovea::bench
