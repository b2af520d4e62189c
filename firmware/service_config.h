// Every setting of the fovead service (issue 5), in one struct: what the
// configuration file (TOML, firmware/config.h) and the board profiles (board/)
// fill, what the command line overrides, what `fovead --print-config` shows,
// and what the service runtime (firmware/service.h) is built from. Each field
// is an existing component's own configuration where one exists, so a setting
// lives in one place.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "firmware/frame_foveator.h"
#include "firmware/gaze_policy.h"
#include "firmware/log.h"
#include "firmware/session_recorder.h"
#include "firmware/status_lines.h"
#include "firmware/streamer.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"

namespace fovea::firmware {

// Where a stage's thread runs. core -1: anywhere; realtime_priority 0: the
// normal scheduler, 1..99: SCHED_FIFO at that priority; nice (-20 .. 19, the
// normal scheduler only): added to the process's nice value for the thread
// (its share of a busy core; 0: as the process). When the system refuses (no
// CAP_SYS_NICE for a priority or a lower nice value, a core that does not
// exist) the service logs it and runs on.
struct ThreadPlacement {
  int core = -1;
  int realtime_priority = 0;
  int nice = 0;
};

// Where the camera is (hal/pose_source.h, docs/pose.md).
struct PoseSettings {
  // "none", "fixed", "socket"; "track" (the map's tracker alone), "track+fixed",
  // "track+socket" (the outside pose as the prior the tracker refines; docs/tracking.md).
  std::string source = "none";
  // fixed: the camera's pose in the world; socket: its mount on the robot.
  std::vector<double> translation_m = {0.0, 0.0, 0.0};
  std::vector<double> rotation_xyzw = {0.0, 0.0, 0.0, 1.0};
  std::string socket = "/run/fovea/pose.sock";
  int64_t max_age_ms = 100;
  int64_t buffer_poses = 256;
};

struct CameraSettings {
  std::string spec = "mock:living-room,realtime=on";  // hal::createCamera
  // A calibration file (hal/calibration_file.h, docs/calibration.md); "": none.
  std::string calibration_file;
  // Depth-to-colour extrinsics over the file's (both empty: not given).
  std::vector<double> extrinsics_rotation_xyzw;
  std::vector<double> extrinsics_translation_m;
  PoseSettings pose;
  pipeline::DepthRange depth;
  // Capture retries after a failure or a disconnect: from retry_initial_ms,
  // doubling up to retry_max_ms, for ever (the camera may come back).
  int64_t retry_initial_ms = 100;
  int64_t retry_max_ms = 5000;
  // No frame for this long is a stall (a fault); 0: three frame periods.
  int64_t stall_timeout_ms = 0;
};

struct GpioSettings {
  std::string spec = "mock";  // hal::createGpio: "mock", "gpiod:gpiochip0"
  StatusLinesConfig lines;
};

struct RuntimeSettings {
  // Frames queued per ring between stages (capture -> foveation -> send); latest
  // wins. 1: a stage always takes the newest frame (a FIFO of 2 hands a stage
  // that fell behind the older of two, a frame period late), and each ring has
  // 3 slots instead of 4.
  int ring_depth = 1;
  ThreadPlacement capture_thread;
  ThreadPlacement foveation_thread;
  ThreadPlacement send_thread;
  ThreadPlacement map_thread;  // the map's fusion (map.fusion_thread)
  bool memory_lock = false;         // mlockall(MCL_CURRENT | MCL_FUTURE) after start-up
  LogLevel log_level = LogLevel::kInfo;
  int64_t status_interval_ms = 5000;  // the status log line
  bool systemd_notify = true;         // READY, STATUS, WATCHDOG when NOTIFY_SOCKET is set
  // One CSV line per frame sent, with its time in each stage (fovead serve
  // --timing-log; docs/eval.md). "": none.
  std::string timing_log;
  // One MCAP file of this run (fovead serve --record; docs/recording.md).
  // record.path "": none.
  RecordSettings record;
};

struct ServiceConfig {
  std::string board = "host-mock";  // the profile these settings started from
  CameraSettings camera;
  pipeline::PipelineCapacity pipeline;  // max points and voxels, kernels, threads per frame
  // pipeline.max_output_points: the points one foveated frame may hold (the fovea
  // whole plus one per voxel), which sizes the foveated slots and the chunk
  // encoder. 0: the camera's pixels. A preset that keeps every point (FREF) and
  // the map source always get the pixels (the map's surfels on top). A frame
  // that needs more is foveated with coarser voxels (pipeline.max_coarsenings,
  // "coarsened"), or past them dropped and counted ("over capacity").
  std::size_t max_output_points = 0;
  pipeline::FoveationConfig foveation;  // preset, m, far eccentricity, fixation
  // foveation.source and [map]: the fused scene map, streamed as bricks the
  // operator keeps (map.delta) unless turned off, fused on a thread of its
  // own (map.fusion_thread, runtime.map_thread) so that no frame and no gaze
  // waits for fusion.
  MapSettings map = [] {
    MapSettings bricks;
    bricks.delta = true;
    bricks.fusion_thread = true;
    return bricks;
  }();
  // listen, key, budget, MTU, gaze timeout, fallback, codec. stream.link.listen
  // "" (the default here): the service does not stream (host-mock's default).
  StreamConfig stream = [] {
    StreamConfig offline;
    offline.link.listen.clear();
    return offline;
  }();
  std::string key_file;                 // read into stream.link.key at start-up
  GpioSettings gpio;
  RuntimeSettings runtime;
};

}  // namespace fovea::firmware
