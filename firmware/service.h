// The fovead service runtime (issue 5): three stage threads joined by
// latest-wins rings of preallocated slots, all memory allocated by create(),
// supervised by the thread that calls run() (status GPIO lines, the status log
// line, systemd notifications, reloads).
//
//   capture ──SlotPoolRing<CapturedFrame>──> foveation ──SlotPoolRing<FoveatedFrame>──> send
//      ^                                        ^                                       |
//      |                                        └──── LatestValue<OperatorGaze> ────────┘
//   camera                                 backproject, gaze policy,               Streamer: encode,
//                                          foveate                                 paced send, status
//
// Threads (one table, PX4 style: name, placement from RuntimeSettings):
//   fovea-capture    camera acquire into a free frame slot, publish
//   fovea-foveate    newest frame -> point cloud -> foveated cloud slot, publish
//   fovea-send       newest foveated frame -> operator; polls the link; the
//                    operator's gaze goes back to fovea-foveate through a mailbox
//   fovea-map        the map source with map.fusion_thread: fuses the newest
//                    frame fovea-foveate handed over whenever it is free; the
//                    two share the map through its gate (pipeline/map/map_gate.h)
//   (caller of run)  supervisor: every few ms the status lines, the watchdog,
//                    the status line every status_interval_ms, SIGHUP reloads
// The frame path takes no lock but the map's gate (held by fusion, which lets
// the foveation stage through at its next safe point) and, after start-up,
// allocates nothing: the rings move slot indices, the mailboxes are triple
// buffers, the counters are relaxed atomics. A stage with nothing to do sleeps 0.5 ms (no condition
// variable: that would put a lock on the frame path).
//
// Exceptions to "allocated once", documented: the stream's chunk encoder is
// made when an operator's session starts (it follows the session's MTU), and a
// reload copies the new foveation configuration in the supervisor thread.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "core/latest_value.h"
#include "core/result.h"
#include "core/ring.h"
#include "firmware/frame_foveator.h"
#include "firmware/gaze_policy.h"
#include "firmware/latency_histogram.h"
#include "firmware/log.h"
#include "firmware/memory_budget.h"
#include "firmware/session_recorder.h"
#include "firmware/service_config.h"
#include "firmware/shared_brick_batch.h"
#include "firmware/status_lines.h"
#include "firmware/streamer.h"
#include "firmware/systemd_notify.h"
#include "hal/camera.h"
#include "hal/gpio.h"
#include "hal/pose_source.h"
#include "hal/usb/usb_monitor.h"

namespace fovea::firmware {

// The columns of fovead serve --timing-log, one line per frame sent (times in
// microseconds): acquire (the camera call, which waits for the next frame), queue
// (captured to foveation start), back-projection, partition (or ACUITY's levels),
// sampling (fixation and voxel sampling), hand-off (foveated to send start),
// encoding, pacing and sending (first datagram to the frame summary), and captured
// to the end of sending. docs/eval.md.
inline constexpr const char* kTimingLogHeader =
    "frame_id,captured_ns,acquire_us,queue_us,backproject_us,partition_us,sample_us,handoff_us,encode_us,send_us,"
    "captured_to_sent_us,points_out,chunks_sent,bytes_sent,completed\n";

// The parameters SIGHUP reloads, from the supervisor to the stage threads.
struct ReloadedParameters {
  pipeline::FoveationConfig foveation;
  uint64_t budget_bytes_per_s = 0;
};

// A consistent-enough snapshot of the counters (each is exact; together they
// are read one after another while the stages run).
struct ServiceStats {
  uint64_t frames_captured = 0;
  uint64_t capture_errors = 0;   // acquire failed (timeout, device error)
  uint64_t frames_foveated = 0;
  uint64_t foveate_errors = 0;
  uint64_t frames_over_capacity = 0;  // of them: more voxels or points than pipeline.max_voxels / max_output_points
  uint64_t frames_coarsened = 0;      // foveated with coarser voxels to fit them (pipeline.max_coarsenings)
  uint64_t frames_sent = 0;      // went out to an operator (a session stood)
  uint64_t frames_withheld = 0;  // taken by the send stage while privacy paused streaming
  uint64_t frames_unsent = 0;    // taken by the send stage with no operator (or not streaming)
  fovea::RingCounters capture_ring;    // capture -> foveation: dropped = frames the foveation stage never saw
  fovea::RingCounters foveation_ring;  // foveation -> send
  uint64_t reloads_requested = 0;
  uint64_t reloads_applied = 0;  // by the foveation stage
  uint64_t reload_failures = 0;
  uint64_t watchdog_keepalives = 0;
  uint64_t status_lines = 0;
  uint64_t wire_bytes = 0;
  bool operator_connected = false;
  // The status lines as the supervisor last drove them.
  uint64_t heartbeat_toggles = 0;
  bool streaming_line = false;
  bool fault_line = false;
  bool privacy_active = false;
  // USB hot-plug of the known RGB-D cameras (hal/usb/usb_monitor.h).
  hal::usb::UsbMonitorCounters usb;
  // The pose source's counts (hal/pose_source.h) and whether the last frame's pose was stale.
  hal::PoseCounters pose;
  bool pose_stale = false;
  // The map's tracker (camera.pose.source = track, track+X; zero otherwise).
  struct Tracking {
    bool enabled = false;
    bool lost = false;              // the last frame's track was lost
    uint64_t tracked = 0;           // frames posed by the tracker (first frames and relocalised included)
    uint64_t lost_frames = 0;       // frames lost (not fused)
    uint64_t relocalised = 0;       // recoveries
    double prior_disagreement_m = 0.0;  // the last tracked frame's, against its outside pose (track+X)
    double moving_share = 0.0;          // the last tracked frame's share of pixels found moving (not fused)
  } tracking;
  // The map (foveation.source = map; zero otherwise).
  struct Map {
    uint64_t surfels = 0;            // live surfels after the last frame
    uint64_t frames_fused = 0;
    uint64_t refused_no_pose = 0;    // frames without a pose (stale, none yet)
    uint64_t refused_other = 0;      // bad pose, pose jump, clock, size
    uint64_t evicted = 0;            // surfels evicted from a full pool
    uint64_t dropped = 0;            // new surfels not added: the pool or the brick table full
    uint64_t dropped_no_brick = 0;   // ... of them for want of a brick (map.max_bricks)
    uint64_t bricks_reused = 0;      // empty bricks given to new places (the table full)
    uint64_t unfused = 0;            // frames the time budget left unfused (map.fuse_budget_ms)
    uint64_t fusion_busy = 0;        // frames left unfused while the fusion thread was busy (map.fusion_thread)
    uint64_t live_thinned = 0;       // frames whose live points did not fit their cloud: thinned outside the eye's cone
    // Its bricks (map.delta, docs/map-delta.md): put in frames by the planner,
    // versions and parts sent, parts resent, versions the operator took whole,
    // versions lost on the way (due again), acknowledgements for nothing in flight.
    uint64_t bricks_planned = 0;
    uint64_t brick_versions = 0;
    uint64_t brick_parts = 0;
    uint64_t brick_resends = 0;
    uint64_t brick_versions_done = 0;
    uint64_t brick_versions_lost = 0;
    uint64_t brick_acks_unknown = 0;
    uint64_t bricks_unstaged = 0;  // the streamer could not stage them (FrameSendReport::bricks_unstaged): due again
    uint64_t bricks_too_large = 0;  // ... of them, more parts than a version may have: due again a level coarser
    uint64_t brick_plans_deferred = 0;  // frames planned while the batch was still out (SharedBrickBatch): due next frame
    // The operator's copy against the map, as of the last frame sent: bricks
    // due that did not fit it (of them the fovea's), and versions not yet
    // acknowledged whole. All zero with sent_gaze_stamp_ns at or after a gaze
    // sample's stamp: the operator holds what that gaze needs.
    uint64_t bricks_waiting = 0;
    uint64_t fovea_bricks_waiting = 0;
    uint64_t bricks_in_flight = 0;
  } map;
  // The operator's stamp of the gaze the last frame whose fovea went out whole
  // (its fovea's bricks and chunks) was foveated (and its bricks planned) for;
  // 0: the fallback's.
  int64_t sent_gaze_stamp_ns = 0;
};

class Service {
 public:
  using Reloader = std::function<Result<ServiceConfig>()>;

  // What the command (or a test) supplies besides the configuration.
  struct Environment {
    std::unique_ptr<hal::Camera> camera;  // null: hal::createCamera(config.camera.spec)
    std::unique_ptr<hal::Gpio> gpio;      // null: hal::createGpio(config.gpio.spec)
    Reloader reloader;                    // SIGHUP; null: a reload request is logged and ignored
    Logger* logger = nullptr;             // null: the process's logger()
  };

  // Streams when config.stream.link.listen is not empty (the key from
  // config.key_file when set, else config.stream.link.key / insecure).
  // Validates the configuration, opens the camera and the GPIO chip, creates
  // the streamer (binds the socket) and allocates every buffer. Logs the
  // memory line. Starts nothing.
  static Result<std::unique_ptr<Service>> create(const ServiceConfig& config, Environment environment);
  ~Service();  // stop()
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  // Requests the status lines, locks memory if configured, starts the camera
  // and the three threads, tells systemd READY=1.
  Status start();
  // Supervises until requestStop(), max_frames captured (then drained through
  // the stages) or max_duration_ns passed (0: no limit), then stop()s.
  // Returns when all is down.
  void run(uint64_t max_frames = 0, int64_t max_duration_ns = 0);
  // Both async-signal-safe (lock-free atomic stores): for signal handlers.
  // Release, paired with run()'s acquire: what the requesting thread did before
  // (say, a test reading localEndpoint()) happens before the teardown or reload
  // that follows. Relaxed, ThreadSanitizer found it racing stop()'s
  // streamer_.reset().
  void requestStop() { stop_requested_.store(true, std::memory_order_release); }
  void requestReload() { reload_requested_.store(true, std::memory_order_release); }
  // Stops capturing, lets the foveation and send stages drain the frames
  // queued (sent if an operator is there), joins, stops the camera, says Bye,
  // drives the status lines low (idempotent).
  void stop();

  const MemoryBudget& memory() const { return memory_; }
  // The recording's counters and summary line (null: not recording).
  const SessionRecorder* recorder() const { return recorder_.get(); }
  const ServiceConfig& config() const { return config_; }
  ServiceStats stats() const;
  // Where the stream listens (streaming only).
  bool streaming() const { return streamer_ != nullptr; }
  net::Endpoint localEndpoint() const;

 private:
  // The status line for the window since the previous one (supervisor only).
  // Writes into `out` (no allocation); returns its length.
  std::size_t formatStatusLine(char* out, std::size_t size);

  struct CapturedFrame {
    hal::RgbdFrame frame;
    int64_t captured_ns = 0;  // when acquire returned (CLOCK_MONOTONIC)
    int64_t acquire_ns = 0;   // how long acquire took (it waits for the camera's next frame)
    bool pose_fresh = true;   // the pose source had a pose for the frame's stamp
  };
  struct FoveatedFrame {
    pipeline::FoveatedCloud cloud{0};
    pipeline::FoveationStats stats;
    uint32_t frame_id = 0;
    int64_t captured_ns = 0;
    int64_t acquire_ns = 0;
    int64_t foveation_start_ns = 0;  // taken from the capture ring
    int64_t backproject_ns = 0;
    int64_t foveated_ns = 0;  // published to the send ring
    // The map's bricks go with the frame whose slot owns bricks_ (map.delta).
    // Deferred: none were planned for its gaze (the batch was still out), so
    // it tells nothing of what the operator holds for that gaze.
    bool bricks_deferred = false;
    uint32_t bricks_waiting = 0, fovea_bricks_waiting = 0;
    int64_t gaze_stamp_ns = 0;              // the operator's stamp of the gaze foveated for (0: fallback)
    int64_t send_window_ns = 0;             // the time its bricks were planned to fill (map bricks)
  };
  // The timing log's line for one frame sent (no allocation: the file's buffer is ours).
  void logTiming(const FoveatedFrame& f, int64_t send_start_ns, const FrameSendReport& sent);

  Service(const ServiceConfig& config, Environment environment, int64_t period_ns);

  // Start-up (service_memory.cpp): allocate() and its steps, in its order; each
  // step adds what it allocated to memory_, pool by pool.
  Status allocate();
  void allocateFrameSlots(const hal::CameraIntrinsics& k, std::size_t depth);
  void allocateFoveatedSlots(std::size_t points, std::size_t depth);
  Status allocateFoveator(const pipeline::PipelineCapacity& capacity, const hal::CameraIntrinsics& k);
  void addMapMemory(const pipeline::map::MapperMemory& m);
  Status allocateStreamer(std::size_t points);
  void allocateSupervisorState();
  Status openTimingLog();
  Status allocateRecorder();

  // The stage threads (service_stages.cpp).
  void placeThread(const char* name, const ThreadPlacement& placement);
  void captureLoop();
  void foveationLoop();
  // One frame through the foveation stage, its slots taken: tracking,
  // back-projection, the gaze, foveation and (map bricks) the bricks' plan.
  Status foveateFrame(CapturedFrame& f, FoveatedFrame& o, fovea::SlotIndex out);
  // The gaze policy's decision for the frame, from the operator's newest gaze.
  GazePolicy::Decision decideGaze(const hal::RgbdFrame& frame);
  Status planFrameBricks(const pipeline::Gaze& gaze, FoveatedFrame& o, fovea::SlotIndex out);
  // A frame the foveation stage dropped: counted and logged (rate-limited).
  void countFoveationError(const Status& s, const FoveatedFrame& o);
  // The foveation stage's map figures to the atomics the status line reads.
  void publishMapFigures();
  void mapLoop();  // map.fusion_thread
  void publishTracking();  // the tracker's figures of the frame backproject() just posed
  void sendLoop();
  // The send stage's link work between frames (streaming only): a reloaded
  // budget cap, the link's datagrams, the operator's gaze, the bricks' budget.
  void pollOperator();
  // A frame to the operator (streaming, not paused for privacy) with the
  // bricks its slot owns (null: none), then the counters the status line reads.
  void sendToOperator(FoveatedFrame& f, fovea::SlotIndex slot, const pipeline::map::BrickBatch* bricks);
  void publishSendCounters(const FoveatedFrame& f);
  // Sends the operator a status report once next_report_ns has come; returns
  // when the next is due.
  int64_t sendStatusReportWhenDue(int64_t next_report_ns);
  // Hands the operator's newest gaze to the foveation stage when it changes
  // (the send stage's, also while it paces a frame out).
  void publishOperatorGaze();

  // The supervisor (service_supervisor.cpp): supervise() every few ms and its steps.
  void supervise(int64_t now_ns);
  void publishStatusState(const StatusState& state);
  void logPoseChange(bool pose_stale);
  void logTrackingChange(bool tracking_lost);
  void logFaultChange(bool fault, bool healthy, bool frames_flow, bool pose_stale, int64_t now_ns);
  void keepWatchdogAlive(bool healthy, int64_t now_ns);
  void applyReload();
  // USB hot-plug (supervisor only): start logs whether it runs, drain logs each
  // arrival and removal of a known camera.
  void startUsbMonitor();
  void drainUsbEvents();

  // The status line (service_status.cpp): written to the log, the recording and
  // systemd every status_interval_ms.
  void writeStatusLine(int64_t now_ns);
  // formatStatusLine's fields: p50/p99 per histogram (capture, foveate, send,
  // fuse) over the window, "-" when empty; the pose's and the map's parts.
  using LatencyTexts = char[4][24];
  void formatWindowLatencies(LatencyTexts& text);
  void formatPoseFields(char* out, std::size_t size) const;
  void formatMapFields(const char* fuse_latency, char* out, std::size_t size) const;

  Logger& log() { return *logger_; }

  ServiceConfig config_;
  std::unique_ptr<hal::Camera> camera_;
  std::unique_ptr<hal::Gpio> gpio_;
  std::unique_ptr<hal::PoseSource> pose_source_;  // the capture thread's (counters: any thread)
  Reloader reloader_;
  Logger* logger_;
  int64_t period_ns_;
  int64_t stall_timeout_ns_;
  MemoryBudget memory_;

  std::unique_ptr<fovea::SlotPoolRing<CapturedFrame>> frames_;
  std::unique_ptr<fovea::SlotPoolRing<FoveatedFrame>> foveated_;
  std::unique_ptr<FrameFoveator> stage_;
  std::unique_ptr<GazePolicy> policy_;  // the foveation thread's
  std::unique_ptr<Streamer> streamer_;  // the send thread's only
  // The map's bricks: what the send stage learns the operator lacks, for the
  // planner in the foveation stage; the session's budget the planner fills.
  bool map_bricks_ = false;
  bool live_points_capped_ = false;  // allocate() sized the frame by map.max_live_points (the warning says so)
  std::unique_ptr<BrickFeedback> brick_feedback_;
  std::unique_ptr<SharedBrickBatch> bricks_;  // the frame's bricks, foveation -> send
  fovea::SlotIndex sending_slot_ = 0;        // the send stage's: the frame sendFrame has (its bricks-done hook)
  std::atomic<uint64_t> brick_budget_bytes_per_s_{0};
  std::atomic<uint64_t> bricks_planned_{0}, brick_versions_{0}, brick_parts_{0}, brick_resends_{0},
      brick_versions_done_{0}, brick_versions_lost_{0}, brick_acks_unknown_{0}, bricks_unstaged_{0},
      bricks_too_large_{0}, brick_plans_deferred_{0};
  // Of the last frame sent (the send stage writes the counts, then the stamp, with release).
  std::atomic<uint64_t> bricks_waiting_{0}, fovea_bricks_waiting_{0}, bricks_in_flight_{0};
  std::atomic<int64_t> sent_gaze_stamp_ns_{0};
  int64_t last_plan_ns_ = 0;  // the foveation stage's: when it planned the last frame's bricks (0: none yet)
  // The send stage's: the operator's gaze it last handed on to the foveation
  // stage, whether valid and when it arrived (a gaze that arrived since is new).
  bool sent_gaze_valid_ = false;
  int64_t sent_gaze_received_ns_ = -1;
  std::unique_ptr<StatusLines> status_lines_;  // the supervisor's
  std::unique_ptr<hal::usb::UsbMonitor> usb_monitor_;  // its thread, drained by the supervisor
  SystemdNotifier notifier_;
  fovea::LatestValue<OperatorGaze> gaze_box_;
  fovea::LatestValue<ReloadedParameters> reload_to_foveation_;
  fovea::LatestValue<ReloadedParameters> reload_to_send_;

  std::atomic<bool> stop_requested_{false};
  std::atomic<bool> reload_requested_{false};
  std::atomic<bool> running_{false};
  // Shutdown drains front to back: capture stops on running_, foveation once the
  // capture stage is done and its ring empty, send likewise after foveation.
  std::atomic<bool> capture_alive_{false};
  std::atomic<bool> foveation_alive_{false};
  std::atomic<uint64_t> max_frames_{0};  // run()'s limit on frames captured (0: none)
  std::atomic<bool> stream_allowed_{true};
  std::atomic<bool> operator_connected_{false};
  std::atomic<int64_t> gaze_received_ns_{0};  // 0: none
  std::atomic<int64_t> last_frame_ns_{0};
  // The capture stage is retrying (hal::CaptureRetry::faulted()): part of the fault line.
  std::atomic<bool> capture_failing_{false};
  std::atomic<bool> pose_stale_{false};  // the last frame's pose was stale
  bool pose_was_stale_ = false;          // the supervisor's, for the log line
  // The tracker (foveation stage writes, any thread reads).
  bool tracking_ = false;
  std::atomic<bool> tracking_lost_{false};
  std::atomic<uint8_t> tracking_lost_reason_{0};  // pipeline::map::LostReason
  std::atomic<uint64_t> frames_tracked_{0}, frames_track_lost_{0}, frames_relocalised_{0};
  std::atomic<double> prior_disagreement_m_{0.0};
  std::atomic<double> moving_share_{0.0};  // the last tracked frame's (pipeline/map/moving_pixels.h)
  std::atomic<int64_t> track_ns_{0};      // the last frame's tracking time
  std::atomic<int64_t> model_ns_{0};      // ... the last fused frame's model build (TrackStats::model_ns)
  bool tracking_was_lost_ = false;        // the supervisor's, for the log line
  uint64_t window_heartbeat_toggles_ = 0;  // the supervisor's, at the last status line
  std::atomic<uint64_t> frames_over_capacity_{0}, frames_coarsened_{0};
  std::atomic<uint64_t> capture_errors_{0}, frames_foveated_{0}, foveate_errors_{0}, frames_sent_{0},
      frames_withheld_{0}, frames_unsent_{0}, reloads_applied_{0}, wire_bytes_{0};
  // Written by the supervisor, read by stats() from any thread.
  std::atomic<uint64_t> reloads_requested_{0}, reload_failures_{0}, watchdog_keepalives_{0}, status_lines_written_{0},
      heartbeat_toggles_{0};
  std::atomic<bool> streaming_line_{false}, fault_line_{false}, privacy_active_{false};
  LatencyHistogram capture_latency_, foveate_latency_, send_latency_;
  LatencyHistogram fuse_latency_;  // the map's fusion (a part of foveate_latency_)
  std::atomic<uint64_t> map_surfels_{0}, map_frames_fused_{0}, map_refused_no_pose_{0}, map_refused_other_{0},
      map_evicted_{0}, map_dropped_{0}, map_dropped_no_brick_{0}, map_bricks_reused_{0}, map_fusion_skipped_{0}, map_fusion_busy_{0},
      map_live_thinned_{0};
  std::vector<std::thread> threads_;

  // Supervisor state (one thread).
  int64_t started_ns_ = 0;
  int64_t next_status_ns_ = 0;
  int64_t next_watchdog_ns_ = 0;
  struct Window {
    int64_t at_ns = 0;
    uint64_t captured = 0, foveated = 0, sent = 0, wire_bytes = 0, capture_drops = 0, foveation_drops = 0;
  } window_;
  std::unique_ptr<uint64_t[]> histogram_scratch_;  // kBuckets: one stage's snapshot, for the quantiles
  std::array<std::unique_ptr<uint64_t[]>, 4> histogram_previous_;  // capture, foveate, send, fuse
  // --timing-log: the file and its buffer, both made at start-up (the send stage writes).
  struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
  };
  std::unique_ptr<std::FILE, FileCloser> timing_log_;
  // --record (null: none); fed by the three stages and the supervisor.
  std::unique_ptr<SessionRecorder> recorder_;
  std::unique_ptr<char[]> timing_log_buffer_;
  bool stopped_ = false;
};

}  // namespace fovea::firmware
