// fovea-operator's run over its sessions with the robot (or over a recording):
// one class, its members split by concern over operator_session.cpp (the live
// sessions and each datagram), operator_replay.cpp (--replay),
// operator_frame_outputs.cpp (what a decoded frame goes to: viewer, frame log,
// PLY files), operator_foxglove.cpp (--foxglove) and operator_summary.cpp.
#pragma once

#include <csignal>
#include <cstddef>
#include <cstdint>
#include <ctime>
#include <deque>
#include <optional>
#include <string>

#include "core/clock.h"
#include "io/foxglove/foxglove.h"
#include "io/mcap/reader.h"
#include "net/codec.h"
#include "net/messages.h"
#include "net/operator_link.h"
#include "tools/operator/foxglove_server.h"
#include "tools/operator/gaze_script.h"
#include "tools/operator/map_holder.h"
#include "tools/operator/operator_exit.h"
#include "tools/operator/operator_options.h"
#include "tools/operator/operator_stats.h"
#include "tools/operator/operator_station.h"
#include "tools/operator/view_frame.h"
#include "tools/operator/view_messages.h"
#include "tools/operator/view_server.h"

namespace fovea::tools {

// Set by SIGINT and SIGTERM (main.cpp): the run stops at its next step.
extern volatile std::sig_atomic_t g_stop;

// One session with the robot: its link and its clocks.
struct Session {
  explicit Session(net::OperatorLink* l) : link(l) {}

  net::OperatorLink* link;  // null in a replay
  bool shared_clock = false;
  std::optional<int64_t> clock_offset_ns;  // robot minus local
  // What a packet capture adds to each UDP payload: the IP and UDP headers.
  std::size_t ip_udp_header_bytes = 0;
  int64_t next_gaze_ns = 0;
  int64_t next_live_ns = 0;
  int64_t live_start_ns = 0;
  uint64_t lost_reported = 0;
  uint64_t last_frame_id = 0;
  std::size_t max_payload = 0;  // of a datagram in this session: its MTU less kDatagramOverhead
};

// The run over all sessions: the figures and what the steps share.
class OperatorRun {
 public:
  OperatorRun(const OperatorOptions& opt, Station& station)
      : opt_(opt),
        station_(station),
        assembler_(*station.assembler),
        map_(*station.map),
        view_(station.view.get()),
        fox_(station.foxglove.get()),
        wall_offset_ns_(wallClockOffsetNs()),
        splat_sizer_(net::CodecConfig{}.periphery_step_ratio),
        start_ns_(monotonicNs()),
        end_ns_(opt.duration_s > 0 ? start_ns_ + static_cast<int64_t>(opt.duration_s * 1e9) : INT64_MAX),
        gaze_period_ns_(static_cast<int64_t>(1e9 / opt.gaze_hz)),
        robot_address_(opt.connect) {
    if (fox_) fox_cloud_.reserve(static_cast<std::size_t>(opt.max_points));
  }

  // Without the viewer: one session, as before. With it: the page stays up and
  // the operator reconnects until it is stopped (a robot restarting, refusing
  // while busy, or not yet up).
  Exit runSessions();
  // --replay: the recording's chunks, frame summaries and map bricks, paced by
  // their log times (--speed), through what a session's datagrams go through.
  Exit runReplay();
  // Prints the summary and writes --summary; the exit code.
  int finish();

 private:
  // What a replay read: the messages played, and those skipped as larger than a datagram.
  struct ReplayCounts {
    uint64_t replayed = 0, too_big = 0;
  };

  Exit connectFailed(const Status& status);
  void runSession(net::OperatorLink& link);
  Session beginSession(net::OperatorLink& link);
  void sendGaze(Session& s, int64_t now);
  void reportLive(Session& s, int64_t now);
  void publishFigures(const Session& s, const tools::LiveFigures& live);
  void handleDatagram(Session& s, const net::Received& received);
  void handleReady(Session& s);
  void sendBrickAcks(Session& s, int64_t now);
  void publishView(const net::AssembledFrame& f);
  // --foxglove: the frame's cloud, the gaze sent (ray and head), a log line.
  void publishFoxgloveCloud(const net::AssembledFrame& f, const Session& s);
  void publishFoxgloveGaze(const net::GazeSample& g, int64_t now);
  void foxLog(foxglove::LogLevel level, const std::string& line);
  uint64_t wallNs(int64_t monotonic_ns) const { return static_cast<uint64_t>(monotonic_ns + wall_offset_ns_); }
  static int64_t wallClockOffsetNs() { return wallClockNs() - monotonicNs(); }
  // The robot keeps being tried while a viewer or a Foxglove client may watch.
  bool persistent() const { return view_ != nullptr || fox_ != nullptr; }
  void logFrame(const net::AssembledFrame& f, const tools::FrameObservation& obs, int64_t fovea_decoded_ns,
                const Session& s);
  // When the frame's fovea (region 0) was decoded: the arrival of its last fovea
  // chunk, or -1 (no fovea chunk, or some of them lost). Takes the frame's
  // entries off chunk_arrivals_.
  int64_t takeFoveaArrival(const net::AssembledFrame& f);
  void saveFramePly(const net::AssembledFrame& f);
  void saveHeld(const net::AssembledFrame& f);
  void endSession(Session& s);
  // --replay's steps (operator_replay.cpp).
  Session beginReplay();
  ReplayCounts replayMessages(mcap::Reader& reader, Session& s, int64_t replay_start_ns);
  void waitForReplayDue(Session& s, int64_t due_ns);
  void replayMessage(Session& s, net::MessageType type, const mcap::MessageView& m);
  void reportReplayEnd(const mcap::Reader& reader, const ReplayCounts& counts) const;
  void holdAfterReplay() const;
  std::string viewerSummary() const;
  Exit writeSummaryJson(double seconds, const std::string& view_json) const;

  void publishState(tools::LinkState state, const std::string& detail) {
    if (view_) view_->publishState(tools::stateJson(state, detail, robot_address_));
  }
  // Waits up to ms, or less when stopped; false when stopped or out of time.
  bool pause(int ms) const {
    for (int i = 0; i < ms / 50 && g_stop == 0 && monotonicNs() < end_ns_; ++i) {
      const timespec t{0, 50'000'000};
      nanosleep(&t, nullptr);
    }
    return g_stop == 0 && monotonicNs() < end_ns_;
  }

  const OperatorOptions& opt_;
  Station& station_;
  net::FrameAssembler& assembler_;
  tools::MapHolder& map_;
  tools::MapTotals map_live_before_{};  // at the last live line
  tools::MapTotals map_logged_before_{};  // at the last --frame-log line
  uint64_t view_map_points_left_out_ = 0, view_map_frames_cut_ = 0;
  tools::ViewServer* view_;  // null without --view
  tools::FoxgloveServer* fox_;  // null without --foxglove
  const int64_t wall_offset_ns_;  // CLOCK_REALTIME - CLOCK_MONOTONIC, at start (Foxglove's times are Unix time)
  foxglove::PointCloudEncoder fox_cloud_;
  foxglove::FrameTransformEncoder fox_head_;
  foxglove::GazeRayEncoder fox_gaze_;
  foxglove::LogEncoder fox_log_;
  tools::OperatorStats stats_;
  tools::SplatSizer splat_sizer_;
  const int64_t start_ns_;
  const int64_t end_ns_;
  const int64_t gaze_period_ns_;
  uint64_t ply_written_ = 0, ply_failed_ = 0, gaze_sent_ = 0, sessions_ = 0;
  bool held_done_ = false;     // --save-held: written (or failed), not tried again
  std::string held_result_;    // what it wrote, or why not
  std::optional<net::GazeSample> last_sent_;
  std::optional<tools::ViewerGaze> last_shown_;
  tools::GazePoint last_gaze_;
  bool robot_said_bye_ = false;
  std::string robot_address_;
  std::optional<net::StatusReport> last_status_;
  net::OperatorLinkCounters link_total_{};
  // Arrival times of the chunks the assembler decoded into frames, in order. A
  // frame's decoded chunks are contiguous in it (the assembler holds one frame
  // in progress), so a completed frame's are the first ones; the robot sends
  // the fovea's chunks first, so in send order (loopback) the fovea was decoded
  // at the arrival of its chunks_received[0]-th chunk. Bounded: at most one
  // frame's chunks (65536) and one more are kept.
  std::deque<int64_t> chunk_arrivals_;
};

}  // namespace fovea::tools
